"""The pure orchestrator: typed samples in, outputs out (no I/O, no clock, no MAVLink).

* :mod:`~companion.engine.core`: :class:`Engine`, the dispatch of samples, the
  publication clock, the local frame and the persistent state;
* :mod:`~companion.engine.config`: :class:`EngineConfig`, the ``[engine]`` block;
* :mod:`~companion.engine.navigators`: which navigator carries the solution;
* :mod:`~companion.engine.bridge`: the position-potential filter through GNSS gaps;
* :mod:`~companion.engine.publish`: what a publication tick publishes;
* :mod:`~companion.engine.silence`: the autopilot's data silent, no GNSS at all.
"""

from companion.engine.config import NAVIGATORS, EngineConfig
from companion.engine.core import LIVE_KEYS, Engine, EngineStats

__all__ = ["LIVE_KEYS", "NAVIGATORS", "Engine", "EngineConfig", "EngineStats"]

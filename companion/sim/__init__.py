"""Flight and sensor simulator: trajectories, IMU/GNSS/attitude models, MAVLink fixtures.

``make_scenario(name, **overrides)`` gives a :class:`Scenario`;
``simulate(scenario, seed)`` flies it and returns a :class:`SimFlight` (truth,
typed samples, MAVLink messages); ``write_scenario`` writes the .tlog, the truth
CSV and the JSON sidecar that ``companion simulate`` produces.

* :mod:`~companion.sim.scenarios` — what to fly, scheduled events, the named catalogue;
* :mod:`~companion.sim.trajectory` — the smooth flight path from a phase script;
* :mod:`~companion.sim.sensors` — IMU, GNSS and attitude error models;
* :mod:`~companion.sim.autopilot` — the autopilot's MAVLink messages and their samples;
* :mod:`~companion.sim.realism` — an autopilot as imperfect as a real one: switches and
  the ``realistic`` profiles; :mod:`~companion.sim.realism_stats` — the statistics
  ``bench/realism.py`` compares with the real logs;
* :mod:`~companion.sim.flight` — :func:`simulate`;
* :mod:`~companion.sim.writer` — the .tlog, truth CSV and sidecar;
* :mod:`~companion.sim.costs` — what an integer IMU message costs a free-running INS;
* :mod:`~companion.sim.integrity_approaches`, :mod:`~companion.sim.integrity_runs` —
  the integrity monitor on synthetic approaches and on simulated flights (tests and
  ``bench/integrity.py``).

A tool layer above the core: it may import the navigation and integrity
packages; nothing in them imports it. ``docs/replay.md`` (the fixtures).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from companion.sim.flight import SimFlight, Truth, TruthPoint, simulate
from companion.sim.scenarios import SCENARIO_NAMES, Event, Scenario, describe, make_scenario

__all__ = [
    "SCENARIO_NAMES",
    "Event",
    "Scenario",
    "SimFlight",
    "Truth",
    "TruthPoint",
    "describe",
    "make_scenario",
    "simulate",
    "write_scenario",
]


def write_scenario(
    name: str,
    out_dir: Path,
    seed: int = 1,
    duration_s: float | None = None,
    **overrides: Any,
) -> list[Path]:
    """Simulate a named scenario and write ``<name>.tlog``, ``.truth.csv``, ``.json``.

    Raises
    ------
    ValueError
        Unknown scenario or field, negative/zero duration, negative seed.
    """
    from companion.sim.writer import write_flight

    if duration_s is not None:
        if not (isinstance(duration_s, int | float) and math.isfinite(duration_s)):
            raise ValueError(f"duration must be a finite number of seconds, got {duration_s!r}")
        if duration_s <= 0:
            raise ValueError(f"duration must be positive, got {duration_s}")
        overrides["duration_s"] = float(duration_s)
    if not isinstance(seed, int) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    sc = make_scenario(name, **overrides)
    flight = simulate(sc, seed)
    return write_flight(flight, Path(out_dir))

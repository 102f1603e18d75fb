"""Integrity: fault detection and exclusion, then protection levels and alerts.

* :mod:`~companion.integrity.fde` — fault detection and exclusion per GNSS fix:
  fix-level tests, solution separation with Kim, Walter and Powell's slope and
  residual tests (thresholds from false-alarm probabilities), attribution of a
  fault to a receiver, exclusion.
* :mod:`~companion.integrity.coast` — coasting free-inertial references: INS
  predictions free of recent fixes, separated against each receiver.
* :mod:`~companion.integrity.protection` — per published solution: flight phase,
  HPL / VPL from the covariance (DO-229), alert limits per phase and approach
  category, the integrity and category alerts and reports.
* :mod:`~companion.integrity.monitor` — :class:`IntegrityMonitor`, what the engine
  calls per fix (:meth:`~IntegrityMonitor.on_fix`) and per published solution
  (:meth:`~IntegrityMonitor.on_solution`), composing the two;
  :mod:`~companion.integrity.config` its settings.

Synthetic approaches and simulated flights through the monitor, for the tests
and ``bench/integrity.py``, are in :mod:`companion.sim.integrity_approaches` and
:mod:`companion.sim.integrity_runs`. Method notes: ``docs/methods.md``.

Pure like the rest of the core: no I/O, no clock.
"""

from companion.integrity.coast import CoastConfig, CoastState, InertialCoast
from companion.integrity.config import IntegrityConfig
from companion.integrity.monitor import IntegrityMonitor
from companion.integrity.protection.limits import (
    CATEGORY_ACCURACY,
    CATEGORY_LIMITS,
    ApproachCategory,
    FlightPhase,
)
from companion.integrity.protection.phase import PhaseConfig

__all__ = [
    "CATEGORY_ACCURACY",
    "CATEGORY_LIMITS",
    "ApproachCategory",
    "CoastConfig",
    "CoastState",
    "FlightPhase",
    "InertialCoast",
    "IntegrityConfig",
    "IntegrityMonitor",
    "PhaseConfig",
]

"""Integrity: fault detection and exclusion, solution separation, protection and alert limits.

* :mod:`~companion.integrity.limits` — requirement tables (alert limits per flight
  phase and approach category, 95 % accuracies), each row with its source.
* :mod:`~companion.integrity.protection` — HPL / VPL from the solution covariance,
  K factors from the integrity risk (DO-229).
* :mod:`~companion.integrity.phase` — taxi / take-off / en-route / approach / landing
  from the state.
* :mod:`~companion.integrity.separation` — solution separation with S3's slope and
  residual tests, thresholds derived from false-alarm probabilities.
* :mod:`~companion.integrity.monitor` — :class:`IntegrityMonitor`, what the engine
  calls per fix (:meth:`~IntegrityMonitor.on_fix`) and per published solution
  (:meth:`~IntegrityMonitor.on_solution`).
* :mod:`~companion.integrity.synthetic` — synthetic approaches with injected faults
  and a sample-driven run, for the tests and ``bench/integrity.py``.

Pure like the rest of the core: no I/O, no clock.
"""

from companion.integrity.limits import ApproachCategory, FlightPhase
from companion.integrity.monitor import IntegrityConfig, IntegrityMonitor

__all__ = ["ApproachCategory", "FlightPhase", "IntegrityConfig", "IntegrityMonitor"]

"""Fault detection and exclusion: every GNSS fix tested, a faulty receiver excluded.

* :mod:`~companion.integrity.fde.fix_tests` — the fix against the navigator's
  innovation and the position potential's prediction (steps);
* :mod:`~companion.integrity.fde.separation` — solution separation of one pair of
  solutions: snapshot, slope (ramps) and residual (dithering) tests;
* :mod:`~companion.integrity.fde.thresholds` — the window tests' thresholds for
  time-correlated errors;
* :mod:`~companion.integrity.fde.pairs` — which solutions are separated:
  receiver pairs, receivers against the references;
* :mod:`~companion.integrity.fde.attribution` — which receiver a failed test blames;
* :mod:`~companion.integrity.fde.receivers` — what is kept per receiver;
* :mod:`~companion.integrity.fde.detector` — :class:`FaultDetector`, the per-fix
  sequence, exclusion and unresolved faults.
"""

"""Protection levels and alerts: whether the published solution can be trusted, for what.

* :mod:`~companion.integrity.protection.levels` — HPL / VPL and the 95 %
  accuracies from the solution covariance, K factors from the integrity risk
  (DO-229);
* :mod:`~companion.integrity.protection.limits` — requirement tables: alert limits
  per flight phase and approach category, 95 % accuracies, each row with its source;
* :mod:`~companion.integrity.protection.phase` — taxi / take-off / en-route /
  approach / landing from the state;
* :mod:`~companion.integrity.protection.alerts` — :class:`AlertState`, the
  integrity and category alerts and the periodic reports.
"""

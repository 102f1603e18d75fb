"""Fix-level tests: one GNSS fix against the navigator's innovation and the potential's prediction.

* **Innovation**: the navigator's own innovation chi-square (NIS) of the fix,
  against ``chi2^-1(1 - P_fa, dof)``.
* **Ellipsoid**: the fix against the position-potential filter's prediction
  (Grzegorzewski (2005), "Navigating by a position potential in 3-D"):
  ``d^T (P_pred + R)^-1 d`` with ``d`` the fix less the prediction carried to the
  fix time with its velocity, against ``chi2^-1(1 - P_fa, 3)``.

A navigator that fuses a receiver follows a slow ramp of it (its innovation
stays small): these tests catch steps; ramps and dithers are left to solution
separation (:mod:`companion.integrity.fde.separation`).
"""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
from scipy.stats import chi2

from companion.nav.navigator import GnssMeasurement, GnssUpdate, NavState


def valid_measurement(meas: GnssMeasurement) -> bool:
    """Finite time, position and variance, and every variance > 0."""
    # on Python floats, not numpy reductions: this runs on every fix
    var = meas.pos_var_ned_m2.tolist()
    return (
        all(map(math.isfinite, meas.pos_ned_m.tolist()))
        and all(map(math.isfinite, var))
        and min(var) > 0.0
        and math.isfinite(meas.t_s)
    )


class FixTests:
    """The innovation and ellipsoid tests at one false-alarm probability.

    ``stats`` (shared with the rest of the monitor) counts failures
    (``fix_innovation``, ``fix_ellipsoid``) and unusable inputs.
    """

    def __init__(self, false_alarm_prob: float, stats: Counter[str]) -> None:
        self.false_alarm_prob = false_alarm_prob
        self.stats = stats
        self._chi2_cache: dict[int, float] = {}

    def chi2_threshold(self, dof: int) -> float:
        """``chi2^-1(1 - P_fa, dof)`` (cached per dof)."""
        th = self._chi2_cache.get(dof)
        if th is None:
            th = float(chi2.isf(self.false_alarm_prob, dof))
            self._chi2_cache[dof] = th
        return th

    def run(
        self, meas: GnssMeasurement, update: GnssUpdate | None, predicted: NavState | None
    ) -> tuple[bool, list[str]]:
        """Test one fix: whether the innovation test failed, and every failure in words.

        ``update``: what the navigator did with the fix (None: not offered);
        ``predicted``: the potential filter's prediction (None: no ellipsoid test).
        """
        reasons: list[str] = []
        innov_failed = False
        if update is not None and update.dof > 0:
            if math.isfinite(update.nis):
                th = self.chi2_threshold(update.dof)
                if update.nis > th:
                    self.stats["fix_innovation"] += 1
                    innov_failed = True
                    reasons.append(f"innovation chi2 {update.nis:.1f} > {th:.1f}")
            else:
                self.stats["bad_update"] += 1
        if predicted is not None:
            dt = meas.t_s - predicted.t_s
            pred_pos = predicted.pos_ned_m + np.nan_to_num(predicted.vel_ned_mps) * dt
            innov = meas.pos_ned_m - pred_pos
            s_cov = predicted.pos_cov_ned_m2 + np.diag(meas.pos_var_ned_m2)
            try:
                stat = float(innov @ np.linalg.solve(s_cov, innov))
            except np.linalg.LinAlgError:
                self.stats["bad_prediction"] += 1
                return innov_failed, reasons
            if not math.isfinite(stat):
                self.stats["bad_prediction"] += 1
                return innov_failed, reasons
            th = self.chi2_threshold(3)
            if stat > th:
                self.stats["fix_ellipsoid"] += 1
                reasons.append(f"potential ellipsoid chi2 {stat:.1f} > {th:.1f}")
        return innov_failed, reasons

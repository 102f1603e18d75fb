"""Vertical solution separation: a receiver's height against the calibrated barometer.

The barometer (:mod:`companion.nav.baro`) is an independent height: a receiver's
slow vertical ramp or vertical dither shows in ``s(t) = h_gnss(t) - h_baro(t)``
(m) although nothing else disagrees with one receiver. The three tests of
:mod:`companion.integrity.fde.separation` (Kim, Walter and Powell), on one axis,
with the barometer's error model:

* ``s`` = the receiver's height error (variance ``sigma_g^2``, the receiver's
  report, correlated in time, correlation unknown) + the barometer's white noise
  (``sigma_w^2``, measured) + its calibration offset (``P_bb``, constant over a
  window) + the offset's rate times time (``P_dd``: a slope);
* **snapshot**: ``s^2 / (sigma_g^2 + sigma_w^2 + P_bb) > chi2^-1(1 - P_fa, 1)``;
* **slope** over ``window_s``: the least-squares slope ``b`` of ``s`` against
  ``K_s sqrt(sigma_w^2 sigma_b^2 + P_dd)``, ``sigma_b^2 = max_tau w^T (I + rho C(tau)) w``,
  ``rho = sigma_g^2 / sigma_w^2``, ``C(tau)_ij = exp(-|t_i - t_j| / tau)``;
* **residual**: the residual sum of squares of ``s / sigma_w`` about that line
  against the moment-matched ``g chi2(h)`` of ``M (I + rho C(tau)) M`` at the worst tau
  (Satterthwaite 1946; :mod:`companion.integrity.fde.thresholds` for the receivers'
  pairs, which assume the whole error correlated).

The white part is white for certain (the second differences measure it), so only
the receiver's part is taken at its worst correlation: far tighter thresholds than
a fully correlated model, which could not tell a 4 cm/s ramp from 0.2 m of noise
over a window. ``rho`` is rounded up to a grid (a larger correlated part only raises
both thresholds), which caches them. A window whose fixes are not regularly spaced
skips the window tests (counted by the caller).

References
----------
Kim, Walter and Powell, "Standalone GPS-based flight inspection system" (slope and
residual tests). Satterthwaite, Biometrics Bulletin 2(6), 1946.
"""

from __future__ import annotations

import functools
import math
from collections import deque

import numpy as np
from scipy.stats import chi2, norm

from companion.integrity.fde.separation import SeparationResult
from companion.integrity.fde.thresholds import (
    REGULAR_SPACING_TOLERANCE,
    TAU_GRID_POINTS,
    TAU_GRID_SPAN_WINDOWS,
)

RHO_STEPS_PER_DECADE = 8
"""Grid of the correlated-to-white variance ratio (rounded up to it)."""
RHO_MIN = 1e-3
"""Smallest ratio used: a receiver's part below it is taken as this."""
DT_STEPS_PER_DECADE = 32
"""Grid of the sampling interval (rounded down to it: a shorter interval for the same
number of samples only raises the slope threshold), which caches the thresholds of a
receiver whose interval jitters by a few milliseconds."""


def dt_grid_ms(dt_s: float) -> int:
    """``dt_s`` in whole milliseconds rounded down to the grid of
    :data:`DT_STEPS_PER_DECADE` per decade (at least 1 ms)."""
    ms = max(dt_s * 1e3, 1.0)
    k = math.floor(DT_STEPS_PER_DECADE * math.log10(ms) + 1e-9)
    return max(1, math.floor(10.0 ** (k / DT_STEPS_PER_DECADE) + 1e-9))


def rho_grid(rho: float) -> float:
    """``rho`` rounded up to the grid of :data:`RHO_STEPS_PER_DECADE` per decade."""
    r = max(rho, RHO_MIN)
    return 10.0 ** (math.ceil(RHO_STEPS_PER_DECADE * math.log10(r) - 1e-9) / RHO_STEPS_PER_DECADE)


@functools.lru_cache(maxsize=512)
def _traces(n: int, dt_ms: int) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """For ``n`` samples ``dt_ms`` apart, per correlation time of the grid: ``w^T w`` and
    ``w^T C w`` (slope variances of the white and the correlated part), ``tr B`` and
    ``tr B^2`` with ``B = M C M`` (``M`` the line fit's residual maker)."""
    t = np.arange(n, dtype=float) * (dt_ms * 1e-3)
    tc = t - t.mean()
    sxx = float(tc @ tc)
    w = tc / sxx
    x_mat = np.column_stack((np.ones(n), tc))
    g_mat = np.linalg.inv(x_mat.T @ x_mat)
    lag = np.abs(t[:, None] - t[None, :])
    span = float(t[-1] - t[0])
    lo = max(span / (n - 1) / 4.0, 1e-3)
    taus = np.geomspace(lo, max(TAU_GRID_SPAN_WINDOWS * span, 10.0 * lo), TAU_GRID_POINTS)
    c = np.exp(-lag[None, :, :] / taus[:, None, None])  # (taus, n, n)
    wcw = np.einsum("i,kij,j->k", w, c, w)
    cx = c @ x_mat  # (taus, n, 2)
    gxcx = g_mat @ (x_mat.T @ cx)  # (taus, 2, 2)
    tr_b = float(n) - (gxcx[:, 0, 0] + gxcx[:, 1, 1])
    cxcx = g_mat @ (cx.transpose(0, 2, 1) @ cx)
    gg = gxcx @ gxcx
    tr_b2 = (c * c).reshape(taus.size, n * n).sum(axis=1)
    tr_b2 = tr_b2 - 2.0 * (cxcx[:, 0, 0] + cxcx[:, 1, 1]) + (gg[:, 0, 0] + gg[:, 1, 1])
    return float(w @ w), wcw, tr_b, tr_b2


@functools.lru_cache(maxsize=4096)
def vertical_thresholds(
    n: int, dt_ms: int, rho: float, slope_false_alarm_prob: float, residual_false_alarm_prob: float
) -> tuple[float, float, float]:
    """For ``n`` samples ``dt_ms`` apart of ``white + correlated`` noise (white variance 1,
    correlated ``rho``): the worst-case slope sigma (1/s), ``K_s`` and the residual
    threshold (in white variances). See the module docstring."""
    if n < 3 or dt_ms <= 0:
        raise ValueError("need n >= 3 samples at dt_ms > 0")
    ww, wcw, tr_b, tr_b2 = _traces(n, dt_ms)
    sb2 = ww + rho * float(wcw.max())
    # A = M (I + rho C) M = M + rho B (M idempotent, tr M = n - 2)
    tr_a = (n - 2) + rho * tr_b
    tr_a2 = (n - 2) + 2.0 * rho * tr_b + rho * rho * tr_b2
    g, h = tr_a2 / tr_a, tr_a * tr_a / tr_a2
    rss = float((g * chi2.isf(residual_false_alarm_prob, h)).max())
    k_s = float(norm.isf(slope_false_alarm_prob / 2.0))
    return math.sqrt(sb2), k_s, rss


class VerticalSeparation:
    """The series of one receiver's height less the barometer's and its three tests."""

    def __init__(
        self,
        window_s: float,
        min_points: int,
        snapshot_false_alarm_prob: float,
        slope_false_alarm_prob: float,
        residual_false_alarm_prob: float,
    ) -> None:
        if not (math.isfinite(window_s) and window_s > 0.0) or min_points < 3:
            raise ValueError("window_s must be > 0 and min_points >= 3")
        self.window_s = window_s
        self.min_points = min_points
        self.p_slope = slope_false_alarm_prob
        self.p_rss = residual_false_alarm_prob
        self.snapshot_threshold = float(chi2.isf(snapshot_false_alarm_prob, 1))
        self._win: deque[tuple[float, float, float, float]] = deque()
        """(t_s, separation m, white variance m^2, receiver variance m^2)."""
        self.irregular = 0
        """Windows whose spacing skipped the window tests."""

    def reset(self) -> None:
        """Empty the window."""
        self._win.clear()

    def update(
        self,
        t_s: float,
        sep_m: float,
        gnss_var_m2: float,
        white_var_m2: float,
        offset_var_m2: float,
        drift_var_m2ps2: float,
    ) -> SeparationResult:
        """Add one separation (receiver height less barometric, m) and test; ``ValueError``
        for a non-finite or non-positive input."""
        vals = (t_s, sep_m, gnss_var_m2, white_var_m2, offset_var_m2, drift_var_m2ps2)
        if not all(map(math.isfinite, vals)) or min(gnss_var_m2, white_var_m2) <= 0.0:
            raise ValueError("vertical separation or its variances not finite and > 0")
        win = self._win
        if win and t_s <= win[-1][0]:
            win.clear()
        win.append((t_s, sep_m, white_var_m2, gnss_var_m2))
        while win[0][0] < t_s - self.window_s:
            win.popleft()
        snap = sep_m * sep_m / (gnss_var_m2 + white_var_m2 + max(offset_var_m2, 0.0))
        reasons: list[str] = []
        if snap > self.snapshot_threshold:
            reasons.append(
                f"separation {abs(sep_m):.2f} m chi2 {snap:.1f} > {self.snapshot_threshold:.1f}"
            )
        n = len(win)
        slope = math.nan
        slope_ratio = rss_ratio = math.nan
        if n >= self.min_points and win[-1][0] - win[0][0] >= 0.5 * self.window_s:
            tests = self._window_tests(n, max(drift_var_m2ps2, 0.0), reasons)
            if tests is not None:
                slope, slope_ratio, rss_ratio = tests
        return SeparationResult(
            float(t_s), np.array([0.0, 0.0, sep_m]), snap, self.snapshot_threshold,
            np.array([0.0, 0.0, slope]), slope_ratio, rss_ratio, n, tuple(reasons),
        )  # fmt: skip

    def _window_tests(
        self, n: int, drift_var: float, reasons: list[str]
    ) -> tuple[float, float, float] | None:
        arr = np.array(self._win)
        t, s = arr[:, 0], arr[:, 1]
        mean_dt = float(t[-1] - t[0]) / (n - 1)
        dt = np.diff(t)
        tol = REGULAR_SPACING_TOLERANCE * mean_dt
        if float(dt.max()) - mean_dt > tol or mean_dt - float(dt.min()) > tol:
            self.irregular += 1
            return None
        white = float(arr[:, 2].mean())
        rho = rho_grid(float(arr[:, 3].mean()) / white)
        sb, k_s, rss_th = vertical_thresholds(n, dt_grid_ms(mean_dt), rho, self.p_slope, self.p_rss)
        tc = t - t.mean()
        sxx = float(tc @ tc)
        b = float(tc @ s) / sxx
        sc = s - s.mean()
        rss = max(float(sc @ sc) - b * b * sxx, 0.0) / white
        slope_th = k_s * math.sqrt(white * sb * sb + drift_var)
        slope_ratio = abs(b) / slope_th
        rss_ratio = rss / rss_th
        if slope_ratio > 1.0:
            reasons.append(f"slope D {100.0 * b:.1f} cm/s > {100.0 * slope_th:.1f}")
        if rss_ratio > 1.0:
            reasons.append(f"residual D rss {rss:.0f} > {rss_th:.0f} sigma2")
        return b, slope_ratio, rss_ratio

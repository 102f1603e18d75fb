"""Solution separation with S3's slope and residual tests on a sliding window.

Two position solutions that do not share a fault source (receiver 0 and
receiver 1, a receiver and an inertial solution coasting from an older
reset, ...) must agree to within their combined covariance. For one such pair
the signed separation ``s(t) = p_a(t) - p_b(t)`` (NED, m, covariance
``C = P_a + P_b`` when the errors are independent) is tested three ways:

1. **Snapshot** (every epoch): ``s^T C^-1 s > chi2^-1(1 - P_fa, 3)`` catches
   steps at once.
2. **Slope** (S3, ramps): per axis, the separation normalised by its sigma,
   ``z_k = s_k / sigma_k``, is fitted by a straight line over the last
   ``window_s``; the fitted slope ``b`` is tested against
   ``K_s * sigma_b`` with ``K_s = Phi^-1(1 - P_s / 2)``.
3. **Residual** (S3, dithering): the residual sum of squares about that line
   is tested against ``sigma^2 * chi2^-1(1 - P_r, n - 2)`` (S3's threshold;
   ``z`` has unit variance, so sigma = 1 here).

S3 states the tests for white errors. GNSS position errors are correlated in
time (first-order Gauss-Markov with a correlation time that depends on the
mode, S1 and the simulator's model), which changes both statistics. The
thresholds are therefore derived for a unit-variance process with
correlation ``exp(-|dt| / tau)`` and taken at the **worst tau** over a grid
from 0 (white: S3's own formulas exactly) to 50 windows:

* slope: ``sigma_b^2(tau) = w^T R(tau) w`` with ``w = (t - mean t) / sum (t - mean t)^2``;
  because it is linear in ``R``, the maximum over tau also bounds any mixture
  of exponential kernels;
* residual: ``RSS = z^T M z`` with ``M`` the residual maker of the line fit is
  a generalised chi-square with matrix ``A = M R M``; it is approximated by
  ``g * chi2(h)`` with the same mean and variance (Welch-Satterthwaite:
  ``g = tr(A^2)/tr(A)``, ``h = tr(A)^2/tr(A^2)``), which for white errors is
  ``chi2(n - 2)``.

No threshold is a tuned literal: each comes from a false-alarm probability,
the window length and the sampling.

References
----------
SEEDS.md S3 (Kim, Walter, Powell: FIS-RAIM solution separation; slope of a
straight-line fit for slow ramps such as a 4 cm/s clock ramp; residual sum of
squares against (30 cm)^2 chi2^-1(95 %, n - 2) for a 1 m dither).
Satterthwaite, Biometrics Bulletin 2(6), 1946 (moment-matched chi-square).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2, norm

from companion.types import FloatArray

AXES = ("N", "E", "D")
TAU_GRID_POINTS = 48
"""Number of correlation times in the worst-case search (log-spaced, plus white)."""
TAU_GRID_SPAN_WINDOWS = 50.0
"""The longest correlation time searched, in window lengths (beyond it the process is a
constant over the window: slope and residual vanish)."""
REGULAR_SPACING_TOLERANCE = 0.5
"""A window whose intervals stay within (1 +- this) x their mean uses the cached
thresholds of a regular grid; otherwise they are computed for the actual times."""


@dataclass(frozen=True, slots=True)
class WindowThresholds:
    """Thresholds of the window tests for a unit-variance separation.

    ``slope_sigma_per_s``: worst-case standard deviation of the fitted slope,
    1/s (in sigmas per second). ``slope_threshold_per_s``: ``K_s`` times it.
    ``rss_threshold``: residual sum of squares threshold (in sigma^2).
    ``tau_slope_s`` / ``tau_rss_s``: the correlation times that set them.
    """

    n: int
    slope_sigma_per_s: float
    slope_threshold_per_s: float
    rss_threshold: float
    tau_slope_s: float
    tau_rss_s: float


def _tau_grid(span_s: float, dt_s: float) -> FloatArray:
    lo = max(dt_s / 4.0, 1e-3)
    hi = max(TAU_GRID_SPAN_WINDOWS * span_s, 10.0 * lo)
    return np.concatenate(([0.0], np.geomspace(lo, hi, TAU_GRID_POINTS)))


def thresholds_for_times(
    t_s: FloatArray, slope_false_alarm_prob: float, residual_false_alarm_prob: float
) -> WindowThresholds:
    """Worst-case window thresholds for samples at times ``t_s`` (shape (n,), n >= 3).

    References
    ----------
    S3 (slope and residual tests); module docstring for the derivation.
    """
    t = np.asarray(t_s, dtype=float)
    n = t.size
    if n < 3:
        raise ValueError("the window tests need at least 3 samples")
    for p in (slope_false_alarm_prob, residual_false_alarm_prob):
        if not 0.0 < p < 1.0:
            raise ValueError("false-alarm probabilities must be in (0, 1)")
    tc = t - t.mean()
    sxx = float(tc @ tc)
    if sxx <= 0.0:
        raise ValueError("window times must not all be equal")
    w = tc / sxx
    x_mat = np.column_stack((np.ones(n), tc))  # the line's design matrix, (n, 2)
    g_mat = np.linalg.inv(x_mat.T @ x_mat)  # (2, 2)
    lag = np.abs(t[:, None] - t[None, :])
    span = float(t[-1] - t[0])
    k_slope = float(norm.isf(slope_false_alarm_prob / 2.0))
    best_sb2, tau_sb = -1.0, 0.0
    best_rss, tau_rss = -1.0, 0.0
    for tau in _tau_grid(span, span / (n - 1)):
        corr = np.eye(n) if tau == 0.0 else np.exp(-lag / tau)
        sb2 = float(w @ corr @ w)
        if sb2 > best_sb2:
            best_sb2, tau_sb = sb2, float(tau)
        # traces of A = M R M (M = I - H, H = X G X^T) in O(n^2):
        # tr A = tr R - tr(G X^T R X); tr A^2 = tr R^2 - 2 tr(G (RX)^T (RX)) + tr((G X^T R X)^2)
        rx = corr @ x_mat
        xrx = x_mat.T @ rx
        gxrx = g_mat @ xrx
        tr_a = float(np.trace(corr) - np.trace(gxrx))
        tr_a2 = float(
            np.sum(corr * corr) - 2.0 * np.trace(g_mat @ (rx.T @ rx)) + np.trace(gxrx @ gxrx)
        )
        if tr_a <= 0.0 or tr_a2 <= 0.0:
            continue
        g = tr_a2 / tr_a
        h = tr_a * tr_a / tr_a2
        rss_th = g * float(chi2.isf(residual_false_alarm_prob, h))
        if rss_th > best_rss:
            best_rss, tau_rss = rss_th, float(tau)
    sb = math.sqrt(best_sb2)
    return WindowThresholds(n, sb, k_slope * sb, best_rss, tau_sb, tau_rss)


@functools.lru_cache(maxsize=256)
def thresholds_regular(
    n: int, dt_ms: int, slope_false_alarm_prob: float, residual_false_alarm_prob: float
) -> WindowThresholds:
    """:func:`thresholds_for_times` for ``n`` samples ``dt_ms`` milliseconds apart (cached)."""
    if dt_ms <= 0:
        raise ValueError("dt_ms must be > 0")
    t = np.arange(n, dtype=float) * (dt_ms * 1e-3)
    return thresholds_for_times(t, slope_false_alarm_prob, residual_false_alarm_prob)


@dataclass(frozen=True, slots=True)
class SeparationResult:
    """The tests of one pair at one epoch.

    ``sep_ned_m`` (3,) the separation; ``snapshot_stat`` its chi-square (3 dof);
    ``slope_mps`` (3,) fitted slope per axis (NaN until the window is usable);
    ``slope_ratio`` / ``rss_ratio``: the largest per-axis statistic over its
    threshold (> 1 fails; NaN until the window is usable). ``reasons`` lists
    the failed tests in words.
    """

    t_s: float
    sep_ned_m: FloatArray
    snapshot_stat: float
    snapshot_threshold: float
    slope_mps: FloatArray
    slope_ratio: float
    rss_ratio: float
    window_points: int
    reasons: tuple[str, ...]

    @property
    def failed(self) -> bool:
        """True when any test failed."""
        return bool(self.reasons)

    @property
    def snapshot_failed(self) -> bool:
        """True when the snapshot (step) test failed."""
        return self.snapshot_stat > self.snapshot_threshold


class SeparationTracker:
    """The separation time series of one pair of solutions and its three tests.

    Parameters
    ----------
    window_s : length of the sliding window, s.
    min_points : the window tests run once the window holds this many samples
        spanning at least half of ``window_s``.
    snapshot_false_alarm_prob, slope_false_alarm_prob, residual_false_alarm_prob :
        per-test false-alarm probabilities.
    """

    def __init__(
        self,
        window_s: float,
        min_points: int,
        snapshot_false_alarm_prob: float,
        slope_false_alarm_prob: float,
        residual_false_alarm_prob: float,
    ) -> None:
        if not (math.isfinite(window_s) and window_s > 0.0):
            raise ValueError("window_s must be finite and > 0")
        if min_points < 3:
            raise ValueError("min_points must be >= 3")
        for p in (snapshot_false_alarm_prob, slope_false_alarm_prob, residual_false_alarm_prob):
            if not 0.0 < p < 1.0:
                raise ValueError("false-alarm probabilities must be in (0, 1)")
        self.window_s = window_s
        self.min_points = min_points
        self.p_slope = slope_false_alarm_prob
        self.p_rss = residual_false_alarm_prob
        self.snapshot_threshold = float(chi2.isf(snapshot_false_alarm_prob, 3))
        self._cap = 256
        self._t = np.zeros(self._cap)
        self._z = np.zeros((self._cap, 3))
        self._sigma = np.zeros((self._cap, 3))
        self._start = 0
        self._end = 0

    def reset(self) -> None:
        """Empty the window."""
        self._start = 0
        self._end = 0

    def _append(self, t_s: float, z: FloatArray, sigma: FloatArray) -> None:
        if self._end == self._cap:
            live = self._end - self._start
            if live > self._cap // 2:  # grow: a window denser than expected
                self._cap *= 2
                self._t = np.concatenate((self._t, np.zeros(self._cap - self._t.size)))
                self._z = np.vstack((self._z, np.zeros((self._cap - self._z.shape[0], 3))))
                self._sigma = np.vstack(
                    (self._sigma, np.zeros((self._cap - self._sigma.shape[0], 3)))
                )
            self._t[:live] = self._t[self._start : self._end]
            self._z[:live] = self._z[self._start : self._end]
            self._sigma[:live] = self._sigma[self._start : self._end]
            self._start, self._end = 0, live
        self._t[self._end] = t_s
        self._z[self._end] = z
        self._sigma[self._end] = sigma
        self._end += 1
        while self._t[self._start] < t_s - self.window_s:
            self._start += 1

    def rotate(self, rot: FloatArray) -> None:
        """Re-express the stored separations with a (3, 3) frame rotation (re-anchoring).

        The normalised series cannot be rotated exactly axis by axis; the window
        is restarted instead (it refills in ``window_s``).
        """
        if rot.shape != (3, 3):
            raise ValueError("rot must be (3, 3)")
        self.reset()

    @property
    def last_t_s(self) -> float | None:
        """Time of the newest sample, None when empty."""
        return float(self._t[self._end - 1]) if self._end > self._start else None

    def update(self, t_s: float, sep_ned_m: FloatArray, cov_ned_m2: FloatArray) -> SeparationResult:
        """Add one separation (m, (3,)) with its covariance (m^2, (3, 3)) and test.

        A non-finite or non-positive-definite input raises ``ValueError`` (the
        monitor rejects and counts such pairs before calling).
        """
        sep = np.asarray(sep_ned_m, dtype=float)
        cov = np.asarray(cov_ned_m2, dtype=float)
        if sep.shape != (3,) or cov.shape != (3, 3):
            raise ValueError("sep_ned_m must be (3,) and cov_ned_m2 (3, 3)")
        if not (np.all(np.isfinite(sep)) and np.all(np.isfinite(cov))):
            raise ValueError("separation or covariance not finite")
        try:
            chol = np.linalg.cholesky(cov)
        except np.linalg.LinAlgError as exc:
            raise ValueError("separation covariance not positive definite") from exc
        white = np.linalg.solve(chol, sep)
        snap = float(white @ white)
        sigma = np.sqrt(np.diag(cov))
        last = self.last_t_s
        if last is not None and t_s <= last:
            self.reset()  # time went backwards or repeated: restart the series
        self._append(float(t_s), sep / sigma, sigma)
        reasons: list[str] = []
        if snap > self.snapshot_threshold:
            reasons.append(
                f"separation {np.linalg.norm(sep):.2f} m chi2 {snap:.1f} > "
                f"{self.snapshot_threshold:.1f}"
            )
        slope_mps = np.full(3, np.nan)
        slope_ratio = math.nan
        rss_ratio = math.nan
        n = self._end - self._start
        t = self._t[self._start : self._end]
        if n >= self.min_points and (t[-1] - t[0]) >= 0.5 * self.window_s:
            z = self._z[self._start : self._end]
            th = self._thresholds(t)
            tc = t - t.mean()
            sxx = float(tc @ tc)
            b = (tc @ z) / sxx
            resid = z - z.mean(axis=0) - np.outer(tc, b)
            rss = np.sum(resid * resid, axis=0)
            mean_sigma = self._sigma[self._start : self._end].mean(axis=0)
            slope_mps = b * mean_sigma
            ratios_s = np.abs(b) / th.slope_threshold_per_s
            ratios_r = rss / th.rss_threshold
            slope_ratio = float(ratios_s.max())
            rss_ratio = float(ratios_r.max())
            if slope_ratio > 1.0:
                i = int(np.argmax(ratios_s))
                reasons.append(
                    f"slope {AXES[i]} {100.0 * slope_mps[i]:.1f} cm/s > "
                    f"{100.0 * th.slope_threshold_per_s * mean_sigma[i]:.1f}"
                )
            if rss_ratio > 1.0:
                i = int(np.argmax(ratios_r))
                reasons.append(
                    f"residual {AXES[i]} rss {rss[i]:.0f} > {th.rss_threshold:.0f} sigma2"
                )
        return SeparationResult(
            t_s=float(t_s),
            sep_ned_m=sep,
            snapshot_stat=snap,
            snapshot_threshold=self.snapshot_threshold,
            slope_mps=slope_mps,
            slope_ratio=slope_ratio,
            rss_ratio=rss_ratio,
            window_points=n,
            reasons=tuple(reasons),
        )

    def _thresholds(self, t: FloatArray) -> WindowThresholds:
        n = t.size
        dt = np.diff(t)
        mean_dt = float(t[-1] - t[0]) / (n - 1)
        if np.all(np.abs(dt - mean_dt) <= REGULAR_SPACING_TOLERANCE * mean_dt):
            dt_ms = max(1, round(mean_dt * 1e3))
            return thresholds_regular(n, dt_ms, self.p_slope, self.p_rss)
        return thresholds_for_times(t, self.p_slope, self.p_rss)

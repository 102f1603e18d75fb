"""Solution separation: one pair of solutions, its series and its three tests.

Two position solutions that do not share a fault source (receiver 0 and
receiver 1, a receiver and an inertial solution coasting from an older
reset, ...) must agree to within their combined covariance. For one such pair
the signed separation ``s(t) = p_a(t) - p_b(t)`` (NED, m, covariance
``C = P_a + P_b`` when the errors are independent) is tested three ways
(Kim, Walter and Powell):

1. **Snapshot** (every epoch): ``s^T C^-1 s > chi2^-1(1 - P_fa, 3)`` catches
   steps at once.
2. **Slope** (ramps): per axis, the separation normalised by its sigma,
   ``z_k = s_k / sigma_k``, is fitted by a straight line over the last
   ``window_s``; the fitted slope ``b`` is tested against
   ``K_s * sigma_b`` with ``K_s = Phi^-1(1 - P_s / 2)``.
3. **Residual** (dithering): the residual sum of squares about that line
   is tested against ``sigma^2 * chi2^-1(1 - P_r, n - 2)`` (``z`` has unit
   variance, so sigma = 1 here).

The thresholds of the window tests hold for time-correlated errors: they are
taken at the worst correlation time (:mod:`companion.integrity.fde.thresholds`).

**Drifting references** (an inertial solution coasting from an anchor, see
:mod:`companion.integrity.coast`). Their error is not a stationary process:
it is the anchor's position error, plus its velocity error times the age, plus
half the acceleration error times the age squared. Over one window this is an
offset (no effect on the window tests), a slope, and a curvature. The caller
gives a :class:`ReferenceDrift`; then

* the series is normalised by the *window* sigma (the fix's variance plus the
  reference's short-term noise), not by the absolute separation covariance,
  which the offset dominates;
* the slope test's variance adds the reference's velocity-error variance
  ``sigma_v^2``: the fitted slope is the noise slope plus the reference's
  velocity error, two independent Gaussians, so the threshold is
  ``K_s sqrt(sigma_b^2 sigma_w^2 + sigma_v^2)`` (m/s), exact for the same ``P_s``;
* the residual test bounds the curvature: the residual of ``a t^2 / 2`` about
  the line has norm ``|a| / 2 ||M t^2||``, so by the triangle inequality
  ``sqrt(RSS) <= sqrt(RSS_noise) + |a| / 2 ||M t^2|| / sigma_w``; with
  ``RSS_noise`` at its ``P_r / 2`` threshold and ``|a| <= Phi^-1(1 - P_r / 4)
  sigma_a`` the test keeps a false-alarm probability of at most ``P_r``.

References
----------
Kim, Walter and Powell, "Standalone GPS-based flight inspection system" (solution
separation; the slope of a straight-line fit for slow ramps such as a 4 cm/s clock
ramp; the residual sum of squares for a 1 m dither). ``docs/methods.md``.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2, norm

from companion.integrity.fde.thresholds import (
    REGULAR_SPACING_TOLERANCE,
    WindowThresholds,
    curvature_regular,
    curvature_residual_norm_s2,
    thresholds_for_times,
    thresholds_regular,
)
from companion.types import FloatArray

AXES = ("N", "E", "D")
_NAN3 = np.full(3, math.nan)
"""The slope of a window too short for the tests (copied per result)."""


@dataclass(frozen=True, slots=True)
class ReferenceDrift:
    """What a drifting reference adds to the window tests, per NED axis (see module docstring).

    ``window_var_m2`` (3,): variance of the separation without the reference's drift
    (the fix's variance plus the reference's short-term noise over a window), m^2.
    ``vel_var_m2ps2`` (3,): variance of the reference's velocity error, m^2/s^2.
    ``acc_var_m2ps4`` (3,): variance of its acceleration error, m^2/s^4.
    """

    window_var_m2: FloatArray
    vel_var_m2ps2: FloatArray
    acc_var_m2ps4: FloatArray

    def __post_init__(self) -> None:
        w, v, a = self.window_var_m2, self.vel_var_m2ps2, self.acc_var_m2ps4
        if np.shape(w) != (3,) or np.shape(v) != (3,) or np.shape(a) != (3,):
            raise ValueError("drift variances must be (3,) each")
        vals = [*np.asarray(w).tolist(), *np.asarray(v).tolist(), *np.asarray(a).tolist()]
        if not (math.isfinite(sum(vals)) and min(vals) >= 0.0 and min(vals[:3]) > 0.0):
            raise ValueError("drift variances must be finite, >= 0 (window_var_m2 > 0)")


def _mahalanobis3(
    s0: float, s1: float, s2: float,
    c00: float, c01: float, c02: float, c11: float, c12: float, c22: float,
) -> float:  # fmt: skip
    """``s^T C^-1 s`` for a symmetric (3, 3) ``C`` (upper triangle given) by its Cholesky
    factor, in floats (the per-fix path); ``ValueError`` when ``C`` is not positive definite.
    """
    if c00 <= 0.0:
        raise ValueError("separation covariance not positive definite")
    l00 = math.sqrt(c00)
    l10, l20 = c01 / l00, c02 / l00
    d1 = c11 - l10 * l10
    if d1 <= 0.0:
        raise ValueError("separation covariance not positive definite")
    l11 = math.sqrt(d1)
    l21 = (c12 - l20 * l10) / l11
    d2 = c22 - l20 * l20 - l21 * l21
    if d2 <= 0.0:
        raise ValueError("separation covariance not positive definite")
    w0 = s0 / l00
    w1 = (s1 - l10 * w0) / l11
    w2 = (s2 - l20 * w0 - l21 * w1) / math.sqrt(d2)
    return w0 * w0 + w1 * w1 + w2 * w2


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
        self._k_acc = float(norm.isf(0.25 * residual_false_alarm_prob))
        """Bound on a drifting reference's acceleration error, in sigmas (two-sided P_r / 2)."""
        self._cap = 256
        self._t = np.zeros(self._cap)
        self._z = np.zeros((self._cap, 3))
        self._sigma = np.zeros((self._cap, 3))
        self._start = 0
        self._end = 0
        self._times: deque[float] = deque()
        """The window's times as floats (``_t[_start:_end]``), for the cheap per-fix checks."""
        self._count = 0
        """Samples appended so far (a sample's serial number is the count before it)."""
        self._first = 0
        """Serial number of the window's oldest sample."""
        self._dt_max: deque[tuple[int, float]] = deque()
        self._dt_min: deque[tuple[int, float]] = deque()
        """Sliding maximum / minimum of the window's sampling intervals: (serial number of
        the later sample, interval), the extreme first (monotonic queues: O(1) per sample
        instead of numpy calls over the window at every fix)."""

    def reset(self) -> None:
        """Empty the window."""
        self._start = 0
        self._end = 0
        self._times.clear()
        self._dt_max.clear()
        self._dt_min.clear()

    def _append(
        self, t_s: float, z: tuple[float, float, float], sigma: tuple[float, float, float]
    ) -> None:
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
        times = self._times
        serial = self._count
        self._count += 1
        if times:
            self._push_interval(serial, t_s - times[-1])
        else:
            self._first = serial
        times.append(t_s)
        while times[0] < t_s - self.window_s:
            times.popleft()
            self._start += 1
            self._first += 1
        first = self._first
        for queue in (self._dt_max, self._dt_min):
            while queue and queue[0][0] <= first:
                queue.popleft()  # the interval's earlier sample left the window

    def _push_interval(self, serial: int, dt_s: float) -> None:
        queue = self._dt_max
        while queue and queue[-1][1] <= dt_s:
            queue.pop()
        queue.append((serial, dt_s))
        queue = self._dt_min
        while queue and queue[-1][1] >= dt_s:
            queue.pop()
        queue.append((serial, dt_s))

    def _window_regular(self, n: int) -> int:
        """:meth:`_regular` of the current window (``n`` >= 2 samples) from the queues."""
        times = self._times
        mean_dt = (times[-1] - times[0]) / (n - 1)
        tol = REGULAR_SPACING_TOLERANCE * mean_dt
        if self._dt_max[0][1] - mean_dt <= tol and mean_dt - self._dt_min[0][1] <= tol:
            return max(1, round(mean_dt * 1e3))
        return 0

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
        return self._times[-1] if self._times else None

    def update(
        self,
        t_s: float,
        sep_ned_m: FloatArray,
        cov_ned_m2: FloatArray,
        drift: ReferenceDrift | None = None,
    ) -> SeparationResult:
        """Add one separation (m, (3,)) with its covariance (m^2, (3, 3)) and test.

        ``drift``: the reference's drift when one side is a drifting (inertial)
        solution (module docstring); the window is then normalised by its
        ``window_var_m2`` and the thresholds account for the drift. A tracker is fed
        either always or never with a drift.

        A non-finite or non-positive-definite input raises ``ValueError`` (the
        monitor rejects and counts such pairs before calling).
        """
        sep = np.asarray(sep_ned_m, dtype=float)
        cov = np.asarray(cov_ned_m2, dtype=float)
        if sep.shape != (3,) or cov.shape != (3, 3):
            raise ValueError("sep_ned_m must be (3,) and cov_ned_m2 (3, 3)")
        # per axis in Python floats (the same IEEE operations as numpy's elementwise ones,
        # without a numpy call each): this runs for every pair at every fix
        s0, s1, s2 = sep.tolist()
        rows = cov.tolist()
        (c00, c01, c02), (_, c11, c12), (_, _, c22) = rows
        if not all(map(math.isfinite, (s0, s1, s2, *rows[0], *rows[1], *rows[2]))):
            raise ValueError("separation or covariance not finite")
        snap = _mahalanobis3(s0, s1, s2, c00, c01, c02, c11, c12, c22)
        # the Cholesky above proved c00, c11, c22 > 0; ReferenceDrift checks window_var_m2 > 0
        var = (c00, c11, c22) if drift is None else np.asarray(drift.window_var_m2).tolist()
        sigma = (math.sqrt(var[0]), math.sqrt(var[1]), math.sqrt(var[2]))
        last = self.last_t_s
        if last is not None and t_s <= last:
            self.reset()  # time went backwards or repeated: restart the series
        self._append(float(t_s), (s0 / sigma[0], s1 / sigma[1], s2 / sigma[2]), sigma)
        reasons: list[str] = []
        if snap > self.snapshot_threshold:
            reasons.append(
                f"separation {np.linalg.norm(sep):.2f} m chi2 {snap:.1f} > "
                f"{self.snapshot_threshold:.1f}"
            )
        n = self._end - self._start
        times = self._times
        if n >= self.min_points and (times[-1] - times[0]) >= 0.5 * self.window_s:
            slope_mps, slope_ratio, rss_ratio = self._window_tests(n, drift, reasons)
        else:
            slope_mps, slope_ratio, rss_ratio = _NAN3.copy(), math.nan, math.nan
        # positional, in field order: cheaper than keywords, per pair and fix
        return SeparationResult(
            float(t_s), sep, snap, self.snapshot_threshold, slope_mps, slope_ratio, rss_ratio,
            n, tuple(reasons),
        )  # fmt: skip

    def _window_tests(
        self, n: int, drift: ReferenceDrift | None, reasons: list[str]
    ) -> tuple[FloatArray, float, float]:
        """Slope and residual tests of the window's ``n`` samples; appends failures to
        ``reasons``; returns the fitted slope (m/s, (3,)) and the largest slope and
        residual ratios. The (n, 3) sums are numpy, the per-axis rest Python floats."""
        lo, hi = self._start, self._end
        t = self._t[lo:hi]
        z = self._z[lo:hi]
        tc = t - float(t.sum()) / n
        sxx = float(tc @ tc)
        b_num = (tc @ z).tolist()
        b = [b_num[0] / sxx, b_num[1] / sxx, b_num[2] / sxx]
        # RSS about the line: sum (z - mean)^2 - b^2 sxx, per axis
        zc = z - z.sum(axis=0) / n
        ss = np.einsum("ij,ij->j", zc, zc).tolist()
        rss = [max(ss[i] - b[i] * b[i] * sxx, 0.0) for i in range(3)]
        sig_sum = self._sigma[lo:hi].sum(axis=0).tolist()
        mean_sigma = [sig_sum[0] / n, sig_sum[1] / n, sig_sum[2] / n]
        slope = [b[0] * mean_sigma[0], b[1] * mean_sigma[1], b[2] * mean_sigma[2]]
        slope_th, rss_th = self._thresholds_floats(t, mean_sigma, drift, self._window_regular(n))
        ratios_s = [abs(slope[i]) / slope_th[i] for i in range(3)]
        ratios_r = [rss[i] / rss_th[i] for i in range(3)]
        slope_ratio = max(ratios_s)
        rss_ratio = max(ratios_r)
        if slope_ratio > 1.0:
            i = ratios_s.index(slope_ratio)
            reasons.append(
                f"slope {AXES[i]} {100.0 * slope[i]:.1f} cm/s > {100.0 * slope_th[i]:.1f}"
            )
        if rss_ratio > 1.0:
            i = ratios_r.index(rss_ratio)
            reasons.append(f"residual {AXES[i]} rss {rss[i]:.0f} > {rss_th[i]:.0f} sigma2")
        return np.array(slope), slope_ratio, rss_ratio

    def window_thresholds(
        self, t_s: FloatArray, sigma_m: FloatArray, drift: ReferenceDrift | None = None
    ) -> tuple[FloatArray, FloatArray]:
        """Per-axis thresholds of the window tests for a window at times ``t_s`` (n,).

        Returns the slope threshold (m/s, (3,)) for the fitted slope in metres per
        second, and the residual threshold (in units of the window sigma squared,
        (3,)) for the residual sum of squares of ``s / sigma``; ``sigma_m`` (3,) is
        the window sigma per axis (the series is normalised by it). See the module
        docstring for the derivation, with and without a drifting reference.
        """
        t = np.asarray(t_s, dtype=float)
        sig = np.asarray(sigma_m, dtype=float).tolist()
        slope_th, rss_th = self._thresholds_floats(t, sig, drift, self._regular(t))
        return np.array(slope_th), np.array(rss_th)

    def _thresholds_floats(
        self, t: FloatArray, sig: list[float], drift: ReferenceDrift | None, regular: int
    ) -> tuple[list[float], list[float]]:
        """:meth:`window_thresholds` per axis in Python floats (``sig``: 3 floats;
        ``regular``: :meth:`_regular` of ``t``)."""
        if drift is None:
            th = self._thresholds(t, self.p_rss, regular)
            k = th.slope_threshold_per_s
            return [k * sig[0], k * sig[1], k * sig[2]], [th.rss_threshold] * 3
        th = self._thresholds(t, 0.5 * self.p_rss, regular)
        sb = th.slope_sigma_per_s
        k_s = th.slope_threshold_per_s / sb
        vel_var = np.asarray(drift.vel_var_m2ps2).tolist()
        acc_var = np.asarray(drift.acc_var_m2ps4).tolist()
        norm_t2 = curvature_regular(t.size, regular) if regular else curvature_residual_norm_s2(t)
        k_curv = 0.5 * self._k_acc
        rss_root = math.sqrt(th.rss_threshold)
        slope_th = []
        rss_th = []
        for i in range(3):
            sbs = sb * sig[i]
            slope_th.append(k_s * math.sqrt(sbs * sbs + vel_var[i]))
            root = rss_root + k_curv * math.sqrt(acc_var[i]) * norm_t2 / sig[i]
            rss_th.append(root * root)
        return slope_th, rss_th

    @staticmethod
    def _regular(t: FloatArray) -> int:
        """The spacing in ms when the window is regular enough for the cached thresholds,
        else 0."""
        n = t.size
        mean_dt = float(t[-1] - t[0]) / (n - 1)
        dt = t[1:] - t[:-1]
        tol = REGULAR_SPACING_TOLERANCE * mean_dt
        if float(dt.max()) - mean_dt <= tol and mean_dt - float(dt.min()) <= tol:
            return max(1, round(mean_dt * 1e3))
        return 0

    def _thresholds(self, t: FloatArray, p_rss: float, dt_ms: int) -> WindowThresholds:
        if dt_ms:
            return thresholds_regular(t.size, dt_ms, self.p_slope, p_rss)
        return thresholds_for_times(t, self.p_slope, p_rss)

"""Thresholds of the slope and residual tests for a time-correlated separation.

Kim, Walter and Powell state the window tests of solution separation
(:mod:`companion.integrity.fde.separation`) for white errors. GNSS position
errors are correlated in time (first-order Gauss-Markov with a correlation
time that depends on the mode: El-Mowafy (2005) and the simulator's model),
which changes both statistics. The thresholds are therefore derived for a
unit-variance process with correlation ``exp(-|dt| / tau)`` and taken at the
**worst tau** over a grid from 0 (white: the paper's own formulas exactly) to
50 windows:

* slope: ``sigma_b^2(tau) = w^T R(tau) w`` with ``w = (t - mean t) / sum (t - mean t)^2``;
  because it is linear in ``R``, the maximum over tau also bounds any mixture
  of exponential kernels; the threshold is ``K_s sigma_b`` with
  ``K_s = Phi^-1(1 - P_s / 2)``;
* residual: ``RSS = z^T M z`` with ``M`` the residual maker of the line fit is
  a generalised chi-square with matrix ``A = M R M``; it is approximated by
  ``g * chi2(h)`` with the same mean and variance (Welch-Satterthwaite:
  ``g = tr(A^2)/tr(A)``, ``h = tr(A)^2/tr(A^2)``), which for white errors is
  ``chi2(n - 2)``, the paper's ``sigma^2 chi2^-1(1 - P_r, n - 2)`` with sigma = 1.

A drifting reference's curvature bound needs ``||M t^2||``
(:func:`curvature_residual_norm_s2`). No threshold is a tuned literal: each
comes from a false-alarm probability, the window length and the sampling.
Regular windows (the usual case: a receiver's fixed rate) use cached values.

References
----------
Kim, Walter and Powell, "Standalone GPS-based flight inspection system" (slope of
a straight-line fit for slow ramps; residual sum of squares against
``sigma^2 chi2^-1(1 - P, n - 2)`` for dithering). Satterthwaite, Biometrics
Bulletin 2(6), 1946 (moment-matched chi-square). ``docs/methods.md``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2, norm

from companion.types import FloatArray

TAU_GRID_POINTS = 48
"""Number of correlation times in the worst-case search (log-spaced, plus white)."""
TAU_GRID_SPAN_WINDOWS = 50.0
"""The longest correlation time searched, in window lengths (beyond it the process is a
constant over the window: slope and residual vanish)."""
_CHUNK_ELEMENTS = 1 << 20
"""Largest number of correlation-matrix elements held at once by :func:`thresholds_for_times`."""
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
    Kim, Walter and Powell (slope and residual tests); the module docstring for the
    derivation.
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
    taus = _tau_grid(span, span / (n - 1))
    sb2 = np.empty(taus.size)
    g_h = np.full((2, taus.size), np.nan)  # Satterthwaite scale and dof per tau (NaN: skip)
    # the taus in chunks of stacked (n, n) correlation matrices: one numpy call per chunk
    # instead of one per tau (memory bounded by _CHUNK_ELEMENTS)
    chunk = max(1, _CHUNK_ELEMENTS // (n * n))
    for lo in range(0, taus.size, chunk):
        hi = min(lo + chunk, taus.size)
        corr = _correlations(lag, taus[lo:hi])
        for k in range(hi - lo):  # per matrix: a stacked product may sum in another order
            sb2[lo + k] = w @ corr[k] @ w
        # traces of A = M R M (M = I - H, H = X G X^T) in O(n^2):
        # tr A = tr R - tr(G X^T R X); tr A^2 = tr R^2 - 2 tr(G (RX)^T (RX)) + tr((G X^T R X)^2)
        # (tr R = n: R has a unit diagonal)
        rx = corr @ x_mat
        gxrx = g_mat @ (x_mat.T @ rx)
        rxrx = g_mat @ (rx.transpose(0, 2, 1) @ rx)
        gg = gxrx @ gxrx
        tr_a = float(n) - (gxrx[:, 0, 0] + gxrx[:, 1, 1])
        tr_r2 = (corr * corr).reshape(hi - lo, n * n).sum(axis=1)
        tr_a2 = tr_r2 - 2.0 * (rxrx[:, 0, 0] + rxrx[:, 1, 1]) + (gg[:, 0, 0] + gg[:, 1, 1])
        ok = (tr_a > 0.0) & (tr_a2 > 0.0)
        g_h[0, lo:hi] = np.where(ok, tr_a2 / np.where(ok, tr_a, 1.0), np.nan)
        g_h[1, lo:hi] = np.where(ok, tr_a * tr_a / np.where(ok, tr_a2, 1.0), np.nan)
    best_sb2, tau_sb = -1.0, 0.0
    for k, value in enumerate(sb2.tolist()):
        if value > best_sb2:
            best_sb2, tau_sb = value, float(taus[k])
    # one vectorised quantile call for every tau (a scipy call costs far more than its maths)
    usable = np.flatnonzero(np.isfinite(g_h[1]))
    quantiles = chi2.isf(residual_false_alarm_prob, g_h[1, usable]).tolist()
    best_rss, tau_rss = -1.0, 0.0
    for k, q in zip(usable.tolist(), quantiles, strict=True):
        rss_th = float(g_h[0, k]) * q
        if rss_th > best_rss:
            best_rss, tau_rss = rss_th, float(taus[k])
    sb = math.sqrt(best_sb2)
    return WindowThresholds(n, sb, k_slope * sb, best_rss, tau_sb, tau_rss)


def _correlations(lag_s: FloatArray, taus_s: FloatArray) -> FloatArray:
    """``exp(-lag / tau)`` for each tau (the identity for tau = 0), shape (taus, n, n)."""
    n = lag_s.shape[0]
    white = taus_s == 0.0
    corr = np.divide(-lag_s, np.where(white, 1.0, taus_s)[:, None, None])
    np.exp(corr, out=corr)
    corr[white] = np.eye(n)
    return corr


@functools.lru_cache(maxsize=256)
def thresholds_regular(
    n: int, dt_ms: int, slope_false_alarm_prob: float, residual_false_alarm_prob: float
) -> WindowThresholds:
    """:func:`thresholds_for_times` for ``n`` samples ``dt_ms`` milliseconds apart (cached)."""
    if dt_ms <= 0:
        raise ValueError("dt_ms must be > 0")
    t = np.arange(n, dtype=float) * (dt_ms * 1e-3)
    return thresholds_for_times(t, slope_false_alarm_prob, residual_false_alarm_prob)


def curvature_residual_norm_s2(t_s: FloatArray) -> float:
    """``||M t^2||`` (s^2): the norm of the residual of ``t^2`` about its least-squares line
    over the window times ``t_s`` (n,). A quadratic ``a t^2 / 2`` leaves ``|a| / 2`` times it.
    """
    t = np.asarray(t_s, dtype=float)
    tc = t - t.mean()
    u = tc * tc
    sxx = float(tc @ tc)
    if sxx <= 0.0:
        raise ValueError("window times must not all be equal")
    r = u - u.mean() - tc * (float(tc @ u) / sxx)
    return float(math.sqrt(float(r @ r)))


@functools.lru_cache(maxsize=256)
def curvature_regular(n: int, dt_ms: int) -> float:
    """:func:`curvature_residual_norm_s2` for ``n`` samples ``dt_ms`` apart (cached)."""
    return curvature_residual_norm_s2(np.arange(n, dtype=float) * (dt_ms * 1e-3))

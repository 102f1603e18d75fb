"""How late a receiver's fixes are stamped: the GNSS lag, estimated from the IMU.

A fix's velocity ``v_k`` is valid at ``t_k - lag`` (``t_k``: its stamp, with the lag the
service already subtracts). Between two fixes the velocity changes by the integral of
the horizontal acceleration ``a_ne = (C_nb f_b)_ne`` (gravity has no horizontal part)::

    v_k - v_{k-1} = int_{t_{k-1} - lag}^{t_k - lag} a_ne dt + b_ne (t_k - t_{k-1}) + noise

with ``b_ne`` a constant over the window (accelerometer bias and tilt error times g). For
each lag of a grid the bias is solved by least squares and the residual sum of squares
``J(lag)`` kept; the minimum, refined by a parabola, is the estimate. Its standard
deviation is Fisher's: ``d r_k / d lag = a(t_k - lag) - a(t_{k-1} - lag)`` (taken as a
difference over +-50 ms of lag: accelerations averaged over 0.1 s), so
``sigma^-2 = sum |d r_k / d lag|^2 / (2 sigma_r^2)``, the factor 2 for the differenced
fixes' correlated noise, and never below the scatter of the window's blocks. The lag is
observable only while the acceleration changes: a straight, steady flight gives a large
sigma and no estimate. Fixes are differenced about a second apart (``baseline_s``): the
velocity change grows with the interval, a fix's noise does not. Every fix is paired
with the first one a baseline after it (a single chain would use one fix in baseline x
rate); the pairs overlap, so Fisher's information is divided by the pairs per disjoint
baseline.

Pure: samples in, an estimate out; no clock.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from companion.types import FloatArray


@dataclass(frozen=True, slots=True)
class LagEstimate:
    """The lag to add to the one already subtracted from the fixes' stamps."""

    lag_s: float
    sigma_s: float
    n_fixes: int
    residual_mps: float
    """RMS of the velocity-change residual at the estimate."""
    excitation_mps2: float
    """RMS change of the horizontal acceleration between fixes that a heading error does
    not explain (what makes the lag observable), m/s^2."""
    rotation_rad: float = 0.0
    """The blocks' mean heading error at the estimate (the acceleration's rotation), rad."""


@dataclass(frozen=True, slots=True)
class LagConfig:
    window_s: float = 60.0
    """Fixes and IMU samples kept."""
    min_lag_s: float = -0.15
    """The grid's ends, relative to the lag already subtracted (negative: it overstates)."""
    max_lag_s: float = 0.35
    step_s: float = 0.005
    min_fixes: int = 30
    baseline_s: float = 1.0
    """Fixes are differenced this far apart at least (the velocity change grows with it,
    a fix's noise does not)."""
    max_fix_interval_s: float = 1.6
    """Longer intervals between the fixes differenced are not used."""
    min_excitation_mps2: float = 0.05
    """Below this RMS acceleration change the lag is not observable enough to try."""
    smooth_s: float = 0.05
    """Half-width of the lag difference the model's slope is taken over, s."""
    blocks: int = 4
    """The window is cut into this many blocks, each with its own bias and heading error;
    the scatter of their lags bounds the estimate's sigma from below."""
    heading_prior_rad: float = 0.1
    """Prior 1-sigma of a block's heading error (a rotation of the acceleration, which a
    body-axis accelerometer bias in a turn also looks like), weighed against
    ``velocity_noise_mps``: 6 deg, far beyond a MEMS autopilot's tenths, so it decides
    nothing in turns; on a straight leg, where the rotation is unobservable, it keeps it
    at zero."""
    velocity_noise_mps: float = 0.05
    """The velocity-change noise the heading prior is weighed against (a receiver's
    Doppler velocity, 1-sigma per axis), m/s."""


class GnssLagEstimator:
    """Keeps the window's horizontal accelerations and fix velocities; :meth:`estimate`."""

    def __init__(self, config: LagConfig | None = None) -> None:
        self.config = config or LagConfig()
        self._acc: deque[tuple[float, float, float]] = deque()
        self._fix: deque[tuple[float, float, float]] = deque()

    def reset(self) -> None:
        """Forget everything (the stamps' lag changed, or the stream restarted)."""
        self._acc.clear()
        self._fix.clear()

    def add_acceleration(self, t_s: float, acc_ne_mps2: FloatArray) -> None:
        """The horizontal acceleration (NED north, east) at ``t_s``; out-of-order dropped."""
        if self._acc and t_s <= self._acc[-1][0]:
            return
        if not (math.isfinite(acc_ne_mps2[0]) and math.isfinite(acc_ne_mps2[1])):
            return
        self._acc.append((t_s, float(acc_ne_mps2[0]), float(acc_ne_mps2[1])))
        self._trim(self._acc, t_s)

    def add_fix(self, t_s: float, vel_ne_mps: FloatArray) -> None:
        """A fix's horizontal velocity at its (lag-corrected) stamp."""
        if self._fix and t_s <= self._fix[-1][0]:
            return
        if not (math.isfinite(vel_ne_mps[0]) and math.isfinite(vel_ne_mps[1])):
            return
        self._fix.append((t_s, float(vel_ne_mps[0]), float(vel_ne_mps[1])))
        self._trim(self._fix, t_s)

    def _trim(self, buf: deque[tuple[float, float, float]], t_s: float) -> None:
        while buf and buf[0][0] < t_s - self.config.window_s:
            buf.popleft()

    def estimate(self) -> LagEstimate | None:
        """The window's estimate, or None when too few fixes or too little excitation."""
        cfg = self.config
        if len(self._fix) < cfg.min_fixes + 1 or len(self._acc) < 4:
            return None
        acc = np.array(self._acc)
        fix = np.array(self._fix)
        t_a = acc[:, 0]
        # cumulative integral of the acceleration (trapezoid), interpolated at any time
        seg = 0.5 * (acc[1:, 1:] + acc[:-1, 1:]) * np.diff(t_a)[:, None]
        cum = np.vstack([np.zeros((1, 2)), np.cumsum(seg, axis=0)])
        # every fix paired with the first one at least a baseline after it: all fixes are
        # used (a single chain would keep one in baseline x rate), the pairs overlap
        t_all = fix[:, 0]
        later = np.searchsorted(t_all, t_all + cfg.baseline_s - 1e-6)
        ok = later < t_all.size
        i0, i1 = np.nonzero(ok)[0], later[ok]
        dt_f = fix[i1, 0] - fix[i0, 0]
        keep = dt_f <= cfg.max_fix_interval_s
        t0, t1, dt = fix[i0, 0][keep], fix[i1, 0][keep], dt_f[keep]
        dv = (fix[i1, 1:] - fix[i0, 1:])[keep]
        lags = np.arange(cfg.min_lag_s, cfg.max_lag_s + 0.5 * cfg.step_s, cfg.step_s)
        # every interval must lie inside the IMU's span at every lag tried
        inside = (t0 - lags[-1] >= t_a[0]) & (t1 - lags[0] <= t_a[-1])
        t0, t1, dt, dv = t0[inside], t1[inside], dt[inside], dv[inside]
        n = t0.size
        if n < cfg.min_fixes:
            return None
        # dI[l, k, axis]: the integral over fix interval k at lag l
        d_int = np.stack(
            [
                np.interp(t1[None, :] - lags[:, None], t_a, cum[:, ax])
                - np.interp(t0[None, :] - lags[:, None], t_a, cum[:, ax])
                for ax in (0, 1)
            ],
            axis=-1,
        )
        resid = dv[None, :, :] - d_int
        # the model's slope in the lag at every lag of the grid, over +-smooth_s (the
        # acceleration averaged over 2 smooth_s: a single vibrating sample says nothing
        # about the motion)
        h = max(1, round(cfg.smooth_s / cfg.step_s))
        k_all = np.arange(lags.size)
        lo_k, hi_k = np.maximum(k_all - h, 0), np.minimum(k_all + h, lags.size - 1)
        slope_all = (d_int[lo_k] - d_int[hi_k]) / (lags[hi_k] - lags[lo_k])[:, None, None]
        # each block of the window has its own constant bias b_NE and its own heading error
        # (a rotation of the acceleration, which a body-axis accelerometer bias also looks
        # like in a turn): both solved by least squares at every lag. In a steady turn a
        # rotation and a lag are the same (the acceleration turns at the turn's rate): the
        # lag is then not observable, and the slope left once the rotation is projected out
        # says so (the excitation and Fisher's information vanish)
        blocks = np.array_split(np.arange(n), cfg.blocks)
        ridge = (cfg.velocity_noise_mps / cfg.heading_prior_rad) ** 2
        costs = np.empty((len(blocks), lags.size))
        block_info = np.empty((len(blocks), lags.size))
        rotation = np.zeros((len(blocks), lags.size))
        for j, idx in enumerate(blocks):
            costs[j], block_info[j], rotation[j] = _profile(
                resid[:, idx], d_int[:, idx], slope_all[:, idx], dt[idx], ridge
            )
        info_l = block_info.sum(axis=0)
        cost = costs.sum(axis=0)
        lag, on_edge = _minimum(lags, cost)
        k = int(np.argmin(np.abs(lags - lag)))
        excitation = math.sqrt(max(float(info_l[k]), 0.0) / n)
        i = int(np.argmin(cost))
        var_r = float(cost[i]) / max(2 * n - 3 * len(blocks), 1)
        # overlapping pairs share fixes and accelerations: the information of as many
        # independent pairs as disjoint baselines fit in the window
        overlap = max(1.0, n * cfg.baseline_s / max(float(t1[-1] - t0[0]), cfg.baseline_s))
        scale = 2.0 * var_r * overlap
        if on_edge or excitation < cfg.min_excitation_mps2 or not scale > 0.0:
            return None
        info = float(info_l[k]) / scale
        if not info > 0.0:
            return None
        # the blocks' own minima, weighted by their own information (a block without a
        # manoeuvre has a flat cost and says nothing): their scatter beyond what that
        # information allows (Birge's ratio) is what the model leaves out (an attitude
        # error in turns), which Fisher's sigma cannot see
        chi2_blocks, informative = 0.0, 0
        for c, info_j in zip(costs, block_info, strict=True):
            lag_j, edge_j = _minimum(lags, c)
            w_j = float(info_j[int(np.argmin(np.abs(lags - lag_j)))]) / scale
            if edge_j or not w_j > 0.0:
                continue
            informative += 1
            chi2_blocks += w_j * (lag_j - lag) ** 2
        birge = math.sqrt(chi2_blocks / (informative - 1)) if informative > 1 else 1.0
        sigma = max(1.0, birge) / math.sqrt(info)
        return LagEstimate(
            lag_s=lag,
            sigma_s=sigma,
            n_fixes=n,
            residual_mps=math.sqrt(var_r),
            excitation_mps2=excitation,
            rotation_rad=float(np.mean(rotation[:, k])),
        )


def _profile(
    resid: FloatArray, d_int: FloatArray, slope: FloatArray, dt: FloatArray, ridge: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """One block at every lag: the residual sum of squares with its bias and heading error
    solved for, the lag's information left once they are (the squared slope projected
    off their regressors), and the heading error, rad.

    ``resid``, ``d_int``, ``slope``: (lags, pairs, 2) velocity-change residuals, the
    acceleration integrals and their slope in the lag; ``dt`` (pairs,) the intervals. The
    heading error ``psi`` rotates the integrals, ``d + psi J d`` with ``J d = (-d_E, d_N)``
    (small angles); the bias adds ``b dt``; ``ridge`` ((m/s)^2 per rad^2) is the heading's
    prior weight (a straight, steady leg leaves it unobservable: it then stays ~0).
    """
    rot = np.stack([-d_int[..., 1], d_int[..., 0]], axis=-1)  # J d, (L, K, 2)
    w2 = float(dt @ dt)
    # normal equations of (b_N, b_E, psi), (L, 3, 3)
    a = np.zeros((d_int.shape[0], 3, 3))
    a[:, 0, 0] = a[:, 1, 1] = w2
    a[:, 0, 2] = a[:, 2, 0] = np.einsum("lk,k->l", rot[..., 0], dt)
    a[:, 1, 2] = a[:, 2, 1] = np.einsum("lk,k->l", rot[..., 1], dt)
    a[:, 2, 2] = np.einsum("lka,lka->l", rot, rot) + ridge

    def project(y: FloatArray) -> tuple[FloatArray, FloatArray]:
        c = np.stack(
            [
                np.einsum("lk,k->l", y[..., 0], dt),
                np.einsum("lk,k->l", y[..., 1], dt),
                np.einsum("lka,lka->l", rot, y),
            ],
            axis=-1,
        )
        theta = np.linalg.solve(a, c[..., None])[..., 0]
        return np.einsum("lka,lka->l", y, y) - np.einsum("li,li->l", c, theta), theta

    cost, theta = project(resid)
    info, _ = project(slope)
    return cost, info, theta[:, 2]


def _minimum(lags: FloatArray, cost: FloatArray) -> tuple[float, bool]:
    """The grid's minimum of ``cost``, refined by a parabola; and whether it is at an end."""
    i = int(np.argmin(cost))
    lag = float(lags[i])
    if 0 < i < lags.size - 1:
        c_m, c_0, c_p = cost[i - 1], cost[i], cost[i + 1]
        curv = c_m - 2.0 * c_0 + c_p
        if curv > 0.0:
            lag += 0.5 * float(lags[1] - lags[0]) * float(c_m - c_p) / float(curv)
    return lag, i in (0, lags.size - 1)

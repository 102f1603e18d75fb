"""How late an IMU stream's stamps are against the attitude stream's: the stamp offset,
measured from the gyro and the attitudes.

An autopilot stamps its IMU messages when it sends them, with readings that went
through its sensor filters (ArduPilot's 20 Hz gyro and accelerometer low-pass: ~10 ms
of group delay), while its attitude is integrated from the unfiltered increments. So
the IMU's readings may be older than their stamps by ``d``. Between two attitudes
``q_{k-1}``, ``q_k`` the body turned by ``theta_k = rotvec(conj(q_{k-1}) q_k)``; the
gyro, shifted by ``d``, gives the same turn::

    theta_k = int_{t_{k-1} + d}^{t_k + d} w_b dt + b (t_k - t_{k-1}) + e_k

with ``b`` the gyro's bias (constant over a block of the window). For each ``d`` of a
grid the bias is solved by least squares per block and the residual sum of squares
kept; the minimum, refined by a parabola, is the estimate. Its sigma is Fisher's,
``sigma^-2 = sum |d r_k / d d|^2 / (2 sigma_r^2)`` (the 2 for consecutive turns sharing
an attitude), and never below the scatter of the blocks' own minima nor the grid's
step. Only a changing rate (rolling into and out of turns) makes it observable.

Pure: samples in, an estimate out; no clock.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from companion.nav.gnss_lag import _minimum
from companion.nav.rotations import Quat, rotvec_between
from companion.types import FloatArray


@dataclass(frozen=True, slots=True)
class StampOffsetEstimate:
    offset_s: float
    """How much older the IMU's readings are than their stamps (negative: newer), s."""
    sigma_s: float
    n_pairs: int
    residual_rad: float
    """RMS of the turn residual at the estimate (one axis), rad."""
    excitation_radps: float
    """RMS change of the body rate across one attitude interval (what makes it observable)."""


@dataclass(frozen=True, slots=True)
class StampOffsetConfig:
    window_s: float = 30.0
    min_offset_s: float = -0.06
    max_offset_s: float = 0.10
    step_s: float = 0.001
    max_pair_s: float = 0.15
    """Attitudes farther apart are not paired."""
    min_pairs: int = 100
    min_excitation_radps: float = 0.01
    smooth_s: float = 0.01
    """Half-width of the offset difference the model's slope is taken over, s."""
    blocks: int = 4


class ImuStampEstimator:
    """Keeps the window's attitudes and gyro readings; :meth:`estimate`."""

    def __init__(self, config: StampOffsetConfig | None = None) -> None:
        self.config = config or StampOffsetConfig()
        self._gyro: deque[tuple[float, float, float, float]] = deque()
        self._att: deque[tuple[float, Quat]] = deque()

    def reset(self) -> None:
        self._gyro.clear()
        self._att.clear()

    def add_gyro(self, t_s: float, gyro_b_radps: FloatArray) -> None:
        """A body rate reading at its stamp; out-of-order or non-finite dropped."""
        if self._gyro and t_s <= self._gyro[-1][0]:
            return
        x, y, z = (float(gyro_b_radps[0]), float(gyro_b_radps[1]), float(gyro_b_radps[2]))
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            return
        self._gyro.append((t_s, x, y, z))
        while self._gyro and self._gyro[0][0] < t_s - self.config.window_s:
            self._gyro.popleft()

    def add_attitude(self, t_s: float, q_nb: Quat) -> None:
        """An attitude (body to NED) at its stamp; out-of-order dropped."""
        if self._att and t_s <= self._att[-1][0]:
            return
        if not math.isfinite(q_nb[0] + q_nb[1] + q_nb[2] + q_nb[3]):
            return
        self._att.append((t_s, q_nb))
        while self._att and self._att[0][0] < t_s - self.config.window_s:
            self._att.popleft()

    def span_s(self) -> float:
        """Time the window's attitudes cover, s."""
        return self._att[-1][0] - self._att[0][0] if len(self._att) > 1 else 0.0

    def estimate(self) -> StampOffsetEstimate | None:
        """The window's estimate, or None: too few attitude pairs or too little excitation."""
        cfg = self.config
        if len(self._gyro) < 4 or len(self._att) < cfg.min_pairs + 1:
            return None
        g = np.array(self._gyro)
        t_g = g[:, 0]
        seg = 0.5 * (g[1:, 1:] + g[:-1, 1:]) * np.diff(t_g)[:, None]
        cum = np.vstack([np.zeros((1, 3)), np.cumsum(seg, axis=0)])
        atts = list(self._att)
        t_a = np.array([t for t, _ in atts])
        theta = np.array(
            [rotvec_between(a[1], b[1]) for a, b in zip(atts[:-1], atts[1:], strict=True)]
        )
        t0, t1 = t_a[:-1], t_a[1:]
        dt = t1 - t0
        offsets = np.arange(cfg.min_offset_s, cfg.max_offset_s + 0.5 * cfg.step_s, cfg.step_s)
        keep = (dt <= cfg.max_pair_s) & (t0 + offsets[0] >= t_g[0]) & (t1 + offsets[-1] <= t_g[-1])
        t0, t1, dt, theta = t0[keep], t1[keep], dt[keep], theta[keep]
        n = t0.size
        if n < cfg.min_pairs:
            return None
        d_int = np.stack(
            [
                np.interp(t1[None, :] + offsets[:, None], t_g, cum[:, ax])
                - np.interp(t0[None, :] + offsets[:, None], t_g, cum[:, ax])
                for ax in (0, 1, 2)
            ],
            axis=-1,
        )
        resid = d_int - theta[None, :, :]
        blocks = np.array_split(np.arange(n), cfg.blocks)
        costs = np.empty((len(blocks), offsets.size))
        for j, idx in enumerate(blocks):
            r, w = resid[:, idx, :], dt[idx]
            b = np.einsum("lka,k->la", r, w) / float(w @ w)
            r = r - b[:, None, :] * w[None, :, None]
            costs[j] = np.einsum("lka,lka->l", r, r)
        cost = costs.sum(axis=0)
        offset, on_edge = _minimum(offsets, cost)
        block_offsets = [_minimum(offsets, c)[0] for c in costs]
        k = int(np.argmin(np.abs(offsets - offset)))
        h = max(1, round(cfg.smooth_s / cfg.step_s))
        lo, hi = max(k - h, 0), min(k + h, offsets.size - 1)
        slope = (d_int[hi] - d_int[lo]) / float(offsets[hi] - offsets[lo])
        excitation = float(np.sqrt(np.mean(np.sum(slope * slope, axis=1) / 3.0)))
        i = int(np.argmin(cost))
        var_r = float(cost[i]) / max(3 * (n - len(blocks)), 1)
        info = float(np.sum(slope * slope)) / (2.0 * var_r) if var_r > 0.0 else math.inf
        if on_edge or excitation < cfg.min_excitation_radps or not info > 0.0:
            return None
        # never below the grid's step: the integrals of the sampled gyro are piecewise
        # linear in the offset, and the parabola's refinement is no finer than that
        sigma = max(
            1.0 / math.sqrt(info),
            float(np.std(block_offsets, ddof=1)) / math.sqrt(len(blocks)),
            cfg.step_s,
        )
        return StampOffsetEstimate(
            offset_s=offset,
            sigma_s=sigma,
            n_pairs=n,
            residual_rad=math.sqrt(var_r),
            excitation_radps=excitation,
        )

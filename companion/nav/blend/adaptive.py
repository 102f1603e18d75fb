"""Adaptive measurement and process noise of the blend (El-Mowafy 2005; Mohamed & Schwarz
1999), from moving windows of GNSS epochs.

The variant implemented, and why:

* R: the **residual form** R = C_v + H P+ H^T, not the innovation form
  R = C_eta - H P- H^T. The innovation form subtracts two comparable positive matrices
  and goes indefinite whenever the window's sample covariance happens to be small
  (common with N = 25 and centimetre RTK); the residual form is a sum of positive
  semi-definite terms, so the estimate stays positive by construction and is unbiased at
  the filter's fixed point (E[v v^T] = R - H P+ H^T). It is estimated per position
  component as a **scale on the receiver's reported variance** (the window mean of
  (v_i^2 + (H P+ H^T)_ii) / R_i, R_i the white R the model used; the scale multiplies
  both the white part and the receiver-error states' variance), so a step in the
  reported accuracy (RTK fixed -> float) is followed at once instead of after N epochs;
  the scale is bounded (``r_scale_bounds``) and R floored.
* Q: El-Mowafy's Q = K C_eta K^T is only the first term of Mohamed & Schwarz's
  estimator; the full one, Q = mean(dx dx^T) + P+_k - Phi P+_{k-1} Phi^T, equals
  Q_used + K (eta eta^T - S) K^T per epoch, which is what is windowed here. Only its
  velocity block is used -- the one that the accelerometer white noise drives directly --
  to re-estimate the accelerometer noise density per NED axis, bounded by
  ``q_scale_bounds`` times the configured value. Bias and attitude noises stay at their
  configured values (too weakly observable over 25 epochs to adapt).
* Which innovations feed which estimate: R and Q estimated jointly from the same
  innovations are not separately identifiable (Mehra 1972), and adapting the velocity R
  together with Q drifts (Q too low, velocity R too high, each excusing the other). So R
  is adapted from the **position** residuals (where R dominates: between 5-10 Hz fixes
  the INS prediction error is far below the receiver noise) and Q from the **velocity**
  innovations, with the receiver's velocity accuracy taken as reported (floored).
* Floors: by default neither R nor Q may fall below the receiver's report and the IMU
  specification (``r_scale_bounds`` and ``q_scale_bounds`` start at 1). Time-correlated
  GNSS errors look like signal between fixes, the residuals come out far smaller than the
  true error, and an unfloored window shrinks R until the filter follows the wandering
  error and mis-estimates the accelerometer biases that carry the next outage. A window
  can reliably tell only that noise is *larger* than modelled, which is also the
  direction that keeps the bridging covariance honest. With white noise (e.g.
  ``r_scale_bounds=(0.05, 20)``) the estimator follows the truth both ways.

References
----------
El-Mowafy (2005), RTK networks for precision approach with an adaptive GPS/INS blend
(adaptive R and Q, moving window N = 20-30); Mohamed & Schwarz, "Adaptive Kalman
filtering for INS/GPS", J. Geodesy 73, 1999, eq. 20-28; Mehra, "Approaches to adaptive
filtering", IEEE TAC 17(5), 1972 (identifiability of Q and R).
"""

from __future__ import annotations

import math

import numpy as np

from companion.nav import ins
from companion.nav.blend.config import BlendConfig
from companion.nav.blend.diagnostics import BlendDiagnostics
from companion.nav.blend.error_model import IGB
from companion.nav.kalman import Correction, InnovationWindow
from companion.types import FloatArray

KH_FLOOR = 0.3
"""Smallest (K H)_vv the adaptive Q divides by (see :meth:`AdaptiveNoise.update`)."""


class AdaptiveNoise:
    """The moving windows of the adaptive R scale and accelerometer PSD.

    ``has_lever`` and ``gauss_markov`` say how the position rows of H look (a lever arm
    couples the attitude; the Gauss-Markov receiver error adds states 15:18).
    """

    def __init__(self, config: BlendConfig, *, has_lever: bool, gauss_markov: bool) -> None:
        self.config = config
        self._has_lever = has_lever
        self._gm = gauss_markov
        self._accel_psd0 = config.accel_vrw_mps_rts**2
        self.reset()

    def set_base_psd(self, psd_m2ps3: float) -> None:
        """The accelerometer PSD the bounds ``q_scale_bounds`` are multiples of (the
        configured one, or the measured one when the IMU is noisier), m^2/s^3."""
        self._accel_psd0 = psd_m2ps3

    def bounded_psd(self, psd_ned: list[float]) -> list[float]:
        """``psd_ned`` (3 floats) within the bounds of the base PSD, m^2/s^3."""
        lo, hi = self.config.q_scale_bounds
        q0 = self._accel_psd0
        return [min(max(q, lo * q0), hi * q0) for q in psd_ned]

    def reset(self) -> None:
        """Empty the windows."""
        window = self.config.adaptive_window
        self._r_win = InnovationWindow(3, window)
        self._q_win = InnovationWindow(3, window)
        self._r_scale_last: list[float] | None = None

    def r_scale(self, diag: BlendDiagnostics) -> list[float]:
        """Adaptive variance scale per position component (ones when not adaptive or not
        ready); the velocity components' scale is 1. A change is recorded in ``diag``."""
        cfg = self.config
        if not cfg.adaptive:
            return [1.0, 1.0, 1.0]
        lo, hi = cfg.r_scale_bounds
        ready_mean = self._r_win.ready_mean
        min_epochs = cfg.adaptive_min_epochs
        values = [1.0, 1.0, 1.0]
        for i in range(3):
            mean = ready_mean(i, min_epochs)
            if mean is not None:
                values[i] = min(max(mean, lo), hi)
        if values != self._r_scale_last:  # a new array only when the scale changes
            diag.r_scale = np.array(values + [1.0, 1.0, 1.0])
            self._r_scale_last = values
        return values

    def update(
        self,
        y: list[float],
        axes: tuple[int, ...],
        h_mat: FloatArray,
        r_rep: list[float],
        p_prior: FloatArray,
        corr: Correction,
        d: list[float],
        t_s: float,
        last_fuse_t_s: float,
        diag: BlendDiagnostics,
    ) -> bool:
        """Window the residual-form R statistics and the Q correction K (eta eta^T - S) K^T
        of a fused fix at ``t_s`` (the previous one at ``last_fuse_t_s``); True when the
        accelerometer PSD in ``diag`` changed.

        For the optimal gain K S K^T = P- - P+, so the velocity diagonal of the Q
        correction is dx_v^2 - (P- - P+)_vv (dx = K eta): no extra matrix products.
        ``d`` is ``corr.dx`` as floats; ``r_rep`` the white R diagonal the update used
        before the scale.
        """
        cfg = self.config
        p_post = corr.p_post
        diag_p = p_post.diagonal().tolist()
        if self._has_lever:
            h3 = h_mat[:3]
            resid = (np.array(y[:3]) - h3.dot(corr.dx)).tolist()
            hph = ((h3.dot(p_post)) * h3).sum(axis=1).tolist()
        elif self._gm:
            # H's position rows select states i and IGB + i: H dx and diag(H P+ H^T) written
            # out (the same two- and four-term sums as the matrix products, same values;
            # P+ is exactly symmetric, so P+[IGB + i, i] is the offset diagonal's entry)
            off = p_post.diagonal(IGB).tolist()
            resid = [y[i] - (d[i] + d[IGB + i]) for i in range(3)]
            hph = [(diag_p[i] + off[i]) + (off[i] + diag_p[IGB + i]) for i in range(3)]
        else:
            resid = [y[i] - d[i] for i in range(3)]
            hph = diag_p[0:3]
        r_add = self._r_win.add
        for k in range(3):  # position rows come first
            r_add(k, (resid[k] ** 2 + hph[k]) / r_rep[k])
        # Q: velocity block of K (eta eta^T - S) K^T per unit time, added to the PSD in use
        if not (math.isfinite(last_fuse_t_s) and t_s > last_fuse_t_s):
            return False
        dt = t_s - last_fuse_t_s
        dp = [p_prior.item(k, k) - diag_p[k] for k in (3, 4, 5)]
        dxv = d[3:6]
        # an unmodelled noise dQ shows in dx_v only through the part of the velocity error
        # the update removes, (K H)_vv: the raw K (eta eta^T - S) K^T sees dQ (K H)_vv^2
        # (worst on the down axis, which GPS_RAW_INT observes through position only);
        # dividing by it makes the increment unbiased. Floored: an axis the fix barely
        # observes cannot say much about its noise. H's velocity rows select the velocity
        # axes measured, so (K H)_vv is the gain's entry of that row (0 for an axis absent).
        kh = [0.0, 0.0, 0.0]
        gain = corr.gain
        for k, axis in enumerate(axes):
            kh[axis] = gain.item(ins.IV + axis, 3 + k)
        psd = diag.accel_psd_ned.tolist()
        lo, hi = cfg.q_scale_bounds
        q0 = self._accel_psd0
        q_lo, q_hi = lo * q0, hi * q0
        min_epochs = cfg.adaptive_min_epochs
        q_win = self._q_win
        new = list(psd)
        changed = False
        for i in range(3):
            kh2 = max(kh[i], KH_FLOOR) ** 2
            q_win.add(i, psd[i] + (dxv[i] ** 2 - dp[i]) / (dt * kh2))
            mean = q_win.ready_mean(i, min_epochs)
            if mean is not None:
                new[i] = min(max(mean, q_lo), q_hi)
                if abs(new[i] - psd[i]) > 1e-3 * psd[i]:
                    changed = True
        if changed:
            diag.accel_psd_ned = np.array(new)
        return changed

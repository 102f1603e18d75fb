"""How far the autopilot's attitude strays from its own body rates (attitude-aided mode).

The autopilot reports its attitude and its body rates (its gyros less its own gyro bias
estimate) together. Integrated from one sample to the next, the rates reach an attitude
that differs from the next sample's by what the autopilot's filter corrected besides them
(its aiding, the error of its bias estimate): the body-frame rotation vector ``r`` from
the one to the other, per unit of time, is a rate the rates alone would miss. An
exponentially weighted mean of ``r / dt`` over ``window_s`` and its scatter give the
uncertainty of the rates' bias when they alone carry the attitude through a gap
(:meth:`~companion.nav.blend.BlendNavigator.hold_attitude`): the mean squared plus the
variance of the mean.
"""

from __future__ import annotations

import math

from companion.nav.rotations import Quat, quat_from_rotvec, quat_mul, rotvec_between

MAX_STEP_S = 0.5
"""Samples further apart than this are not compared (a gap in the attitude stream)."""
MAX_RATE_RADPS = math.radians(5.0)
"""A residual rate above this is a jump of the autopilot's attitude (an EKF reset, a lane
switch), not a drift: not used."""


class RateDrift:
    """Exponentially weighted statistics of the attitude's residual against the rates.

    Parameters
    ----------
    window_s
        Time constant of the weighting, s.
    """

    def __init__(self, window_s: float) -> None:
        if not window_s > 0.0:
            raise ValueError("window_s must be > 0")
        self.window_s = window_s
        self.skipped = 0
        """Residuals not used (:data:`MAX_STEP_S`, :data:`MAX_RATE_RADPS`)."""
        self._last: tuple[float, Quat, list[float]] | None = None
        self._sum_r = [0.0, 0.0, 0.0]
        self._sum_r2_dt = [0.0, 0.0, 0.0]
        self._span_s = 0.0
        self._n = 0.0
        self._n2 = 0.0

    def restart(self) -> None:
        """The next sample does not follow the last one (a changed yaw correction)."""
        self._last = None

    def on_sample(self, t_s: float, q_nb: Quat, rate_b_radps: list[float]) -> None:
        """One attitude sample ``q_nb`` with its body rates (rad/s) at ``t_s``."""
        last = self._last
        self._last = (t_s, q_nb, rate_b_radps)
        if last is None:
            return
        t0, q0, w0 = last
        dt = t_s - t0
        if not 0.0 < dt <= MAX_STEP_S:
            self.skipped += 1
            return
        h = 0.5 * dt
        dq = quat_from_rotvec(
            (w0[0] + rate_b_radps[0]) * h,
            (w0[1] + rate_b_radps[1]) * h,
            (w0[2] + rate_b_radps[2]) * h,
        )
        self._residual(dt, quat_mul(q0, dq), q_nb)

    def on_increment(self, t_s: float, q_nb: Quat, dq_b: Quat | None) -> None:
        """One attitude sample ``q_nb`` at ``t_s`` and the rotation ``dq_b`` (body frame)
        that carries the previous sample to it (the IMU's gyro, :mod:`.gyro_carry`; None:
        not known, the sample only starts the next step)."""
        last = self._last
        self._last = (t_s, q_nb, [])
        if last is None or dq_b is None:
            return
        dt = t_s - last[0]
        if not 0.0 < dt <= MAX_STEP_S:
            self.skipped += 1
            return
        self._residual(dt, quat_mul(last[1], dq_b), q_nb)

    def _residual(self, dt: float, carried: Quat, q_nb: Quat) -> None:
        r = rotvec_between(carried, q_nb)
        if not math.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]) <= MAX_RATE_RADPS * dt:
            self.skipped += 1
            return
        k = math.exp(-dt / self.window_s)
        for i in range(3):
            self._sum_r[i] = k * self._sum_r[i] + r[i]
            self._sum_r2_dt[i] = k * self._sum_r2_dt[i] + r[i] * r[i] / dt
        self._span_s = k * self._span_s + dt
        self._n = k * self._n + 1.0
        self._n2 = k * k * self._n2 + 1.0

    def mean_rate(self) -> list[float] | None:
        """Per body axis, the mean rate (rad/s) at which the attitude strayed from the
        rates: what the autopilot's aiding corrected them by. None before any residual."""
        span = self._span_s
        if span <= 0.0:
            return None
        return [self._sum_r[i] / span for i in range(3)]

    def bias_variance(self) -> list[float] | None:
        """Per body axis, the variance ((rad/s)^2) of the rates' bias the residuals show:
        their mean rate squared plus the variance of that mean (its scatter over the
        effective number of samples). None before any residual."""
        span = self._span_s
        if span <= 0.0 or self._n2 <= 0.0:
            return None
        n_eff = max(self._n * self._n / self._n2, 1.0)
        out = []
        for i in range(3):
            mean = self._sum_r[i] / span
            scatter = max(self._sum_r2_dt[i] / span - mean * mean, 0.0)
            out.append(mean * mean + scatter / n_eff)
        return out

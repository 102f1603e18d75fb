"""The IMU's own account of the motion, for testing a receiver against it.

:class:`InertialIncrements` integrates the IMU's specific force, rotated to NED by the
autopilot's attitude (plus normal gravity on the down axis), into cumulative increments
with a short history, so that they can be read at a GNSS fix's (older) time of validity:

    V(t) = int (C_nb f + g) dt,      P(t) = int V dt,
    W(t) = int C_nb[:2, :] dt,       WW(t) = int W dt,     R(t) = int |omega x f| dt.

``V`` and ``P`` carry the motion; ``W`` and ``WW`` carry how a constant body-frame
accelerometer bias ``b`` enters the horizontal velocity and position (``dV = -dW b``,
``dP = -dWW b``): the disagreement of a real autopilot's attitude and accelerometer is
mostly such a bias (1-5 deg of tilt on the ArduPilot logs of ../shared/realdata, which a
body-frame bias explains down to 0.1 m/s^2 over 10 s windows where a NED one leaves
0.35). It also measures the specific force's white noise in flight (the vibration a
real autopilot's IMU stream aliases), which bounds how small a drag the IMU can see.

The frame is the engine's flat local NED frame (as :mod:`companion.nav.ins`). Between
attitude samples the attitude is carried to the IMU time with the attitude sample's body
rate (first order). Pure: no I/O, no clock; time is the samples' ``t_s``.

References
----------
Tanil, Khanafseh, Joerger and Pervan, "An INS monitor to detect GNSS spoofers capable of
tracking vehicle position", IEEE Trans. AES 54(1), 2018 (the IMU as the reference a
spoofer cannot control). Titterton & Weston, Strapdown Inertial Navigation Technology,
2nd ed., eq. 12.20-12.22 (the velocity error of a bias and of an attitude error).
"""

from __future__ import annotations

import bisect
import logging
import math
from collections import Counter
from dataclasses import dataclass

import numpy as np

from companion.nav.rotations import euler_to_quat_values, quat_to_mat_values
from companion.types import AttitudeSample, FloatArray, ImuSample

log = logging.getLogger(__name__)

HISTORY_S = 3.0
"""How far back the increments can be read, s (GNSS fixes arrive up to a few tenths
of a second after their time of validity; a measured lag adds up to 0.5 s)."""
MAX_IMU_GAP_S = 0.5
"""A longer gap between IMU samples breaks the integration (:attr:`InertialIncrements.epoch`
changes: increments across it are not comparable)."""
NOISE_TAU_S = 20.0
"""Time constant of the running estimate of the specific force's white noise, s."""


@dataclass(frozen=True, slots=True)
class Increments:
    """The cumulative increments at one time: ``vel`` (3,) m/s, ``pos`` (3,) m, ``w`` (2, 3)
    s, ``ww`` (2, 3) s^2, ``turn`` m/s^2 s (``R``), of integration ``epoch`` (comparable
    only within one epoch)."""

    t_s: float
    epoch: int
    vel: FloatArray
    pos: FloatArray
    w: FloatArray
    ww: FloatArray
    turn: float = 0.0


class InertialIncrements:
    """Cumulative IMU increments with a short history (see the module docstring).

    Parameters
    ----------
    gravity_d_mps2 : normal gravity along the down axis at the frame's origin, m/s^2.
    """

    def __init__(self, gravity_d_mps2: float) -> None:
        if not math.isfinite(gravity_d_mps2):
            raise ValueError("gravity_d_mps2 must be finite")
        self._g = float(gravity_d_mps2)
        self.stats: Counter[str] = Counter()
        self.reset()

    def reset(self) -> None:
        """Forget everything (autopilot reboot)."""
        self._att: tuple[float, ...] | None = None
        self._att_t = 0.0
        self._att_rate = (0.0, 0.0, 0.0)
        self._last_t: float | None = None
        self._last_a = (0.0, 0.0, 0.0)
        self._last_c = (0.0,) * 6
        self._last_f = (0.0, 0.0, 0.0)
        self._last_turn = 0.0
        self._acc = [0.0] * 19
        """V (3), P (3), W (6), WW (6), R, cumulative."""
        self._h_t: list[float] = []
        self._h: list[tuple[float, ...]] = []
        self.epoch = 0
        self._noise_var = 0.0
        self._noise_n = 0
        self._dt_mean = 0.0

    # ------------------------------------------------------------------ inputs

    def on_attitude(self, sample: AttitudeSample, yaw_correction_rad: float = 0.0) -> None:
        """Take the autopilot's attitude (``yaw_correction_rad`` is subtracted from its yaw)."""
        r = sample.rate_b_radps.tolist()
        vals = (sample.t_s, sample.roll_rad, sample.pitch_rad, sample.yaw_rad, yaw_correction_rad)
        if len(r) != 3 or not math.isfinite(sum(vals) + sum(r)):
            self.stats["bad_attitude"] += 1
            return
        q = euler_to_quat_values(
            sample.roll_rad, sample.pitch_rad, sample.yaw_rad - yaw_correction_rad
        )
        self._att = quat_to_mat_values(q)
        self._att_t = sample.t_s
        self._att_rate = (r[0], r[1], r[2])

    def on_imu(self, sample: ImuSample) -> None:
        """Integrate one IMU sample (trapezoid between samples)."""
        t = sample.t_s
        fx, fy, fz = sample.acc_b_mps2.tolist()
        if not (math.isfinite(t) and math.isfinite(fx + fy + fz)):
            self.stats["bad_imu"] += 1
            return
        c = self._att
        if c is None:
            self.stats["imu_before_attitude"] += 1
            return
        last_t = self._last_t
        dt = 0.0 if last_t is None else t - last_t
        if last_t is not None and dt <= 0.0:
            self.stats["imu_time_not_increasing"] += 1
            return
        # the attitude carried to the IMU time: f' = f + theta x f, theta = omega (t - t_att)
        h = t - self._att_t
        wx, wy, wz = self._att_rate
        tx, ty, tz = wx * h, wy * h, wz * h
        gx = fx + ty * fz - tz * fy
        gy = fy + tz * fx - tx * fz
        gz = fz + tx * fy - ty * fx
        a = (
            c[0] * gx + c[1] * gy + c[2] * gz,
            c[3] * gx + c[4] * gy + c[5] * gz,
            c[6] * gx + c[7] * gy + c[8] * gz + self._g,
        )
        crow = (c[0], c[1], c[2], c[3], c[4], c[5])
        # |omega x f|: how fast the specific force turns, per second of attitude time error
        turn = math.sqrt(
            (wy * fz - wz * fy) ** 2 + (wz * fx - wx * fz) ** 2 + (wx * fy - wy * fx) ** 2
        )
        if last_t is None or dt > MAX_IMU_GAP_S:
            if last_t is not None:
                self.stats["imu_gap"] += 1
                log.info("inertial increments: IMU gap of %.3f s at t=%.3f s", dt, t)
            self.epoch += 1
            self._acc = [0.0] * 19
            self._h_t.clear()
            self._h.clear()
        else:
            self._integrate(dt, a, crow)
            self._acc[18] += 0.5 * (turn + self._last_turn) * dt
            self._note_noise(dt, fx, fy, fz)
        self._last_t = t
        self._last_a = a
        self._last_c = crow
        self._last_f = (fx, fy, fz)
        self._last_turn = turn
        self._h_t.append(t)
        self._h.append(tuple(self._acc))
        if t - self._h_t[0] > 2.0 * HISTORY_S:
            k = bisect.bisect_left(self._h_t, t - HISTORY_S) - 1
            if k > 0:
                del self._h_t[:k]
                del self._h[:k]

    def _integrate(self, dt: float, a: tuple[float, float, float], crow: tuple[float, ...]) -> None:
        acc = self._acc
        hdt = 0.5 * dt
        la, lc = self._last_a, self._last_c
        for i in range(3):
            v0 = acc[i]
            acc[i] = v0 + (a[i] + la[i]) * hdt
            acc[3 + i] += (v0 + acc[i]) * hdt
        for i in range(6):
            w0 = acc[6 + i]
            acc[6 + i] = w0 + (crow[i] + lc[i]) * hdt
            acc[12 + i] += (w0 + acc[6 + i]) * hdt

    def _note_noise(self, dt: float, fx: float, fy: float, fz: float) -> None:
        """Running variance of the specific force's sample-to-sample change, halved (its
        white part per sample), the largest axis: an upper bound where the motion adds."""
        lf = self._last_f
        var = max((fx - lf[0]) ** 2, (fy - lf[1]) ** 2, (fz - lf[2]) ** 2) * 0.5
        n = self._noise_n
        w = max(dt / NOISE_TAU_S, 1.0 / (n + 1))
        self._noise_var += w * (var - self._noise_var)
        self._dt_mean += w * (dt - self._dt_mean)
        self._noise_n = n + 1

    # ------------------------------------------------------------------ outputs

    @property
    def newest_t_s(self) -> float | None:
        """Time of the newest IMU sample integrated (None before the first)."""
        return self._last_t

    def vrw_psd_m2ps3(self) -> float:
        """The measured white noise of the specific force as a velocity random walk PSD,
        m^2/s^3 (per axis; 0 before a second sample)."""
        if self._noise_n < 2:
            return 0.0
        return self._noise_var * self._dt_mean

    def at(self, t_s: float) -> Increments | None:
        """The increments at ``t_s`` (interpolated; extrapolated with the last acceleration
        up to :data:`HISTORY_S` past the newest sample), None outside the history."""
        ht = self._h_t
        if not ht:
            return None
        last = ht[-1]
        if t_s >= last:
            h = t_s - last
            if h > HISTORY_S:
                return None
            acc, la, lc = self._acc, self._last_a, self._last_c
            vel = [acc[i] + la[i] * h for i in range(3)]
            pos = [acc[3 + i] + acc[i] * h + 0.5 * la[i] * h * h for i in range(3)]
            w = [acc[6 + i] + lc[i] * h for i in range(6)]
            ww = [acc[12 + i] + acc[6 + i] * h + 0.5 * lc[i] * h * h for i in range(6)]
            turn = acc[18] + self._last_turn * h
        else:
            k = bisect.bisect_right(ht, t_s)
            if k == 0:
                return None
            t0, t1 = ht[k - 1], ht[k]
            x0, x1 = self._h[k - 1], self._h[k]
            u = (t_s - t0) / (t1 - t0)
            d = t_s - t0
            vel = [x0[i] + (x1[i] - x0[i]) * u for i in range(3)]
            pos = [x0[3 + i] + 0.5 * (x0[i] + vel[i]) * d for i in range(3)]
            w = [x0[6 + i] + (x1[6 + i] - x0[6 + i]) * u for i in range(6)]
            ww = [x0[12 + i] + 0.5 * (x0[6 + i] + w[i]) * d for i in range(6)]
            turn = x0[18] + (x1[18] - x0[18]) * u
        return Increments(
            t_s,
            self.epoch,
            np.array(vel),
            np.array(pos),
            np.array(w).reshape(2, 3),
            np.array(ww).reshape(2, 3),
            turn,
        )

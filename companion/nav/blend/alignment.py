"""Coarse alignment of the blend's own INS when no autopilot attitude is available.

Levelling (Groves, 2nd ed., ch. 5, coarse alignment): at rest the accelerometers
measure the reaction to gravity, so roll and pitch follow from the mean specific force,
and the mean gyro reading is the gyro bias (the Earth's rate, 0.004 deg/s, is below a
MEMS gyro's bias and is taken with it). The rest detector is a window of
``align_static_s`` whose accelerometer and gyro standard deviations are below
``align_static_acc_std_mps2`` and ``align_static_gyro_std_radps``; the whole rest period
is averaged.

Yaw from the GNSS velocity in motion (in-motion alignment by velocity matching, Groves
ch. 14): with the attitude carried by the gyros from
the level start at an arbitrary yaw, the horizontal specific force rotated into that
frame and integrated between two fixes, ``u``, equals the change of the GNSS horizontal
velocity, ``dv``, rotated by the yaw error (gravity has no horizontal component). The
least-squares yaw over the pairs of a window is
``atan2(sum(u x dv), sum(u . dv))``, its 1-sigma the residual's scatter over the
horizontal specific-force energy ``sqrt(sum |u|^2)``. The alignment is ready once that
sigma is below ``align_yaw_sigma_max_rad``; the filter then refines yaw from the GNSS
velocity (yaw is observable while the vehicle accelerates horizontally).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from companion.nav.rotations import (
    Quat,
    euler_to_quat_values,
    quat_from_rotvec,
    quat_mul,
    quat_normalise,
    quat_to_mat_values,
)

_GYRO_BIAS_UNSEEN_RADPS = math.radians(0.5)
"""Gyro-bias 1-sigma when no rest period was seen (a consumer MEMS gyro's turn-on bias)."""


@dataclass(frozen=True, slots=True)
class Alignment:
    """A coarse attitude at ``t_s``: body-to-NED quaternion, gyro bias (body, rad/s) and
    1-sigma of the tilt (rad, per axis), the yaw (rad) and the gyro bias (rad/s)."""

    t_s: float
    q_nb: Quat
    gyro_bias_b_radps: tuple[float, float, float]
    tilt_sigma_rad: float
    yaw_sigma_rad: float
    gyro_bias_sigma_radps: float
    rest_specific_force_b_mps2: tuple[float, float, float] | None = None
    """Mean specific force of the rest period (body, m/s^2): its magnitude less gravity
    is the accelerometer bias along the vertical; None when not levelled at rest."""


class CoarseAligner:
    """Levels at rest, carries the attitude with the gyros, finds yaw from GNSS velocity."""

    def __init__(
        self,
        static_s: float,
        static_acc_std_mps2: float,
        static_gyro_std_radps: float,
        window_s: float,
        yaw_sigma_max_rad: float,
        tilt_sigma_rad: float,
    ) -> None:
        self._static_s = static_s
        self._acc_std = static_acc_std_mps2
        self._gyro_std = static_gyro_std_radps
        self._window_s = window_s
        self._yaw_sigma_max = yaw_sigma_max_rad
        self._tilt_sigma = tilt_sigma_rad
        self.reset()

    def reset(self) -> None:
        """Forget everything."""
        self._recent: deque[tuple[float, list[float], list[float]]] = deque()
        self._win_sum = [0.0] * 6
        self._win_sq = [0.0] * 6
        self._rest_n = 0
        self._rest_acc = [0.0, 0.0, 0.0]
        self._rest_gyro = [0.0, 0.0, 0.0]
        self._q: Quat | None = None
        self._bg = [0.0, 0.0, 0.0]
        self._bg_sigma = _GYRO_BIAS_UNSEEN_RADPS
        self._t_s = math.nan
        self._last_gyro: list[float] | None = None
        self._u = [0.0, 0.0]  # horizontal integral of the rotated specific force
        self._u_hist: deque[tuple[float, float, float]] = deque()
        self._fixes: deque[tuple[float, float, float, float, float]] = deque()
        self._seeded: Alignment | None = None
        self._rest_f: tuple[float, float, float] | None = None

    @property
    def levelled(self) -> bool:
        return self._q is not None

    def seed(self, alignment: Alignment) -> None:
        """Start from a known attitude (the blend's own before a restart)."""
        self.reset()
        self._q = alignment.q_nb
        self._bg = list(alignment.gyro_bias_b_radps)
        self._bg_sigma = alignment.gyro_bias_sigma_radps
        self._t_s = alignment.t_s
        self._seeded = alignment

    def on_imu(self, t_s: float, acc: list[float], gyro: list[float]) -> None:
        """One IMU sample (body, m/s^2 and rad/s)."""
        rec = self._recent
        rec.append((t_s, acc, gyro))
        self._window_add(acc, gyro, 1.0)
        while rec and rec[0][0] < t_s - self._static_s:
            _, a_old, g_old = rec.popleft()
            self._window_add(a_old, g_old, -1.0)
        at_rest = self._is_static()
        if at_rest:
            if self._rest_n == 0:  # a new rest period: average its window
                self._rest_acc = [0.0, 0.0, 0.0]
                self._rest_gyro = [0.0, 0.0, 0.0]
                for _, a, g in rec:
                    self._add_rest(a, g)
            else:
                self._add_rest(acc, gyro)
            self._level_from_rest()
        else:
            self._rest_n = 0
        if self._q is None:
            return
        self._propagate(t_s, acc, gyro)

    def _add_rest(self, a: list[float], g: list[float]) -> None:
        self._rest_n += 1
        for i in range(3):
            self._rest_acc[i] += a[i]
            self._rest_gyro[i] += g[i]

    def _window_add(self, acc: list[float], gyro: list[float], sign: float) -> None:
        """Running sums and sums of squares of the rest window (six channels)."""
        sums, sq = self._win_sum, self._win_sq
        for i in range(3):
            a, g = acc[i], gyro[i]
            sums[i] += sign * a
            sq[i] += sign * a * a
            sums[3 + i] += sign * g
            sq[3 + i] += sign * g * g

    def _is_static(self) -> bool:
        rec = self._recent
        if len(rec) < 10 or rec[-1][0] - rec[0][0] < 0.9 * self._static_s:
            return False
        n = len(rec)
        for i in range(6):
            lim = self._acc_std if i < 3 else self._gyro_std
            m = self._win_sum[i] / n
            if self._win_sq[i] / n - m * m > lim * lim:
                return False
        return True

    def _level_from_rest(self) -> None:
        """Roll and pitch from the rest period's mean specific force, gyro bias its mean
        rate (Groves ch. 5); yaw kept (0 at the first levelling)."""
        n = self._rest_n
        fx, fy, fz = (c / n for c in self._rest_acc)
        roll = math.atan2(-fy, -fz)
        pitch = math.atan2(fx, math.hypot(fy, fz))
        yaw = 0.0
        if self._q is not None:
            w, x, y, z = self._q
            yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
        self._q = euler_to_quat_values(roll, pitch, yaw)
        self._bg = [c / n for c in self._rest_gyro]
        # the mean of n samples of the gyro noise, bounded below by 0.01 deg/s
        self._bg_sigma = max(self._gyro_std / math.sqrt(n), math.radians(0.01))
        self._rest_f = (fx, fy, fz)
        self._t_s = self._recent[-1][0]
        self._last_gyro = None

    def _propagate(self, t_s: float, acc: list[float], gyro: list[float]) -> None:
        dt = t_s - self._t_s
        lg = self._last_gyro if self._last_gyro is not None else gyro
        self._last_gyro = gyro
        self._t_s = t_s
        if not (0.0 < dt < 1.0):
            return
        q = self._q
        if q is None:
            return
        bg = self._bg
        rot = quat_from_rotvec(*(((gyro[i] + lg[i]) * 0.5 - bg[i]) * dt for i in range(3)))
        q = quat_normalise(quat_mul(q, rot))
        self._q = q
        c = quat_to_mat_values(q)
        self._u[0] += (c[0] * acc[0] + c[1] * acc[1] + c[2] * acc[2]) * dt
        self._u[1] += (c[3] * acc[0] + c[4] * acc[1] + c[5] * acc[2]) * dt
        hist = self._u_hist
        hist.append((t_s, self._u[0], self._u[1]))
        while len(hist) > 2 and hist[1][0] < t_s - 3.0:
            hist.popleft()

    def _u_at(self, t_s: float) -> tuple[float, float] | None:
        hist = self._u_hist
        if not hist or t_s < hist[0][0]:
            return None
        best = None
        for t, un, ue in reversed(hist):
            if t <= t_s:
                best = (un, ue)
                break
        return best

    def on_fix(self, t_s: float, vn: float, ve: float) -> None:
        """A GNSS horizontal velocity at ``t_s`` (NaN: none)."""
        if self._q is None or not (math.isfinite(vn) and math.isfinite(ve)):
            return
        u = self._u_at(t_s)
        if u is None:
            return
        fixes = self._fixes
        fixes.append((t_s, vn, ve, u[0], u[1]))
        while fixes and fixes[0][0] < t_s - self._window_s:
            fixes.popleft()

    def alignment(self) -> Alignment | None:
        """The attitude at the newest IMU time, or None until yaw is known well enough."""
        q = self._q
        if q is None:
            return None
        seeded = self._seeded
        if seeded is not None:
            return Alignment(
                self._t_s,
                q,
                (self._bg[0], self._bg[1], self._bg[2]),
                seeded.tilt_sigma_rad,
                seeded.yaw_sigma_rad,
                seeded.gyro_bias_sigma_radps,
            )
        fixes = list(self._fixes)
        s_dot = s_cross = s_uu = 0.0
        pairs = []
        for a, b in zip(fixes, fixes[1:], strict=False):
            if b[0] - a[0] > 1.0:
                continue
            dvn, dve = b[1] - a[1], b[2] - a[2]
            un, ue = b[3] - a[3], b[4] - a[4]
            s_dot += un * dvn + ue * dve
            s_cross += un * dve - ue * dvn
            s_uu += un * un + ue * ue
            pairs.append((un, ue, dvn, dve))
        if len(pairs) < 8 or s_uu <= 0.0:
            return None
        psi = math.atan2(s_cross, s_dot)
        c, s = math.cos(psi), math.sin(psi)
        res = 0.0
        for un, ue, dvn, dve in pairs:
            res += (dvn - (c * un - s * ue)) ** 2 + (dve - (s * un + c * ue)) ** 2
        sigma_dv2 = res / max(1, 2 * len(pairs) - 1)
        yaw_sigma = math.sqrt(sigma_dv2 / s_uu)
        if yaw_sigma > self._yaw_sigma_max:
            return None
        q_aligned = quat_normalise(quat_mul(quat_from_rotvec(0.0, 0.0, psi), q))
        return Alignment(
            self._t_s,
            q_aligned,
            (self._bg[0], self._bg[1], self._bg[2]),
            self._tilt_sigma,
            yaw_sigma,
            self._bg_sigma,
            self._rest_f,
        )

"""INS mechanisation in the local NED frame, and its error model.

The nominal state (:class:`Mechanisation`) is kept in plain Python floats (the
per-sample path must cost microseconds): body-to-NED quaternion ``q_nb`` (w, x, y, z),
velocity ``vel`` (NED, m/s) and position ``pos`` (m) in the engine's local NED frame,
and the accelerometer and gyro bias estimates ``ba`` (body, m/s^2) and ``bg`` (body,
rad/s). Quaternion and matrix helpers: :mod:`companion.nav.rotations`.

Two ways of keeping attitude:

* ``strapdown``: the gyros (less their bias estimate) are integrated;
* ``attitude_aided``: the autopilot's attitude (ATTITUDE, with the taxi
  heading correction applied) replaces the attitude at each attitude sample,
  and the gyros only carry it to the IMU times between attitude samples.

In both modes the measured specific force, rotated by the attitude and with
WGS-84 normal gravity added, drives velocity and position (the motion model is
the aircraft's own specific force, not a stationary-acceleration guess: "Tracking
with the aircraft's kinematic and dynamic parameters").

The local frame is treated as an inertial, flat frame with the vertical of
its anchor (Earth rate, transport rate and the tilt of the local vertical
are neglected: over a 60 s bridge at 70 m/s the tilt is 0.6 mrad, and the
simulator's truth is generated in the same frame); gravity magnitude follows
height and latitude (:func:`companion.nav.earth.gravity_mps2`).

Error convention: errors are estimate minus truth; the attitude error
``psi`` (NED, rad) is defined by ``C_hat = (I - [psi x]) C``.

References
----------
Titterton & Weston, Strapdown Inertial Navigation Technology, 2nd ed., ch. 3
(quaternion attitude update) and ch. 12 (psi-angle error equations, 12.20-12.22);
El-Mowafy (2005), RTK networks for precision approach with an adaptive GPS/INS blend
(the INS filter states); "Tracking with the aircraft's kinematic and dynamic
parameters" (specific force as the motion model).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from companion.nav import earth
from companion.nav.rotations import (
    Quat,
    quat_from_rotvec,
    quat_mul,
    quat_normalise,
    rotate_by_rotvec,
    skew,
)
from companion.types import FloatArray

_M_RATIO = earth.OMEGA_IE_RADPS**2 * earth.A_M**2 * earth.B_M / earth.GM_M3PS2

N_ERR = 15
"""Error-state size: position (0:3), velocity (3:6), attitude (6:9), accel bias (9:12),
gyro bias (12:15)."""
IP, IV, IA, IBA, IBG = 0, 3, 6, 9, 12


class LocalGravity:
    """WGS-84 normal gravity in the local NED frame (down component only).

    ``down_mps2(pos_n_m, pos_d_m)`` evaluates the Somigliana formula with the
    free-air term at the latitude and height of the local position.

    References
    ----------
    NIMA TR8350.2 eq. 4-1 and 4-3 (via :func:`companion.nav.earth.gravity_mps2`).
    """

    __slots__ = ("lat0_rad", "alt0_m", "_inv_m")

    def __init__(self, lat0_rad: float, alt0_m: float) -> None:
        self.lat0_rad = lat0_rad
        self.alt0_m = alt0_m
        m_m, _ = earth.radii_of_curvature_m(lat0_rad)
        self._inv_m = 1.0 / (m_m + alt0_m)

    def down_mps2(self, pos_n_m: float, pos_d_m: float) -> float:
        """Gravity (down positive) at a local position, m/s^2."""
        return earth.gravity_mps2(self.lat0_rad + pos_n_m * self._inv_m, self.alt0_m - pos_d_m)

    def coefficients(self, pos_n_m: float) -> tuple[float, float, float]:
        """``(g0, c1, c2)`` with gravity = g0 (1 - c1 h + c2 h^2) at height h (m) on the
        latitude of local north offset ``pos_n_m``: the same formula as
        :func:`companion.nav.earth.gravity_mps2`, split so the per-sample path only
        evaluates the height polynomial."""
        lat = self.lat0_rad + pos_n_m * self._inv_m
        s2 = math.sin(lat) ** 2
        g0 = earth.gravity_mps2(lat, 0.0)
        c1 = 2.0 / earth.A_M * (1.0 + earth.F + _M_RATIO - 2.0 * earth.F * s2)
        return g0, c1, 3.0 / earth.A_M**2


class Mechanisation:
    """Nominal INS state and its per-sample integration (plain floats).

    Each IMU sample's reading is taken as the average over the interval from
    the previous sample (trapezoid of the two readings), the attitude is
    advanced by the rotation vector of the bias-corrected rate, the specific
    force is rotated with the mid-interval attitude, and velocity and
    position are integrated with the trapezoid rule.

    Between covariance epochs it accumulates the time and the NED specific
    force so the error model can be evaluated at a lower rate.
    """

    __slots__ = (
        "gravity",
        "t_s",
        "q_nb",
        "vel",
        "pos",
        "ba",
        "bg",
        "_last_acc",
        "_last_gyro",
        "seg_dt_s",
        "seg_fn_sum",
        "last_gyro_b_radps",
        "_g_coef",
        "_g_n",
    )

    def __init__(self, gravity: LocalGravity) -> None:
        self.gravity = gravity
        self.t_s = 0.0
        self.q_nb: Quat = (1.0, 0.0, 0.0, 0.0)
        self.vel = [0.0, 0.0, 0.0]
        self.pos = [0.0, 0.0, 0.0]
        self.ba = [0.0, 0.0, 0.0]
        self.bg = [0.0, 0.0, 0.0]
        self._last_acc: Sequence[float] | None = None
        self._last_gyro: Sequence[float] | None = None
        self.seg_dt_s = 0.0
        self.seg_fn_sum = [0.0, 0.0, 0.0]
        self.last_gyro_b_radps: Sequence[float] = (0.0, 0.0, 0.0)
        self._g_coef = gravity.coefficients(0.0)
        self._g_n = 0.0

    def initialise(
        self, t_s: float, pos_ned_m: FloatArray, vel_ned_mps: FloatArray, q_nb: Quat
    ) -> None:
        """Set the nominal state (biases are kept)."""
        self.t_s = t_s
        self.pos = [float(c) for c in pos_ned_m]
        self.vel = [float(c) for c in vel_ned_mps]
        self.q_nb = quat_normalise(q_nb)
        self.seg_dt_s = 0.0
        self.seg_fn_sum = [0.0, 0.0, 0.0]
        self._refresh_gravity()

    def set_gravity(self, gravity: LocalGravity) -> None:
        """Use another gravity model (a re-anchored local frame)."""
        self.gravity = gravity
        self._refresh_gravity()

    def _refresh_gravity(self) -> None:
        self._g_n = self.pos[0]
        self._g_coef = self.gravity.coefficients(self._g_n)

    def set_raw(self, acc: Sequence[float], gyro: Sequence[float]) -> None:
        """Remember a reading without integrating (the first sample after a start)."""
        self._last_acc = acc
        self._last_gyro = gyro
        self.last_gyro_b_radps = gyro

    def step(self, t_s: float, acc: Sequence[float], gyro: Sequence[float]) -> None:
        """Integrate from ``self.t_s`` to ``t_s`` with one IMU reading (m/s^2, rad/s, body).

        Attitude: q <- q * exp(theta / 2), theta the bias-corrected trapezoid rotation vector.
        Velocity: dv_n = C(q_prev) (dv_b + theta x dv_b / 2) + g dt (rotation compensation:
        the specific force rotated with the mid-interval attitude to second order).

        References
        ----------
        Savage, "Strapdown inertial navigation integration algorithm design part 2",
        JGCD 21(2), 1998, eq. 18 (velocity rotation compensation, first-order form).
        """
        dt = t_s - self.t_s
        la = self._last_acc if self._last_acc is not None else acc
        lg = self._last_gyro if self._last_gyro is not None else gyro
        self._last_acc = acc
        self._last_gyro = gyro
        self.last_gyro_b_radps = gyro
        self.t_s = t_s
        if dt <= 0.0:
            return
        bg, ba = self.bg, self.ba
        hdt = 0.5 * dt
        tx = ((gyro[0] + lg[0]) * 0.5 - bg[0]) * dt
        ty = ((gyro[1] + lg[1]) * 0.5 - bg[1]) * dt
        tz = ((gyro[2] + lg[2]) * 0.5 - bg[2]) * dt
        ux = ((acc[0] + la[0]) * 0.5 - ba[0]) * dt
        uy = ((acc[1] + la[1]) * 0.5 - ba[1]) * dt
        uz = ((acc[2] + la[2]) * 0.5 - ba[2]) * dt
        # rotation compensation: u + theta x u / 2
        bx = ux + 0.5 * (ty * uz - tz * uy)
        by = uy + 0.5 * (tz * ux - tx * uz)
        bz = uz + 0.5 * (tx * uy - ty * ux)
        w, x, y, z = self.q_nb
        # rotate (bx, by, bz) by q: v + w t + q_vec x t, t = 2 q_vec x v
        rx = 2.0 * (y * bz - z * by)
        ry = 2.0 * (z * bx - x * bz)
        rz = 2.0 * (x * by - y * bx)
        dvn = bx + w * rx + (y * rz - z * ry)
        dve = by + w * ry + (z * rx - x * rz)
        dvd = bz + w * rz + (x * ry - y * rx)
        # attitude: q * exp(theta / 2)
        ang2 = tx * tx + ty * ty + tz * tz
        if ang2 < 1e-12:
            c, k = 1.0 - ang2 / 8.0, 0.5 - ang2 / 48.0
        else:
            ang = math.sqrt(ang2)
            c, k = math.cos(0.5 * ang), math.sin(0.5 * ang) / ang
        dx, dy, dz = tx * k, ty * k, tz * k
        qw = w * c - x * dx - y * dy - z * dz
        qx = w * dx + x * c + y * dz - z * dy
        qy = w * dy - x * dz + y * c + z * dx
        qz = w * dz + x * dy - y * dx + z * c
        n = 1.0 / math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        self.q_nb = (qw * n, qx * n, qy * n, qz * n)
        pos, vel = self.pos, self.vel
        if abs(pos[0] - self._g_n) > 10.0:  # latitude term: 10 m of northing is 8e-8 m/s^2
            self._refresh_gravity()
        h_mid = self.gravity.alt0_m - pos[2] - vel[2] * hdt
        g0, c1, c2 = self._g_coef
        g_d = g0 * (1.0 - c1 * h_mid + c2 * h_mid * h_mid)
        v0n, v0e, v0d = vel
        vel[0] = v0n + dvn
        vel[1] = v0e + dve
        vel[2] = v0d + dvd + g_d * dt
        pos[0] += (v0n + vel[0]) * hdt
        pos[1] += (v0e + vel[1]) * hdt
        pos[2] += (v0d + vel[2]) * hdt
        sm = self.seg_fn_sum
        sm[0] += dvn
        sm[1] += dve
        sm[2] += dvd
        self.seg_dt_s += dt

    def take_segment(self) -> tuple[float, FloatArray]:
        """Return and reset the accumulated (dt_s, mean NED specific force (3,))."""
        dt, fn = self.take_segment_values()
        return dt, np.array(fn)

    def take_segment_values(self) -> tuple[float, tuple[float, float, float]]:
        """:meth:`take_segment` with the mean specific force as 3 floats, m/s^2."""
        dt = self.seg_dt_s
        sm = self.seg_fn_sum
        fn = (sm[0] / dt, sm[1] / dt, sm[2] / dt) if dt > 0.0 else (0.0, 0.0, 0.0)
        self.seg_dt_s = 0.0
        self.seg_fn_sum = [0.0, 0.0, 0.0]
        return dt, fn

    def carry_attitude(self, q_nb: Quat, dt_s: float) -> Quat:
        """``q_nb`` advanced by the last bias-corrected gyro reading over ``dt_s`` (may be < 0)."""
        g = self.last_gyro_b_radps
        bg = self.bg
        omega_dt = quat_from_rotvec(
            (g[0] - bg[0]) * dt_s, (g[1] - bg[1]) * dt_s, (g[2] - bg[2]) * dt_s
        )
        return quat_normalise(quat_mul(q_nb, omega_dt))

    def inject(self, dx: FloatArray) -> None:
        """Apply an error-state correction (estimate minus truth convention), shape (15,)."""
        self.inject_values(dx.tolist())

    def inject_values(self, d: Sequence[float]) -> None:
        """:meth:`inject` with the correction as a sequence of (at least 15) floats."""
        pos, vel, ba, bg = self.pos, self.vel, self.ba, self.bg
        for i in range(3):
            pos[i] -= d[IP + i]
            vel[i] -= d[IV + i]
            ba[i] -= d[IBA + i]
            bg[i] -= d[IBG + i]
        self.q_nb = rotate_by_rotvec(self.q_nb, d[IA], d[IA + 1], d[IA + 2])

    def state_vectors(self) -> tuple[FloatArray, FloatArray]:
        """Position and velocity as arrays, shape (3,) each."""
        return np.array(self.pos), np.array(self.vel)


def rotate_by_psi(q_nb: Quat, psi_ned_rad: FloatArray) -> Quat:
    """Remove an attitude error ``psi`` (rad, NED, shape (3,)): C = (I + [psi x]) C_hat, as
    quaternions (:func:`companion.nav.rotations.rotate_by_rotvec`)."""
    rx, ry, rz = np.asarray(psi_ned_rad, dtype=float).tolist()
    return rotate_by_rotvec(q_nb, rx, ry, rz)


def error_model_f(
    f_ned_mps2: FloatArray,
    mat_nb: FloatArray,
    *,
    strapdown: bool,
    tau_att_s: float,
    tau_ba_s: float,
    tau_bg_s: float,
) -> FloatArray:
    """System matrix F (15, 15) of the psi-angle INS error model.

    d(dp)/dt = dv;  d(dv)/dt = [f x] psi - C dba;  d(psi)/dt = C dbg (strapdown) or
    -psi / tau_att (attitude-aided: the autopilot's attitude error as a first-order
    Gauss-Markov process); biases first-order Gauss-Markov with their correlation times
    (``inf`` gives a random walk).

    References
    ----------
    Titterton & Weston, eq. 12.20-12.22 (flat, non-rotating frame); El-Mowafy (2005)
    (first-order Gauss-Markov sensor errors).
    """
    f = np.zeros((N_ERR, N_ERR))
    f[IP : IP + 3, IV : IV + 3] = np.eye(3)
    f[IV : IV + 3, IA : IA + 3] = skew(f_ned_mps2)
    f[IV : IV + 3, IBA : IBA + 3] = -mat_nb
    if strapdown:
        f[IA : IA + 3, IBG : IBG + 3] = mat_nb
    else:
        f[IA : IA + 3, IA : IA + 3] = -np.eye(3) / tau_att_s
    if math.isfinite(tau_ba_s):
        f[IBA : IBA + 3, IBA : IBA + 3] = -np.eye(3) / tau_ba_s
    if math.isfinite(tau_bg_s):
        f[IBG : IBG + 3, IBG : IBG + 3] = -np.eye(3) / tau_bg_s
    return f

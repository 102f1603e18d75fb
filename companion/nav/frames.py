"""Frames and rotations: the local NED frame, Euler angles, angle wrapping.

Naming: ``mat_nb`` rotates a body (FRD) vector into NED, ``vec_n = mat_nb @ vec_b``.
Euler angles are the aerospace ZYX sequence (yaw, then pitch, then roll).

The local NED frame is anchored at a geodetic point; geodesy is pymap3d's.
Heights are whatever datum the caller uses consistently (the core uses MSL
heights; within a local frame the geoid undulation is a constant offset of
centimetres to metres that drops out of every difference).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pymap3d

from companion.types import FloatArray


def wrap_pi(angle_rad: float) -> float:
    """Wrap an angle to [-pi, pi)."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


def wrap_2pi(angle_rad: float) -> float:
    """Wrap an angle to [0, 2 pi)."""
    return angle_rad % (2.0 * math.pi)


def skew(v: FloatArray) -> FloatArray:
    """Cross-product matrix: ``skew(a) @ b == cross(a, b)``, shape (3, 3)."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def euler_to_mat_nb(roll_rad: float, pitch_rad: float, yaw_rad: float) -> FloatArray:
    """Body-to-NED rotation matrix from ZYX Euler angles, shape (3, 3)."""
    cr, sr = math.cos(roll_rad), math.sin(roll_rad)
    cp, sp = math.cos(pitch_rad), math.sin(pitch_rad)
    cy, sy = math.cos(yaw_rad), math.sin(yaw_rad)
    return np.array(
        [
            [cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy],
            [cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy],
            [-sp, sr * cp, cr * cp],
        ]
    )


def mat_nb_to_euler(mat_nb: FloatArray) -> tuple[float, float, float]:
    """ZYX Euler angles (roll, pitch, yaw) in radians from a body-to-NED matrix."""
    roll = math.atan2(mat_nb[2, 1], mat_nb[2, 2])
    pitch = -math.asin(max(-1.0, min(1.0, mat_nb[2, 0])))
    yaw = math.atan2(mat_nb[1, 0], mat_nb[0, 0])
    return roll, pitch, yaw


def quat_to_euler(q_nb: FloatArray) -> tuple[float, float, float]:
    """ZYX Euler angles from a body-to-NED quaternion (w, x, y, z)."""
    w, x, y, z = (float(c) for c in q_nb)
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return roll, pitch, yaw


def euler_to_quat(roll_rad: float, pitch_rad: float, yaw_rad: float) -> FloatArray:
    """Body-to-NED quaternion (w, x, y, z) from ZYX Euler angles, shape (4,)."""
    cr, sr = math.cos(roll_rad / 2), math.sin(roll_rad / 2)
    cp, sp = math.cos(pitch_rad / 2), math.sin(pitch_rad / 2)
    cy, sy = math.cos(yaw_rad / 2), math.sin(yaw_rad / 2)
    return np.array(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ]
    )


@dataclass(frozen=True, slots=True)
class LocalFrame:
    """A local NED frame anchored at a geodetic point (radians, metres)."""

    lat0_rad: float
    lon0_rad: float
    alt0_m: float

    def lla_to_ned(self, lat_rad: float, lon_rad: float, alt_m: float) -> FloatArray:
        """Geodetic to local NED position, m, shape (3,)."""
        n, e, d = pymap3d.geodetic2ned(
            lat_rad, lon_rad, alt_m, self.lat0_rad, self.lon0_rad, self.alt0_m, deg=False
        )
        return np.array([float(n), float(e), float(d)])

    def ned_to_lla(self, pos_ned_m: FloatArray) -> tuple[float, float, float]:
        """Local NED position to geodetic (lat_rad, lon_rad, alt_m)."""
        lat, lon, alt = pymap3d.ned2geodetic(
            float(pos_ned_m[0]),
            float(pos_ned_m[1]),
            float(pos_ned_m[2]),
            self.lat0_rad,
            self.lon0_rad,
            self.alt0_m,
            deg=False,
        )
        return float(lat), float(lon), float(alt)

    def distance_from_anchor_m(self, pos_ned_m: FloatArray) -> float:
        """Horizontal distance of a local position from the anchor, m."""
        return float(math.hypot(pos_ned_m[0], pos_ned_m[1]))

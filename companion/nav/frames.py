"""Coordinate frames: WGS-84 geodetic (LLA), ECEF, and the local NED frame.

Rotations (quaternions, matrices, Euler angles) are in :mod:`companion.nav.rotations`.

The local NED frame is anchored at a geodetic point; its conversions are exact
closed forms through ECEF (tested against pymap3d, which costs far more per point).
Heights are whatever datum the caller uses consistently (the core uses MSL
heights; within a local frame the geoid undulation is a constant offset of
centimetres to metres that drops out of every difference).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from companion.nav.earth import A_M, B_M, E2
from companion.types import FloatArray

_EP2 = (A_M * A_M - B_M * B_M) / (B_M * B_M)
"""Second eccentricity squared."""


def geodetic_to_ecef_m(lat_rad: float, lon_rad: float, alt_m: float) -> tuple[float, float, float]:
    """WGS-84 geodetic to ECEF, m (closed form)."""
    slat, clat = math.sin(lat_rad), math.cos(lat_rad)
    n_m = A_M / math.sqrt(1.0 - E2 * slat * slat)
    r = (n_m + alt_m) * clat
    return r * math.cos(lon_rad), r * math.sin(lon_rad), (n_m * (1.0 - E2) + alt_m) * slat


def ecef_to_geodetic(x_m: float, y_m: float, z_m: float) -> tuple[float, float, float]:
    """ECEF to WGS-84 (lat_rad, lon_rad, alt_m), exact closed form.

    References
    ----------
    Heikkinen, "Geschlossene Formeln zur Berechnung raeumlicher geodaetischer
    Koordinaten aus rechtwinkligen Koordinaten", Z. Vermess. 107 (1982); as given by
    Zhu, IEEE TAES 30(3), 1994, eq. 5-16. Valid away from the Earth's centre.
    """
    p = math.hypot(x_m, y_m)
    zz = z_m * z_m
    f_ = 54.0 * B_M * B_M * zz
    g_ = p * p + (1.0 - E2) * zz - E2 * (A_M * A_M - B_M * B_M)
    c = E2 * E2 * f_ * p * p / (g_ * g_ * g_)
    s = (1.0 + c + math.sqrt(c * c + 2.0 * c)) ** (1.0 / 3.0)
    k = s + 1.0 / s + 1.0
    pp = f_ / (3.0 * k * k * g_ * g_)
    q = math.sqrt(1.0 + 2.0 * E2 * E2 * pp)
    r0 = -pp * E2 * p / (1.0 + q) + math.sqrt(
        max(
            0.5 * A_M * A_M * (1.0 + 1.0 / q)
            - pp * (1.0 - E2) * zz / (q * (1.0 + q))
            - 0.5 * pp * p * p,
            0.0,
        )
    )
    t = p - E2 * r0
    u = math.sqrt(t * t + zz)
    v = math.sqrt(t * t + (1.0 - E2) * zz)
    z0 = B_M * B_M * z_m / (A_M * v)
    alt = u * (1.0 - B_M * B_M / (A_M * v))
    lat = math.atan2(z_m + _EP2 * z0, p)
    return lat, math.atan2(y_m, x_m), alt


@dataclass(frozen=True, slots=True)
class LocalFrame:
    """A local NED frame anchored at a geodetic point (radians, metres).

    Conversions are exact (through ECEF) and cheap (the anchor's ECEF position and
    rotation are computed once): they run at every fix and every publication.
    pymap3d is the reference they are tested against.
    """

    lat0_rad: float
    lon0_rad: float
    alt0_m: float
    _ecef0: tuple[float, float, float] = field(init=False, repr=False, compare=False)
    _rot: tuple[tuple[float, float, float], ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "_ecef0", geodetic_to_ecef_m(self.lat0_rad, self.lon0_rad, self.alt0_m)
        )
        sl, cl = math.sin(self.lat0_rad), math.cos(self.lat0_rad)
        so, co = math.sin(self.lon0_rad), math.cos(self.lon0_rad)
        object.__setattr__(
            self,
            "_rot",
            ((-sl * co, -sl * so, cl), (-so, co, 0.0), (-cl * co, -cl * so, -sl)),
        )

    def lla_to_ned(self, lat_rad: float, lon_rad: float, alt_m: float) -> FloatArray:
        """Geodetic to local NED position, m, shape (3,)."""
        x, y, z = geodetic_to_ecef_m(lat_rad, lon_rad, alt_m)
        x0, y0, z0 = self._ecef0
        dx, dy, dz = x - x0, y - y0, z - z0
        (a, b, c), (d, e, f), (g, h, i) = self._rot
        return np.array(
            [a * dx + b * dy + c * dz, d * dx + e * dy + f * dz, g * dx + h * dy + i * dz]
        )

    def ned_to_lla(self, pos_ned_m: FloatArray) -> tuple[float, float, float]:
        """Local NED position to geodetic (lat_rad, lon_rad, alt_m)."""
        n, e_, d_ = float(pos_ned_m[0]), float(pos_ned_m[1]), float(pos_ned_m[2])
        (a, b, c), (d, e, f), (g, h, i) = self._rot
        x0, y0, z0 = self._ecef0
        return ecef_to_geodetic(
            x0 + a * n + d * e_ + g * d_, y0 + b * n + e * e_ + h * d_, z0 + c * n + f * e_ + i * d_
        )

    def mat_ne(self) -> FloatArray:
        """ECEF-to-NED rotation at the anchor, shape (3, 3)."""
        return np.array(self._rot)

    def distance_from_anchor_m(self, pos_ned_m: FloatArray) -> float:
        """Horizontal distance of a local position from the anchor, m."""
        return float(math.hypot(pos_ned_m[0], pos_ned_m[1]))


def rotation_between_frames(old: LocalFrame, new: LocalFrame) -> FloatArray:
    """Rotation taking NED vectors of ``old`` into NED vectors of ``new``, shape (3, 3).

    Computed from the two frames' ECEF-to-NED rotations (C_new_e @ C_e_old).
    """
    return new.mat_ne() @ old.mat_ne().T

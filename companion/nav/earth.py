"""WGS-84 constants, radii of curvature and normal gravity.

All angles in radians, lengths in metres. Pure functions, no state.

References
----------
NIMA TR8350.2 (WGS-84), table 3.1 and eq. 4-1 (Somigliana normal gravity),
eq. 4-3 (height correction).
"""

from __future__ import annotations

import math

import numpy as np

from companion.types import FloatArray

A_M = 6378137.0
"""WGS-84 semi-major axis, m."""
F = 1.0 / 298.257223563
"""WGS-84 flattening."""
B_M = A_M * (1.0 - F)
"""Semi-minor axis, m."""
E2 = F * (2.0 - F)
"""First eccentricity squared."""
OMEGA_IE_RADPS = 7.292115e-5
"""Earth rotation rate, rad/s."""
GM_M3PS2 = 3.986004418e14
"""Earth's gravitational constant, m^3/s^2."""
GAMMA_E_MPS2 = 9.7803253359
"""Normal gravity at the equator, m/s^2."""
GAMMA_P_MPS2 = 9.8321849378
"""Normal gravity at the poles, m/s^2."""
_K_SOMIGLIANA = (B_M * GAMMA_P_MPS2) / (A_M * GAMMA_E_MPS2) - 1.0
_M_RATIO = OMEGA_IE_RADPS**2 * A_M**2 * B_M / GM_M3PS2


def radii_of_curvature_m(lat_rad: float) -> tuple[float, float]:
    """Meridian (M) and prime-vertical (N) radii of curvature, m.

    References
    ----------
    Groves, Principles of GNSS, inertial and multisensor navigation, eq. 2.105-2.106.
    """
    s2 = math.sin(lat_rad) ** 2
    d = 1.0 - E2 * s2
    n_m = A_M / math.sqrt(d)
    m_m = A_M * (1.0 - E2) / d**1.5
    return m_m, n_m


def gravity_mps2(lat_rad: float, alt_m: float) -> float:
    """Magnitude of normal gravity at latitude and height (WGS-84 Somigliana with free-air term).

    References
    ----------
    NIMA TR8350.2 eq. 4-1 and 4-3.
    """
    s2 = math.sin(lat_rad) ** 2
    g0 = GAMMA_E_MPS2 * (1.0 + _K_SOMIGLIANA * s2) / math.sqrt(1.0 - E2 * s2)
    return g0 * (
        1.0 - 2.0 / A_M * (1.0 + F + _M_RATIO - 2.0 * F * s2) * alt_m + 3.0 / A_M**2 * alt_m**2
    )


def gravity_ned_mps2(lat_rad: float, alt_m: float) -> FloatArray:
    """Normal gravity as an NED vector (down positive), shape (3,)."""
    return np.array([0.0, 0.0, gravity_mps2(lat_rad, alt_m)])

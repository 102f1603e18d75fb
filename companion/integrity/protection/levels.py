"""Protection levels from the solution covariance.

The horizontal protection level bounds the horizontal error along the major
axis of the error ellipse, the vertical one the vertical error, each with a
K factor taken from the allocated integrity risk:

    d_major = sqrt( (d_N^2 + d_E^2)/2 + sqrt( ((d_N^2 - d_E^2)/2)^2 + d_NE^2 ) )
    HPL = K_H * d_major ,   VPL = K_V * d_V

K_V is the two-sided Gaussian quantile, K_V = Phi^-1(1 - P_V/2); K_H bounds the
2-D error by a circular Gaussian with the major-axis sigma on both axes
(Rayleigh tail), P(|e_H| > K d_major) <= exp(-K^2/2), so K_H = sqrt(-2 ln P_H).
With P_V = 1e-7 and P_H = 5e-9 these give DO-229's 5.33 and 6.18.

The 95 % accuracies that decide the available category use the same bounds
at probability 0.05: sqrt(chi2^-1(0.95, 2)) d_major and Phi^-1(0.975) d_V.

References
----------
RTCA DO-229 (WAAS MOPS), appendix J: d_major, HPL = K_H d_major,
VPL = K_V d_V with K_H 6.18 (the non-precision value; 6.0 for precision approach)
and K_V 5.33. Kim, Walter and Powell, "Standalone GPS-based flight inspection
system" (protection levels against the alert limits of
:mod:`companion.integrity.protection.limits`). ``docs/methods.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2, norm

from companion.types import FloatArray

ACCURACY_PROB = 0.95
"""Probability of the '95 %' accuracy figures (El-Mowafy (2005), requirement tables)."""


def k_vertical(integrity_risk: float) -> float:
    """K factor of the vertical protection level: two-sided Gaussian quantile.

    References
    ----------
    DO-229 appendix J (K_V = 5.33 for a risk of 1e-7).
    """
    if not 0.0 < integrity_risk < 1.0:
        raise ValueError("integrity_risk must be in (0, 1)")
    return float(norm.isf(integrity_risk / 2.0))


def k_horizontal(integrity_risk: float) -> float:
    """K factor of the horizontal protection level: Rayleigh tail on the major-axis sigma.

    References
    ----------
    DO-229 appendix J (K_H = 6.18 corresponds to a risk of 5e-9 with this bound).
    """
    if not 0.0 < integrity_risk < 1.0:
        raise ValueError("integrity_risk must be in (0, 1)")
    return math.sqrt(-2.0 * math.log(integrity_risk))


def d_major_m(pos_cov_ned_m2: FloatArray) -> float:
    """Major semi-axis sigma of the horizontal error ellipse, m.

    Parameters
    ----------
    pos_cov_ned_m2 : (3, 3) or (2, 2) position covariance, NED, m^2.

    References
    ----------
    DO-229 appendix J, d_major.
    """
    cov = np.asarray(pos_cov_ned_m2, dtype=float)
    if cov.shape not in ((3, 3), (2, 2)):
        raise ValueError("pos_cov_ned_m2 must be (3, 3) or (2, 2)")
    return _d_major(float(cov[0, 0]), float(cov[1, 1]), float(cov[0, 1]))


def _d_major(dn2: float, de2: float, dne: float) -> float:
    """:func:`d_major_m` from the N-N, E-E and N-E covariances (m^2), in floats."""
    half_sum = 0.5 * (dn2 + de2)
    half_diff = 0.5 * (dn2 - de2)
    return math.sqrt(max(half_sum + math.sqrt(half_diff * half_diff + dne * dne), 0.0))


@dataclass(frozen=True, slots=True)
class ProtectionLevels:
    """Protection levels and accuracies of one solution (all m)."""

    hpl_m: float
    vpl_m: float
    d_major_m: float
    d_v_m: float
    h95_m: float
    v95_m: float


def protection_levels(pos_cov_ned_m2: FloatArray, k_h: float, k_v: float) -> ProtectionLevels:
    """HPL, VPL and the 95 % accuracies from a (3, 3) NED position covariance.

    A covariance with a non-finite entry gives infinite levels (integrity not
    available), never an exception.

    References
    ----------
    DO-229 appendix J (HPL = K_H d_major, VPL = K_V d_V).
    """
    cov = np.asarray(pos_cov_ned_m2, dtype=float)
    if cov.shape != (3, 3):
        raise ValueError("pos_cov_ned_m2 must be (3, 3)")
    # on Python floats, not numpy reductions: this runs on every published solution
    (dn2, dne, _), (_, de2, _), (_, _, dd2) = rows = cov.tolist()
    if not all(map(math.isfinite, rows[0] + rows[1] + rows[2])):
        inf = math.inf
        return ProtectionLevels(inf, inf, inf, inf, inf, inf)
    dmaj = _d_major(dn2, de2, dne)
    dv = math.sqrt(max(dd2, 0.0))
    # positional (hpl, vpl, d_major, d_v, h95, v95): cheaper than keywords, per solution
    return ProtectionLevels(k_h * dmaj, k_v * dv, dmaj, dv, _H95_FACTOR * dmaj, _V95_FACTOR * dv)


_H95_FACTOR = math.sqrt(float(chi2.ppf(ACCURACY_PROB, 2)))
_V95_FACTOR = float(norm.ppf(0.5 + ACCURACY_PROB / 2.0))

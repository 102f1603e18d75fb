"""A receiver's fix as a measurement in the local frame, and the accuracies assumed for a
fix that reports none: the one table the engine, the blend and the motion models share."""

from __future__ import annotations

import numpy as np

from companion.nav.frames import LocalFrame
from companion.nav.navigator import GnssMeasurement
from companion.types import FixType, GnssFix

FALLBACK_H_STD_M: dict[FixType, float] = {
    FixType.RTK_FIXED: 0.02,
    FixType.RTK_FLOAT: 0.3,
    FixType.DGPS: 1.0,
    FixType.FIX_3D: 2.5,
    FixType.FIX_2D: 5.0,
    FixType.STATIC: 0.02,
    FixType.PPP: 0.3,
}
"""Horizontal 1-sigma position error (m) per fix type when the receiver reports neither an
accuracy nor a DOP: RTK fixed ~2 cm, float ~0.3 m, DGPS ~1 m, autonomous 3-D ~2.5 m
(El-Mowafy 2005: fixed 1.6-2.2 cm 2-D, float 26-32 cm, no corrections 3.5-4 m at 95 %)."""
UNKNOWN_H_STD_M = 10.0
"""Horizontal 1-sigma (m) for a fix type not in :data:`FALLBACK_H_STD_M`."""
VERTICAL_OVER_HORIZONTAL = 1.5
"""Vertical 1-sigma as a multiple of horizontal when the receiver reports no vertical
accuracy (El-Mowafy 2005's height-to-2-D ratios)."""
FALLBACK_STD_M: dict[FixType, tuple[float, float]] = {
    fix: (h, VERTICAL_OVER_HORIZONTAL * h) for fix, h in FALLBACK_H_STD_M.items()
}
"""Horizontal and vertical 1-sigma (m) per fix type, from the two facts above."""
UNKNOWN_STD_M = (UNKNOWN_H_STD_M, VERTICAL_OVER_HORIZONTAL * UNKNOWN_H_STD_M)
"""Horizontal and vertical 1-sigma (m) for a fix type not in the table."""
UERE_M = 2.5
"""User-equivalent range error turning HDOP/VDOP into a 1-sigma position error (m)."""
DEFAULT_VEL_SIGMA_MPS = 0.3
"""Velocity 1-sigma (m/s) when the receiver reports no velocity accuracy."""


def h_sigma_m(fix: GnssFix) -> float:
    """A fix's horizontal 1-sigma: reported, else HDOP x UERE, else by fix type (m)."""
    if fix.h_acc_m is not None:
        return fix.h_acc_m
    if fix.hdop is not None:
        return fix.hdop * UERE_M
    return FALLBACK_H_STD_M.get(fix.fix_type, UNKNOWN_H_STD_M)


def gnss_measurement(fix: GnssFix, frame: LocalFrame) -> GnssMeasurement:
    """A fix as a measurement in ``frame``, with per-axis variances from its accuracies.

    Falls back to DOP x UERE, then to :data:`FALLBACK_H_STD_M`, when the receiver
    does not report h_acc / v_acc / vel_acc.
    """
    pos_ned_m = frame.lla_to_ned(fix.lat_rad, fix.lon_rad, fix.alt_msl_m)
    h_sigma = fix.h_acc_m
    if h_sigma is None:
        h_sigma = (
            fix.hdop * UERE_M
            if fix.hdop is not None
            else FALLBACK_H_STD_M.get(fix.fix_type, UNKNOWN_H_STD_M)
        )
    v_sigma = fix.v_acc_m
    if v_sigma is None:
        v_sigma = fix.vdop * UERE_M if fix.vdop is not None else VERTICAL_OVER_HORIZONTAL * h_sigma
    vel_sigma = fix.vel_acc_mps if fix.vel_acc_mps is not None else DEFAULT_VEL_SIGMA_MPS
    if fix.vel_ne_mps is not None:
        vel = np.array([fix.vel_ne_mps[0], fix.vel_ne_mps[1], np.nan])
        vel_var = np.array([vel_sigma**2, vel_sigma**2, np.nan])
    else:
        vel = np.full(3, np.nan)
        vel_var = np.full(3, np.nan)
    return GnssMeasurement(
        t_s=fix.t_s,
        pos_ned_m=pos_ned_m,
        pos_var_ned_m2=np.array([h_sigma**2, h_sigma**2, v_sigma**2]),
        vel_ned_mps=vel,
        vel_var_ned_m2ps2=vel_var,
        fix_type=fix.fix_type,
        receiver_id=fix.receiver_id,
    )

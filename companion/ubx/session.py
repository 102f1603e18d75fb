"""A recorded raw-observation file and its reference solution, ready for T-D PRP.

Reads the ``.ubx`` (observations, navigation words, the receiver's NAV-PVT) and an
RTKLIB ``.pos`` reference; decodes the broadcast ephemerides; puts the reference in
the local East-North-Up frame of epoch 0. The ``.pos`` heights may be above the geoid
(as the receiver's hMSL): they are made ellipsoidal with the receiver's own geoid
separation (NAV-PVT height − hMSL) at the first epoch.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from companion.nav.frames import geodetic_to_ecef_m
from companion.raw.broadcast import collect_ephemerides
from companion.raw.geometry import enu_rotation
from companion.raw.lnav import Ephemeris
from companion.raw.obs import RawEpoch
from companion.raw.orbit import FloatArray
from companion.ubx.pos import PosRow, read_pos
from companion.ubx.reader import read_file


@dataclass
class Session:
    epochs: list[RawEpoch]
    ephemerides: dict[tuple[str, int], Ephemeris]
    rejected: Counter[str]
    x0_ecef_m: FloatArray
    reference_enu_m: dict[int, tuple[FloatArray, int]] = field(default_factory=dict)
    """Reference position change from epoch 0 (ENU, m) and RTKLIB quality, by the
    epoch's time of week in ms."""

    def reference(self, tow_s: float) -> tuple[FloatArray, int] | None:
        return self.reference_enu_m.get(round(tow_s * 1000.0))


def tow_ms(tow_s: float) -> int:
    return round(tow_s * 1000.0)


def load_session(ubx_path: str, pos_path: str, start_index: int = 0) -> Session:
    """Epoch ``start_index`` of the file is epoch 0, at the reference's position then."""
    epochs, nav, pvt, rejected = read_file(ubx_path)
    ephs, eph_rejected = collect_ephemerides(nav)
    rejected = rejected + eph_rejected
    rows, bad = read_pos(pos_path)
    if bad:
        rejected["malformed reference lines"] += bad
    if not epochs or not rows or not pvt:
        raise ValueError("no observations, no reference or no NAV-PVT")
    geoid_sep = pvt[0].height_msl_m - pvt[0].height_m
    epochs = epochs[start_index:]
    by_ms = {tow_ms(r.tow_s): r for r in rows}
    # reference and observation times agree to the millisecond (rounding of the .pos)
    first = None
    for dt in (0, -1, 1):
        first = by_ms.get(tow_ms(epochs[0].tow_s) + dt)
        if first is not None:
            break
    if first is None:
        raise ValueError("the reference has no row at epoch 0")

    def ecef(r: PosRow) -> FloatArray:
        lat, lon = math.radians(r.lat_deg), math.radians(r.lon_deg)
        return np.asarray(geodetic_to_ecef_m(lat, lon, r.height_m - geoid_sep), dtype=float)

    x0 = ecef(first)
    r_enu = enu_rotation(math.radians(first.lat_deg), math.radians(first.lon_deg))
    session = Session(epochs=epochs, ephemerides=ephs, rejected=rejected, x0_ecef_m=x0)
    for ep in epochs:
        key = tow_ms(ep.tow_s)
        for dt in (0, -1, 1):
            r = by_ms.get(key + dt)
            if r is not None:
                session.reference_enu_m[key] = (r_enu @ (ecef(r) - x0), r.quality)
                break
    return session

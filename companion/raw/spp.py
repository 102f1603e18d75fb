"""Single-epoch code solution (standard point positioning) by iterated least squares.

Pseudoranges of the chosen bands, satellite clock with the relativistic term and the
single-frequency group delay (GPS T_GD, Galileo BGD E1-E5b), Earth rotation during the
flight, Saastamoinen troposphere; no ionospheric model (the Klobuchar coefficients are
not decoded), so a few metres of ionospheric error remain, mostly in height and clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from companion.nav.frames import ecef_to_geodetic
from companion.raw.geometry import elevation_rad, enu_rotation, saastamoinen_m
from companion.raw.lnav import Ephemeris
from companion.raw.obs import C_MPS, L1_BANDS, RawEpoch
from companion.raw.orbit import FloatArray, sat_state_at_reception
from companion.raw.tdprp import wls


@dataclass(frozen=True)
class CodeSolution:
    pos_ecef_m: FloatArray
    clock_m: float
    keys: tuple[tuple[str, int, str], ...]
    g_enu: FloatArray
    y_m: FloatArray
    w: FloatArray


def code_solution(
    epoch: RawEpoch,
    ephemerides: dict[tuple[str, int], Ephemeris],
    x_init_ecef_m: FloatArray | None = None,
    bands: frozenset[str] = L1_BANDS,
    elevation_mask_deg: float = 10.0,
    iterations: int = 8,
) -> CodeSolution | None:
    """The receiver position from one epoch's pseudoranges, or None below 4 satellites."""
    sigs = [
        s
        for s in epoch.signals
        if s.band in bands and s.pr_valid and (s.system, s.sv) in ephemerides
    ]
    x = np.zeros(3) if x_init_ecef_m is None else np.asarray(x_init_ecef_m, float).copy()
    systems = sorted({s.system for s in sigs})
    clocks = np.zeros(len(systems))
    for it in range(iterations):
        rows, ys, ws, keys = [], [], [], []
        have_place = np.linalg.norm(x) > 6.0e6
        if have_place:
            lat, lon, h = ecef_to_geodetic(*x)
            r_enu = enu_rotation(lat, lon)
        for s in sigs:
            eph = ephemerides[(s.system, s.sv)]
            st, _ = sat_state_at_reception(eph, epoch.tow_s, s.pseudorange_m, x)
            los = st.pos_ecef_m - x
            rng = float(np.linalg.norm(los))
            u = los / rng
            el = elevation_rad(x, st.pos_ecef_m) if have_place else math.pi / 2
            if have_place and it > 1 and el < math.radians(elevation_mask_deg):
                continue
            trop = saastamoinen_m(h, lat, el) if have_place else 0.0
            j = systems.index(s.system)
            pred = rng + clocks[j] - C_MPS * (st.clock_s - eph.tgd_s) + trop
            row = np.zeros(3 + len(systems))
            row[:3] = -(r_enu @ u) if have_place else -u
            row[3 + j] = 1.0
            rows.append(row)
            ys.append(s.pseudorange_m - pred)
            ws.append(max(math.sin(el), 0.1) ** 2)
            keys.append((s.system, s.sv, s.band))
        g = np.array(rows)
        if g.shape[0] < 4 or g.shape[0] < np.linalg.matrix_rank(g):
            return None
        used = np.any(g != 0.0, axis=0)
        if g.shape[0] <= int(used.sum()) - 1:
            return None
        sol = np.zeros(g.shape[1])
        sol[used] = wls(g[:, used], np.array(ys), np.array(ws))
        dx = r_enu.T @ sol[:3] if have_place else sol[:3]
        x = x + dx
        clocks = clocks + sol[3:]
        if np.linalg.norm(dx) < 1e-4 and it > 2:
            break
    y = np.array(ys) - g @ sol
    return CodeSolution(x, float(clocks[0]), tuple(keys), g[:, used], y, np.array(ws))

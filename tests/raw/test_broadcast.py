"""Broadcast ephemerides decoded from the receiver's words, and the orbits they give.

Independent checks: the IS-GPS-200 parity of every word; the receiver's Doppler
against the range rate of the computed orbits (a measurement the orbit code never
sees); the relativistic clock term against its closed form −2 r·v / c²; the analytic
velocity against a finite difference; the code solution against the receiver's own.
"""

from __future__ import annotations

import math

import numpy as np

from companion.nav.frames import geodetic_to_ecef_m
from companion.raw.geometry import enu_rotation
from companion.raw.lnav import LnavCollector, parity_ok
from companion.raw.obs import C_MPS, SIGNAL_HZ, NavWords
from companion.raw.orbit import rotate_earth, sat_state, sat_state_at_reception
from companion.raw.spp import code_solution
from companion.ubx.reader import read_file
from tests.raw.helpers import UBX, walk


def test_every_gps_word_passes_parity_and_a_flipped_bit_fails() -> None:
    _, nav, _, _ = read_file(str(UBX))
    words = [w for n in nav if n.system == "GPS" and n.signal == "L1" for w in n.words]
    assert len(words) > 500
    assert all(parity_ok(w) for w in words)
    assert not any(parity_ok(w ^ (1 << 17)) for w in words[:50])


def test_corrupted_subframe_is_a_counted_rejection() -> None:
    _, nav, _, _ = read_file(str(UBX))
    sf = next(n for n in nav if n.system == "GPS" and n.signal == "L1")
    bad = NavWords(sf.system, sf.sv, (sf.words[0] ^ (1 << 20),) + sf.words[1:], sf.signal)
    c = LnavCollector(2)
    assert c.add(bad) is None
    assert c.rejected["bad parity"] == 1


def test_ephemerides_decode_with_plausible_orbits() -> None:
    ephs = walk().ephemerides
    assert {k for k in ephs if k[0] == "GPS"} == {("GPS", s) for s in (10, 23, 27, 32)}
    assert len([k for k in ephs if k[0] == "Galileo"]) == 6
    for (system, _), eph in ephs.items():
        a = eph.sqrt_a**2
        assert abs(a - (26_559_700.0 if system == "GPS" else 29_600_000.0)) < 150_000.0
        assert eph.e < 0.03
        assert eph.week == 2381
        assert 0.0 <= eph.toe_s < 604_800.0


def test_doppler_matches_the_computed_range_rate() -> None:
    s = walk()
    ep = s.epochs[0]
    diffs = []
    for sig in ep.signals:
        key = (sig.system, sig.sv)
        if sig.band not in ("L1", "E1") or key not in s.ephemerides:
            continue
        st, _ = sat_state_at_reception(s.ephemerides[key], ep.tow_s, sig.pseudorange_m, s.x0_ecef_m)
        u = st.pos_ecef_m - s.x0_ecef_m
        u /= np.linalg.norm(u)
        rate = float(u @ st.vel_ecef_mps) - C_MPS * st.clock_drift_sps
        measured = -sig.doppler_hz * C_MPS / SIGNAL_HZ[sig.band]
        diffs.append(measured - rate)
    # what is left is the receiver's clock drift, common to every satellite
    assert len(diffs) == 10
    assert np.ptp(diffs) < 0.2, diffs


def test_relativistic_term_and_velocity() -> None:
    for eph in walk().ephemerides.values():
        t = eph.toe_s + 1234.5
        st = sat_state(eph, t)
        # ECEF velocity -> inertial for r·v: add ω × r
        v_inertial = st.vel_ecef_mps + np.cross([0.0, 0.0, 7.2921151467e-5], st.pos_ecef_m)
        closed = -2.0 * float(st.pos_ecef_m @ v_inertial) / C_MPS**2
        # equal for a Keplerian orbit; the radius harmonics (Crs, Crc) add a radial
        # velocity of up to 2n·hypot(Crs, Crc), hence a bound of 2·a·that / c² (x1.5)
        a = eph.sqrt_a**2
        n = math.sqrt(3.986e14 / a**3)
        bound = 1.5 * 2.0 * a * 2.0 * n * math.hypot(eph.crs_m, eph.crc_m) / C_MPS**2
        assert abs(st.relativistic_s - closed) < bound
        h = 0.5
        fd = (sat_state(eph, t + h).pos_ecef_m - sat_state(eph, t - h).pos_ecef_m) / (2 * h)
        assert np.linalg.norm(fd - st.vel_ecef_mps) < 1e-3


def test_earth_rotation_during_flight() -> None:
    p = np.array([20_000_000.0, 0.0, 5_000_000.0])
    q = rotate_earth(p, 0.07)
    ang = 7.2921151467e-5 * 0.07
    assert np.allclose(q, [p[0] * math.cos(ang), -p[0] * math.sin(ang), p[2]])


def test_code_solution_near_the_receivers_own() -> None:
    """Measured: 5-8 m horizontal, 4-8 m vertical from the RTK position on this walk
    (no ionospheric model; static start beside buildings): bounds 10 m and 15 m."""
    s = walk()
    _, _, pvt, _ = read_file(str(UBX))
    for k in (0, 80, 160):
        sol = code_solution(s.epochs[k], s.ephemerides)
        assert sol is not None
        f = pvt[k]
        lat, lon = math.radians(f.lat_deg), math.radians(f.lon_deg)
        ref = np.array(geodetic_to_ecef_m(lat, lon, f.height_m))
        enu = enu_rotation(lat, lon) @ (sol.pos_ecef_m - ref)
        assert math.hypot(enu[0], enu[1]) < 10.0
        assert abs(enu[2]) < 15.0

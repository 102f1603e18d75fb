"""Frames: exact geodesy against pymap3d, and the rotation between two local frames."""

from __future__ import annotations

import math

import numpy as np
import pymap3d
import pytest

from companion.nav.frames import (
    LocalFrame,
    ecef_to_geodetic,
    geodetic_to_ecef_m,
    rotation_between_frames,
)


def test_local_frame_matches_pymap3d_everywhere():
    rng = np.random.default_rng(7)
    for _ in range(500):
        frame = LocalFrame(rng.uniform(-1.5, 1.5), rng.uniform(-3.1, 3.1), rng.uniform(-100, 5000))
        ned = np.array([*rng.uniform(-50_000, 50_000, 2), rng.uniform(-10_000, 1000)])
        ref = pymap3d.ned2geodetic(*ned, frame.lat0_rad, frame.lon0_rad, frame.alt0_m, deg=False)
        got = frame.ned_to_lla(ned)
        assert got[0] == pytest.approx(ref[0], abs=1e-14)
        assert got[1] == pytest.approx(ref[1], abs=1e-14)
        assert got[2] == pytest.approx(ref[2], abs=1e-7)
        np.testing.assert_allclose(frame.lla_to_ned(*ref), ned, atol=1e-6)


def test_ecef_round_trip_including_poles_and_high_altitude():
    for lat, lon, alt in [(0.0, 0.0, 0.0), (1.5707, 2.0, 100.0), (-1.2, -3.0, 35_000.0)]:
        x, y, z = geodetic_to_ecef_m(lat, lon, alt)
        ref = pymap3d.geodetic2ecef(lat, lon, alt, deg=False)
        np.testing.assert_allclose((x, y, z), ref, atol=1e-6)
        back = ecef_to_geodetic(x, y, z)
        np.testing.assert_allclose(back, (lat, lon, alt), atol=1e-7)


def test_rotation_between_frames_is_the_ned_axes_turn():
    a = LocalFrame(math.radians(52.0), math.radians(21.0), 100.0)
    b = LocalFrame(math.radians(52.0), math.radians(21.3), 100.0)
    rot = rotation_between_frames(a, b)
    np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-12)
    # meridians converge northwards: seen from the eastern frame, the western frame's
    # north points east of north, by d_lon * sin(lat) to first order in d_lon
    angle = math.atan2(rot[1, 0], rot[0, 0])
    assert angle == pytest.approx(math.radians(0.3) * math.sin(math.radians(52.0)), rel=1e-5)

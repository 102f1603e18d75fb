"""The arbitration on the real flights (``../shared/realdata/flights``; skipped where
absent): the receiver is used whenever it reports a 3D fix with >= 6 satellites (after
the first 10 s), no GPS_INPUT with fix type >= 3 is more than 25 m from the receiver's
concurrent 3D fix, a healthy receiver is never called stale, and a slow IMU (the
plane's 10 Hz, the ground station's ~1 Hz) never dead-reckons nor flaps."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import pytest

from companion.mavlink.decode import LIGHT_MESSAGE_IDS
from companion.mavlink.tlog import TlogReader
from companion.pipeline import Pipeline
from companion.types import AlertCode, GnssFix, NavSolution

FLIGHTS = Path(__file__).resolve().parent.parent.parent / "shared" / "realdata" / "flights"
WITH_GNSS = [
    "real_copter_dronekit_log171",
    "real_copter_erle_gps_issues1",
    "real_copter_erle_loiter_rtl",
    "real_gcs_copter_phoenix_mission1",
    "real_plane_erle_2014-12-04",
]
SLOW_IMU = {"real_plane_erle_2014-12-04", "real_gcs_copter_phoenix_mission1"}


def _replay(name: str):
    tlog = FLIGHTS / name / f"{name}.tlog"
    if not tlog.exists():
        pytest.skip(f"{tlog} is absent (the real recorded flights are not in this checkout)")
    pipeline = Pipeline()
    engine_handle = pipeline.engine.handle
    used: list[tuple[float, int, int, bool]] = []
    solutions: list[NavSolution] = []

    def spy(sample):  # type: ignore[no-untyped-def]
        engine = pipeline.engine
        before = engine.stats.gnss.copy()
        outs = engine_handle(sample)
        if isinstance(sample, GnssFix) and sample.receiver_id == 0:
            after = engine.stats.gnss
            took = any(after[k] > before[k] for k in ("fused", "fused_vouched", "reinitialised"))
            used.append((sample.t_s, int(sample.fix_type), sample.satellites or 0, took))
        solutions.extend(o for o in outs if isinstance(o, NavSolution))
        return outs

    pipeline.engine.handle = spy  # type: ignore[method-assign]
    for t_rx_s, msg in TlogReader(tlog, light_ids=LIGHT_MESSAGE_IDS):
        pipeline.on_message(msg, t_rx_s)
    return pipeline, used, solutions


def _receiver_track(name: str) -> list[tuple[float, int, float, float]]:
    with open(FLIGHTS / name / "receiver_track.csv", newline="") as f:
        return [
            (
                float(r["time_boot_s"]),
                int(float(r["fix_type"])),
                float(r["lat_deg"]),
                float(r["lon_deg"]),
            )
            for r in csv.DictReader(f)
        ]


@pytest.mark.parametrize("name", WITH_GNSS)
def test_the_receiver_is_used_and_never_far_from_the_output(name):
    pipeline, used, solutions = _replay(name)
    t0 = used[0][0]
    eligible = [u for u in used if u[1] >= 3 and u[2] >= 6 and u[0] - t0 >= 10.0]
    frac = sum(u[3] for u in eligible) / len(eligible)
    assert frac >= 0.98, f"{name}: receiver used {frac:.1%} of its good 3D fixes"
    # the published solutions (GPS_INPUT's content) with a 3D fix, against the receiver's
    # latest 3D fix at most 1 s older
    track = [r for r in _receiver_track(name) if r[1] >= 3]
    times = [r[0] for r in track]
    worst = 0.0
    k = 0
    for s in solutions:
        if s.fix_type < 3:
            continue
        while k + 1 < len(times) and times[k + 1] <= s.t_s:
            k += 1
        t, _, lat, lon = track[k]
        if not 0.0 <= s.t_s - t <= 1.0:
            continue
        dn = math.radians(math.degrees(s.lat_rad) - lat) * 6_371_000.0
        de = math.radians(math.degrees(s.lon_rad) - lon) * 6_371_000.0 * math.cos(s.lat_rad)
        worst = max(worst, math.hypot(dn, de))
    assert worst <= 25.0, f"{name}: a 3D solution {worst:.0f} m from the receiver's fix"
    stale = [a.text for a in pipeline.alerts if a.code is AlertCode.GNSS_STALE]
    assert not stale, f"{name}: a healthy receiver called stale: {stale[:3]}"
    navs = pipeline.engine.navigators
    if name in SLOW_IMU:
        assert not navs.imu_rate.usable and navs.navigator is navs.fallback
        assert navs.switches <= 2

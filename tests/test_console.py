"""The console's model: what an operator reads from the service's messages (no terminal)."""

from __future__ import annotations

import math
from pathlib import Path

from companion.console.model import STALE_S, ConsoleModel, NavMode
from companion.mavlink.tlog import TlogReader
from companion.replay import replay

ROOT = Path(__file__).resolve().parent.parent


def test_console_shows_position_fix_outage_and_alerts(tmp_path):
    out = tmp_path / "out.tlog"
    replay(ROOT / "sitl_fixtures" / "cruise_gnss_loss.tlog", out)
    state = ConsoleModel()
    in_outage_screen = None
    modes = set()
    for t, msg in TlogReader(out):
        assert state.take(msg, t)  # every message of the output is the service's
        modes.add(state.mode(t))
        outg = state.values.get("CMP_OUTG", 0.0)
        if in_outage_screen is None and outg > 30.0:
            in_outage_screen = state.render(t)
            assert state.mode(t) is NavMode.BRIDGING
    screen = state.render(t)
    assert "position" in screen and "no solution" not in screen
    assert "mode      normal" in screen
    assert state.heartbeats > 100 and state.fix_type is not None
    assert in_outage_screen is not None and "bridging" in in_outage_screen
    assert {NavMode.NORMAL, NavMode.BRIDGING} <= modes
    # no taxi in this flight: the heading correction's state (CMP_HDGS) is idle
    assert [line for line in screen.splitlines() if line.startswith("heading")][0].endswith("idle")
    codes = [a.text.split()[1] for a in state.alerts]
    assert "GNSS_LOST" in codes and "GNSS_BACK" in codes
    assert any(a.severity_name == "WARN" for a in state.alerts)
    # alerts carry the autopilot time, and the plots' history is bounded to the last minutes
    assert all(a.t_boot_s is not None for a in state.alerts)
    hist = state.history["CMP_HACC"]
    assert hist and hist[-1][0] - hist[0][0] <= 300.0
    # silence: STALE after STALE_S, and the text says so
    assert not state.service_stale(t + 1.0)
    assert state.service_stale(t + STALE_S)
    assert "STALE" in state.render(t + 10.0)
    assert state.acknowledge() == len(state.alerts) and state.unacked() == 0


def test_console_ignores_other_components_but_times_the_autopilot():
    from pymavlink.dialects.v20 import ardupilotmega as apm

    ap = apm.MAVLink(None, 1, 1)
    hb = apm.MAVLink_heartbeat_message(1, 3, 0, 0, 4, 3)
    parsed = apm.MAVLink(None).decode(bytearray(hb.pack(ap)))
    state = ConsoleModel()
    assert not state.take(parsed, 5.0)
    assert "waiting for the service" in state.render(5.0)
    snap = state.snapshot(6.0)
    assert snap["link"]["autopilot_age_s"] == 1.0 and not snap["link"]["autopilot_stale"]
    assert snap["link"]["service_stale"] and snap["navigation"]["mode"] == "waiting"


def test_console_tracks_from_a_station(tmp_path):
    """With a station, the positions and the autopilot's attitude/IMU feed the dynamic channel."""
    from companion.console.main import parse_station

    src = ROOT / "sitl_fixtures" / "cruise_gnss_loss.tlog"
    out = tmp_path / "out.tlog"
    replay(src, out)
    records = sorted(list(TlogReader(src)) + list(TlogReader(out)), key=lambda r: r[0])
    first = next(m for _, m in TlogReader(out) if m.get_type() == "GLOBAL_POSITION_INT")
    lat, lon = first.lat / 1e7, first.lon / 1e7
    # 1 km north of the first position, on the ground 300 m below
    station = parse_station(f"{lat + 1000.0 / 111_000.0},{lon},{first.alt / 1000.0 - 300.0}")
    state = ConsoleModel(station=station)
    for t, msg in records[: len(records) // 2]:
        state.take(msg, t)
    assert state.tracker.positions > 100 and state.tracker.accelerations > 100
    snap = state.snapshot(t)
    pos = station.lla_to_ned(
        math.radians(state.lat_deg), math.radians(state.lon_deg), state.alt_msl_m
    )
    true_range = float((pos**2).sum() ** 0.5)
    assert abs(snap["track"]["range_m"] - true_range) < 20.0
    assert 0.0 <= snap["track"]["az_deg"] < 360.0 and snap["track"]["pointing_sigma_deg"] < 1.0
    # 5 s of silence: predicted, with a larger uncertainty
    later = state.snapshot(t + 5.0)["track"]
    assert later["predicted_s"] > 4.5
    assert later["pointing_sigma_deg"] > snap["track"]["pointing_sigma_deg"]

    # the prediction for an antenna tracker: the aircraft's GLOBAL_POSITION_INT and HEARTBEAT
    from pymavlink.dialects.v20 import ardupilotmega as apm

    from companion.console.antenna import MAX_PREDICTION_S, AntennaFeed

    assert state.aircraft_system == 1 and state.aircraft_type is not None
    feed = AntennaFeed(station)
    est = state.track_estimate(t + 3.0)
    frames = feed.frames(t + 3.0, est, state.aircraft_system, state.aircraft_type)
    decoder = apm.MAVLink(None)
    msgs = [decoder.decode(bytearray(f)) for f in frames]
    assert [m.get_type() for m in msgs] == ["HEARTBEAT", "GLOBAL_POSITION_INT"]
    assert all(m.get_srcSystem() == 1 for m in msgs) and msgs[0].type == state.aircraft_type
    gpi = msgs[1]
    back = station.lla_to_ned(
        math.radians(gpi.lat / 1e7), math.radians(gpi.lon / 1e7), gpi.alt / 1e3
    )
    assert float(((back - est.pos_ned_m) ** 2).sum() ** 0.5) < 0.05  # 1e-7 deg, mm
    assert gpi.time_boot_ms == int(est.t_s * 1000.0)
    speed = math.hypot(gpi.vx, gpi.vy) / 100.0
    assert abs(speed - math.hypot(*est.vel_ned_mps[:2])) < 0.02 and speed > 20.0
    # the heartbeat once a second; nothing once the prediction has gone on too long
    assert len(feed.frames(t + 3.1, est, 1, state.aircraft_type)) == 1
    assert feed.frames(t + 3.2, state.track_estimate(t + MAX_PREDICTION_S + 1.0), 1, 1) == []
    assert feed.frames(t + 3.2, None, 1, 1) == [] and feed.frames(t + 3.2, est, None, 1) == []


def test_console_json_returns_within_duration_when_nothing_is_heard():
    import json
    import socket
    import subprocess
    import sys
    import time

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    t0 = time.monotonic()
    proc = subprocess.run(
        [sys.executable, "-m", "companion", "console", "--master", f"udpin:127.0.0.1:{port}"]
        + ["--json", "--duration", "1"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 1  # nothing heard
    snap = json.loads(proc.stdout)
    assert snap["link"]["service_stale"] and snap["navigation"]["mode"] == "waiting"
    assert time.monotonic() - t0 < 30.0  # the process start dominates; the wait is 1 s
    bad = subprocess.run(
        [sys.executable, "-m", "companion", "console", "--master", "udpin:127.0.0.1:1"]
        + ["--once", "--station", "95,0,0"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert bad.returncode == 1 and "station" in bad.stderr and bad.stderr.count("\n") == 1

"""The ground-station console: what an operator reads from the service's messages."""

from __future__ import annotations

from pathlib import Path

from companion.console.app import ConsoleState
from companion.mavlink.tlog import TlogReader
from companion.replay import replay

ROOT = Path(__file__).resolve().parent.parent


def test_console_shows_position_fix_outage_and_alerts(tmp_path):
    out = tmp_path / "out.tlog"
    replay(ROOT / "sitl_fixtures" / "cruise_gnss_loss.tlog", out)
    state = ConsoleState()
    in_outage_screen = None
    for t, msg in TlogReader(out):
        assert state.take(msg, t)  # every message of the output is the service's
        outg = state.values.get("CMP_OUTG", 0.0)
        if in_outage_screen is None and outg > 30.0:
            in_outage_screen = state.render(t)
    screen = state.render(t)
    assert "position" in screen and "no solution" not in screen
    assert state.heartbeats > 100 and state.fix_type is not None
    assert in_outage_screen is not None and "outage" in in_outage_screen
    # no taxi in this flight: the heading correction's state (CMP_HDGS) is idle
    assert [line for line in screen.splitlines() if line.startswith("heading")][0].endswith("idle")
    codes = [text.split()[1] for _, _, text in state.alerts]
    assert "GNSS_LOST" in codes and "GNSS_BACK" in codes
    assert any(sev == "WARN" for _, sev, _ in state.alerts)


def test_console_ignores_other_components():
    from pymavlink.dialects.v20 import ardupilotmega as apm

    ap = apm.MAVLink(None, 1, 1)
    hb = apm.MAVLink_heartbeat_message(1, 3, 0, 0, 4, 3)
    parsed = apm.MAVLink(None).decode(bytearray(hb.pack(ap)))
    state = ConsoleState()
    assert not state.take(parsed, 0.0)
    assert "waiting for the service" in state.render(0.0)

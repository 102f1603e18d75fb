"""The Textual console driven headless (Textual's test pilot) against a running service.

``companion run`` as a real process on 127.0.0.1, a peer playing the bundled taxi as
the autopilot (from a state saved when the heading correction was READY), and the
console listening on the service's ground-station link: the panels show what the
service publishes, a key press confirms the heading correction and the ACK is shown,
a parameter is edited and read back, and STALE appears within 3 s of silence.
"""

from __future__ import annotations

import asyncio
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("textual", reason="the console extra (textual) is not installed")

from companion.console.app import ConsoleApp  # noqa: E402
from companion.console.model import ConsoleModel  # noqa: E402
from tests.test_commands_udp import (  # noqa: E402,F401
    FEED_RATE_HZ,
    Autopilot,
    free_udp_port,
    ready_state,
)

ROOT = Path(__file__).resolve().parent.parent
TIMEOUT_S = 30.0
STALE_WITHIN_S = 3.0


class Router(Autopilot):
    """The autopilot's frames to the service and to the console, from one socket (as a
    MAVLink router merges the autopilot and the companion on a ground station's link)."""

    def __init__(self, frames: list[bytes], port: int, console_port: int) -> None:
        super().__init__(frames, port, console_port)
        self.console_port = console_port


def text_of(app: ConsoleApp, panel: str) -> str:
    return str(app.query_one(panel).render())


POLL_S = 0.05
loop_stall_s = 0.0
"""The longest a poll of :func:`wait_for` overran its pause, s: how long the event loop (the
app's timers run in it) was starved; reset by the tests that bound a latency."""


async def wait_for(pilot, cond, timeout_s: float = TIMEOUT_S) -> bool:
    global loop_stall_s
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if cond():
            return True
        t0 = time.monotonic()
        await pilot.pause(POLL_S)
        loop_stall_s = max(loop_stall_s, time.monotonic() - t0 - POLL_S)
    return bool(cond())


def start_service(tmp_path: Path, state_file: Path, autopilot_port: int, console_port: int):
    state = tmp_path / "state.json"
    shutil.copy(state_file, state)
    config = tmp_path / "companion.toml"
    config.write_text(f'[link]\nstate_file = "{state}"\n')
    return subprocess.Popen(
        [sys.executable, "-m", "companion", "--log-level", "warning", "run"]
        + ["--master", f"udpin:127.0.0.1:{autopilot_port}"]
        + ["--gcs", f"udpout:127.0.0.1:{console_port}"]
        + ["--config", str(config), "--record-dir", ""],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )


def stop_service(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def test_console_app_against_a_running_service(tmp_path, ready_state):  # noqa: F811
    state_file, frames = ready_state
    autopilot_port, console_port = free_udp_port(), free_udp_port()
    proc = start_service(tmp_path, state_file, autopilot_port, console_port)
    autopilot = Router(frames, autopilot_port, console_port)
    app = ConsoleApp(f"udpin:127.0.0.1:{console_port}", ConsoleModel())
    m = app.model

    async def scenario() -> None:
        async with app.run_test(size=(160, 50)) as pilot:
            assert await wait_for(pilot, lambda: m.heartbeats > 0), "no HEARTBEAT heard"
            autopilot.start()
            # the panels show what the service publishes, and the autopilot is heard too
            assert await wait_for(pilot, lambda: m.heading_state() == "ready")
            assert await wait_for(pilot, lambda: "CMP_HACC" in m.values and m.lat_deg)
            await pilot.pause(0.6)
            assert "ready" in text_of(app, "#heading")
            assert "c confirm" in text_of(app, "#heading")
            nav = text_of(app, "#nav")
            assert "NORMAL" in nav and "RTK fixed" in nav and "lat   52.167" in nav
            assert "acc   H 0.0" in nav  # RTK: centimetres
            link = text_of(app, "#link")
            assert "STALE" not in link and "never heard" not in link
            assert any("HDG_RESTORED" in a.text for a in m.alerts)
            assert app.query_one("#alerts").row_count == len(m.alerts)

            # a key press sends the confirmation; the ACK is shown
            await pilot.press("c")
            assert await wait_for(pilot, lambda: len(m.acks) > 0), "no COMMAND_ACK"
            assert m.acks[-1].command == 31010 and m.acks[-1].result_name == "ACCEPTED"
            assert await wait_for(pilot, lambda: "ACCEPTED" in text_of(app, "#decisions"))
            assert await wait_for(pilot, lambda: m.heading_state() == "applied")

            # the parameters: listed, one edited in the field, read back from the service
            await pilot.press("p")
            assert await wait_for(
                pilot, lambda: m.param_count is not None and len(m.params) == m.param_count
            ), (len(m.params), m.param_count, app.status)
            assert m.params["ENG_PUB_RATE"].value != 5.0
            field = app.screen.query_one("#param-edit")
            field.focus()
            field.value = "ENG_PUB_RATE 5"
            assert await wait_for(pilot, lambda: app.focused is field)
            await pilot.press("enter")
            assert await wait_for(pilot, lambda: m.params["ENG_PUB_RATE"].value == 5.0), (
                str(app.screen.query_one("#param-status").render()),
                m.params["ENG_PUB_RATE"],
                [a.text for a in m.alerts][-5:],
            )
            await pilot.press("escape")

            # acknowledge the alerts
            await pilot.press("a")
            assert m.unacked() == 0

            # silence: the autopilot first, then the service; STALE within 3 s of each
            autopilot.stop.set()
            assert await wait_for(pilot, lambda: (m.autopilot_age(time.time()) or 0) > 0.3)
            last = m.last_autopilot_rx_s
            global loop_stall_s
            loop_stall_s = 0.0
            assert await wait_for(pilot, lambda: text_of(app, "#link").count("STALE") == 1, 5.0)
            # within 3 s, and no later than a starved event loop (a loaded machine) delayed it
            assert time.time() - last <= STALE_WITHIN_S + loop_stall_s, loop_stall_s
            stop_service(proc)
            assert await wait_for(pilot, lambda: (m.service_age(time.time()) or 0) > 0.3)
            last = m.last_rx_s
            loop_stall_s = 0.0
            assert await wait_for(pilot, lambda: text_of(app, "#link").count("STALE") == 2, 5.0)
            assert time.time() - last <= STALE_WITHIN_S + loop_stall_s, loop_stall_s
            assert app.query_one("#link").has_class("stale")
            assert "(old)" in text_of(app, "#nav")

    try:
        asyncio.run(scenario())
    finally:
        autopilot.stop.set()
        stop_service(proc)
    err = proc.stderr.read().decode() if proc.stderr else ""
    assert proc.returncode == 0, err


def test_console_app_draws_with_nothing_heard():
    """Nothing heard yet: empty panels and plots, no crash (the log-scale plot has no data)."""
    app = ConsoleApp(f"udpin:127.0.0.1:{free_udp_port()}", ConsoleModel())

    async def scenario() -> None:
        async with app.run_test(size=(160, 50)) as pilot:
            await pilot.pause(1.2)
            assert text_of(app, "#link").count("never heard") == 2
            assert "WAITING" in text_of(app, "#nav")
            await pilot.press("c")  # no service: nothing is sent, and it says so
            await pilot.pause(0.2)
            assert "not sent" in text_of(app, "#decisions")
            app.save_screenshot("empty.svg", str(tmp))

    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        asyncio.run(scenario())
        assert (Path(tmp) / "empty.svg").stat().st_size > 0
    assert app.return_code in (None, 0)


def test_console_forwards_the_prediction_to_an_antenna_tracker():
    """``--tracker-out``: the console sends its tracking channel's position to an antenna
    tracker's link as the aircraft's GLOBAL_POSITION_INT, and keeps sending it (predicted)
    when the positions stop."""
    import math
    import socket

    from pymavlink.dialects.v20 import ardupilotmega as apm

    from companion.console.main import parse_station

    lat0, lon0, alt0 = 52.0, 21.0, 100.0
    station = parse_station(f"{lat0},{lon0},{alt0}")
    console_port = free_udp_port()
    antenna = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    antenna.bind(("127.0.0.1", 0))
    antenna.settimeout(0.05)
    app = ConsoleApp(
        f"udpin:127.0.0.1:{console_port}",
        ConsoleModel(station=station),
        tracker_out=f"udpout:127.0.0.1:{antenna.getsockname()[1]}",
    )
    service = apm.MAVLink(None, srcSystem=1, srcComponent=191)
    autopilot = apm.MAVLink(None, srcSystem=1, srcComponent=1)
    out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    t0 = time.time()
    heard: list = []
    decoder = apm.MAVLink(None)
    decoder.robust_parsing = True

    def drain() -> None:
        try:
            while True:
                data = antenna.recv(4096)
                heard.extend(m for m in decoder.parse_buffer(data) or [])
        except (TimeoutError, BlockingIOError):
            pass

    def position_at(t: float) -> tuple[float, float]:
        # 2 km north of the station, flying east at 30 m/s
        return lat0 + 2000.0 / 111_200.0, lon0 + 30.0 * t / (111_200.0 * math.cos(math.radians(52)))

    async def scenario() -> None:
        async with app.run_test(size=(160, 50)) as pilot:
            for k in range(40):  # 8 s at 5 Hz
                t = time.time() - t0
                lat, lon = position_at(t)
                gpi = service.global_position_int_encode(
                    int(t * 1000), round(lat * 1e7), round(lon * 1e7), 400_000, 300_000,
                    0, 3000, 0, 9000,
                )  # fmt: skip
                out.sendto(gpi.pack(service), ("127.0.0.1", console_port))
                if k % 5 == 0:
                    hb = autopilot.heartbeat_encode(1, 3, 0, 0, 4)
                    out.sendto(hb.pack(autopilot), ("127.0.0.1", console_port))
                await pilot.pause(0.2)
                drain()
            n_heard = len(heard)
            await pilot.pause(2.0)  # the positions stop: the prediction goes on
            drain()
            assert len(heard) > n_heard + 10
            assert "antenna:" in text_of(app, "#track")

    try:
        asyncio.run(scenario())
    finally:
        antenna.close()
        out.close()
    gpis = [m for m in heard if m.get_type() == "GLOBAL_POSITION_INT"]
    assert gpis and all(m.get_srcSystem() == 1 for m in heard)
    assert any(m.get_type() == "HEARTBEAT" and m.type == 1 for m in heard)
    last = gpis[-1]
    lat, lon = position_at(last.time_boot_ms / 1000.0)
    err_m = math.hypot(
        (last.lat / 1e7 - lat) * 111_200.0,
        (last.lon / 1e7 - lon) * 111_200.0 * math.cos(math.radians(52)),
    )
    assert err_m < 15.0, err_m  # predicted 2 s past the last position, straight flight
    assert abs(last.vy / 100.0 - 30.0) < 2.0 and abs(last.alt / 1000.0 - 400.0) < 5.0

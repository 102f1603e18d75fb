"""``companion run`` end to end: a real process, a pymavlink-speaking peer as the
autopilot, over UDP, TCP and a real pseudo-terminal (with unplug and replug).

The peer plays the first seconds of a bundled ArduPilot-flavoured flight and
checks that the service answers with HEARTBEAT, GLOBAL_POSITION_INT and
GPS_INPUT from component 191, then stops it with SIGTERM (exit status 0).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import select
import signal
import socket
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import pytest

from companion.config import Config, LinkConfig
from companion.mavlink.framing import FrameParser
from companion.mavlink.ids import MAV_COMP_ID_ONBOARD_COMPUTER
from companion.mavlink.tlog import TlogReader
from companion.service import Service

ROOT = Path(__file__).resolve().parent.parent
FIXTURE = ROOT / "sitl_fixtures" / "approach_rtk20.tlog"
START_TIMEOUT_S = 30.0
EXPECTED = {"HEARTBEAT", "GLOBAL_POSITION_INT", "GPS_INPUT"}


def flight_frames(seconds: float) -> list[bytes]:
    """Raw frames of the first ``seconds`` of the fixture."""
    frames = []
    t0 = None
    for t, msg in TlogReader(FIXTURE):
        t0 = t if t0 is None else t0
        if t - t0 > seconds:
            break
        frames.append(bytes(msg.get_msgbuf()))
    return frames


def start_service(master: str, tmp_path: Path) -> subprocess.Popen[bytes]:
    return subprocess.Popen(
        [
            sys.executable,
            "-m",
            "companion",
            "--log-level",
            "warning",
            "run",
            "--master",
            master,
            "--record-dir",
            str(tmp_path / "rec"),
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )


def stop_service(proc: subprocess.Popen[bytes]) -> str:
    proc.send_signal(signal.SIGTERM)
    try:
        _, err = proc.communicate(timeout=15)
    except subprocess.TimeoutExpired:
        proc.kill()
        _, err = proc.communicate()
        pytest.fail("service did not stop on SIGTERM")
    assert proc.returncode == 0, err.decode()
    return err.decode()


class Collector:
    """Parses what the service sends and counts the types from component 191."""

    def __init__(self) -> None:
        self.parser = FrameParser()
        self.types: Counter[str] = Counter()

    def feed(self, data: bytes) -> None:
        for msg in self.parser.feed(data):
            if msg.get_srcComponent() == MAV_COMP_ID_ONBOARD_COMPUTER:
                self.types[msg.get_type()] += 1

    def has_all(self) -> bool:
        return EXPECTED <= set(self.types)


def free_port(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def recorded(tmp_path: Path) -> int:
    files = list((tmp_path / "rec").glob("*.tlog"))
    return sum(f.stat().st_size for f in files)


# ----------------------------------------------------------------------------- timer


def _run_timer(heartbeat_rate_hz: float, watchdog_s: float | None, seconds: float):
    """Run the service's timer alone for ``seconds``: (heartbeats sent, watchdog feeds)."""
    link = LinkConfig(heartbeat_rate_hz=heartbeat_rate_hz, state_file="", record_dir="")
    service = Service(Config(link=link))
    service.notifier.watchdog_period_s = watchdog_s
    fed: list[str] = []
    service.notifier.notify = fed.append  # type: ignore[method-assign]

    async def run() -> None:
        with contextlib.suppress(asyncio.TimeoutError):
            await asyncio.wait_for(service._timer(), seconds)

    asyncio.run(run())
    return service.pipeline.stats.out_by_type["HEARTBEAT"], fed.count("WATCHDOG=1")


def test_the_timer_sleeps_until_the_pipeline_is_due():
    beats, feeds = _run_timer(10.0, None, 0.55)
    assert 3 <= beats <= 7  # at 0, 0.1, ... 0.5 s on an idle machine
    assert feeds >= beats


def test_the_watchdog_is_fed_whatever_the_heartbeat_rate():
    beats, feeds = _run_timer(0.1, 0.2, 0.55)
    assert beats == 1
    assert feeds >= 3  # every 0.1 s (half the watchdog timeout) on an idle machine


# ----------------------------------------------------------------------------- UDP


def test_udp_loopback(tmp_path):
    frames = flight_frames(20.0)
    port = free_port(socket.SOCK_DGRAM)
    proc = start_service(f"udpin:127.0.0.1:{port}", tmp_path)
    peer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    peer.bind(("127.0.0.1", 0))
    peer.settimeout(0.05)
    got = Collector()
    try:
        # knock with the autopilot's first messages until the service answers
        deadline = time.monotonic() + START_TIMEOUT_S
        while not got.types and time.monotonic() < deadline:
            for frame in frames[:20]:
                peer.sendto(frame, ("127.0.0.1", port))
            try:
                got.feed(peer.recv(65536))
            except TimeoutError:
                pass
            assert proc.poll() is None, proc.stderr.read().decode() if proc.stderr else ""
        assert got.types, "service never answered"
        for k, frame in enumerate(frames):
            peer.sendto(frame, ("127.0.0.1", port))
            if k % 50 == 0:
                _drain_udp(peer, got)
        deadline = time.monotonic() + 5.0
        while not got.has_all() and time.monotonic() < deadline:
            _drain_udp(peer, got)
    finally:
        peer.close()
        stop_service(proc)
    assert got.has_all(), got.types
    assert got.types["GLOBAL_POSITION_INT"] >= 50
    assert recorded(tmp_path) > 0


def _drain_udp(sock: socket.socket, got: Collector) -> None:
    while True:
        try:
            got.feed(sock.recv(65536))
        except (TimeoutError, BlockingIOError):
            return


# ----------------------------------------------------------------------------- TCP


def _tcp_session(server: socket.socket, frames: list[bytes], got: Collector) -> None:
    conn, _ = server.accept()
    conn.settimeout(0.05)
    try:
        for k in range(0, len(frames), 20):
            conn.sendall(b"".join(frames[k : k + 20]))
            _drain_tcp(conn, got)
        deadline = time.monotonic() + 5.0
        while not got.has_all() and time.monotonic() < deadline:
            _drain_tcp(conn, got)
    finally:
        conn.close()


def _drain_tcp(conn: socket.socket, got: Collector) -> None:
    while True:
        try:
            data = conn.recv(65536)
        except TimeoutError:
            return
        if not data:
            return
        got.feed(data)


def test_tcp_client_reconnects_when_the_autopilot_restarts(tmp_path):
    frames = flight_frames(15.0)
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    server.settimeout(START_TIMEOUT_S)
    port = server.getsockname()[1]
    proc = start_service(f"tcp:127.0.0.1:{port}", tmp_path)
    try:
        first = Collector()
        _tcp_session(server, frames, first)
        assert first.has_all(), first.types
        # the peer drops the connection (SITL restarted): the service must come back
        second = Collector()
        _tcp_session(server, frames, second)
        assert second.has_all(), second.types
    finally:
        server.close()
        stop_service(proc)


# ----------------------------------------------------------------------------- serial


def _pty_pair(link: Path) -> tuple[int, int]:
    master_fd, slave_fd = os.openpty()
    if link.is_symlink() or link.exists():
        link.unlink()
    link.symlink_to(os.ttyname(slave_fd))
    return master_fd, slave_fd


def _pty_session(master_fd: int, frames: list[bytes], got: Collector, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    # bytes written before the service has the port open (and in raw mode) are eaten by
    # the tty's line discipline: wait for its first heartbeat before streaming the flight
    while not got.types and time.monotonic() < deadline:
        ready, _, _ = select.select([master_fd], [], [], 0.1)
        if ready:
            try:
                got.feed(os.read(master_fd, 65536))
            except OSError:
                return
    sent = 0
    while time.monotonic() < deadline:
        if sent < len(frames):
            os.write(master_fd, b"".join(frames[sent : sent + 20]))
            sent += 20
        ready, _, _ = select.select([master_fd], [], [], 0.01)
        if ready:
            try:
                got.feed(os.read(master_fd, 65536))
            except OSError:
                return
        if got.has_all() and sent >= len(frames):
            return


def test_serial_pty_unplug_and_replug(tmp_path):
    frames = flight_frames(10.0)
    link = tmp_path / "ttyFAKE0"
    master_fd, slave_fd = _pty_pair(link)
    proc = start_service(f"serial:{link}:115200", tmp_path)
    try:
        first = Collector()
        _pty_session(master_fd, frames, first, START_TIMEOUT_S)
        assert first.has_all(), first.types
        # unplug: the device vanishes
        os.close(master_fd)
        os.close(slave_fd)
        link.unlink()
        time.sleep(1.5)
        assert proc.poll() is None, "service died when the device vanished"
        # replug: a new device at the same path
        master_fd, slave_fd = _pty_pair(link)
        second = Collector()
        _pty_session(master_fd, frames, second, START_TIMEOUT_S)
        assert second.has_all(), second.types
    finally:
        for fd in (master_fd, slave_fd):
            try:
                os.close(fd)
            except OSError:
                pass
        err = stop_service(proc)
    assert "Traceback" not in err


def test_frames_go_out_together_in_writes_below_the_mtu():
    from companion.service import WRITE_MAX_BYTES, _pack_writes

    frames = [bytes([k]) * 300 for k in range(10)]
    writes = _pack_writes(frames)
    assert b"".join(writes) == b"".join(frames)  # in order, nothing lost
    assert all(len(w) <= WRITE_MAX_BYTES for w in writes) and len(writes) == 3
    assert _pack_writes([b"x" * 2000]) == [b"x" * 2000]  # a longer frame goes alone

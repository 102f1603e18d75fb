"""The heading commands over real UDP on 127.0.0.1: a running ``companion run``, a peer
playing the bundled taxi as the autopilot, and pymavlink (mavutil) as the ground station.

The service starts from a state file saved when the taxi's correction was READY (as
after a restart during the taxi): it must announce the restored correction, publish
its state (``CMP_HDGS``), and answer every command with exactly one COMMAND_ACK.
"""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest
from pymavlink import mavutil

from companion.mavlink.ids import (
    MAV_COMP_ID_ONBOARD_COMPUTER,
    MAV_RESULT_ACCEPTED,
    MAV_RESULT_DENIED,
    MAV_RESULT_UNSUPPORTED,
)
from companion.mavlink.tlog import TlogReader
from companion.nav.heading import HeadingStatus
from companion.pipeline import Pipeline

ROOT = Path(__file__).resolve().parent.parent
TAXI = ROOT / "sitl_fixtures" / "taxi.tlog"
HEADING = 31010
TIMEOUT_S = 30.0
FEED_RATE_HZ = 400.0
"""Autopilot messages per second (the taxi's own rate is about 100)."""


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Autopilot(threading.Thread):
    """Sends the taxi's frames to the service at FEED_RATE_HZ until stopped."""

    def __init__(self, frames: list[bytes], port: int, *more_ports: int) -> None:
        """``frames`` to ``port`` (and to ``more_ports``: a router's other listeners)."""
        super().__init__(daemon=True)
        self.frames = frames
        self.port = port
        self.ports = (port, *more_ports)
        self.stop = threading.Event()
        self.sent = 0

    def run(self) -> None:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            sock.bind(("127.0.0.1", 0))
            start = time.monotonic()
            for k, frame in enumerate(self.frames):
                if self.stop.is_set():
                    return
                delay = start + k / FEED_RATE_HZ - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                for port in self.ports:
                    sock.sendto(frame, ("127.0.0.1", port))
                self.sent += 1


class GroundStation:
    """pymavlink's mavutil on udpin: sends commands, keeps what the service says."""

    def __init__(self, port: int) -> None:
        self.conn = mavutil.mavlink_connection(
            f"udpin:127.0.0.1:{port}", source_system=255, source_component=190
        )
        self.acks: list[Any] = []
        self.texts: list[str] = []
        self.hdgs: list[float] = []
        self.sent = 0

    def pump(self, until, timeout_s: float = TIMEOUT_S) -> bool:
        """Read until ``until()`` holds (True) or the timeout (False)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if until():
                return True
            msg = self.conn.recv_match(blocking=True, timeout=0.1)
            if msg is None or msg.get_srcComponent() != MAV_COMP_ID_ONBOARD_COMPUTER:
                continue
            kind = msg.get_type()
            if kind == "COMMAND_ACK":
                self.acks.append(msg)
            elif kind == "STATUSTEXT":
                self.texts.append(msg.text)
            elif kind == "NAMED_VALUE_FLOAT" and msg.name == "CMP_HDGS":
                self.hdgs.append(msg.value)
        return until()

    def command(
        self, param1: float, *, command: int = HEADING, confirmation: int = 0, kind: str = "long"
    ) -> int:
        """Send one command to component 191; the result of its one ACK."""
        before = len(self.acks)
        self.sent += 1
        if kind == "long":
            self.conn.mav.command_long_send(
                1, MAV_COMP_ID_ONBOARD_COMPUTER, command, confirmation, param1, 0, 0, 0, 0, 0, 0
            )
        else:
            self.conn.mav.command_int_send(
                1, MAV_COMP_ID_ONBOARD_COMPUTER, 0, command, 0, 0, param1, 0, 0, 0, 0, 0, 0
            )
        assert self.pump(lambda: len(self.acks) > before), f"no COMMAND_ACK for {command}"
        ack = self.acks[before]
        assert ack.command == command and (ack.target_system, ack.target_component) == (255, 190)
        return int(ack.result)

    def saw(self, prefix: str) -> bool:
        return any(t.startswith(prefix) for t in self.texts)


@pytest.fixture(scope="module")
def ready_state(tmp_path_factory) -> tuple[Path, list[bytes]]:
    """A state file saved at READY, and the taxi's frames from a little later on."""
    taxi = list(TlogReader(TAXI))
    pipeline = Pipeline()
    k = 0
    while pipeline.engine.heading.status is not HeadingStatus.READY:
        t, msg = taxi[k]
        pipeline.on_message(msg, t)
        k += 1
    path = tmp_path_factory.mktemp("state") / "state.json"
    path.write_text(json.dumps(pipeline.engine.persistent_state()))
    frames = [bytes(msg.get_msgbuf()) for _, msg in taxi[k + 200 :]]  # clearly later
    return path, frames


def test_heading_commands_over_udp(tmp_path, ready_state):
    state_file, frames = ready_state
    autopilot_port, gcs_port = free_udp_port(), free_udp_port()
    config = tmp_path / "companion.toml"
    config.write_text(f'[link]\nstate_file = "{state_file}"\n')
    gcs = GroundStation(gcs_port)
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "companion",
            "--log-level",
            "warning",
            "run",
            "--master",
            f"udpin:127.0.0.1:{autopilot_port}",
            "--gcs",
            f"udpout:127.0.0.1:{gcs_port}",
            "--config",
            str(config),
            "--record-dir",
            "",
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    autopilot = Autopilot(frames, autopilot_port)
    try:
        # the service's HEARTBEAT reaches the ground station (and tells mavutil its address)
        assert gcs.conn.wait_heartbeat(timeout=TIMEOUT_S) is not None, "no HEARTBEAT"
        autopilot.start()
        assert gcs.pump(lambda: gcs.saw("CMP HDG_RESTORED ready")), gcs.texts
        assert gcs.pump(lambda: HeadingStatus.READY in gcs.hdgs), gcs.hdgs

        assert gcs.command(2) == MAV_RESULT_DENIED  # nothing applied yet
        assert gcs.command(1) == MAV_RESULT_ACCEPTED
        assert gcs.pump(lambda: gcs.saw("CMP HDG_APPLIED"))
        assert gcs.pump(lambda: gcs.hdgs[-1] == HeadingStatus.APPLIED)
        assert gcs.command(1, confirmation=1) == MAV_RESULT_ACCEPTED  # a retransmission
        assert gcs.command(1, kind="int") == MAV_RESULT_ACCEPTED  # idempotent
        assert gcs.command(0) == MAV_RESULT_DENIED
        assert gcs.pump(lambda: gcs.saw("CMP HDG_CMD refuse: applied"))
        assert gcs.command(2) == MAV_RESULT_ACCEPTED
        assert gcs.pump(lambda: gcs.saw("CMP HDG_UNDONE"))
        assert gcs.command(2, confirmation=1) == MAV_RESULT_ACCEPTED  # its retransmission
        assert gcs.pump(lambda: gcs.hdgs[-1] == HeadingStatus.READY)
        assert gcs.command(5) == MAV_RESULT_DENIED
        assert gcs.pump(lambda: gcs.saw("CMP HDG_CMD param1 5"))
        assert gcs.command(33, command=512) == MAV_RESULT_UNSUPPORTED
        assert gcs.command(33, command=512, kind="int") == MAV_RESULT_UNSUPPORTED
        assert gcs.command(0) == MAV_RESULT_ACCEPTED
        assert gcs.pump(lambda: gcs.saw("CMP HDG_REJECT refused"))
        assert gcs.pump(lambda: gcs.hdgs[-1] == HeadingStatus.REJECTED)
        # exactly one ACK each: nothing more arrives
        gcs.pump(lambda: False, timeout_s=1.0)
        assert len(gcs.acks) == gcs.sent == 11, [(a.command, a.result) for a in gcs.acks]
        assert autopilot.is_alive(), "the taxi ran out before the end of the exchange"
    finally:
        autopilot.stop.set()
        proc.send_signal(signal.SIGTERM)
        try:
            _, err = proc.communicate(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            _, err = proc.communicate()
            pytest.fail("service did not stop on SIGTERM")
        gcs.conn.close()
    assert proc.returncode == 0, err.decode()
    # the state file follows: refused, nothing applied, accumulating again
    saved = json.loads(state_file.read_text())["heading"]
    assert saved["phase"] == "accumulating" and saved["applied"] is None

"""Fail fast and say why, at the command line (real processes).

* A malformed link URL or a bad configuration stops ``companion run`` at once: one line
  on stderr, exit status 1 (the URL on the command line within a second).
* A well-formed link that cannot open (device absent) is retried, its failures logged
  with backoff, until it opens.
* An autopilot link that delivers bytes but no autopilot HEARTBEAT (random bytes over
  UDP on 127.0.0.1) is warned about, again later, without a crash; a HEARTBEAT ends it.
* ``replay`` and ``evaluate`` refuse a file that holds no tlog record, in one line that
  names what it looks like (by content, whatever its name).
"""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from companion.mavlink.framing import FrameParser
from companion.mavlink.ids import MAV_COMP_ID_ONBOARD_COMPUTER
from companion.mavlink.tlog import TlogReader

ROOT = Path(__file__).resolve().parent.parent
FIXTURE = ROOT / "sitl_fixtures" / "approach_rtk20.tlog"
TRUTH = ROOT / "sitl_fixtures" / "approach_rtk20.truth.csv"
URL_FAIL_WITHIN_S = 1.0
"""A malformed URL on the command line: exit within this (the acceptance), s."""
WAIT_S = 40.0
"""Patience for a process on a loaded machine (start-up imports), s."""


def companion(*args: str, timeout_s: float = 60.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "companion", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=timeout_s,
    )


def one_error_line(done: subprocess.CompletedProcess[str], command: str) -> str:
    """The single stderr line of a failed command (asserts there is exactly one)."""
    assert done.returncode == 1, (done.returncode, done.stderr)
    lines = done.stderr.splitlines()
    assert len(lines) == 1, done.stderr
    assert lines[0].startswith(f"companion {command}: error: "), lines[0]
    return lines[0]


# ----------------------------------------------------------------------------- link URLs


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["--master", "udpin:127.0.0.1"],
            "bad link URL 'udpin:127.0.0.1': expected udpin:HOST:PORT",
        ),
        (
            ["--master", "udpin:127.0.0.1:14550", "--gcs", "udpot:127.0.0.1:14551"],
            "bad link URL 'udpot:127.0.0.1:14551': unknown scheme 'udpot'",
        ),
        (["--master", "tcp:127.0.0.1:57x0"], "port '57x0' is not a number"),
        (["--master", "serial:/dev/ttyUSB0:0"], "baud rate 0 must be > 0"),
    ],
)
def test_a_malformed_url_is_one_line_and_exit_1_within_a_second(args, message):
    t0 = time.monotonic()
    done = companion("run", *args, "--record-dir", "", timeout_s=20.0)
    elapsed_s = time.monotonic() - t0
    assert message in one_error_line(done, "run")
    assert elapsed_s < URL_FAIL_WITHIN_S, f"{elapsed_s:.2f} s"


@pytest.mark.parametrize(
    ("toml", "message"),
    [
        ('[link]\ngcs = "udpot:127.0.0.1:14550"\n', "[link] gcs: bad link URL"),
        ('[link]\nmaster = "tcp:localhost"\n', "[link] master: bad link URL 'tcp:localhost'"),
        ("[link]\nno_autopilot_warn_s = 0\n", "[link] no_autopilot_warn_s"),
        ("[link\n", "not valid TOML"),
    ],
)
def test_a_bad_configuration_is_one_line_and_exit_1(tmp_path, toml, message):
    config = tmp_path / "companion.toml"
    config.write_text(toml)
    done = companion("run", "--config", str(config), timeout_s=WAIT_S)
    assert message in one_error_line(done, "run")


# ----------------------------------------------------------------------------- live


class Service:
    """``companion run`` in a subprocess, its stderr collected line by line."""

    def __init__(self, master: str, config: Path, log_level: str = "info") -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "companion", "--log-level", log_level]
            + ["run", "--master", master, "--config", str(config)],
            cwd=ROOT,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self.lines.append(line.rstrip("\n"))

    def matching(self, pattern: str) -> list[re.Match[str]]:
        rx = re.compile(pattern)
        return [m for m in (rx.search(line) for line in list(self.lines)) if m]

    def alive(self) -> None:
        assert self.proc.poll() is None, "\n".join(self.lines)

    def stop(self) -> str:
        """SIGTERM; asserts exit 0 and no traceback; returns all of stderr."""
        self.proc.send_signal(signal.SIGTERM)
        try:
            self.proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
            pytest.fail("service did not stop on SIGTERM")
        self._reader.join(timeout=5)
        text = "\n".join(self.lines)
        assert self.proc.returncode == 0, text
        assert "Traceback" not in text, text
        return text


def live_config(tmp_path: Path, **link: float) -> Path:
    path = tmp_path / "companion.toml"
    keys = "".join(f"{k} = {v}\n" for k, v in link.items())
    path.write_text(f'[link]\nstate_file = ""\nrecord_dir = ""\n{keys}')
    return path


def test_an_absent_device_is_retried_and_its_failures_logged_with_backoff(tmp_path):
    device = tmp_path / "ttyLATER0"
    service = Service(f"serial:{device}:57600", live_config(tmp_path, reconnect_s=0.1))
    pattern = (
        r"autopilot link serial:\S+: cannot open serial .*; retrying every 0\.1 s \((\d+) failed\)"
    )
    master_fd = slave_fd = -1
    try:
        deadline = time.monotonic() + WAIT_S
        while not service.matching(pattern) and time.monotonic() < deadline:
            time.sleep(0.1)
        time.sleep(3.0)  # some 30 attempts
        service.alive()
        logged = [int(m.group(1)) for m in service.matching(pattern)]
        assert logged[:4] == [1, 2, 4, 8], service.lines
        assert all(n & (n - 1) == 0 for n in logged), logged  # not every attempt
        # the device appears: the link opens, saying after how many failures
        master_fd, slave_fd = os.openpty()
        device.symlink_to(os.ttyname(slave_fd))
        opened = r"autopilot link open: serial:\S+ after (\d+) failed"
        deadline = time.monotonic() + WAIT_S
        while not service.matching(opened) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert service.matching(opened), service.lines
        assert int(service.matching(opened)[0].group(1)) >= logged[-1]
    finally:
        for fd in (master_fd, slave_fd):
            if fd >= 0:
                os.close(fd)
        service.stop()


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_random_bytes_on_the_master_link_warn_no_heartbeat_again_and_again(tmp_path):
    port = _free_udp_port()
    config = live_config(tmp_path, no_autopilot_warn_s=1.0, no_autopilot_repeat_s=1.5)
    service = Service(f"udpin:127.0.0.1:{port}", config)
    peer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    peer.bind(("127.0.0.1", 0))
    peer.settimeout(0.02)
    noise = np.random.default_rng(7)
    warning = (
        rf"no autopilot heartbeat on master udpin:127\.0\.0\.1:{port} after (\d+) s: "
        r"(\d+) bytes, (\d+) good frames, (\d+) bad \((\d+) bytes not MAVLink\): "
        r"wrong baud rate or not MAVLink\?"
    )
    try:
        deadline = time.monotonic() + WAIT_S
        while len(service.matching(warning)) < 3 and time.monotonic() < deadline:
            peer.sendto(noise.bytes(512), ("127.0.0.1", port))  # 5 kB/s of noise
            time.sleep(0.1)
            service.alive()
        found = service.matching(warning)
        assert len(found) >= 3, service.lines
        silences = [int(m.group(1)) for m in found]
        sizes = [int(m.group(2)) for m in found]
        assert silences[0] == 1 and silences[1] - silences[0] in (1, 2)  # then every 1.5 s
        assert sizes[0] > 0 and sizes == sorted(sizes) and sizes[2] > sizes[0]  # still counted
        assert all(int(m.group(4)) > 0 and int(m.group(5)) > 0 for m in found)
        # the autopilot after all: its HEARTBEAT ends the warnings, the service answers
        frames = [bytes(msg.get_msgbuf()) for _, msg in _first_records(200)]
        parser = FrameParser()
        answered = False
        back = (
            r"INFO companion\.service: autopilot heartbeat on master "
            rf"udpin:127\.0\.0\.1:{port} after \d+ s"
        )
        deadline = time.monotonic() + WAIT_S
        while not (answered and service.matching(back)) and time.monotonic() < deadline:
            for frame in frames[:20]:
                peer.sendto(frame, ("127.0.0.1", port))
            try:
                msgs = parser.feed(peer.recv(65536))
            except TimeoutError:
                continue
            answered |= any(
                m.get_type() == "HEARTBEAT" and m.get_srcComponent() == MAV_COMP_ID_ONBOARD_COMPUTER
                for m in msgs
            )
        assert answered and service.matching(back), service.lines
        # the autopilot keeps talking (frames[:20] hold its HEARTBEAT): no more warnings
        n_warnings = len(service.matching("no autopilot heartbeat"))
        until = time.monotonic() + 2.5  # > the 1 s timeout
        while time.monotonic() < until:
            for frame in frames[:20]:
                peer.sendto(frame, ("127.0.0.1", port))
            time.sleep(0.2)
        service.alive()
    finally:
        peer.close()
        text = service.stop()
    assert len(service.matching("no autopilot heartbeat")) == n_warnings, text


def _first_records(n: int) -> list[tuple[float, object]]:
    records = []
    for rec in TlogReader(FIXTURE):
        records.append(rec)
        if len(records) >= n:
            break
    return records


# ----------------------------------------------------------------------------- files

DATAFLASH = b"\xa3\x95\x80\x80\x59FMT\x00" + bytes(16) + b"BBnNZ" + bytes(64)
"""The first bytes of an ArduPilot DataFlash log: HEAD1 HEAD2, then its FMT record."""
ULOG = b"ULog\x01\x12\x35\x01" + (1_000_000).to_bytes(8, "little") + bytes(64)
"""A PX4 ULog header: magic, version, timestamp."""
PNG = b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR" + bytes(64)


@pytest.mark.parametrize(
    ("name", "content", "says"),
    [
        # read by content, whatever the name, and refused when there is nothing in them
        ("flight.tlog", DATAFLASH, "an ArduPilot DataFlash log (.bin) with nothing to replay"),
        ("00000042.BIN", DATAFLASH, "an ArduPilot DataFlash log (.bin) with nothing to replay"),
        ("flight.tlog", ULOG, "a PX4 ULog (.ulg) with nothing to replay"),
        ("flight.tlog", PNG, "a PNG image, not a .tlog"),
        ("flight.tlog", b"", "no tlog record: an empty file"),
        (
            "flight.tlog",
            b"t_s,lat_deg,lon_deg\n0.0,52.1,20.9\n",
            "a text file (34 bytes, first line 't_s,lat_deg,lon_deg')",
        ),
        ("flight.tlog", bytes(range(256)) * 8, "no tlog record: binary data (2048 bytes)"),
    ],
)
def test_replay_of_a_file_that_is_no_tlog_is_one_line_naming_what_it_is(
    tmp_path, name, content, says
):
    path = tmp_path / name
    path.write_bytes(content)
    out = tmp_path / "out.tlog"
    line = one_error_line(companion("replay", str(path), "-o", str(out), "-q"), "replay")
    assert f"{path}: " in line and says in line, line
    assert not out.exists()  # no empty output left behind


@pytest.mark.parametrize(
    ("content", "says"),
    [
        (DATAFLASH, "an ArduPilot DataFlash log (.bin), not a .tlog: `companion replay` reads"),
        (ULOG, "a PX4 ULog (.ulg), not a .tlog: `companion replay` reads it"),
        (PNG, "a PNG image"),
        (b"", "an empty file"),
    ],
)
def test_evaluate_of_a_file_that_is_no_tlog_is_one_line_naming_what_it_is(tmp_path, content, says):
    path = tmp_path / "out.tlog"
    path.write_bytes(content)
    line = one_error_line(companion("evaluate", str(path), "--truth", str(TRUTH)), "evaluate")
    assert says in line, line

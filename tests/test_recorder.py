"""The flight recorder: rotation by size, the total and age caps, flushing, write
errors, and ``companion run`` killed with SIGKILL mid-flight (every message older than
the flush interval readable with TlogReader)."""

from __future__ import annotations

import json
import logging
import os
import signal
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from companion.config import ConfigError, config_from_dict
from companion.mavlink.ids import MAV_COMP_ID_ONBOARD_COMPUTER
from companion.mavlink.tlog import TlogReader
from companion.recorder import (
    BYTES_PER_MB,
    HOUSEKEEPING_PERIOD_S,
    RETRY_S,
    S_PER_DAY,
    Recorder,
    RecorderConfig,
    recorder_files,
)

ROOT = Path(__file__).resolve().parent.parent
FIXTURE = ROOT / "sitl_fixtures" / "nominal.tlog"
T0_S = 1_750_000_000.0
"""A UNIX time to start the unit tests' recorders at (2025-06-15)."""


def fixture_frames(count: int) -> list[bytes]:
    frames = []
    for _, msg in TlogReader(FIXTURE):
        frames.append(bytes(msg.get_msgbuf()))
        if len(frames) == count:
            break
    return frames


def read_back(paths: list[Path]) -> list[tuple[float, bytes]]:
    """Every record of the files, in order; asserts that the reader skipped nothing."""
    out = []
    for path in paths:
        reader = TlogReader(path)
        out += [(t, bytes(msg.get_msgbuf())) for t, msg in reader]
        assert not reader.stats, (path, reader.stats)
    return out


def folder_bytes(folder: Path) -> int:
    return sum(p.stat().st_size for p in folder.iterdir())


def make_file(folder: Path, name: str, size_bytes: int, age_days: float, now_s: float) -> Path:
    path = folder / name
    path.write_bytes(b"\0" * size_bytes)
    mtime_s = now_s - age_days * S_PER_DAY
    os.utime(path, (mtime_s, mtime_s))
    return path


# ----------------------------------------------------------------------------- caps


def test_rotates_by_size_and_loses_nothing(tmp_path, caplog):
    caplog.set_level(logging.INFO, logger="companion.recorder")
    frames = fixture_frames(3000)
    cfg = RecorderConfig(max_file_mb=0.01, max_total_mb=100.0)
    rec = Recorder(tmp_path, T0_S, cfg)
    sent = [(T0_S + 0.01 * k, frame) for k, frame in enumerate(frames)]
    for t_s, frame in sent:
        rec.record(t_s, frame)
    rec.close()
    files = recorder_files(tmp_path)
    total_bytes = sum(8 + len(f) for f in frames)
    assert len(files) == rec.files_started >= total_bytes // 10_000
    assert [f.seq for f in files] == list(range(len(files)))
    assert all(f.size_bytes <= 10_000 for f in files)
    assert all(f.size_bytes > 10_000 - 300 for f in files[:-1])  # full up to one record
    got = read_back([f.path for f in files])
    assert [frame for _, frame in got] == frames
    assert [t for t, _ in got] == pytest.approx([t for t, _ in sent], abs=1e-6)
    assert rec.records == len(frames)
    assert sum("reached 0.01 MB" in r.message for r in caplog.records) == len(files) - 1


def test_total_cap_deletes_the_oldest_and_never_the_current(tmp_path, caplog):
    caplog.set_level(logging.INFO, logger="companion.recorder")
    frames = fixture_frames(4000)
    cfg = RecorderConfig(max_file_mb=0.01, max_total_mb=0.035)
    rec = Recorder(tmp_path, T0_S, cfg)
    for k, frame in enumerate(frames):
        rec.record(T0_S + 0.01 * k, frame)
        if k % 97 == 0:
            assert folder_bytes(tmp_path) <= 35_000
            assert rec.path is not None and rec.path.exists()
    files = recorder_files(tmp_path)
    rec.close()
    # the newest files, the current one among them: two full ones fit beside it
    assert len(files) == 3
    assert files[-1].path == rec.path
    assert [f.seq for f in files] == list(range(rec.files_started - 3, rec.files_started))
    assert rec.files_deleted == rec.files_started - 3
    deleted = [r.message for r in caplog.records if "deleted" in r.message]
    assert len(deleted) == rec.files_deleted
    assert all("folder over max_total_mb 0.035" in m for m in deleted)
    # what is left is the end of the flight, every record of it
    got = read_back([f.path for f in files])
    assert [frame for _, frame in got] == frames[len(frames) - len(got) :]


def test_the_current_file_is_kept_when_it_alone_fills_the_cap(tmp_path):
    frames = fixture_frames(1000)
    cfg = RecorderConfig(max_file_mb=0.01, max_total_mb=0.01)
    rec = Recorder(tmp_path, T0_S, cfg)
    for k, frame in enumerate(frames):
        rec.record(T0_S + 0.01 * k, frame)
        assert rec.path is not None and rec.path.exists()
        assert len(recorder_files(tmp_path)) == 1
    rec.close()
    assert rec.files_started > 3 and rec.write_errors == 0


def test_age_cap_at_start_and_hourly(tmp_path, caplog):
    caplog.set_level(logging.INFO, logger="companion.recorder")
    now_s = T0_S
    legacy = make_file(tmp_path, "companion-20250101-000000.tlog", 500, 45.0, now_s)
    old = make_file(tmp_path, "companion-000007-20250510T000000Z.tlog", 500, 31.0, now_s)
    aging = make_file(tmp_path, "companion-000008-20250520T000000Z.tlog", 500, 29.99, now_s)
    fresh = make_file(tmp_path, "companion-000009-20250614T000000Z.tlog", 500, 1.0, now_s)
    foreign = [
        make_file(tmp_path, "notes.txt", 500, 400.0, now_s),
        make_file(tmp_path, "flight.tlog", 500, 400.0, now_s),
    ]
    rec = Recorder(tmp_path, now_s, RecorderConfig(max_age_days=30.0))
    assert not legacy.exists() and not old.exists()
    assert aging.exists() and fresh.exists() and all(p.exists() for p in foreign)
    assert rec.path is not None and rec.path.name.startswith("companion-000010-20250615T")
    # an hour later the next one is past the cap; the current file never is deleted,
    # even when its time says so (a clock set forward)
    rec.record(now_s + 10.0, fixture_frames(1)[0])
    rec.tick(now_s + HOUSEKEEPING_PERIOD_S - 1.0)
    assert aging.exists()
    os.utime(rec.path, (now_s - 90 * S_PER_DAY, now_s - 90 * S_PER_DAY))
    rec.tick(now_s + HOUSEKEEPING_PERIOD_S + 1.0)
    assert not aging.exists() and fresh.exists() and rec.path.exists()
    rec.close()
    assert rec.files_deleted == 3
    deleted = [r.message for r in caplog.records if "deleted" in r.message]
    assert len(deleted) == 3 and all("older than max_age_days 30" in m for m in deleted)


def test_age_cap_zero_keeps_files_whatever_their_age(tmp_path):
    old = make_file(tmp_path, "companion-000001-20200101T000000Z.tlog", 500, 2000.0, T0_S)
    Recorder(tmp_path, T0_S, RecorderConfig(max_age_days=0.0)).close()
    assert old.exists()


def test_the_sequence_not_the_clock_says_which_is_oldest(tmp_path):
    # a computer without a real-time clock booted in 1970 for the newest flight
    newest = make_file(tmp_path, "companion-000005-19700101T000012Z.tlog", 20_000, 20_000, T0_S)
    older = make_file(tmp_path, "companion-000004-20250610T000000Z.tlog", 20_000, 5.0, T0_S)
    cfg = RecorderConfig(max_file_mb=0.01, max_total_mb=0.03, max_age_days=0.0)
    rec = Recorder(tmp_path, T0_S, cfg)
    assert newest.exists() and not older.exists()
    assert rec.path is not None and rec.path.name.startswith("companion-000006-")
    rec.close()


# ----------------------------------------------------------------------------- flush


def test_flushed_when_due_on_write_or_on_tick(tmp_path):
    frames = fixture_frames(50)
    rec = Recorder(tmp_path, T0_S, RecorderConfig(flush_interval_s=0.5))
    assert rec.path is not None
    rec.record(T0_S + 0.1, frames[0])
    assert rec.next_due_s() == pytest.approx(T0_S + 0.5)
    assert rec.path.stat().st_size == 0  # buffered: not due yet
    rec.tick(T0_S + 0.49)
    assert rec.path.stat().st_size == 0
    rec.tick(T0_S + 0.5)  # the timer, no message since
    assert len(read_back([rec.path])) == 1
    for k, frame in enumerate(frames[1:20], start=1):
        rec.record(T0_S + 0.5 + 0.03 * k, frame)
    assert len(read_back([rec.path])) == 18  # the write at 1.01 s flushed itself and those before
    rec.record(T0_S - 3600.0, frames[20])  # the wall clock stepped back an hour: flush now
    assert rec.path.stat().st_size == sum(8 + len(f) for f in frames[:21])
    assert rec.next_due_s() == pytest.approx(T0_S - 3600.0 + 0.5)
    rec.close()


def test_a_torn_last_record_is_counted_and_the_rest_read(tmp_path):
    frames = fixture_frames(30)
    rec = Recorder(tmp_path, T0_S)
    for k, frame in enumerate(frames):
        rec.record(T0_S + 0.01 * k, frame)
    rec.close()
    assert rec.path is not None
    data = rec.path.read_bytes()
    for cut in (1, 8, 12, 8 + len(frames[-1]) - 1):
        torn = tmp_path / f"torn{cut}.bin"
        torn.write_bytes(data[: len(data) - 8 - len(frames[-1]) + cut])
        reader = TlogReader(torn)
        assert [bytes(m.get_msgbuf()) for _, m in reader] == frames[:-1]
        assert dict(reader.stats) == {"truncated_record": 1, "bad_bytes": cut}


# ----------------------------------------------------------------------------- errors

_FULL_CARD = textwrap.dedent(
    """
    import json, logging, resource, signal, sys
    from pathlib import Path
    from companion.mavlink.tlog import TlogReader
    from companion.recorder import RETRY_S, Recorder, RecorderConfig, recorder_files

    logging.basicConfig(level=logging.INFO, stream=sys.stderr)
    frames = [bytes(m.get_msgbuf()) for _, m in TlogReader(sys.argv[2])][:2000]
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # EFBIG instead of a signal
    resource.setrlimit(resource.RLIMIT_FSIZE, (20_000, 20_000))
    t0 = 1_750_000_000.0
    rec = Recorder(Path(sys.argv[1]), t0, RecorderConfig(flush_interval_s=0.1))
    for k, frame in enumerate(frames):
        rec.record(t0 + 0.01 * k, frame)  # 20 s: the cap is hit, then retried
        rec.tick(t0 + 0.01 * k)
    rec.close()
    sizes = [f.size_bytes for f in recorder_files(Path(sys.argv[1]))]
    print(json.dumps({"errors": rec.write_errors, "files": rec.files_started, "sizes": sizes}))
    """
)


def test_a_write_error_is_logged_and_retried_never_raised(tmp_path):
    """A real EFBIG (the file-size limit of the process) in a child: a full card."""
    out = subprocess.run(
        [sys.executable, "-c", _FULL_CARD, str(tmp_path), str(FIXTURE)],
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout)
    # ~4 s to fill a file to 20 kB, then a new file RETRY_S (10 s) later that works for a
    # while (so the next wait is not doubled), full at ~17 s: 2 files, 2 errors
    assert RETRY_S == 10.0
    assert result["errors"] == 2
    assert result["files"] == 2
    assert all(size <= 20_000 for size in result["sizes"])
    assert out.stderr.count("recording suspended, retrying in 10 s") == 2
    assert out.stderr.count("writing again") == 1
    assert "Traceback" not in out.stderr


def test_retries_back_off_while_no_file_can_be_created(tmp_path, caplog):
    folder = tmp_path / "logs"
    frames = fixture_frames(2000)
    rec = Recorder(folder, T0_S, RecorderConfig(max_file_mb=0.01, max_total_mb=1.0))
    for path in folder.iterdir():  # the card's folder vanishes: the next file cannot be made
        path.unlink()
    folder.rmdir()
    for k, frame in enumerate(frames):  # 0.05 s apart: 100 s
        rec.record(T0_S + 0.05 * k, frame)
        rec.tick(T0_S + 0.05 * k)
    rec.close()
    waits = [
        r.message.rsplit("retrying in ", 1)[1] for r in caplog.records if "retrying" in r.message
    ]
    assert waits == ["10 s", "20 s", "40 s", "80 s"]  # the first file full at ~10 s
    assert rec.write_errors == 4 and rec.files_started == 1
    assert 150 < rec.records < 250  # what fitted in the first file (10 kB)


def test_an_unwritable_folder_is_an_os_error(tmp_path):
    (tmp_path / "file").write_text("")
    with pytest.raises(OSError):
        Recorder(tmp_path / "file" / "logs", T0_S)


# ----------------------------------------------------------------------------- config


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ({"flush_interval_s": 2.0}, "[recorder] flush_interval_s must be in (0, 1], got 2.0"),
        ({"flush_interval_s": 0}, "[recorder] flush_interval_s must be in (0, 1]"),
        ({"max_file_mb": 0}, "[recorder] max_file_mb must be >= 0.01"),
        ({"max_age_days": -1}, "[recorder] max_age_days must be >= 0"),
        ({"max_total_mb": 10}, "[recorder] max_total_mb must be >= max_file_mb (64)"),
    ],
)
def test_config_ranges(table, message):
    with pytest.raises(ConfigError) as err:
        config_from_dict({"recorder": table})
    assert message in str(err.value)


def test_config_keys_are_taken():
    cfg = config_from_dict({"recorder": {"max_file_mb": 8, "max_total_mb": 100}})
    assert cfg.recorder.max_file_mb == 8.0 and cfg.recorder.max_total_mb == 100.0
    assert int(cfg.recorder.max_total_mb * BYTES_PER_MB) == 100_000_000


# ----------------------------------------------------------------------------- kill -9

FLUSH_INTERVAL_S = 0.5
SPEED = 2.0
"""The fake autopilot plays the flight at twice real time (about 200 messages/s)."""
LAG_ALLOWANCE_S = 1.0
"""How far the service may lag the fake autopilot on a loaded machine."""


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _recorded_inbound(folder: Path) -> tuple[list[bytes], dict[str, int]]:
    """The autopilot's frames in the recording, and what the reader skipped."""
    files = recorder_files(folder)
    assert len(files) == 1
    reader = TlogReader(files[0].path)
    frames = [
        bytes(m.get_msgbuf())
        for _, m in reader
        if m.get_srcComponent() != MAV_COMP_ID_ONBOARD_COMPUTER
    ]
    return frames, dict(reader.stats)


def _stream(peer: socket.socket, port: int, flight: list[tuple[float, bytes]], sent: list):
    """Send ``flight`` at ``SPEED`` times real time; append (send time, frame) to ``sent``."""
    t_wall0 = time.monotonic()
    t_flight0 = flight[0][0]
    for t_s, frame in flight:
        wait_s = (t_s - t_flight0) / SPEED - (time.monotonic() - t_wall0)
        if wait_s > 0.002:
            time.sleep(wait_s)
        peer.sendto(frame, ("127.0.0.1", port))
        sent.append((time.time(), frame))


def test_kill_9_mid_flight_loses_only_the_last_flush_interval(tmp_path):
    flight = [(t, bytes(m.get_msgbuf()), m.get_type()) for t, m in TlogReader(FIXTURE)]
    t_start = flight[0][0]
    knock_at = next(i for i, (_, _, kind) in enumerate(flight) if kind == "HEARTBEAT")
    knock = flight[knock_at][1]
    stream = [(t, frame) for t, frame, _ in flight[knock_at + 1 :]]
    phase1 = [r for r in stream if r[0] - t_start < 8.0]
    # the quiet ends when the test sees the timer's flush, so the flushes that follow keep
    # its phase: 6.5 s of flight (3.25 s) puts the kill half an interval after one of them
    phase2 = [r for r in stream if 8.0 <= r[0] - t_start < 14.5]
    config = tmp_path / "c.toml"
    config.write_text(
        # a heartbeat every 10 s: no output of the service flushes the recorder by chance
        f'[link]\nheartbeat_rate_hz = 0.1\nstate_file = ""\n'
        f"[recorder]\nflush_interval_s = {FLUSH_INTERVAL_S}\n"
    )
    rec_dir = tmp_path / "rec"
    port = _free_udp_port()
    log_path = tmp_path / "service.log"
    log_file = open(log_path, "wb")  # noqa: SIM115 - closed below; a pipe could fill and block
    proc = subprocess.Popen(
        [sys.executable, "-m", "companion", "--log-level", "info", "run", "--config",
         str(config), "--master", f"udpin:127.0.0.1:{port}", "--record-dir", str(rec_dir)],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=log_file,
    )  # fmt: skip
    peer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    peer.bind(("127.0.0.1", 0))
    peer.settimeout(0.2)
    sent: list[tuple[float, bytes]] = []
    try:
        # knock with the autopilot's HEARTBEAT until the service answers (stream requests)
        deadline = time.monotonic() + 30.0
        knocks = 0
        answered = False
        while not answered and time.monotonic() < deadline:
            assert proc.poll() is None, log_path.read_text()
            peer.sendto(knock, ("127.0.0.1", port))
            knocks += 1
            try:
                answered = bool(peer.recv(65536))
            except TimeoutError:
                pass
        assert answered, "service never answered"
        # what the service sends from now on is not read: UDP drops it
        _stream(peer, port, phase1, sent)
        # the link goes quiet: no further write comes to flush, the recorder's timer must
        t_quiet = time.time()
        deadline = time.monotonic() + FLUSH_INTERVAL_S + 5.0
        while time.monotonic() < deadline:
            inbound, _ = _recorded_inbound(rec_dir)
            if inbound and inbound[-1] == phase1[-1][1]:
                break
            time.sleep(0.05)
        quiet_flush_s = time.time() - t_quiet
        assert inbound and inbound[-1] == phase1[-1][1], "the quiet link's records never flushed"
        _stream(peer, port, phase2, sent)
        t_kill = time.time()
        proc.send_signal(signal.SIGKILL)  # mid-flight: the autopilot is still streaming
        proc.wait(timeout=10)
    finally:
        peer.close()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        log_file.close()
    assert proc.returncode == -signal.SIGKILL, log_path.read_text()
    assert "Traceback" not in log_path.read_text()
    inbound, stats = _recorded_inbound(rec_dir)
    # at most the last record torn (counted), nothing else skipped
    assert set(stats) <= {"truncated_record", "bad_bytes"} and stats.get("truncated_record", 0) <= 1
    # the recording is exactly what was sent, byte for byte, up to where it stops
    knocks_recorded = next(i for i, f in enumerate(inbound) if f != knock)
    assert 1 <= knocks_recorded <= knocks
    recorded = inbound[knocks_recorded:]
    assert recorded == [f for _, f in sent[: len(recorded)]]
    assert len(recorded) < len(sent), "killed after the service had recorded everything"
    # every message older than the flush interval (and the service's lag) is in
    older = [f for t, f in sent if t < t_kill - FLUSH_INTERVAL_S - LAG_ALLOWANCE_S]
    assert len(recorded) >= len(older) > len(phase1)
    missing_age_s = t_kill - sent[len(recorded)][0]
    print(
        f"\nkill -9: {len(sent)} sent, {len(recorded)} recorded, newest missing sent "
        f"{missing_age_s:.2f} s before the kill; quiet link flushed within {quiet_flush_s:.2f} s;"
        f" reader stats {stats}"
    )

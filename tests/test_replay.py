"""Replay contract: deterministic, the promised messages from component 191 at the
GNSS rate, readable by pymavlink; bad input is a one-line error and a non-zero exit."""

from __future__ import annotations

import math
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from pymavlink import mavutil

from companion.cli import main
from companion.mavlink.tlog import TlogReader
from companion.pipeline import Pipeline
from companion.replay import replay

ROOT = Path(__file__).resolve().parent.parent
FIXTURE = ROOT / "sitl_fixtures" / "approach_rtk20.tlog"


@pytest.fixture(scope="module")
def replayed(tmp_path_factory):
    out = tmp_path_factory.mktemp("replay")
    first, second = out / "a.tlog", out / "b.tlog"
    summary = replay(FIXTURE, first)
    replay(FIXTURE, second)
    return summary, first, second


def test_replay_is_byte_identical(replayed):
    _, first, second = replayed
    assert first.read_bytes() == second.read_bytes()
    assert first.stat().st_size > 100_000


def test_output_reads_back_with_pymavlink_at_the_gnss_rate(replayed):
    summary, first, _ = replayed
    conn = mavutil.mavlink_connection(str(first), dialect="ardupilotmega")
    kinds: Counter[str] = Counter()
    components = set()
    times: dict[str, list[float]] = {"GLOBAL_POSITION_INT": [], "GPS_INPUT": []}
    while (msg := conn.recv_msg()) is not None:
        if msg.get_type() == "BAD_DATA":
            continue
        kinds[msg.get_type()] += 1
        components.add(msg.get_srcComponent())
        if msg.get_type() == "GLOBAL_POSITION_INT":
            times["GLOBAL_POSITION_INT"].append(msg.time_boot_ms / 1000)
        elif msg.get_type() == "GPS_INPUT":
            times["GPS_INPUT"].append(msg.time_usec / 1e6)
    assert components == {191}
    assert {"HEARTBEAT", "GLOBAL_POSITION_INT", "GPS_INPUT"} <= set(kinds)
    # the fixture's GNSS is 10 Hz; so is publication, without gaps: each solution is
    # published by the first sample past its tick, so at most one IMU period (10 ms
    # at this fixture's 100 Hz) late
    for name, t in times.items():
        rate = np.median(1.0 / np.diff(t))
        assert rate == pytest.approx(10.0, rel=0.01), name
        assert np.max(np.diff(t[1:])) <= 0.1 + 0.010 + 1e-6, name
    assert kinds["HEARTBEAT"] == pytest.approx(summary.log_duration_s, abs=2)
    assert summary.messages_out == sum(kinds.values())


def test_the_pipeline_clocks_its_heartbeat():
    """The timer API: due at once, then a heartbeat period after each one sent."""
    pipeline = Pipeline()
    assert pipeline.next_due_s() == -math.inf
    assert len(pipeline.on_timer(100.0)) == 1
    assert pipeline.next_due_s() == 101.0
    assert pipeline.on_timer(100.5) == []  # called early: nothing due
    assert len(pipeline.on_timer(101.25)) == 1
    assert pipeline.next_due_s() == 102.25
    assert pipeline.stats.out_by_type["HEARTBEAT"] == 2


def test_replayed_heartbeats_come_at_their_due_time(replayed):
    """As the live timer sends them: the first at the first record, then one a period after
    the other, in log time, whether or not a record arrives then."""
    _, first, _ = replayed
    inputs = [t for t, _ in TlogReader(FIXTURE)]
    beats = [t for t, msg in TlogReader(first) if msg.get_type() == "HEARTBEAT"]
    assert beats[0] == pytest.approx(inputs[0], abs=1e-6)
    for prev, beat in zip(beats, beats[1:], strict=False):
        assert beat == pytest.approx(prev + 1.0, abs=1e-6)
    assert beats[-1] <= inputs[-1] < beats[-1] + 1.0


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "companion", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["replay", "missing.tlog", "--output", "{tmp}/o.tlog"], "cannot open tlog"),
        (
            ["replay", str(FIXTURE), "--output", "{tmp}/o.tlog", "--config", "nope.toml"],
            "config file not found",
        ),
        (["simulate", "no_such_flight", "--out", "{tmp}"], "no_such_flight"),
        (["simulate", "taxi", "--out", "{tmp}", "--duration", "-5"], "duration"),
        (["evaluate", "missing.tlog", "--truth", "missing.csv"], "missing"),
    ],
)
def test_bad_input_is_one_line_and_nonzero(tmp_path, args, message):
    done = run_cli(*(a.replace("{tmp}", str(tmp_path)) for a in args))
    assert done.returncode != 0
    lines = [line for line in done.stderr.splitlines() if "error" in line]
    assert len(lines) == 1 and message in lines[0], done.stderr
    assert "Traceback" not in done.stderr


def test_a_tlog_with_corrupt_records_replays_the_rest_counted(tmp_path, capsys):
    """Bursts of garbage inside a real flight: skipped and counted, exit 0 (a file with no
    record at all is an error: tests/test_failfast.py)."""
    data = FIXTURE.read_bytes()[:400_000]
    rng = np.random.default_rng(1)
    damaged = tmp_path / "damaged.tlog"
    damaged.write_bytes(
        data[:100_000] + rng.bytes(5_000) + data[100_000:250_000] + rng.bytes(300) + data[250_000:]
    )
    clean = tmp_path / "clean.tlog"
    clean.write_bytes(data)

    def replayed_n(path: Path) -> tuple[int, str]:
        args = ["--log-level", "error", "replay", str(path), "-o", str(tmp_path / "o.tlog"), "-q"]
        assert main(args) == 0
        out = capsys.readouterr().out
        return int(out.split()[1]), out

    n_clean, _ = replayed_n(clean)
    n_damaged, out = replayed_n(damaged)
    # garbage inserted inside a record destroys that record, at most one per burst
    assert n_clean - 2 <= n_damaged <= n_clean and n_clean > 5000
    assert "corrupt_frame 2" in out, out

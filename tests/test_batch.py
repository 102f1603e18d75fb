"""``companion batch`` on Dask: rows for every log, error rows for bad ones, the same
table whatever the workers, a real scheduler with two worker processes, and a worker
killed in the middle of a flight."""

from __future__ import annotations

import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("dask.distributed")

from companion import sim  # noqa: E402
from companion.batch.run import run_batch  # noqa: E402
from companion.batch.table import read_table  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PX4_SMALL = ROOT / "tests" / "data" / "logs" / "sample_log_small.ulg"


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """Four logs: a short simulated flight with truth, a PX4 .ulg, a text file, and a
    missing path."""
    d = tmp_path_factory.mktemp("fleet")
    sim.write_scenario("approach_rtk20", d / "sim", seed=2, duration_s=25.0)
    shutil.copy(PX4_SMALL, d / "px4.ulg")
    (d / "broken.tlog").write_text("not a log\n")
    return d


def _equal(u: object, v: object) -> bool:
    both_nan = isinstance(u, float) and isinstance(v, float) and math.isnan(u) and math.isnan(v)
    return both_nan or u == v


def same(a, b) -> bool:
    return all(
        x.keys() == y.keys() and all(_equal(v, y[k]) for k, v in x.items())
        for x, y in zip(a, b, strict=True)
    )


def test_rows_errors_and_the_same_table_with_one_or_two_workers(fleet, tmp_path):
    paths = [fleet, fleet / "absent.bin"]
    one = run_batch(paths, tmp_path / "one", workers=1, plots=False, table_format="csv")
    two = run_batch(paths, tmp_path / "two", workers=2, plots=False, table_format="csv")
    assert one.table is not None and two.table is not None
    assert one.table.read_bytes() == two.table.read_bytes()
    assert same(one.rows, two.rows)
    by_name = {r["name"]: r for r in one.rows}
    assert set(by_name) == {"approach_rtk20.tlog", "px4.ulg", "broken.tlog", "absent.bin"}
    assert "no tlog record" in by_name["broken.tlog"]["error"]
    assert "cannot open" in by_name["absent.bin"]["error"]
    simulated = by_name["approach_rtk20.tlog"]
    assert simulated["error"] == "" and simulated["scoring"] == "truth"
    assert simulated["truth_h95_m"] > 0.0 and simulated["messages_in"] > 1000
    px4 = by_name["px4.ulg"]
    assert px4["error"] == "" and px4["format"] == "ulog" and px4["vehicle"] == "PX4 VTOL"
    assert px4["scoring"] == "against_input" and px4["rej_no_system_yet"] > 0
    summary = json.loads((tmp_path / "one" / "summary.json").read_text())
    assert summary["flights"] == 4 and summary["errors"] == 2


def _start(args: list[str], log: Path) -> subprocess.Popen[bytes]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen(
        [sys.executable, "-m", "dask", *args],
        stdout=open(log, "wb"),  # noqa: SIM115 - closed with the process
        stderr=subprocess.STDOUT,
        env=env,
        cwd=ROOT,
    )


@pytest.fixture
def cluster(tmp_path):
    """A real ``dask scheduler`` and two ``dask worker`` processes on 127.0.0.1."""
    sched_file = tmp_path / "scheduler.json"
    procs = [
        _start(
            ["scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
             "--scheduler-file", str(sched_file)],
            tmp_path / "scheduler.log",
        )
    ]  # fmt: skip
    try:
        deadline = time.monotonic() + 60
        while not sched_file.exists() and time.monotonic() < deadline:
            time.sleep(0.2)
        address = json.loads(sched_file.read_text())["address"]
        for i in range(2):
            procs.append(
                _start(
                    ["worker", address, "--host", "127.0.0.1", "--nthreads", "1", "--no-nanny",
                     "--no-dashboard", "--name", f"w{i}"],
                    tmp_path / f"worker{i}.log",
                )
            )  # fmt: skip
        from dask.distributed import Client

        with Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=60)
        yield address, procs[1:]
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                p.terminate()
        for p in procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()


def test_companion_batch_against_a_running_scheduler(fleet, cluster, tmp_path):
    address, _ = cluster
    out = tmp_path / "out"
    done = subprocess.run(
        [sys.executable, "-m", "companion", "batch", str(fleet), "--output", str(out),
         "--scheduler", address, "--format", "csv", "--no-plots"],
        cwd=ROOT, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    rows = read_table(out / "flights.csv")
    # sorted by path: fleet/broken.tlog, fleet/px4.ulg, fleet/sim/approach_rtk20.tlog
    assert [r["name"] for r in rows] == ["broken.tlog", "px4.ulg", "approach_rtk20.tlog"]
    assert [bool(r["error"]) for r in rows] == [True, False, False]
    assert "3 flights (1 errors)" in done.stdout
    assert "] 3/3 flights" in done.stderr  # the progress bar


def test_a_worker_killed_mid_flight_loses_no_row(fleet, cluster, tmp_path):
    """``companion batch`` in its own process (one Dask client per process, as in use)
    while this test kills a busy worker: every flight still has its row."""
    from dask.distributed import Client

    address, workers = cluster
    logs = tmp_path / "logs"
    logs.mkdir()
    for i in range(6):
        shutil.copy(fleet / "sim" / "approach_rtk20.tlog", logs / f"flight{i}.tlog")
    out = tmp_path / "out"
    runner = subprocess.Popen(
        [sys.executable, "-m", "companion", "batch", str(logs), "--output", str(out),
         "--scheduler", address, "--format", "csv", "--no-plots"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    killed = None
    try:
        with Client(address, timeout="30s") as watcher:
            pids = watcher.run(os.getpid)
            deadline = time.monotonic() + 120
            while killed is None and time.monotonic() < deadline and runner.poll() is None:
                busy = [addr for addr, keys in watcher.processing().items() if keys]
                if busy:
                    pid = pids[busy[0]]
                    if pid in {w.pid for w in workers}:  # ours to kill: a worker we started
                        os.kill(pid, signal.SIGKILL)
                        killed = pid
                time.sleep(0.05)
        stdout, stderr = runner.communicate(timeout=300)
    finally:
        if runner.poll() is None:
            runner.kill()
    assert runner.returncode == 0, stderr
    assert killed is not None, "no worker was ever busy"
    rows = read_table(out / "flights.csv")
    assert sorted(r["name"] for r in rows) == [f"flight{i}.tlog" for i in range(6)]
    assert all(not r["error"] for r in rows), [r["error"] for r in rows]
    assert len({r["messages_in"] for r in rows}) == 1  # the same log: the same replay

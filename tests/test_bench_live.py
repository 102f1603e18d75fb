"""bench/live.py's plumbing: a short live play against the real service over UDP.

No figure is judged (timings belong to the bench): the bench must start the
service, play, receive GPS_INPUTs that are the replay pipeline's own, match them
to their fixes and triggers, and compute every figure.
"""

from __future__ import annotations

import importlib.util
import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _bench():  # type: ignore[no-untyped-def]
    spec = importlib.util.spec_from_file_location("bench_live", ROOT / "bench" / "live.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["bench_live"] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
def test_a_short_live_play_yields_every_figure(capsys):
    bench = _bench()
    assert bench.main(["--duration", "1.5", "--json"]) == 0
    out = capsys.readouterr().out
    fig = json.loads(out.strip().splitlines()[-1])
    assert fig["messages"] > 300
    assert fig["gps_inputs"] > 0
    # GPS_INPUTs matched to the replay pipeline's, byte for byte (sequence number and CRC
    # aside); not all required: a datagram lost to a stalled, loaded machine changes
    # the ones after it
    assert fig["identical"] > 0
    assert fig["fixes_matched"] > 0 and fig["triggers_matched"] > 0
    for key in ("fix_latency_ms", "service_latency_ms"):
        assert 0.0 < fig[key]["median"] <= fig[key]["p99"]
    for key in (
        "live_cpu_us_per_message",
        "replay_cpu_us_per_message",
        "paced_work_us_per_message",
        "receive_cpu_us_per_message",
        "live_peak_rss_mib",
    ):
        assert math.isfinite(fig[key]) and fig[key] > 0.0
    assert "live / replay per message" in out


_BUSY_THREAD = """
import threading, time
def spin():
    while time.thread_time() < 0.3:
        pass
    print("spun", flush=True)
    time.sleep(60)
threading.Thread(target=spin, daemon=True).start()
time.sleep(60)
"""


def test_the_cpu_of_every_thread_is_counted():
    # a receiving thread's CPU must not escape the live figure: /proc/PID/schedstat is
    # the main thread's alone
    bench = _bench()
    proc = subprocess.Popen([sys.executable, "-c", _BUSY_THREAD], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "spun"
        run_s, _, _ = bench._proc_cpu_s(proc.pid)
        with open(f"/proc/{proc.pid}/schedstat") as fh:
            main_thread_s = int(fh.read().split()[0]) / 1e9
    finally:
        proc.kill()
        proc.wait()
    assert run_s >= 0.3 > main_thread_s

"""bench/live.py's plumbing: a short live play against the real service over UDP.

No figure is judged (timings belong to the bench): the bench must start the
service, play, receive GPS_INPUTs that are the replay pipeline's own, match them
to their fixes and triggers, and compute every figure.
"""

from __future__ import annotations

import importlib.util
import json
import math
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
        "live_peak_rss_mib",
    ):
        assert math.isfinite(fig[key]) and fig[key] > 0.0
    assert "live / replay per message" in out

"""The [raw] link end to end: ``companion replay LOG --raw RAW.ubx`` with the bundled walk
cut beside a MAVLink log built from the same receiver's NAV-PVT (bench/raw_link.py).

The integrity monitor receives the carrier-phase solution (separations of every fix from
it), FIS-RAIM's alert on a faulty satellite is published and withdraws the solution
before it blames the receiver, and a ramp in the autopilot's fixes, which nothing else
in a one-receiver replay catches, is caught against it.
"""

from __future__ import annotations

import importlib.util
import math
import sys
from functools import lru_cache
from pathlib import Path

import pytest

from companion.cli import main
from companion.config import Config
from companion.raw import faults
from companion.raw.obs import RawEpoch
from companion.replay import replay

ROOT = Path(__file__).resolve().parents[1]
FAULT_AFTER_S = 15.0


@lru_cache(maxsize=1)
def bench():
    spec = importlib.util.spec_from_file_location("bench_raw_link", ROOT / "bench" / "raw_link.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["bench_raw_link"] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


@lru_cache(maxsize=1)
def items():
    return bench().read_items(bench().CUT_UBX)


def _start_tow() -> float:
    return next(i.tow_s for i in items() if isinstance(i, RawEpoch)) + FAULT_AFTER_S


def _alerts(res, prefix: str) -> list[float]:
    """Seconds after the fault's start of the alerts whose text starts with ``prefix``."""
    return [tow - _start_tow() for tow, text in res.alerts if text.startswith(prefix)]


def test_the_monitor_receives_the_carrier_solution(tmp_path: Path) -> None:
    res = bench().run(items(), tmp_path)
    s = res.summary
    assert s.raw_solutions > 100
    # every fix after the time mapping is separated from the carrier solution
    assert res.separations_tested == s.raw_solutions
    assert not _alerts(res, "CMP RAW_") and not _alerts(res, "CMP FAULT")
    assert {v for _, v in res.named["CMP_RSTAT"]} == {2.0}  # tested and trusted
    # FIS-RAIM's statistics go out with the status (all available: every frequency)
    assert len(res.named["CMP_RSEP"]) == len(res.named["CMP_RSTAT"])
    assert all(math.isfinite(v) for _, v in res.named["CMP_RSLP"])


def test_a_ramp_on_one_satellite_raises_the_raw_alert(tmp_path: Path) -> None:
    """4 cm/s on Galileo 26's code, carrier and Doppler: FIS-RAIM alerts before the ramp
    reaches 1 m; the solution is withdrawn, the receiver is not blamed."""
    res = bench().run(items(), tmp_path, raw_fault=faults.ramp(0.04), fault_tow_s=_start_tow())
    first = _alerts(res, "CMP RAW_FAULT")
    assert first and 0.0 < first[0] < 1.0 / 0.04
    assert not _alerts(res, "CMP FAULT")
    assert res.separations_tested < res.summary.raw_solutions


def test_a_dither_on_one_satellite_raises_the_raw_alert_within_10_s(tmp_path: Path) -> None:
    res = bench().run(
        items(), tmp_path, raw_fault=faults.dither(1.0, 10.0), fault_tow_s=_start_tow()
    )
    first = _alerts(res, "CMP RAW_FAULT")
    assert first and 0.0 < first[0] < 10.0
    assert not _alerts(res, "CMP FAULT")  # not blamed on the receiver between its alerts


def test_a_ramp_in_the_fixes_is_caught_against_the_carrier_solution(tmp_path: Path) -> None:
    """0.1 m/s north in the autopilot's fixes: excluded on the carrier solution's word
    before 1 m; the same replay without the raw receiver says nothing."""
    start = _start_tow()
    res = bench().run(items(), tmp_path, fix_fault=faults.ramp(0.1), fault_tow_s=start)
    fault = [(tow - start, text) for tow, text in res.alerts if text.startswith("CMP FAULT")]
    assert fault and 0.0 < fault[0][0] < 10.0 and "ref:tdprp" in fault[0][1]
    tlog = tmp_path / "alone.tlog"
    bench().write_pvt_tlog(items(), tlog, faults.ramp(0.1), start)
    alone = replay(tlog, tmp_path / "alone_out.tlog", Config())
    assert "FAULT" not in alone.alerts


def test_the_command_line_replays_with_the_raw_file(tmp_path: Path, capsys) -> None:
    tlog = tmp_path / "walk.tlog"
    bench().write_pvt_tlog(items(), tlog)
    rc = main(
        ["replay", str(tlog), "-o", str(tmp_path / "out.tlog"), "-q", "--raw", str(bench().CUT_UBX)]
    )
    assert rc == 0
    text = capsys.readouterr().out
    line = next(ln for ln in text.splitlines() if ln.startswith("raw receiver:"))
    assert int(line.split()[2]) > 100 and "time not mapped" in line


def test_a_missing_raw_file_is_one_line(tmp_path: Path, capsys) -> None:
    tlog = tmp_path / "walk.tlog"
    bench().write_pvt_tlog(items(), tlog)
    rc = main(["replay", str(tlog), "-o", str(tmp_path / "o.tlog"), "--raw", "nope.ubx"])
    assert rc != 0
    assert "nope.ubx" in capsys.readouterr().err


@pytest.mark.parametrize("delay_s", [0.2])
def test_raw_messages_later_than_the_fixes_still_pair(tmp_path: Path, delay_s: float) -> None:
    """Raw epochs arriving after their fixes (``--raw-delay-s``): the fix of an epoch is
    separated from the previous carrier solution, carried by its velocity."""
    tlog = tmp_path / "walk.tlog"
    bench().write_pvt_tlog(items(), tlog)
    from companion.replay import timed_raw_items

    s = replay(tlog, tmp_path / "o.tlog", Config(), raw=timed_raw_items(items(), delay_s))
    assert s.raw_solutions > 100
    assert s.integrity_stats.get("raw_reference_tested", 0) > 100
    assert "FAULT" not in s.alerts

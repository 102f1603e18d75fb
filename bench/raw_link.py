"""Bench: the ``[raw]`` link end to end, a real walk's raw observations beside its MAVLink.

Data: a u-blox recording with RXM-RAWX, RXM-SFRBX and NAV-PVT: by default the full walk
``../shared/realdata/gnss_imu/walk_0827/gnss_1730.ubx`` (134 s, 4 Hz), else ``--ubx``
(the bundled 40 s cut: ``tests/data/walk_0827/gnss_1730_cut.ubx``).

The MAVLink side is what the autopilot would send with that receiver on its GPS port:
:func:`write_pvt_tlog` turns each NAV-PVT into a GPS_RAW_INT (the autopilot clock
``BOOT_BEFORE_FIRST_FIX_S`` ahead of the first fix, fix type 6 / 5 for a fixed / float
carrier solution, the receiver's own accuracies), written ``FIX_DELAY_S`` after its GPS
time (UNIX record times), with a 1 Hz HEARTBEAT. No IMU: the pass-through carries the
solution. The replay (:func:`companion.replay.replay` with the .ubx beside) then maps the
receiver's GPS time onto the autopilot clock, runs T-D PRP with FIS-RAIM and hands each
solution to the integrity monitor.

Runs: untouched; a 4 cm/s ramp and a 1 m dither (period 10 s) injected into one
satellite's code, carrier and Doppler (Galileo 26) from ``--fault-s`` (15 s after the
first epoch); and, the other way round, a 0.1 m/s ramp injected into the autopilot's
fixes (north) from the same time, which the separation from the carrier solution must
catch. Printed per run: solutions passed to the engine, separations of the fixes from
the carrier solution tested, the ``CMP RAW`` and ``CMP FAULT`` alerts with their times
after the fault's start, the raw link's rejections.

Run: ``python bench/raw_link.py [--ubx FILE]`` (skips, saying why, without the data).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import tempfile
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mav

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.walk_0827 import write_rover_tlog  # noqa: E402
from companion.config import Config  # noqa: E402
from companion.mavlink.tlog import TlogReader  # noqa: E402
from companion.raw import faults  # noqa: E402
from companion.raw.obs import NavWords, PvtFix, RawEpoch  # noqa: E402
from companion.replay import (  # noqa: E402
    GPS_EPOCH_UNIX_S,
    GPS_UTC_LEAP_S,
    SECONDS_PER_WEEK,
    ReplaySummary,
    replay,
    timed_raw_items,
)
from companion.ubx.reader import UbxSource  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
WALK_UBX = ROOT.parent / "shared" / "realdata" / "gnss_imu" / "walk_0827" / "gnss_1730.ubx"
CUT_UBX = ROOT / "tests" / "data" / "walk_0827" / "gnss_1730_cut.ubx"
BOOT_BEFORE_FIRST_FIX_S = 20.0
FIX_DELAY_S = 0.05
"""The autopilot's fix reaches the companion this long after its GPS time (s)."""
VICTIM = ("Galileo", 26)

FixFault = Callable[[float], tuple[float, float]]


def read_items(path: Path) -> list[RawEpoch | NavWords | PvtFix]:
    with open(path, "rb") as fh:
        return list(UbxSource(fh))


def write_pvt_tlog(
    items: list[RawEpoch | NavWords | PvtFix],
    path: Path,
    fix_fault: FixFault | None = None,
    fault_tow_s: float = math.inf,
) -> dict[str, Any]:
    """The GPS_RAW_INT stream an autopilot would send with this receiver (module docstring);
    ``fix_fault`` (time since ``fault_tow_s`` -> north error m, rate) added to the fixes."""
    week = next(i.week for i in items if isinstance(i, RawEpoch))
    pvts = [i for i in items if isinstance(i, PvtFix) and i.fix_type >= 3]
    if not pvts:
        raise ValueError("no NAV-PVT with a fix")
    boot_tow_s = pvts[0].itow_s - BOOT_BEFORE_FIRST_FIX_S
    events: list[tuple[float, int, Any]] = []
    for p in pvts:
        lat = p.lat_deg
        if p.itow_s >= fault_tow_s and fix_fault is not None:
            north_m, _ = fix_fault(p.itow_s - fault_tow_s)
            lat += math.degrees(north_m / 6_371_000.0)
        vn, ve, _ = p.vel_ned_mps
        speed = math.hypot(vn, ve)
        fix_type = {2: 6, 1: 5}.get(p.carrier_solution, 3)
        msg = mav.MAVLink_gps_raw_int_message(
            round((p.itow_s - boot_tow_s) * 1e6),
            fix_type,
            round(lat * 1e7),
            round(p.lon_deg * 1e7),
            round(p.height_msl_m * 1000),
            65535,
            65535,
            round(speed * 100),
            round(math.degrees(math.atan2(ve, vn)) % 360.0 * 100) % 36000,
            p.num_sv,
            round(p.height_m * 1000),
            max(1, round(p.h_acc_m * 1000)),
            max(1, round(p.v_acc_m * 1000)),
            100,
            0,
            0,
        )
        unix_s = GPS_EPOCH_UNIX_S + week * SECONDS_PER_WEEK + p.itow_s - GPS_UTC_LEAP_S
        events.append((unix_s + FIX_DELAY_S, 1, msg))
    write_rover_tlog(path, events, events[0][0] - 1.0, events[-1][0])
    return {"fixes": len(pvts), "boot_tow_s": boot_tow_s, "first_tow_s": pvts[0].itow_s}


def with_fault(
    items: list[RawEpoch | NavWords | PvtFix], start_tow_s: float, fault: faults.Fault
) -> list[RawEpoch | NavWords | PvtFix]:
    """The stream with ``fault`` injected into the victim satellite's epochs."""
    out: list[RawEpoch | NavWords | PvtFix] = []
    for item in items:
        if isinstance(item, RawEpoch):
            item = faults.inject([item], *VICTIM, start_tow_s, fault)[0]
        out.append(item)
    return out


@dataclasses.dataclass
class RunResult:
    summary: ReplaySummary
    alerts: list[tuple[float, str]]
    """(GPS time of week, STATUSTEXT) of every ``CMP`` alert sent."""
    separations_tested: int
    named: dict[str, list[tuple[float, float]]]


def run(
    items: list[RawEpoch | NavWords | PvtFix],
    workdir: Path,
    raw_fault: faults.Fault | None = None,
    fix_fault: FixFault | None = None,
    fault_tow_s: float = math.inf,
    config: Config | None = None,
) -> RunResult:
    """One replay of the MAVLink side with the raw stream beside it."""
    week = next(i.week for i in items if isinstance(i, RawEpoch))
    tlog = workdir / "walk_pvt.tlog"
    write_pvt_tlog(items, tlog, fix_fault, fault_tow_s)
    if raw_fault is not None:
        items = with_fault(items, fault_tow_s, raw_fault)
    cfg = config or Config()
    cfg = dataclasses.replace(cfg, raw=dataclasses.replace(cfg.raw, file="(replay)"))
    out = workdir / "out.tlog"
    summary = replay(tlog, out, cfg, raw=timed_raw_items(items))
    alerts: list[tuple[float, str]] = []
    named: dict[str, list[tuple[float, float]]] = {}
    for t_rx_s, msg in TlogReader(out):
        tow = t_rx_s + GPS_UTC_LEAP_S - GPS_EPOCH_UNIX_S - week * SECONDS_PER_WEEK
        if msg.get_type() == "STATUSTEXT" and str(msg.text).startswith("CMP "):
            alerts.append((tow, str(msg.text)))
        elif msg.get_type() == "NAMED_VALUE_FLOAT":
            named.setdefault(str(msg.name), []).append((tow, float(msg.value)))
    tested = summary.integrity_stats.get("raw_reference_tested", 0)
    return RunResult(summary, alerts, tested, named)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ubx", type=Path, default=WALK_UBX)
    ap.add_argument("--fault-s", type=float, default=15.0)
    args = ap.parse_args()
    if not args.ubx.is_file():
        print(f"skipped: no recording at {args.ubx} (try --ubx {CUT_UBX})")
        return 0
    items = read_items(args.ubx)
    first_tow = next(i.tow_s for i in items if isinstance(i, RawEpoch))
    start = first_tow + args.fault_s
    runs: list[tuple[str, dict[str, Any]]] = [
        ("untouched", {}),
        ("raw: ramp 4 cm/s on Galileo 26", {"raw_fault": faults.ramp(0.04)}),
        ("raw: dither 1 m, 10 s on Galileo 26", {"raw_fault": faults.dither(1.0, 10.0)}),
        ("fixes: ramp 0.1 m/s north", {"fix_fault": faults.ramp(0.1)}),
    ]
    print(f"{args.ubx.name}: faults from {args.fault_s:.1f} s after the first epoch")
    print(
        f"{'run':38} {'solutions':>9} {'tested':>6} {'RAW_FAULT':>9} {'FAULT':>6} "
        f"{'RAW_BACK':>8}  CMP_RSTAT (1 untested, 2 trusted, 3 fault)"
    )
    with tempfile.TemporaryDirectory() as tmp:
        for name, kw in runs:
            res = run(items, Path(tmp), fault_tow_s=start, **kw)
            s = res.summary

            def first(prefix: str, res: RunResult = res) -> str:
                times = [tow - start for tow, text in res.alerts if text.startswith(prefix)]
                return f"{times[0]:+.2f}" if times else "none"

            states = Counter(v for _, v in res.named.get("CMP_RSTAT", []))
            print(
                f"{name:38} {s.raw_solutions:9d} {res.separations_tested:6d} "
                f"{first('CMP RAW_FAULT'):>9} {first('CMP FAULT'):>6} {first('CMP RAW_BACK'):>8}"
                f"  {dict(sorted(states.items()))}"
            )
            for tow, text in res.alerts:
                if text.startswith(("CMP RAW", "CMP FAULT")):
                    print(f"    {tow - start:+7.2f} s  {text}")
        print(f"raw rejections (untouched and faulty alike): {s.raw_rejections}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

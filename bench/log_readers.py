"""Replay each real flight from its original log (.bin, .ulg) and from its converted .tlog.

For every folder of ``../shared/realdata/flights`` that holds an original beside
the converted telemetry log, both are replayed with the default configuration and
the published solutions compared (GPS_INPUT for ArduPilot; for PX4, whose
GLOBAL_POSITION_SENSOR has no time of its own, our GLOBAL_POSITION_INT): how many each
replay published, how many share a time stamp, the largest horizontal and vertical
distance between those, whether the frames are identical and whether the output files
are (record times included). Prints one line per
flight; skips (with the reason) where the folder is absent.

    python bench/log_readers.py
"""

from __future__ import annotations

import logging
import math
import sys
import tempfile
from pathlib import Path

from companion.mavlink.tlog import TlogReader
from companion.replay import replay

ROOT = Path(__file__).resolve().parents[1]
FLIGHTS = ROOT.parent / "shared" / "realdata" / "flights"
EARTH_RADIUS_M = 6_371_000.0


def solutions(path: Path) -> dict[int, tuple[float, float, float]]:
    """time -> (lat deg, lon deg, alt m) of every solution the replay published:
    GPS_INPUT (ArduPilot) or GLOBAL_POSITION_INT (PX4's logs: their GLOBAL_POSITION_SENSOR
    carries the same solution), keyed by the message's own time (µs)."""
    gps_input: dict[int, tuple[float, float, float]] = {}
    gpi: dict[int, tuple[float, float, float]] = {}
    for _t, msg in TlogReader(path):
        kind = msg.get_type()
        if kind == "GPS_INPUT":
            gps_input[msg.time_usec] = (msg.lat / 1e7, msg.lon / 1e7, msg.alt)
        elif kind == "GLOBAL_POSITION_INT":
            gpi[msg.time_boot_ms * 1000] = (msg.lat / 1e7, msg.lon / 1e7, msg.alt / 1e3)
    return gps_input or gpi


def frames(path: Path) -> list[bytes]:
    """The output's frames without their record times (the UTC offsets may differ)."""
    return [bytes(msg.get_msgbuf()) for _t, msg in TlogReader(path)]


def compare(original: Path, tlog: Path, work: Path) -> str:
    out_a, out_b = work / "orig.tlog", work / "conv.tlog"
    sa = replay(original, out_a)
    sb = replay(tlog, out_b)
    a, b = solutions(out_a), solutions(out_b)
    common = sorted(set(a) & set(b))
    dh = dv = 0.0
    for t in common:
        (la, lo, al), (lb, lob, alb) = a[t], b[t]
        dn = math.radians(la - lb) * EARTH_RADIUS_M
        de = math.radians(lo - lob) * EARTH_RADIUS_M * math.cos(math.radians(la))
        dh = max(dh, math.hypot(dn, de))
        dv = max(dv, abs(al - alb))
    same = frames(out_a) == frames(out_b)
    same_bytes = out_a.read_bytes() == out_b.read_bytes()
    rej = {k: v for k, v in sa.rejections.items() if sb.rejections.get(k) != v}
    rej_b = {k: v for k, v in sb.rejections.items() if sa.rejections.get(k) != v}
    return (
        f"{original.parent.name:38s} {original.suffix:4s} solutions {len(a):5d} / tlog "
        f"{len(b):5d}, same time {len(common):5d}, max diff {dh:.3f} m horiz {dv:.3f} m vert;"
        f" frames identical {same}, files identical {same_bytes}"
        + (f"; rejections differ: original {rej} tlog {rej_b}" if rej or rej_b else "")
    )


def main() -> int:
    logging.disable(logging.WARNING)  # the replays' own warnings are not the comparison
    if not FLIGHTS.is_dir():
        print(f"skipped: no real flights at {FLIGHTS} (the data folder is not part of the clone)")
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        for folder in sorted(FLIGHTS.iterdir()):
            tlog = folder / f"{folder.name}.tlog"
            originals = [p for p in folder.iterdir() if p.suffix.lower() in (".bin", ".ulg")]
            if not tlog.exists() or not originals:
                continue
            print(compare(originals[0], tlog, Path(tmp)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

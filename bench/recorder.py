"""The flight recorder's cost per message, against a bare buffered write of the same records.

    python bench/recorder.py [--tlog sitl_fixtures/nominal.tlog] [--passes 3] [--repeat 5]

The recorder runs on the live path once per message in and out, so its cost is per
message. Measured in this run, best of ``--repeat``, over the fixture's frames
(``--passes`` times end to end, stamped with the fixture's times shifted to now):

* ``bare``: ``BufferedWriter.write(timestamp + frame)``, the least a .tlog writer
  in Python does (no checks, no flush, no caps);
* ``recorder``: :meth:`companion.recorder.Recorder.record` with the default caps (the
  bench writes less than one file: no rotation);
* ``rotating``: the same with ``max_file_mb`` small enough that it rotates every
  ~1 MB and deletes the oldest files to stay under ``max_total_mb`` (when the
  recorder has caps: the code before them has neither).

Prints the CPU time (``time.process_time``: not the time other processes took the
core) per message for each, and its ratio to ``bare``.
"""

from __future__ import annotations

import argparse
import struct
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:  # run from anywhere, against this tree unless PYTHONPATH says
    sys.path.append(str(ROOT))

from companion.mavlink.tlog import TlogReader  # noqa: E402
from companion.recorder import Recorder  # noqa: E402

try:  # the recorder before its caps had no configuration
    from companion.recorder import RecorderConfig
except ImportError:  # pragma: no cover - only when benchmarking the old code
    RecorderConfig = None  # type: ignore[assignment,misc]

DEFAULT_TLOG = ROOT / "sitl_fixtures" / "nominal.tlog"
_TS = struct.Struct(">Q")


def _records(path: Path, passes: int) -> list[tuple[float, bytes]]:
    """The fixture's frames with times shifted to start now, ``passes`` times in a row."""
    frames = [(t, bytes(msg.get_msgbuf())) for t, msg in TlogReader(path)]
    t0 = frames[0][0]
    span_s = frames[-1][0] - t0 + 1.0
    start_s = time.time()
    return [(start_s + k * span_s + t - t0, frame) for k in range(passes) for t, frame in frames]


def _bare(folder: Path, records: list[tuple[float, bytes]]) -> float:
    pack = _TS.pack
    with open(folder / "bare.tlog", "wb") as fh:
        write = fh.write
        t0 = time.process_time()
        for t_s, frame in records:
            write(pack(int(round(t_s * 1e6))) + frame)
        return time.process_time() - t0


def _recorder(folder: Path, records: list[tuple[float, bytes]], config: Any) -> float:
    rec = (
        Recorder(folder, records[0][0])
        if config is None
        else Recorder(folder, records[0][0], config)
    )
    record = rec.record
    t0 = time.process_time()
    for t_s, frame in records:
        record(t_s, frame)
    wall_s = time.process_time() - t0
    rec.close()
    return wall_s


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tlog", type=Path, default=DEFAULT_TLOG)
    parser.add_argument("--passes", type=int, default=3)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    records = _records(args.tlog, args.passes)
    modes: dict[str, Callable[[Path], float]] = {
        "bare": lambda d: _bare(d, records),
        "recorder": lambda d: _recorder(d, records, None),
    }
    if RecorderConfig is not None:
        rotating = RecorderConfig(max_file_mb=1.0, max_total_mb=4.0)
        modes["rotating"] = lambda d: _recorder(d, records, rotating)
    best: dict[str, float] = {}
    for _ in range(args.repeat):
        for mode, run in modes.items():
            with tempfile.TemporaryDirectory() as tmp:
                wall_s = run(Path(tmp))
            best[mode] = min(best.get(mode, float("inf")), wall_s)
    n = len(records)
    print(f"{n} records ({args.passes} x {args.tlog.name}), best of {args.repeat}")
    print(f"{'mode':<10} {'ns/message':>11} {'/ bare':>7}")
    for mode, wall_s in best.items():
        print(f"{mode:<10} {wall_s / n * 1e9:>11.0f} {wall_s / best['bare']:>7.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

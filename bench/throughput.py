"""Throughput: the full pipeline against bare pymavlink parsing of the same bytes.

    python bench/throughput.py [--tlog sitl_fixtures/nominal.tlog] [--repeat 3]

Both are measured in this run, each in its own child process (so the peak RSS
printed is that mode's own), best of ``--repeat`` runs:

* ``bare``: pymavlink's own tlog reader (``mavutil.mavlink_connection``) parsing
  every message, nothing else;
* ``foundation``: ``companion replay`` minus the CLI with the first navigator
  (GNSS pass-through with constant velocity) — robust tlog reading, decoding
  to typed samples, the engine with outage, heading and integrity monitoring,
  encoding and writing the output tlog;
* ``blend``: the same with the default navigator, the GNSS/INS blend.

Prints messages/s for each, the ratio to bare parsing (the target is at least
0.5) and the peak RSS of each.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_TLOG = ROOT / "sitl_fixtures" / "nominal.tlog"
MODES = {"bare": "", "foundation": "passthrough", "blend": "blend"}
"""Measured modes and the navigator each runs."""


def _bare(path: Path) -> dict[str, float]:
    from pymavlink import mavutil

    t0 = time.perf_counter()
    conn = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    count = 0
    while conn.recv_msg() is not None:
        count += 1
    wall = time.perf_counter() - t0
    return {"messages": count, "wall_s": wall}


def _pipeline(path: Path, navigator: str) -> dict[str, float]:
    sys.path.insert(0, str(ROOT))
    from dataclasses import replace

    from companion.config import Config
    from companion.replay import replay

    config = Config()
    config = replace(config, engine=replace(config.engine, navigator=navigator))
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        summary = replay(path, Path(tmp) / "out.tlog", config)
        wall = time.perf_counter() - t0
    return {"messages": summary.messages_in, "wall_s": wall, "out": summary.messages_out}


def _child(mode: str, path: Path) -> None:
    result = _bare(path) if mode == "bare" else _pipeline(path, MODES[mode])
    result["peak_rss_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(json.dumps(result))


def _run(mode: str, path: Path) -> dict[str, float]:
    out = subprocess.run(
        [sys.executable, __file__, "--child", mode, "--tlog", str(path)],
        check=True,
        capture_output=True,
        text=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tlog", type=Path, default=DEFAULT_TLOG)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--child", choices=list(MODES), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        _child(args.child, args.tlog)
        return 0
    if not args.tlog.exists():
        print(f"no such tlog: {args.tlog}", file=sys.stderr)
        return 1
    best: dict[str, dict[str, float]] = {}
    for k in range(args.repeat):
        for mode in MODES:
            print(f"run {k + 1}/{args.repeat}: {mode} ...", file=sys.stderr, flush=True)
            result = _run(mode, args.tlog)
            if mode not in best or result["wall_s"] < best[mode]["wall_s"]:
                best[mode] = result
    size_mib = args.tlog.stat().st_size / 2**20
    print(f"tlog: {args.tlog.name} ({size_mib:.1f} MiB, {best['bare']['messages']:.0f} messages)")
    header = f"{'mode':<11} {'messages':>9} {'wall s':>8} {'msg/s':>10} {'/ bare':>7}"
    print(f"{header} {'peak RSS MiB':>13}")
    bare_rate = best["bare"]["messages"] / best["bare"]["wall_s"]
    for mode in MODES:
        r = best[mode]
        rate = r["messages"] / r["wall_s"]
        print(
            f"{mode:<11} {r['messages']:>9.0f} {r['wall_s']:>8.2f} {rate:>10,.0f} "
            f"{rate / bare_rate:>7.2f} {r['peak_rss_mib']:>13.1f}"
        )
    for mode in ("foundation", "blend"):
        ratio = best[mode]["messages"] / best[mode]["wall_s"] / bare_rate
        verdict = "meets" if ratio >= 0.5 else "MISSES"
        print(f"{mode} / bare pymavlink = {ratio:.2f} ({verdict} the 0.5 target)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

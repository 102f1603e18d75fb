"""companion batch on a local Dask cluster with one and then two worker processes.

The fleet: ``--flights`` simulated flights (default 500) of ``--duration`` seconds
(default 30 s), as ``companion simulate --many`` makes them (each with a GNSS
outage of 4-7 s starting half-way, the catalogue's scenarios in turn, seeds
``seed * 100000 + i``: :mod:`companion.sim.fleet`); plus the real logs: the
bundled originals (tests/data/logs) and, where ``../shared/realdata/flights`` is
present, every log there (.tlog, .bin, .ulg). The same fleet is run with 1 and
with 2 workers (one thread each) in this one run; printed for each: wall time (the
cluster's start included), flights per minute, the peak resident memory of each
worker; then the ratio of the two rates (goal >= 1.7 on a 2-core machine) and
whether the two tables are identical.

    python bench/batch.py [--flights 500] [--duration 30] [--seed 1] [--out DIR]
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import tempfile
import time
from pathlib import Path

from companion.batch.run import flights_per_minute, run_batch
from companion.sim.fleet import write_fleet

ROOT = Path(__file__).resolve().parents[1]
BUNDLED = ROOT / "tests" / "data" / "logs"
REAL = ROOT.parent / "shared" / "realdata" / "flights"


def real_logs() -> list[Path]:
    found = sorted(BUNDLED.glob("*.bin")) + sorted(BUNDLED.glob("*.ulg"))
    if REAL.is_dir():
        found += sorted(
            p for p in REAL.glob("*/*") if p.suffix.lower() in (".tlog", ".bin", ".ulg")
        )
    return found


def quiet_worker() -> None:
    logging.getLogger("companion").setLevel(logging.ERROR)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--flights", type=int, default=500)
    ap.add_argument("--duration", type=float, default=30.0, help="s per simulated flight")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", type=Path, help="keep the fleet and the tables here")
    args = ap.parse_args()
    import distributed  # noqa: F401 - its logging set up first, then quietened

    logging.getLogger("companion").setLevel(logging.ERROR)
    logging.getLogger("distributed").setLevel(logging.ERROR)
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out if args.out is not None else Path(tmp)
        t0 = time.perf_counter()
        fleet = write_fleet(out / "fleet", args.flights, args.seed, args.duration)
        gen_s = time.perf_counter() - t0
        real = real_logs()
        print(
            f"fleet: {len(fleet)} simulated flights of {args.duration:.0f} s (made in "
            f"{gen_s:.0f} s) + {len(real)} real logs; {os.cpu_count()} CPUs, "
            f"load average {os.getloadavg()[0]:.1f} at the start",
            flush=True,
        )
        rates = {}
        tables = {}
        for workers in (1, 2):
            result = run_batch(
                [*fleet, *real], out / f"batch{workers}", workers=workers, plots=False,
                table_format="csv", worker_setup=quiet_worker,
            )  # fmt: skip
            rate = flights_per_minute(result)
            rates[workers] = rate
            assert result.table is not None
            tables[workers] = result.table.read_bytes()
            errors = sum(1 for r in result.rows if r["error"])
            peaks = ", ".join(f"{v:.0f}" for v in result.worker_peak_rss_mb.values())
            print(
                f"{workers} worker(s): {len(result.rows)} flights ({errors} errors) in "
                f"{result.wall_s:.0f} s = {rate:.1f} flights/min; peak RSS per worker "
                f"{peaks} MB; load average {os.getloadavg()[0]:.1f}",
                flush=True,
            )
        print(
            f"ratio 2 workers / 1 worker: {rates[2] / rates[1]:.2f}x (goal >= 1.7 on 2 cores); "
            f"tables identical: {tables[1] == tables[2]}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The service beside PX4 SIH (quadrotor, aux global position fusion): PX4's error over a
GNSS cut with the service fused and without it, and the service's own.

Runs ``tests.sitl.px4_runner gnss_cut`` inside ``private-net`` ``--runs`` times each with
``EKF2_AGP0_CTRL`` = 1 and = 0 (PX4 SIH's sensor noise differs from run to run, so one
pair says little) and prints, per run, PX4's horizontal error against SIH's truth
(mean / p95 / max, m) over the 10 s before the cut, over the cut and over the first 2 s
after GNSS returned, when PX4 was back under its pre-cut maximum for good, the service's
error over the cut, the share of its positions whose published 1-sigma accuracy (x 2.45,
95 % in 2-D) covers the error, the GLOBAL_POSITION_SENSORs sent through the cut, and how
far EKF2's accelerometer bias estimate moved over it (HIGHRES_IMU carries PX4's IMU less
that estimate). PX4 runs in real time; all times are its own: check the machine's load.

    python bench/sitl_px4.py                 # 2 runs each, 20 s cut
    python bench/sitl_px4.py --runs 3 --cut-s 30 --json out.json

``--airframe 10041``: the SIH airplane (runway take-off, then PX4's Hold loiter circle,
``--cruise-s`` of it before the cut, 120 s by default), with the service's own error
over the cruise and the cut and its GNSS_LOST / GNSS_BACK latencies beside PX4's.

    python bench/sitl_px4.py --airframe 10041 --runs 2
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.sitl.harness import run_scenario  # noqa: E402
from tests.sitl.locate import missing  # noqa: E402

RUNNER = "tests.sitl.px4_runner"


def _mm(stats: dict[str, Any]) -> str:
    if not stats.get("n"):
        return "-"
    return f"{stats['mean_m']:.2f}/{stats['p95_m']:.2f}/{stats['max_m']:.2f}"


def _bias_change(r: dict[str, Any]) -> str:
    """EKF2's horizontal accelerometer bias change over the cut, mm/s^2 (x, y)."""
    rows = r.get("px4_biases_at_cut_and_back", {}).get("accel_bias")
    if not rows:
        return "-"
    (x0, y0, _), (x1, y1, _) = rows
    return f"{1e3 * (x1 - x0):+.1f},{1e3 * (y1 - y0):+.1f}"


PLANE = 10041


def run_px4(
    runs: int,
    cut_s: float,
    after_s: float,
    engine: list[str] | None = None,
    airframe: int = 10040,
    cruise_s: float = 120.0,
    extra: list[str] | None = None,
) -> dict[str, list[dict[str, Any]]]:
    """``runs`` flights with the fusion on and as many with it off (alternating)."""
    results: dict[str, list[dict[str, Any]]] = {"with": [], "without": []}
    with tempfile.TemporaryDirectory(prefix="companion-bench-px4-") as tmp:
        for k in range(runs):
            for fusion, key in ((1, "with"), (0, "without")):
                args = [
                    "gnss_cut",
                    "--fusion",
                    str(fusion),
                    "--cut-s",
                    f"{cut_s:g}",
                    "--after-s",
                    f"{after_s:g}",
                ]
                if airframe == PLANE:
                    args += ["--airframe", str(PLANE), "--climb-s", "25"]
                    args += ["--hover-s", f"{cruise_s:g}", "--pre-window-s", f"{cruise_s:g}"]
                for setting in engine or []:
                    args += ["--engine", setting]
                args += extra or []
                out = Path(tmp) / f"px4_{key}_{k}.json"
                timeout_s = 300.0 + 3.0 * cut_s + (2.0 * cruise_s if airframe == PLANE else 0.0)
                result = run_scenario(RUNNER, args, out, timeout_s=timeout_s)
                result.pop("companion_log_tail", None)
                result.pop("_output_tail", None)
                results[key].append(result)
    return results


def print_px4(results: dict[str, list[dict[str, Any]]], cut_s: float) -> None:
    print(f"PX4 SIH quadrotor, hover at 10 m, {cut_s:g} s GNSS cut (MAV_CMD_INJECT_FAILURE)")
    print("horizontal error vs SIH truth, m: mean/p95/max; 'back': s after GNSS returned until")
    print("PX4 stays under its largest error of the 10 s before the cut ('-': not in the flight)")
    head = (
        f"{'run':10s} {'PX4 pre-cut':>15s} {'PX4 cut':>15s} {'PX4 2 s after':>16s} {'back':>6s} "
        f"{'service cut':>15s} {'cover95':>7s} {'sent':>5s} {'dAccB mm/s2':>12s}"
    )
    print(head)
    for key in ("with", "without"):
        for k, r in enumerate(results[key]):
            back = r["px4_back_under_pre_max_s"]
            back_txt = "-" if math.isnan(back) else f"{back:.1f}"
            print(
                f"{f'{key} {k + 1}':10s} {_mm(r['px4_pre']):>15s} {_mm(r['px4_cut']):>15s} "
                f"{_mm(r['px4_after_2s']):>16s} {back_txt:>6s} {_mm(r['service_cut']):>15s} "
                f"{r['service_cover_95']:>7.3f} {r['service_sensor_in_cut']:>5d} "
                f"{_bias_change(r):>12s}"
            )
    print("'sent': GLOBAL_POSITION_SENSORs sent in the cut from 1.5 s after it began (PX4")
    print("fuses them only 'with'); 'PX4 2 s after': the first 2 s after GNSS returned;")
    print("dAccB: EKF2's accelerometer bias estimate (x, y) moved over the cut")
    _print_cut_means(results, "the service")


def _latency(r: dict[str, Any], code: str, t0: float) -> str:
    times = [t for t, text in r["service_alerts"] if t >= t0 and text.startswith(f"CMP {code}")]
    return f"{min(times) - t0:.2f}" if times else "-"


def print_plane(results: dict[str, list[dict[str, Any]]], cut_s: float, cruise_s: float) -> None:
    print(
        f"PX4 SIH airplane, Hold loiter circle at 40 m, {cruise_s:g} s cruise, "
        f"{cut_s:g} s GNSS cut (MAV_CMD_INJECT_FAILURE)"
    )
    print("horizontal error vs SIH truth, m: mean/p95/max; LOST/BACK: alert latency, s;")
    print("cover: share of the service's positions within 2.45 x its 1-sigma over the cut")
    head = (
        f"{'run':10s} {'PX4 cruise':>15s} {'svc cruise':>15s} {'PX4 cut':>15s} "
        f"{'svc cut':>15s} {'PX4 2 s after':>15s} {'LOST':>5s} {'BACK':>5s} {'cover':>6s} "
        f"{'stray alerts':>12s}"
    )
    print(head)
    bad = ("CMP GNSS_STALE", "CMP GNSS_LOST", "CMP GNSS_BACK", "CMP FAULT")
    for key in ("with", "without"):
        for k, r in enumerate(results[key]):
            t_cut, t_back = r["t_cut_s"], r["t_back_s"]
            stray = [
                text.split()[1]
                for t, text in r["service_alerts"]
                if text.startswith(bad)
                and not (t_cut <= t <= t_cut + 1.5 and "GNSS_LOST" in text)
                and not (t_back <= t <= t_back + 1.5 and "GNSS_BACK" in text)
            ]
            print(
                f"{f'{key} {k + 1}':10s} {_mm(r['px4_pre']):>15s} {_mm(r['service_pre']):>15s} "
                f"{_mm(r['px4_cut']):>15s} {_mm(r['service_cut']):>15s} "
                f"{_mm(r['px4_after_2s']):>15s} {_latency(r, 'GNSS_LOST', t_cut):>5s} "
                f"{_latency(r, 'GNSS_BACK', t_back):>5s} {r['service_cover_95_cut']:>6.3f} "
                f"{','.join(stray) or '-':>12s}"
            )
    _print_cut_means(results, "the service's aux position")


def _print_cut_means(results: dict[str, list[dict[str, Any]]], what: str) -> None:
    """PX4's error over the cut, averaged over the runs with and without ``what``."""
    for key in ("with", "without"):
        done = [r for r in results[key] if r["px4_cut"].get("n")]
        if done:
            mean = statistics.fmean(r["px4_cut"]["mean_m"] for r in done)
            worst = statistics.fmean(r["px4_cut"]["max_m"] for r in done)
            print(
                f"PX4 over the cut, {key} {what}: mean of means {mean:.2f} m, "
                f"mean of maxima {worst:.2f} m ({len(done)} runs)"
            )


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=int, default=2)
    p.add_argument("--cut-s", type=float, default=20.0)
    p.add_argument("--after-s", type=float, default=10.0)
    p.add_argument("--airframe", type=int, default=10040, choices=(10040, PLANE))
    p.add_argument("--cruise-s", type=float, default=120.0, help="airplane: cruise before the cut")
    p.add_argument(
        "--engine",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="an [engine] setting of the service, e.g. gap_feed_max_h_acc_m=1.5",
    )
    p.add_argument(
        "--encoder",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="an [encoder] setting of the service, e.g. px4_agp_lead_s=0",
    )
    p.add_argument(
        "--px4-param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a PX4 parameter at boot, e.g. EKF2_AGP0_DELAY=0 (both runs of a pair)",
    )
    p.add_argument("--json", type=Path, help="also write the runner's results here")
    args = p.parse_args(argv)
    reason = missing("px4/run-sih.sh", "px4/bin/px4")
    if reason:
        print(f"bench/sitl_px4.py: {reason}", file=sys.stderr)
        return 2
    extra = [a for kv in args.encoder for a in ("--encoder", kv)]
    extra += [a for kv in args.px4_param for a in ("--px4-param", kv)]
    results = run_px4(
        args.runs, args.cut_s, args.after_s, args.engine, args.airframe, args.cruise_s, extra
    )
    if args.airframe == PLANE:
        print_plane(results, args.cut_s, args.cruise_s)
    else:
        print_px4(results, args.cut_s)
    if args.json:
        args.json.write_text(json.dumps(results, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())

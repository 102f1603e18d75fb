"""The service beside PX4 SIH (quadrotor, aux global position fusion): PX4's error over a
GNSS cut with the service fused and without it, and the service's own.

Runs ``tests.sitl.px4_runner gnss_cut`` inside ``private-net`` ``--runs`` times each with
``EKF2_AGP0_CTRL`` = 1 and = 0 (PX4 SIH's sensor noise differs from run to run, so one
pair says little) and prints, per run, PX4's horizontal error against SIH's truth
(mean / max, m) over the 10 s before the cut, over the cut and after it, when PX4 was
back under its pre-cut maximum for good, the service's error over the cut, the share of
its positions whose published 1-sigma accuracy (x 2.45, 95 % in 2-D) covers the error,
and whether PX4 fused the service. PX4 runs in real time; all times are its own.

    python bench/sitl_px4.py                 # 2 runs each, 20 s cut
    python bench/sitl_px4.py --runs 3 --cut-s 30 --json out.json
"""

from __future__ import annotations

import argparse
import json
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
    return f"{stats['mean_m']:.2f} / {stats['max_m']:.2f}"


def run_px4(runs: int, cut_s: float, after_s: float) -> dict[str, list[dict[str, Any]]]:
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
                out = Path(tmp) / f"px4_{key}_{k}.json"
                result = run_scenario(RUNNER, args, out, timeout_s=300.0 + 3.0 * cut_s)
                result.pop("companion_log_tail", None)
                result.pop("_output_tail", None)
                results[key].append(result)
    return results


def print_px4(results: dict[str, list[dict[str, Any]]], cut_s: float) -> None:
    print(f"PX4 SIH quadrotor, hover at 10 m, {cut_s:g} s GNSS cut (MAV_CMD_INJECT_FAILURE)")
    print("horizontal error vs SIH truth, m: mean / max")
    head = (
        f"{'run':10s} {'PX4 pre-cut':>13s} {'PX4 cut':>13s} {'PX4 after':>13s} "
        f"{'PX4 back':>9s} {'service cut':>13s} {'cover95':>8s} {'fused':>6s}"
    )
    print(head)
    for key in ("with", "without"):
        for k, r in enumerate(results[key]):
            back = r["px4_back_under_pre_max_s"]
            fused = any(on for _, on in r["px4_aux_fused"])
            print(
                f"{f'{key} {k + 1}':10s} {_mm(r['px4_pre']):>13s} {_mm(r['px4_cut']):>13s} "
                f"{_mm(r['px4_after']):>13s} {back:>8.1f}s {_mm(r['service_cut']):>13s} "
                f"{r['service_cover_95']:>8.3f} {'yes' if fused else 'no':>6s}"
            )
    for key in ("with", "without"):
        cut = [r["px4_cut"]["mean_m"] for r in results[key] if r["px4_cut"].get("n")]
        worst = [r["px4_cut"]["max_m"] for r in results[key] if r["px4_cut"].get("n")]
        if cut:
            print(
                f"PX4 over the cut, {key} the service: mean of means {statistics.fmean(cut):.2f} m,"
                f" mean of maxima {statistics.fmean(worst):.2f} m ({len(cut)} runs)"
            )
    held = [r["service_sensor_in_cut"] for r in results["with"]]
    print(f"GLOBAL_POSITION_SENSOR sent to PX4 during the cut (fusion on): {held}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=int, default=2)
    p.add_argument("--cut-s", type=float, default=20.0)
    p.add_argument("--after-s", type=float, default=10.0)
    p.add_argument("--json", type=Path, help="also write the runner's results here")
    args = p.parse_args(argv)
    reason = missing("px4/run-sih.sh", "px4/bin/px4")
    if reason:
        print(f"bench/sitl_px4.py: {reason}", file=sys.stderr)
        return 2
    results = run_px4(args.runs, args.cut_s, args.after_s)
    print_px4(results, args.cut_s)
    if args.json:
        args.json.write_text(json.dumps(results, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())

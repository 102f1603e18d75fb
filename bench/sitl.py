"""The service beside ArduPilot SITL: its error against the autopilot's own, and its
alert latencies, on the scenarios of ``tests/sitl`` (ArduPlane and ArduCopter mission
circuits with a GPS outage, a reboot and a restart) flown longer.

Runs ``tests.sitl.ardupilot_runner`` inside ``private-net`` (the simulators are found
in ``../shared/sitl`` or ``$COMPANION_SITL_DIR``; nothing runs without them) and prints
one table: per scenario, the horizontal error (mean / 95th percentile / max, m) of the
service and of the autopilot's EKF3 against the simulator's truth over the healthy
cruise (the copter: and a hover) and over the GPS outage (the copter's cut as it turns
at a corner; how far the true course turned in it), GNSS_LOST and GNSS_BACK latencies,
and the alerts that should not be there. Then the plane and copter circuits again with
the service feeding the autopilot (``--feed``: its GPS 2, taken while GPS 1 is lost),
``--feed-runs`` and ``--copter-feed-runs`` times: the autopilot's own error over the
outage with the service and without it (the first flight), also with its last position
held where it published none. All times are the autopilot's; ``--speedup`` changes
only the wall time.

    python bench/sitl.py                      # 5 min cruise, 30 s outage
    python bench/sitl.py --cruise-s 600 --speedup 3 --json out.json
    python bench/sitl.py --feed-runs 3 --px4-runs 0
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.sitl.harness import run_scenario  # noqa: E402
from tests.sitl.locate import missing  # noqa: E402

RUNNER = "tests.sitl.ardupilot_runner"
UNWANTED = ("GNSS_STALE", "GNSS_LOST", "FAULT", "BRIDGING")


def _fmt(stats: dict[str, Any]) -> str:
    if not stats.get("n"):
        return "-"
    return f"{stats['mean_m']:.2f} / {stats['p95_m']:.2f} / {stats['max_m']:.2f}"


def _latency(value: float | None) -> str:
    return "missed" if value is None else f"{value:.2f} s"


def _print_flight(name: str, flight: dict[str, Any]) -> None:
    healthy, outage = flight["healthy"], flight["outage"]
    print(f"\n{name}")
    print(f"  {'phase':30s} {'service':>22s} {'autopilot EKF3':>22s}")
    span = healthy["t1_s"] - healthy["t0_s"]
    rows = []
    if "hover" in flight:
        hover = flight["hover"]
        rows.append((f"hover ({hover['t1_s'] - hover['t0_s']:.0f} s)", hover))
    rows += [
        (f"healthy cruise ({span:.0f} s)", healthy),
        (f"GPS outage ({outage['t_on_s'] - outage['t_off_s']:.0f} s)", outage),
        ("after GPS returns (+5 s on)", flight["after"]),
    ]
    for label, sec in rows:
        print(f"  {label:30s} {_fmt(sec['service']):>22s} {_fmt(sec['autopilot']):>22s}")
    lag = flight.get("gps_lag_s")
    print(
        "  GPS_RAW_INT time_usec trails the truth by "
        + ("-" if lag is None else f"{lag * 1000:.0f} ms")
        + " (measured: what GPS1_DELAY_MS should be)"
    )
    print(
        f"  the autopilot published no position for {outage['autopilot_max_gap_s']:.1f} s "
        "of the outage (longest gap); its last one held through its gaps: "
        f"{_fmt(outage['autopilot_held'])}"
    )
    print(f"  the true course turned by {outage['truth_turn_deg']:.0f} deg over the outage")
    print(
        f"  GNSS_LOST {_latency(outage['gnss_lost_latency_s'])} after the GPS went off, "
        f"GNSS_BACK {_latency(outage['gnss_back_latency_s'])} after it returned"
    )
    print(
        f"  over the outage the service was beyond 2.45 x its published 1-sigma in "
        f"{outage['service_beyond_coverage']} of {outage['service_with_accuracy']} positions"
    )
    per_second = outage.get("service_per_second") or []
    if per_second:
        print("  outage second: the service's error / 2.45 x its published 1-sigma, m")
        for k in range(0, len(per_second), 6):
            row = per_second[k : k + 6]
            print("    " + "  ".join(f"{s:4.0f} s {e:5.1f}/{2.45 * h:5.1f}" for s, e, h in row))
    unwanted = [
        (t, a)
        for t, a in healthy["alerts"] + flight.get("hover", {}).get("alerts", [])
        if a.split()[1] in UNWANTED
    ]
    print(f"  unwanted alerts in the hover and the healthy cruise: {len(unwanted)}")
    for t, a in unwanted[:10]:
        print(f"    {t:8.2f} s  {a}")
    print("  alerts from the GPS cut on:")
    for t, a in outage["alerts"]:
        print(f"    {t:8.2f} s  {a}")


def _print_fed(name: str, alone: dict[str, Any], feds: list[dict[str, Any]]) -> None:
    span = alone["outage"]["t_on_s"] - alone["outage"]["t_off_s"]
    print(
        f"\n{name}, the autopilot's own error (EKF3) over the {span:.0f} s outage, "
        "with the service feeding its GPS 2 and without (held: its last position standing "
        "in where it published none; pre-cut: the healthy cruise)"
    )
    print(
        f"  {'run':18s} {'EKF3 pre-cut':>20s} {'EKF3':>20s} {'EKF3 held':>20s} "
        f"{'no position':>11s} {'service':>20s}"
    )
    for label, run in [("alone (not fed)", alone)] + [
        (f"fed, run {k}", fed) for k, fed in enumerate(feds, 1)
    ]:
        out = run["outage"]
        print(
            f"  {label:18s} {_fmt(run['healthy']['autopilot']):>20s} "
            f"{_fmt(out['autopilot']):>20s} {_fmt(out['autopilot_held']):>20s} "
            f"{out['autopilot_max_gap_s']:9.1f} s {_fmt(out['service']):>20s}"
        )
    for k, fed in enumerate(feds, 1):
        out = fed["outage"]
        lag = fed.get("feed_lag_s")
        print(
            f"  fed, run {k}: the autopilot's stamps of our fixes trail the truth by "
            + ("-" if lag is None else f"{lag * 1000:.0f} ms")
            + f"; the service beyond 2.45 x its published 1-sigma in "
            f"{out['service_beyond_coverage']} of {out['service_with_accuracy']} positions; "
            f"after GPS returns (+5 s on) EKF3 {_fmt(fed['after']['autopilot'])}"
        )


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--speedup", type=float, default=4.0)
    p.add_argument("--cruise-s", type=float, default=300.0)
    p.add_argument("--outage-s", type=float, default=30.0)
    p.add_argument("--after-s", type=float, default=60.0)
    p.add_argument(
        "--params",
        default='{"GPS1_DELAY_MS": 100}',
        help="autopilot parameters (JSON); default: the GPS lag set to SITL's 100 ms "
        "(SIM_GPS1_LAG_MS; the lag the autopilot's stamps really carry is printed per flight)",
    )
    p.add_argument(
        "--feed-runs",
        type=int,
        default=1,
        help="plane circuits with the service feeding the autopilot's GPS 2; 0: none",
    )
    p.add_argument(
        "--copter-feed-runs",
        type=int,
        default=1,
        help="copter circuits with the service feeding the autopilot's GPS 2; 0: none",
    )
    p.add_argument("--json", type=Path, help="also write the runner's results here")
    p.add_argument(
        "--px4-runs",
        type=int,
        default=1,
        help="PX4 SIH GNSS-cut flights with and without the service (bench/sitl_px4.py); 0: none",
    )
    args = p.parse_args(argv)
    reason = missing("arduplane")
    if reason:
        print(f"bench/sitl.py: {reason}", file=sys.stderr)
        return 2
    results: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(prefix="companion-bench-sitl-") as tmp:
        runs = {
            "plane circuit": [
                "flight",
                "--speedup",
                f"{args.speedup:g}",
                "--cruise-s",
                f"{args.cruise_s:g}",
                "--outage-s",
                f"{args.outage_s:g}",
                "--after-s",
                f"{args.after_s:g}",
                "--params",
                args.params,
            ],
            "copter circuit": [
                "flight",
                "--vehicle",
                "copter",
                "--speedup",
                f"{args.speedup:g}",
                "--cruise-s",
                f"{min(args.cruise_s, 120.0):g}",
                "--outage-s",
                f"{args.outage_s:g}",
                "--after-s",
                "20",
                "--hover-s",
                "30",
                "--outage-at-corner",
                "--params",
                args.params,
            ],
            "plane reboot": ["reboot", "--speedup", "1"],
        }
        for k in range(args.feed_runs):
            runs[f"plane circuit fed {k + 1}"] = [*runs["plane circuit"], "--feed"]
        for k in range(args.copter_feed_runs):
            runs[f"copter circuit fed {k + 1}"] = [*runs["copter circuit"], "--feed"]
        for name, run_args in runs.items():
            out = Path(tmp) / f"{name.replace(' ', '_')}.json"
            timeout_s = 120.0 + 3.0 * (args.cruise_s + args.outage_s + args.after_s + 120.0)
            results[name] = run_scenario(RUNNER, run_args, out, timeout_s=timeout_s)
    print(f"autopilot parameters {args.params}, speed-up {args.speedup:g}")
    print("horizontal error vs SITL truth, m: mean / p95 / max")
    for name in ("plane circuit", "copter circuit"):
        _print_flight(name, results[name])
    for name, n_runs in (
        ("plane circuit", args.feed_runs),
        ("copter circuit", args.copter_feed_runs),
    ):
        feds = [results[f"{name} fed {k + 1}"] for k in range(n_runs)]
        if feds:
            _print_fed(name, results[name], feds)
    for event in results["plane reboot"]["events"]:
        delay = event["resume_delay_s"]
        print(
            f"{event['kind']:8s}: publishing resumed "
            f"{'never' if delay is None else f'{delay:.1f} s'} after the autopilot was back"
        )
    if args.px4_runs > 0 and missing("px4/run-sih.sh", "px4/bin/px4") is None:
        from bench.sitl_px4 import print_px4, run_px4

        print()
        px4 = run_px4(args.px4_runs, 20.0, 10.0)
        print_px4(px4, 20.0)
        results["px4 gnss cut"] = px4  # type: ignore[assignment]
    if args.json:
        args.json.write_text(json.dumps(results, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""How real is the simulated autopilot? The same statistics on the real logs and on
simulated flights of the matching vehicle's ``realistic`` profile, side by side.

    PYTHONPATH=. python bench/realism.py [--seed 1] [--check]

Every statistic (``companion/sim/realism_stats.py``) is computed by the project's own
decoder from the .tlog: the real logs' converted .tlogs in
``../shared/realdata/flights`` (skipped, with the reason, where that folder is absent)
and the simulated flight written to a temporary .tlog. A statistic is *shown* by a real
log when it is not "—" there. Acceptance: the simulated value lies within the range of
the vehicle's real logs, or within a factor of 2 of the one real log that shows it (a
zero must be matched by a zero). Context rows (the flight's length, how much of it is
at rest, how many IMU messages the converter wrote) are printed but not judged: they
describe the flown script, not the autopilot. ``--check`` exits 1 if any judged
statistic is out of range.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from companion.sim import make_scenario, simulate
from companion.sim.realism import realistic
from companion.sim.realism_stats import LogStats, format_value, log_stats
from companion.sim.writer import write_tlog

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT.parent / "shared" / "realdata" / "flights"

GROUPS: dict[str, tuple[str, dict[str, float], tuple[str, ...]]] = {
    "copter": (
        "px4_rotorcraft", {},
        ("real_copter_dronekit_log171", "real_copter_erle_gps_issues1",
         "real_copter_erle_loiter_rtl"),
    ),
    "copter_radio": (
        "px4_rotorcraft", {"parked_s": 300.0}, ("real_gcs_copter_phoenix_mission1",)
    ),
    "plane": ("nominal", {}, ("real_plane_erle_2014-12-04",)),
    "px4": (
        "px4_rotorcraft", {},
        ("real_quad_px4_nogps_sample", "real_vtol_px4_ground_sample_log_small"),
    ),
}  # fmt: skip
"""vehicle -> (the simulated scenario flown with its realistic profile, its overrides (the
radio copter stands 300 s on each end: a ground station records long), the real logs)."""

CONTEXT = ("duration_s", "rest_fraction", "imu_units")

NOT_SHOWN = (
    (
        "RTK fixed/float",
        "no real log has RTK; magnitudes: El-Mowafy (2005), 1.6-2.2 cm 2-D "
        "fixed, 26-32 cm float (the simulator's GNSS_MODE_SPECS)",
    ),
    (
        "2D/3D flapping",
        "no real log flaps (0 per hour in every log); the switch exists "
        "(gnss_flap_per_h) and is off in every realistic profile",
    ),
    (
        "GNSS latency",
        "not measurable without truth; 0.2 s (ArduPilot) / 0.12 s (PX4) taken "
        "from the receivers' default lag the autopilots assume (ArduPilot GPS_DELAY_MS)",
    ),
    (
        "weather drift of the barometer",
        "the one baro log is too short to separate it from "
        "climb; 1 hPa/h, a typical synoptic pressure tendency",
    ),
    (
        "baro ground effect",
        "not separable in the one baro log; 0.1 hPa (~1 m) step within "
        "2 m of the ground with motors running, as ArduPilot's ground-effect compensation "
        "assumes",
    ),
    (
        "receiver accuracy vs scatter (ArduPilot)",
        "the ArduPilot logs of that era report no h_acc; only the PX4 log does",
    ),
)


def _sim_stats(
    vehicle: str, scenario: str, over: dict[str, float], seed: int, tmp: Path
) -> tuple[LogStats, float]:
    t = time.perf_counter()
    flight = simulate(make_scenario(scenario, **over, **realistic(vehicle)), seed)
    path = write_tlog(flight, tmp / f"sim_{vehicle}.tlog")
    return log_stats(f"sim {vehicle}", path), time.perf_counter() - t


def judge(real: list[float | None], sim: float | None) -> tuple[str, bool | None]:
    """(range text, within?) for one statistic; within is None when no real log shows it."""
    shown = [v for v in real if v is not None]
    if not shown:
        return "not shown", None
    if len(shown) == 1:
        lo, hi = shown[0] / 2.0, shown[0] * 2.0
        lo, hi = min(lo, hi), max(lo, hi)
    else:
        lo, hi = min(shown), max(shown)
    text = f"{format_value(lo)}..{format_value(hi)}"
    if sim is None:
        return text, False
    tol = 1e-9 + 1e-6 * max(abs(lo), abs(hi))
    return text, bool(lo - tol <= sim <= hi + tol)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--vehicle", action="append", choices=list(GROUPS), help="only these")
    ap.add_argument("--check", action="store_true", help="exit 1 if a statistic is out of range")
    args = ap.parse_args(argv)
    if not REAL.is_dir():
        print(f"real logs not found at {REAL}: nothing to compare against (skipped)")
        return 0
    bad_total = judged_total = 0
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        for vehicle, (scenario, over, logs) in GROUPS.items():
            if args.vehicle and vehicle not in args.vehicle:
                continue
            reals = []
            for name in logs:
                p = REAL / name / f"{name}.tlog"
                if p.is_file():
                    reals.append(log_stats(name.removeprefix("real_"), p))
                else:
                    print(f"{name}: missing, skipped")
            if not reals:
                continue
            sim, secs = _sim_stats(vehicle, scenario, over, args.seed, tmp)
            print(f"\n## {vehicle}: simulated '{scenario}' with realistic('{vehicle}'), "
                  f"seed {args.seed} ({secs:.1f} s)")  # fmt: skip
            head = ["statistic", *[r.name[:22] for r in reals], "real range", "sim", "ok"]
            widths = [26, *[23] * len(reals), 14, 10, 4]
            print("".join(h.ljust(w) for h, w in zip(head, widths, strict=True)))
            for key in reals[0].stats:
                vals = [r.stats.get(key) for r in reals]
                sv = sim.stats.get(key)
                if key in CONTEXT:
                    rng_text, ok_text = "context", ""
                else:
                    rng_text, ok = judge(vals, sv)
                    ok_text = "" if ok is None else ("yes" if ok else "NO")
                    if ok is not None:
                        judged_total += 1
                        bad_total += 0 if ok else 1
                cells = [key, *[format_value(v) for v in vals], rng_text, format_value(sv), ok_text]
                print("".join(c.ljust(w) for c, w in zip(cells, widths, strict=True)))
    print(f"\n{judged_total - bad_total} of {judged_total} statistics shown by a real log are "
          "within range (or a factor of 2 of the single log)")  # fmt: skip
    print("\nTraits no real log shows (the magnitude's source):")
    for trait, why in NOT_SHOWN:
        print(f"  {trait}: {why}")
    return 1 if (args.check and bad_total) else 0


if __name__ == "__main__":
    sys.exit(main())

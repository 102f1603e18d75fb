"""Position error through GNSS outages: the blend against the baselines and El-Mowafy's figures.

The published figures are those of El-Mowafy (2005), "RTK networks for precision
approach with an adaptive GPS/INS blend".

For each IMU grade (tactical, MEMS), flight (3 deg approach, cruise with
coordinated turns), outage length (10, 20, 40, 60 s) and seed, one flight is
simulated with :mod:`companion.sim`; every navigator is driven with the same
typed samples (fixes converted by :func:`companion.nav.gnss.gnss_measurement`),
the fixes inside the outage window are withheld, and the error of
``predict(t)`` against the truth is taken at 10 Hz through the gap.

Navigators (one run):
  blend-adapt-sd   adaptive blend, strapdown mechanisation
  blend-adapt-aa   adaptive blend, attitude-aided (autopilot ATTITUDE)
  blend-fixed-sd   non-adaptive blend, strapdown
  singer           Singer model without IMU (the baseline of "Tracking with the
                   aircraft's kinematic and dynamic parameters")
  cv               constant-velocity extrapolation (PassthroughNavigator)
  hold             holding the last fix (the failure mode of Grzegorzewski 2005)

Per cell: mean and max over seeds of the mean and max 2-D and height error
in the gap, and the time CAT III / CAT II were held (the first instant the
error exceeds the 95 % accuracy limit of El-Mowafy's table; the gap length if never),
mean and minimum over seeds. Also: microseconds per IMU sample and per fix of
the blend, against bare pymavlink parsing of the same flight's messages,
measured in the same run.

Realistic column: the same flights as an imperfect ArduPlane delivers them
(:func:`companion.sim.realism.realistic` ``"plane"``: RAW_IMU at 10 Hz with bias,
scale, misalignment, aliased engine vibration, ATTITUDE off by a trim tilt, GNSS 5 Hz
with 0.2 s latency and a velocity bias; the receiver stays RTK fixed before the gap),
with ``--realistic-seeds`` seeds (default 5) per cell; only IMU 0 is fed.

Run: ``python bench/outage.py`` (all 20 seeds; several minutes) or
``python bench/outage.py --seeds 3`` for a quick look. Progress goes to stderr.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from companion.integrity import CATEGORY_ACCURACY, ApproachCategory
from companion.nav.blend import BlendConfig, BlendNavigator
from companion.nav.frames import LocalFrame
from companion.nav.gnss import gnss_measurement
from companion.nav.motion import SingerNavigator
from companion.nav.navigator import GnssMeasurement, GnssUpdate, Navigator, NavState
from companion.nav.passthrough import PassthroughNavigator
from companion.sim import SimFlight, make_scenario, simulate
from companion.sim.realism import realistic as _realistic
from companion.types import AttitudeSample, FixType, FloatArray, GnssFix, ImuSample

EL_MOWAFY_2005_TABLE = {
    # outage s: (heli 2-D avg/max, heli H avg/max, plane 2-D avg/max, plane H avg/max), m
    20: ((2.64, 3.73), (0.35, 0.58), (2.14, 3.97), (0.31, 0.53)),
    40: ((4.16, 5.10), (0.92, 1.66), (3.65, 4.84), (0.83, 1.39)),
}


class HoldLastFix:
    """The receiver that keeps repeating its last fix (Grzegorzewski 2005's failure case):
    position frozen."""

    def __init__(self) -> None:
        self._last: GnssMeasurement | None = None

    @property
    def initialised(self) -> bool:
        return self._last is not None

    def on_imu(self, sample: ImuSample) -> None:
        """Unused."""

    def on_attitude(self, sample: AttitudeSample, yaw_correction_rad: float) -> None:
        """Unused."""

    def on_gnss(self, meas: GnssMeasurement, *, gate: bool = True) -> GnssUpdate:
        self._last = meas
        return GnssUpdate(meas.t_s, True, 0.0, 3, math.inf, np.zeros(3), np.eye(3))

    def predict(self, t_s: float) -> NavState | None:
        if self._last is None:
            return None
        z = np.zeros(3)
        return NavState(t_s, self._last.pos_ned_m, z, np.diag(self._last.pos_var_ned_m2), np.eye(3))

    def reset(self) -> None:
        self._last = None

    def shift_frame(self, old: LocalFrame, new: LocalFrame) -> None:
        """Not needed in the bench (one frame)."""


def navigators(grade: str, frame: LocalFrame) -> dict[str, Callable[[], Navigator]]:
    """Factories of the navigators compared, in table order."""
    return {
        "blend-adapt-sd": lambda: BlendNavigator(
            BlendConfig.for_grade(grade, mode="strapdown", adaptive=True), frame
        ),
        "blend-adapt-aa": lambda: BlendNavigator(
            BlendConfig.for_grade(grade, mode="attitude_aided", adaptive=True), frame
        ),
        "blend-fixed-sd": lambda: BlendNavigator(
            BlendConfig.for_grade(grade, mode="strapdown", adaptive=False), frame
        ),
        "singer": SingerNavigator,
        "cv": PassthroughNavigator,
        "hold": HoldLastFix,
    }


@dataclass
class RunResult:
    mean_2d: float
    max_2d: float
    mean_h: float
    max_h: float
    held_cat3_s: float
    held_cat2_s: float


@dataclass
class Timing:
    imu_s: float = 0.0
    imu_n: int = 0
    gnss_s: float = 0.0
    gnss_n: int = 0


@dataclass
class Cell:
    runs: list[RunResult] = field(default_factory=list)


def outage_start_s(flight: SimFlight, kind: str) -> float:
    """Where the gap goes: 40 s into the glide (approach, as the simulator's RTK-outage
    scenarios), or 70 s into the cruise (covering the end of a 180 deg turn, a straight
    and the next turn)."""
    phase = "descent" if kind == "approach" else "cruise"
    starts = [t0 for name, t0, _ in flight.phases if name == phase]
    if not starts:
        raise ValueError(f"flight has no {phase} phase")
    return starts[0] + (40.0 if kind == "approach" else 70.0)


def run_one(
    nav: Navigator,
    flight: SimFlight,
    t_gap0: float,
    gap_s: float,
    timing: Timing | None,
    eval_dt: float = 0.1,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Drive one navigator through the flight up to the end of the gap.

    Returns the time into the gap (s), the 2-D and the height error (m) at 10 Hz. The
    errors of a shorter gap starting at the same time are a prefix of these (the same
    samples reach the navigator), so one run serves every gap length.
    """
    t_gap1 = t_gap0 + gap_s
    frame = flight.frame
    truth = flight.truth
    t_in: list[float] = []
    e2d: list[float] = []
    eh: list[float] = []
    next_eval = t_gap0 + eval_dt
    perf = time.perf_counter
    for s in flight.samples:
        if isinstance(s, ImuSample):
            if s.imu_id != 0:
                continue
            if s.t_s > t_gap1:
                break
            if timing is not None:
                t0 = perf()
                nav.on_imu(s)
                timing.imu_s += perf() - t0
                timing.imu_n += 1
            else:
                nav.on_imu(s)
            if s.t_s >= next_eval and nav.initialised:
                next_eval += eval_dt
                st = nav.predict(s.t_s)
                if st is None:
                    continue
                err = st.pos_ned_m - truth.at(s.t_s).pos_ned_m
                t_in.append(s.t_s - t_gap0)
                e2d.append(math.hypot(err[0], err[1]))
                eh.append(abs(err[2]))
        elif isinstance(s, AttitudeSample):
            nav.on_attitude(s, 0.0)
        elif isinstance(s, GnssFix):
            if s.receiver_id != 0 or t_gap0 <= s.t_s < t_gap1 or s.fix_type < FixType.FIX_3D:
                continue  # (the engine's outage monitor drops no-fix reports likewise)
            meas = gnss_measurement(s, frame)
            if timing is not None and nav.initialised:
                t0 = perf()
                nav.on_gnss(meas)
                timing.gnss_s += perf() - t0
                timing.gnss_n += 1
            else:
                nav.on_gnss(meas)
    return np.array(t_in), np.array(e2d), np.array(eh)


def gap_result(t_in: FloatArray, e2d: FloatArray, eh: FloatArray, gap_s: float) -> RunResult:
    """Figures of a gap of ``gap_s`` from the error series of the longest gap."""
    cat3 = CATEGORY_ACCURACY[ApproachCategory.CAT_III]
    cat2 = CATEGORY_ACCURACY[ApproachCategory.CAT_II]
    sel = t_in <= gap_s + 1e-9
    if not np.any(sel):
        raise ValueError("no evaluation point in the gap")
    t, d2, dh = t_in[sel], e2d[sel], eh[sel]

    def held(h_lim: float, v_lim: float) -> float:
        bad = np.flatnonzero((d2 > h_lim) | (dh > v_lim))
        return float(t[bad[0]]) if bad.size else gap_s

    return RunResult(
        float(np.mean(d2)),
        float(np.max(d2)),
        float(np.mean(dh)),
        float(np.max(dh)),
        held(cat3.h95_m, cat3.v95_m),
        held(cat2.h95_m, cat2.v95_m),
    )


def pymavlink_parse_us(flight: SimFlight, limit: int = 20000) -> float:
    """Bare pymavlink: microseconds to parse one message of this flight (same run)."""
    packer = ardupilotmega.MAVLink(None, srcSystem=1, srcComponent=1)
    blobs = [bytes(m.pack(packer)) for _, m in flight.messages[:limit]]  # type: ignore[attr-defined]
    data = b"".join(blobs)
    best = math.inf
    for _ in range(3):
        parser = ardupilotmega.MAVLink(None)
        parser.robust_parsing = True
        t0 = time.perf_counter()
        msgs = parser.parse_buffer(data)
        dt = time.perf_counter() - t0
        if msgs is None or len(msgs) != len(blobs):
            raise ValueError("pymavlink did not parse back every message")
        best = min(best, dt)
    return best / len(blobs) * 1e6


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20, help="seeds per cell (default 20)")
    ap.add_argument("--outages", type=float, nargs="+", default=[10.0, 20.0, 40.0, 60.0])
    ap.add_argument("--grades", nargs="+", default=["tactical", "mems"])
    ap.add_argument("--flights", nargs="+", default=["approach", "cruise"])
    ap.add_argument(
        "--realistic-seeds", type=int, default=5, help="seeds per realistic cell (default 5)"
    )
    args = ap.parse_args(argv)
    if args.seeds < 1:
        ap.error("--seeds must be >= 1")

    cells: dict[tuple[str, str, float, str], Cell] = {}
    timing = Timing()
    parse_us: list[float] = []
    total = len(args.grades) * len(args.flights) * args.seeds
    done = 0
    t_start = time.perf_counter()
    for grade in args.grades:
        for kind in args.flights:
            for seed in range(args.seeds):
                flight = simulate_flight(kind, grade, seed, max(args.outages))
                t_gap0 = outage_start_s(flight, kind)
                _note_rates(kind, grade, flight)
                if len(parse_us) < 4:
                    parse_us.append(pymavlink_parse_us(flight))
                for name, make in navigators(grade, flight.frame).items():
                    timed = name == "blend-adapt-sd"
                    series = run_one(
                        make(), flight, t_gap0, max(args.outages), timing if timed else None
                    )
                    for gap in args.outages:
                        res = gap_result(*series, gap)
                        cells.setdefault((grade, kind, gap, name), Cell()).runs.append(res)
                done += 1
                el = time.perf_counter() - t_start
                print(
                    f"[{done}/{total}] {grade} {kind} seed {seed} done, "
                    f"{el:.0f} s elapsed, ~{el / done * (total - done):.0f} s left",
                    file=sys.stderr,
                    flush=True,
                )
    rcells: dict[tuple[str, str, float, str], Cell] = {}
    for grade in args.grades:
        for kind in args.flights:
            for seed in range(min(args.realistic_seeds, args.seeds)):
                flight = simulate_flight(kind, grade, seed, max(args.outages), realistic=True)
                t_gap0 = outage_start_s(flight, kind)
                for name, make in navigators(grade, flight.frame).items():
                    series = run_one(make(), flight, t_gap0, max(args.outages), None)
                    for gap in args.outages:
                        res = gap_result(*series, gap)
                        rcells.setdefault((grade, kind, gap, name), Cell()).runs.append(res)
                print(f"realistic {grade} {kind} seed {seed} done", file=sys.stderr, flush=True)
    print_tables(args, cells, timing, float(np.median(parse_us)), rcells)
    return 0


def simulate_flight(
    kind: str, grade: str, seed: int, max_gap_s: float, realistic: bool = False
) -> SimFlight:
    """A flight long enough for the longest gap (tactical: HIGHRES_IMU at 100 Hz; MEMS:
    RAW_IMU at 50 Hz with its mG / mrad/s quantisation), RTK fixed, no events.
    ``realistic``: as the realistic ArduPlane profile delivers it (RTK kept)."""
    imu = {"tactical": ("HIGHRES_IMU", 100.0), "mems": ("RAW_IMU", 50.0)}[grade]
    common: dict[str, object] = {
        "imu_grade": grade, "imu_message": imu[0], "imu_rate_hz": imu[1], "events": ()
    }  # fmt: skip
    if realistic:
        common.update({k: v for k, v in _realistic("plane").items() if k != "gnss_mode"})
    if kind == "approach":
        # 40 s before the gap from the script start (20 s level + 40 s into the glide)
        sc = make_scenario("approach", **common, duration_s=20.0 + 40.0 + max_gap_s + 2.0)
    elif kind == "cruise":
        sc = make_scenario(
            "cruise_gnss_loss", **common, gnss_mode="rtk_fixed", duration_s=70.0 + max_gap_s + 2.0
        )
    else:
        raise ValueError(f"unknown flight kind {kind!r}")
    return simulate(sc, seed)


def print_tables(
    args: argparse.Namespace,
    cells: dict[tuple[str, str, float, str], Cell],
    timing: Timing,
    parse_us: float,
    rcells: dict[tuple[str, str, float, str], Cell] | None = None,
) -> None:
    names = list(navigators("tactical", LocalFrame(0.0, 0.0, 0.0)))
    print(f"# GNSS outage bench: {args.seeds} seeds per cell, RTK fixed before the gap")
    print("# errors in m: mean over seeds of the per-run mean / max over seeds of the per-run max;")
    print("# CAT held: mean / min over seeds, s (El-Mowafy 95 % limits: CAT III 4.1 m H / 0.6 m V,")
    print("# CAT II 5.2 / 1.7); ratio = error / the same cell's cv (constant-velocity) error")
    if rcells:
        print(f"# realistic: the same with the realistic ArduPlane autopilot, "
              f"{args.realistic_seeds} seeds: 2-D mean, H mean, CAT III held mean/min")  # fmt: skip
    for grade in args.grades:
        for kind in args.flights:
            print()
            print(f"## {grade} IMU, {kind}")
            header = (
                f"{'gap s':>5} {'navigator':<15} {'2-D mean':>9} {'2-D max':>9} {'H mean':>8} "
                f"{'H max':>8} {'CAT III held':>13} {'CAT II held':>12} {'2-D/cv':>7}"
                + (f" | {'real. 2-D':>9} {'real. H':>8} {'real. CAT III':>13}" if rcells else "")
            )
            print(header)
            for gap in args.outages:
                cv = cells[(grade, kind, gap, "cv")].runs
                cv_mean = float(np.mean([r.mean_2d for r in cv]))
                for name in names:
                    runs = cells[(grade, kind, gap, name)].runs
                    m2 = float(np.mean([r.mean_2d for r in runs]))
                    x2 = float(np.max([r.max_2d for r in runs]))
                    mh = float(np.mean([r.mean_h for r in runs]))
                    xh = float(np.max([r.max_h for r in runs]))
                    c3 = [r.held_cat3_s for r in runs]
                    c2 = [r.held_cat2_s for r in runs]
                    print(
                        f"{gap:5.0f} {name:<15} {m2:9.3f} {x2:9.3f} {mh:8.3f} {xh:8.3f} "
                        f"{np.mean(c3):6.1f}/{np.min(c3):5.1f} "
                        f"{np.mean(c2):5.1f}/{np.min(c2):5.1f} "
                        f"{m2 / cv_mean:7.3g}" + _realistic_cells(rcells, (grade, kind, gap, name))
                    )
    print()
    print("## El-Mowafy (2005), tactical INS only, avg / max, m")
    print(f"{'gap s':>5} {'heli 2-D':>12} {'heli H':>12} {'plane 2-D':>12} {'plane H':>12}")
    for gap, row in EL_MOWAFY_2005_TABLE.items():
        cols = " ".join(f"{a:5.2f}/{b:5.2f}" for a, b in row)
        print(f"{gap:5d} {cols}")
    print("El-Mowafy (2005): CAT III held 25-31 s, CAT II up to 43 s.")
    print(
        "Targets (tactical): 20 s <= 1.0 m 2-D, <= 0.2 m H; 40 s <= 2.0 m, <= 0.5 m; "
        "CAT III >= 40 s."
    )
    print()
    imu_us = timing.imu_s / max(timing.imu_n, 1) * 1e6
    gnss_us = timing.gnss_s / max(timing.gnss_n, 1) * 1e6
    print("## cost of the blend (blend-adapt-sd), this machine, this run")
    print(f"bare pymavlink parse        {parse_us:8.2f} us/message (baseline)")
    print(f"blend on_imu                {imu_us:8.2f} us/IMU sample  ({timing.imu_n} samples)")
    print(f"blend on_gnss               {gnss_us:8.2f} us/fix        ({timing.gnss_n} fixes)")
    for name, rates in MESSAGE_RATES.items():
        parse_per_s = rates["all"] * parse_us
        blend_per_s = rates["imu"] * imu_us + rates["gnss"] * gnss_us
        print(
            f"{name}: per second of flight {rates['all']:.0f} messages parse in "
            f"{parse_per_s / 1e3:.2f} ms, the blend needs {blend_per_s / 1e3:.2f} ms "
            f"({rates['imu']:.0f} IMU + {rates['gnss']:.0f} fixes): parse + blend runs at "
            f"{parse_per_s / (parse_per_s + blend_per_s):.2f}x bare parsing throughput"
        )


def _realistic_cells(
    rcells: dict[tuple[str, str, float, str], Cell] | None, key: tuple[str, str, float, str]
) -> str:
    if not rcells or key not in rcells:
        return ""
    runs = rcells[key].runs
    c3 = [r.held_cat3_s for r in runs]
    return (
        f" | {np.mean([r.mean_2d for r in runs]):9.3f} {np.mean([r.mean_h for r in runs]):8.3f} "
        f"{np.mean(c3):7.1f}/{np.min(c3):5.1f}"
    )


MESSAGE_RATES: dict[str, dict[str, float]] = {}
"""Per flight kind: messages, IMU samples and fixes per second (filled while simulating)."""


def _note_rates(kind: str, grade: str, flight: SimFlight) -> None:
    key = f"{grade} {kind}"
    if key in MESSAGE_RATES:
        return
    span = flight.truth.t_s[-1] - flight.truth.t_s[0]
    n_imu = sum(1 for s in flight.samples if isinstance(s, ImuSample))
    n_gnss = sum(1 for s in flight.samples if isinstance(s, GnssFix) and s.receiver_id == 0)
    MESSAGE_RATES[key] = {
        "all": len(flight.messages) / span,
        "imu": n_imu / span,
        "gnss": n_gnss / span,
    }


if __name__ == "__main__":
    raise SystemExit(main())

"""Integrity monitor Monte Carlo: detection of steps, ramps and dithers; false alerts per hour.

Run: ``python bench/integrity.py`` (``--runs N`` per fault case, ``--hours H`` of
nominal flight; defaults 20 and 10). Progress goes to stderr; the table to stdout.

What runs (all seeded): synthetic 3 deg approaches (115 s, 70 m/s, from 440 m
to 15 m above the field) with a wandering velocity, two RTK-fixed receivers at
10 Hz with the simulator's Gauss-Markov error model
(:mod:`companion.sim.integrity_approaches`), CAT II required (VAL 5.4 m, HAL 17 m,
TTA 2 s / 1 s objective). The navigator (a constant-velocity Kalman filter)
fuses the primary receiver (the first not excluded); the second receiver is
the independent solution. A fault is injected on receiver 0 at a random time
20-45 s into the approach, in a random direction (steps at the alert limits
along the limit's axis). The same fixes go, in the same run, to

* **monitor**: :class:`companion.integrity.monitor.IntegrityMonitor` (FDE,
  separation with Kim, Walter and Powell's slope and residual tests, protection
  levels);
* **plain**: an innovation-only chi-square monitor on a navigator with the same
  fusion policy and no exclusion (alarm at each onset of NIS above
  chi2^-1(1 - P_fa, 3), the same P_fa).

A detection is the first FAULT or INTEGRITY-lost alert (plain: NIS onset) at or
after the fault start. A single-receiver section shows what is left without
the second receiver. The nominal hours are dual-receiver approaches without
faults: they exercise the fix-level tests, the separation snapshot, slope and
residual tests on the receiver pair, the phase logic (approach, landing) and
the protection levels against CAT II limits, but not the INS or take-off/taxi.
The end of the run replays the simulator's ramp_fault, dither_fault and
nominal flights (the paper's ramp and dither) through the monitor.

**With an inertial reference** (``--ins-runs N`` per case, default 3,
``--ins-hours H`` of nominal flight per row, default 0.5, ``--jobs J`` processes,
default 2; the defaults keep the whole bench near 15 min on 2 cores, each
simulated flight through the blend costs seconds): simulated approaches
(:mod:`companion.sim`, the "approach" scenario: 3 deg glide from 250 m at
33 m/s, flare, landing roll; RTK fixed at 10 Hz, IMU at 100 Hz), flown by the
GNSS/INS blend (:class:`companion.nav.blend.BlendNavigator`) with the inertial
coast (:class:`companion.integrity.coast.InertialCoast`, 6 slots over 30 s,
anchored from the blend with its accelerometer-bias estimate, not while a fault
is reported) giving references to the monitor
(:func:`companion.sim.integrity_runs.run_samples_ins`). The fault (same kinds
and sizes, plus vertical- and horizontal-only 4 cm/s ramps) is injected on
receiver 0 at a random time 40-80 s into the glide, in a random direction.
Rows: one receiver with a tactical IMU (beside the same flights without the
references: "no ref", the baseline), one receiver with a MEMS IMU, two
receivers with a tactical IMU (attribution: which receiver was excluded).

**With the barometer** (``--baro-runs N`` per case, default 20; ``--baro-hours H`` of
nominal flight, default 10; ``--baro-gap-runs N``, default 20): the same simulated
approaches, one RTK receiver, MEMS IMU, with a barometer as the realistic simulator
makes it (SCALED_PRESSURE at 10 Hz: 0.025 hPa white noise, about 0.2 m; 1 hPa/h
weather drift; a 0.1 hPa ground-effect step within 2 m of the ground), calibrated
against the fused fixes (:mod:`companion.nav.baro`) and given to the monitor as a
vertical-only independent solution; each flight runs through the current monitor
(the inertial references alone) and the monitor with the barometer. Cases: a 4 cm/s
vertical ramp (detected before it reaches 1 m?) and a 1 m vertical dither; nominal
hours of the same approaches without faults (alarms). Then a 20 s GNSS gap in the
glide, flown by the engine with and without ``engine.baro_in_blend``: the mean and max
height error through the gap and how often it is within the published 95 %.
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import companion.sim as sim  # noqa: E402
from companion.integrity.monitor import IntegrityConfig, IntegrityMonitor  # noqa: E402
from companion.integrity.protection.limits import CATEGORY_LIMITS, ApproachCategory  # noqa: E402
from companion.integrity.protection.phase import PhaseConfig  # noqa: E402
from companion.nav.navigator import NavState  # noqa: E402
from companion.sim.integrity_approaches import ApproachSpec, Fault, run_approach  # noqa: E402
from companion.sim.integrity_runs import run_samples  # noqa: E402
from companion.sim.realism import realistic  # noqa: E402

FIELD_M = 110.0
CAT = ApproachCategory.CAT_II
LIMIT = CATEGORY_LIMITS[CAT]


@dataclass(frozen=True)
class Case:
    """A fault case: kind, size (m, m/s or m amplitude) and how its direction is drawn."""

    label: str
    kind: str
    size: float
    axis: str  # "random", "vertical", "horizontal"
    at_limit: bool = False

    def fault(self, t_start_s: float, direction_ned: np.ndarray) -> Fault:
        """This case's fault on receiver 0 from ``t_start_s`` along a unit direction (a
        dither: ``size`` is its amplitude, 20 s period)."""
        if self.kind == "dither":
            return Fault(
                "dither", t_start_s, tuple(direction_ned), amplitude_m=self.size, period_s=20.0
            )
        return Fault(self.kind, t_start_s, tuple(direction_ned * self.size))


CASES = [
    Case("step 0.2 m", "step", 0.2, "random"),
    Case("step 1 m", "step", 1.0, "random"),
    Case(f"step VAL {LIMIT.val_m} m", "step", LIMIT.val_m, "vertical", True),
    Case("step 10 m", "step", 10.0, "random", True),
    Case(f"step HAL {LIMIT.hal_m:.0f} m", "step", LIMIT.hal_m, "horizontal", True),
    Case("ramp 1 cm/s", "ramp", 0.01, "random"),
    Case("ramp 2 cm/s", "ramp", 0.02, "random"),
    Case("ramp 4 cm/s", "ramp", 0.04, "random"),
    Case("ramp 10 cm/s", "ramp", 0.10, "random"),
    Case("dither 0.5 m", "dither", 0.5, "random"),
    Case("dither 1 m", "dither", 1.0, "random"),
    Case("dither 2 m", "dither", 2.0, "random"),
    Case("dither 5 m", "dither", 5.0, "random"),
]
SINGLE_CASES = [CASES[2], CASES[3], CASES[7], CASES[10]]


def config() -> IntegrityConfig:
    return IntegrityConfig(approach_category=CAT, phase=PhaseConfig(field_elevation_msl_m=FIELD_M))


def first_test_name(text: str) -> str:
    """Which test an alarm text names first (innovation, ellipsoid, snapshot, slope, ...)."""
    best, where = "integrity", len(text) + 1
    for key, name in (
        ("innovation", "innovation"),
        ("ellipsoid", "ellipsoid"),
        ("separation", "snapshot"),
        ("slope", "slope"),
        ("residual", "residual"),
    ):
        i = text.find(key)
        if 0 <= i < where:
            best, where = name, i
    return best


def direction(rng: np.random.Generator, axis: str) -> np.ndarray:
    if axis == "vertical":
        return np.array([0.0, 0.0, 1.0 if rng.random() < 0.5 else -1.0])
    v = rng.normal(size=3)
    if axis == "horizontal":
        v[2] = 0.0
    return v / np.linalg.norm(v)


@dataclass
class Tally:
    """Detections of one case by one monitor."""

    runs: int = 0
    detected: int = 0
    within_tta: int = 0
    within_objective: int = 0
    before_1m: int = 0
    delays: list[float] | None = None
    sizes: list[float] | None = None
    first_test: dict[str, int] | None = None

    def add(self, fault: Fault, t_det: float | None, text: str = "") -> None:
        self.runs += 1
        if text:
            if self.first_test is None:
                self.first_test = {}
            name = first_test_name(text)
            self.first_test[name] = self.first_test.get(name, 0) + 1
        if self.delays is None:
            self.delays, self.sizes = [], []
        if t_det is None:
            return
        assert self.sizes is not None
        delay = t_det - fault.t_start_s
        size = float(np.linalg.norm(fault.offset_ned_m(np.array([t_det]))[0]))
        self.detected += 1
        self.delays.append(delay)
        self.sizes.append(size)
        self.within_tta += delay <= LIMIT.time_to_alert_s
        self.within_objective += delay <= LIMIT.time_to_alert_objective_s
        self.before_1m += size < 1.0 or fault.kind != "ramp"

    def cells(self) -> list[str]:
        if not self.detected or not self.delays or not self.sizes:
            return [f"{0:>4d}/{self.runs:<3d}", "-", "-", "-", "-"]
        return [
            f"{self.detected:>4d}/{self.runs:<3d}",
            f"{np.median(self.delays):6.2f}",
            f"{max(self.delays):6.2f}",
            f"{np.median(self.sizes):6.2f}",
            f"{max(self.sizes):6.2f}",
        ]


def run_case(case: Case, runs: int, receivers: int, seed: int) -> tuple[Tally, Tally]:
    mine, plain = Tally(), Tally()
    monitor = IntegrityMonitor(config())
    rng = np.random.default_rng(seed)
    for _ in range(runs):
        t0 = float(rng.uniform(20.0, 45.0))
        fault = case.fault(t0, direction(rng, case.axis))
        spec = ApproachSpec(receivers=receivers, faults=(fault,))
        res = run_approach(spec, monitor, rng, t_from_s=t0)
        mine.add(fault, res.first_alert_s, res.first_alert_text)
        plain.add(fault, res.baseline_first_s)
    return mine, plain


def print_section(title: str, rows: list[tuple[Case, Tally, Tally]]) -> None:
    print(f"\n{title}")
    head = (
        f"{'case':<18} | {'monitor: det':>12} {'t med':>6} {'t max':>6} {'sz med':>6} "
        f"{'sz max':>6} | {'plain: det':>10} {'t med':>6} {'t max':>6} {'sz med':>6} "
        f"{'sz max':>6} | {'t plain/mon':>11}"
    )
    print(head + " | first test (monitor)")
    print("-" * (len(head) + 22))
    for case, mine, plain in rows:
        ratio = "-"
        if mine.delays and plain.delays:
            ratio = f"{np.median(plain.delays) / max(np.median(mine.delays), 1e-3):11.1f}"
        elif mine.delays and not plain.delays:
            ratio = "plain blind"
        m, p = mine.cells(), plain.cells()
        print(
            f"{case.label:<18} | {m[0]:>12} {m[1]:>6} {m[2]:>6} {m[3]:>6} {m[4]:>6} | "
            f"{p[0]:>10} {p[1]:>6} {p[2]:>6} {p[3]:>6} {p[4]:>6} | {ratio:>11} | "
            + " ".join(f"{k} {v}" for k, v in sorted((mine.first_test or {}).items()))
        )


def nominal(hours: float, seed: int) -> tuple[float, int, int, dict[str, int]]:
    monitor = IntegrityMonitor(config())
    rng = np.random.default_rng(seed)
    spec = ApproachSpec()
    total_h, mine, plain = 0.0, 0, 0
    stats: dict[str, int] = {}
    n = math.ceil(hours * 3600.0 / spec.duration_s)
    t_start = time.perf_counter()
    for i in range(n):
        res = run_approach(spec, monitor, rng, t_offset_s=i * (spec.duration_s + 1.0))
        total_h += res.hours
        mine += len(res.alerts)
        plain += len(res.baseline_alerts)
        if (i + 1) % 25 == 0 or i + 1 == n:
            el = time.perf_counter() - t_start
            print(f"nominal {i + 1}/{n} approaches, {total_h:.2f} h, {el:.0f} s", file=sys.stderr)
    stats = dict(monitor.stats)  # lifetime counters of the monitor (not reset per approach)
    return total_h, mine, plain, stats


def sim_flights() -> None:
    print("\nSimulator flights (seed 1), monitor on the typed samples, pass-through navigator")
    print("(real.: the same flight as the realistic ArduPlane autopilot delivers it)")
    print(
        f"{'flight':<14} {'fault':<32} {'first alarm':>12} {'delay s':>8} {'size m':>7} alarms"
        f" | {'real. alarm':>12} {'delay s':>8} {'size m':>7} alarms"
    )
    real_over = {k: v for k, v in realistic("plane").items() if k != "gnss_mode"}
    for name in ("ramp_fault", "dither_fault", "nominal"):
        print(f"flight {name}", file=sys.stderr)
        cells = []
        for over in ({}, real_over):
            flight = sim.simulate(sim.make_scenario(name, **over), seed=1)
            res = run_samples(flight.samples, IntegrityMonitor())
            faults = [e for e in flight.events if e.kind in ("step", "ramp", "dither")]
            cells.append(_sim_flight_cells(faults, res.alarms))
        desc, plain = cells[0]
        _, real = cells[1]
        print(f"{name:<14} {desc:<32} {plain} | {real}")


def _sim_flight_cells(
    faults: list[sim.Event], alarms: tuple[tuple[float, str, str], ...]
) -> tuple[str, str]:
    """(fault description, 'first alarm, delay, size, alarms' cells) of one flight."""
    if not faults:
        return "none", f"{'-':>12} {'-':>8} {'-':>7} {len(alarms)}"
    ev = faults[0]
    after = [a for a in alarms if a[0] >= ev.t_start_s]
    desc = f"{ev.kind} {dict(ev.params)}"[:32]
    if not after:
        return desc, f"{'missed':>12} {'':>8} {'':>7} {len(alarms)}"
    t_a = after[0][0]
    tau = t_a - ev.t_start_s
    if ev.kind == "ramp":
        size = tau * float(np.linalg.norm(ev.params["rate_ned_mps"]))
    else:
        size = abs(
            float(ev.params["amplitude_m"]) * math.sin(2 * math.pi * tau / ev.params["period_s"])
        )
    return desc, f"{after[0][1]:>12} {tau:8.2f} {size:7.2f} {len(alarms)}"


INS_CASES = [
    Case("step 0.2 m", "step", 0.2, "random"),
    Case("step 1 m", "step", 1.0, "random"),
    Case(f"step VAL {LIMIT.val_m} m", "step", LIMIT.val_m, "vertical", True),
    Case("step 10 m", "step", 10.0, "random", True),
    Case("ramp 1 cm/s", "ramp", 0.01, "random"),
    Case("ramp 2 cm/s", "ramp", 0.02, "random"),
    Case("ramp 4 cm/s", "ramp", 0.04, "random"),
    Case("ramp 4 cm/s vert", "ramp", 0.04, "vertical"),
    Case("ramp 4 cm/s horiz", "ramp", 0.04, "horizontal"),
    Case("ramp 10 cm/s", "ramp", 0.10, "random"),
    Case("dither 0.5 m", "dither", 0.5, "random"),
    Case("dither 1 m", "dither", 1.0, "random"),
    Case("dither 2 m", "dither", 2.0, "random"),
    Case("dither 5 m", "dither", 5.0, "random"),
]
INS_ROWS = (("tactical", 1), ("mems", 1), ("tactical", 2))
GLIDE_START_S = 30.0
"""The approach scenario's descent starts 30 s into the autopilot clock (10 s boot + 20 s)."""


@dataclass(frozen=True)
class InsOutcome:
    """One simulated flight through blend + coast + monitor (picklable for the pool)."""

    fault: Fault | None
    first_s: float | None
    text: str
    excluded: dict[int, float]
    early_alarms: int
    hours: float
    alarms: int
    base_first_s: float | None
    stats: dict[str, int]


def fault_events(
    case: Case | None, rng: np.random.Generator
) -> tuple[Fault | None, tuple[sim.Event, ...], float]:
    """The fault of ``case`` (None: none) started at a seeded time of the glide: the fault,
    the simulator's events that carry it, and its start time (0 without a fault)."""
    if case is None:
        return None, (), 0.0
    t0 = GLIDE_START_S + float(rng.uniform(40.0, 80.0))
    fault = case.fault(t0, direction(rng, case.axis))
    return fault, (fault.as_event(t0 + 1000.0),), t0


def ins_flight(
    case: Case | None, grade: str, receivers: int, seed: int, baseline: bool
) -> InsOutcome:
    """Simulate one approach with the fault of ``case`` (None: nominal) and run it."""
    from companion.integrity.coast import CoastConfig
    from companion.nav.blend import BlendConfig
    from companion.sim.integrity_runs import run_samples_ins

    logging.disable(logging.WARNING)
    fault, events, t0 = fault_events(case, np.random.default_rng(seed))
    scenario = sim.make_scenario(
        "approach", imu_grade=grade, events=events, second_receiver=receivers == 2
    )
    flight = sim.simulate(scenario, seed=seed)
    blend_cfg = BlendConfig.for_grade(grade)
    coast_cfg = CoastConfig.for_grade(grade)
    res = run_samples_ins(flight.samples, IntegrityMonitor(config()), blend_cfg, coast_cfg)
    after = [a for a in res.alarms if a[0] >= t0]
    base_first = None
    if baseline:
        base = run_samples_ins(
            flight.samples, IntegrityMonitor(config()), blend_cfg, coast_cfg, use_coast=False
        )
        base_first = next((a[0] for a in base.alarms if a[0] >= t0), None)
    hours = float(flight.truth.t_s[-1] - flight.truth.t_s[0]) / 3600.0
    return InsOutcome(
        fault,
        after[0][0] if after else None,
        after[0][2] if after else "",
        dict(res.excluded_first_s),
        len([a for a in res.alarms if a[0] < t0]),
        hours,
        len(res.alarms),
        base_first,
        dict(res.monitor.stats),
    )


def ins_sections(runs: int, hours: float, jobs: int, seed: int) -> None:
    """Fault cases and nominal hours through blend + coast + monitor; prints the tables."""
    approach_h = 228.0 / 3600.0
    n_nom = max(1, math.ceil(hours / approach_h))
    tasks: list[tuple[tuple[str, int], Case | None, int, bool]] = []
    for r, (grade, rx) in enumerate(INS_ROWS):
        for i, case in enumerate(INS_CASES):
            for k in range(runs):
                s = seed + 10_000 * (r + 1) + 100 * i + k
                tasks.append(((grade, rx), case, s, grade == "tactical" and rx == 1))
        for k in range(n_nom):
            tasks.append(((grade, rx), None, seed + 10_000 * (r + 1) + 9_000 + k, False))
    results: dict[tuple[str, int], list[tuple[Case | None, InsOutcome]]] = {
        row: [] for row in INS_ROWS
    }
    t_start = time.perf_counter()
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        futures = {
            pool.submit(ins_flight, case, row[0], row[1], s, base): (row, case)
            for row, case, s, base in tasks
        }
        for done, fut in enumerate(as_completed(futures), 1):
            row_key, fcase = futures[fut]
            results[row_key].append((fcase, fut.result()))
            if done % 10 == 0 or done == len(futures):
                el = time.perf_counter() - t_start
                print(f"ins flights {done}/{len(futures)}, {el:.0f} s", file=sys.stderr)
    for grade, rx in INS_ROWS:
        rows = []
        attribution: dict[str, str] = {}
        for case in INS_CASES:
            mine, base = Tally(), Tally()
            ex0 = ex1 = 0
            for c, out in results[(grade, rx)]:
                if c is not case or out.fault is None:
                    continue
                mine.add(out.fault, out.first_s, out.text)
                base.add(out.fault, out.base_first_s)
                ex0 += 0 in out.excluded
                ex1 += 1 in out.excluded
            rows.append((case, mine, base))
            attribution[case.label] = f"rx0 {ex0}, rx1 {ex1}"
        title = f"One RTK receiver + inertial reference, {grade} IMU (simulated approaches)"
        if rx == 2:
            title = f"Two RTK receivers + inertial reference, {grade} IMU (simulated approaches)"
        if grade == "tactical" and rx == 1:
            print_section(title + "; plain = the same flights without the reference", rows)
        else:
            print_section(title + "; plain column not run", rows)
        if rx == 2:
            print("  excluded by the end of the flight (runs): ", end="")
            print("; ".join(f"{k}: {v}" for k, v in attribution.items()))
        nom = [o for c, o in results[(grade, rx)] if c is None]
        h = sum(o.hours for o in nom)
        alarms = sum(o.alarms for o in nom)
        early = sum(o.early_alarms for c, o in results[(grade, rx)] if c is not None)
        fault_h = sum(
            (o.fault.t_start_s - 10.0) / 3600.0
            for c, o in results[(grade, rx)]
            if c is not None and o.fault is not None
        )
        stats: dict[str, int] = {}
        for o in nom:
            for counter, v in o.stats.items():
                stats[counter] = stats.get(counter, 0) + v
        print(
            f"  nominal: {len(nom)} flights, {h:.2f} h, alarms {alarms} ({alarms / h:.3f}/h); "
            f"before fault onset in the fault runs: {early} alarms in {fault_h:.2f} h"
        )
        print(f"  monitor counters (nominal): {stats}")


BARO_CASES = [
    Case("ramp 4 cm/s vert", "ramp", 0.04, "vertical"),
    Case("dither 1 m vert", "dither", 1.0, "vertical"),
]


def baro_realism() -> object:
    """The barometer of the realistic simulator, every other trait off."""
    from companion.sim.realism import Realism

    return Realism(
        baro_rate_hz=10.0,
        baro_noise_hpa=0.025,
        baro_drift_hpa_per_h=1.0,
        baro_ground_effect_hpa=0.1,
    )


@dataclass(frozen=True)
class BaroOutcome:
    """One simulated flight through the current monitor and the monitor with the barometer."""

    fault: Fault | None
    first_s: float | None
    text: str
    base_first_s: float | None
    alarms: int
    base_alarms: int
    early_alarms: int
    hours: float
    stats: dict[str, int]


def baro_flight(case: Case | None, seed: int) -> BaroOutcome:
    """One MEMS approach (one receiver, barometer) with the fault of ``case`` (None: none)."""
    from companion.integrity.coast import CoastConfig
    from companion.nav.blend import BlendConfig
    from companion.sim.integrity_runs import run_samples_ins

    logging.disable(logging.WARNING)
    fault, events, t0 = fault_events(case, np.random.default_rng(seed))
    scenario = sim.make_scenario(
        "approach", imu_grade="mems", events=events, realism=baro_realism()
    )
    flight = sim.simulate(scenario, seed=seed)
    blend_cfg = BlendConfig.for_grade("mems")
    coast_cfg = CoastConfig.for_grade("mems")
    runs = []
    for use_baro in (True, False):
        res = run_samples_ins(
            flight.samples, IntegrityMonitor(config()), blend_cfg, coast_cfg, use_baro=use_baro
        )
        runs.append(res)
    res, base = runs
    after = [a for a in res.alarms if a[0] >= t0]
    base_first = next((a[0] for a in base.alarms if a[0] >= t0), None)
    return BaroOutcome(
        fault,
        after[0][0] if after else None,
        after[0][2] if after else "",
        base_first,
        len(res.alarms),
        len(base.alarms),
        len([a for a in res.alarms if a[0] < t0]),
        float(flight.truth.t_s[-1] - flight.truth.t_s[0]) / 3600.0,
        dict(res.monitor.stats),
    )


@dataclass(frozen=True)
class GapOutcome:
    """Height error through a 20 s GNSS gap, without and with the barometer in the blend:
    (mean |error| m, max |error| m, fraction within the published 95 %)."""

    without: tuple[float, float, float]
    with_baro: tuple[float, float, float]


def baro_gap_flight(seed: int, gap_s: float = 20.0) -> GapOutcome:
    """One MEMS approach through the engine with a ``gap_s`` GNSS gap in the glide."""
    from companion.engine import Engine
    from companion.engine.config import EngineConfig
    from companion.types import GnssFix, NavSolution

    logging.disable(logging.WARNING)
    rng = np.random.default_rng(seed)
    flight = sim.simulate(
        sim.make_scenario("approach", imu_grade="mems", realism=baro_realism()), seed=seed
    )
    g0 = GLIDE_START_S + float(rng.uniform(40.0, 80.0))
    g1 = g0 + gap_s
    cells = []
    for use in (False, True):
        engine = Engine(EngineConfig(baro_in_blend=use))
        errs: list[tuple[float, float]] = []
        for s in flight.samples:
            if isinstance(s, GnssFix) and g0 <= s.t_s < g1:
                continue
            for out in engine.handle(s):
                if isinstance(out, NavSolution) and g0 <= out.t_s < g1:
                    truth = flight.truth.at(out.t_s)
                    alt = flight.frame.ned_to_lla(truth.pos_ned_m)[2]
                    errs.append((abs(out.alt_msl_m - alt), out.v_acc_m))
        e = np.array(errs)
        # 95 % of a normal error: 1.96 sigma
        cells.append((float(e[:, 0].mean()), float(e[:, 0].max()),
                      float(np.mean(e[:, 0] <= 1.96 * e[:, 1]))))  # fmt: skip
    return GapOutcome(cells[0], cells[1])


def baro_sections(runs: int, hours: float, gap_runs: int, jobs: int, seed: int) -> None:
    """The barometer's fault cases, nominal hours and GNSS gap; prints the tables."""
    approach_h = 228.0 / 3600.0
    n_nom = max(1, math.ceil(hours / approach_h)) if hours > 0 else 0
    tasks: list[tuple[Case | None, int]] = []
    for i, case in enumerate(BARO_CASES):
        tasks += [(case, seed + 50_000 + 100 * i + k) for k in range(runs)]
    tasks += [(None, seed + 59_000 + k) for k in range(n_nom)]
    results: list[tuple[Case | None, BaroOutcome]] = []
    gaps: list[GapOutcome] = []
    t_start = time.perf_counter()
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        futures = {pool.submit(baro_flight, case, s): case for case, s in tasks}
        gap_futures = [pool.submit(baro_gap_flight, seed + 70_000 + k) for k in range(gap_runs)]
        for done, fut in enumerate(as_completed(futures), 1):
            results.append((futures[fut], fut.result()))
            if done % 10 == 0 or done == len(futures):
                el = time.perf_counter() - t_start
                print(f"baro flights {done}/{len(futures)}, {el:.0f} s", file=sys.stderr)
        gaps = [f.result() for f in gap_futures]
    rows = []
    for case in BARO_CASES:
        mine, base = Tally(), Tally()
        for c, out in results:
            if c is case and out.fault is not None:
                mine.add(out.fault, out.first_s, out.text)
                base.add(out.fault, out.base_first_s)
        rows.append((case, mine, base))
    print_section(
        "One RTK receiver + barometer (10 Hz, 0.2 m noise, 1 hPa/h drift, ground effect) "
        "+ inertial reference, MEMS IMU; plain = the current monitor (inertial reference "
        "alone) on the same flights",
        rows,
    )
    for case, mine, base in rows:
        if case.kind == "ramp":
            print(
                f"  {case.label}: caught before 1 m: with barometer {mine.before_1m}/{mine.runs}, "
                f"current monitor {base.before_1m}/{base.runs}"
            )
    nom = [o for c, o in results if c is None]
    if nom:
        h = sum(o.hours for o in nom)
        alarms = sum(o.alarms for o in nom)
        base_alarms = sum(o.base_alarms for o in nom)
        stats: dict[str, int] = {}
        for o in nom:
            for k, v in o.stats.items():
                if k.startswith("baro") or k in ("fault_alerts", "unresolved"):
                    stats[k] = stats.get(k, 0) + v
        early = sum(o.early_alarms for c, o in results if c is not None)
        print(
            f"  nominal: {len(nom)} flights, {h:.2f} h: alarms with barometer {alarms} "
            f"({alarms / h:.3f}/h), current monitor {base_alarms} ({base_alarms / h:.3f}/h); "
            f"before fault onset in the fault runs (with barometer): {early}"
        )
        print(f"  monitor counters (nominal, with barometer): {stats}")
    if gaps:
        print(f"\n20 s GNSS gap in the glide, MEMS IMU, engine ({len(gaps)} seeded flights)")
        head = f"{'height error':<22} {'mean m':>13} {'max of means':>13} {'max m':>7}"
        print(f"{head} {'in 95 %':>8}")
        for label, cells in (
            ("without barometer", [g.without for g in gaps]),
            ("with barometer", [g.with_baro for g in gaps]),
        ):
            a = np.array(cells)
            print(
                f"{label:<22} {a[:, 0].mean():13.3f} {a[:, 0].max():13.3f} {a[:, 1].max():7.2f} "
                f"{100.0 * a[:, 2].mean():7.1f}%"
            )


def coast_timing() -> None:
    """Per-call cost of the inertial coast and of the monitor's separation with its
    references, on a simulated tactical approach's samples (best of 3 passes)."""
    from companion.integrity.coast import CoastConfig, InertialCoast
    from companion.nav import earth
    from companion.nav.navigator import GnssMeasurement
    from companion.types import AttitudeSample, GnssFix, ImuSample

    flight = sim.simulate(sim.make_scenario("approach", imu_grade="tactical"), seed=3)
    fr = flight.frame
    stream = [s for s in flight.samples if isinstance(s, ImuSample | AttitudeSample)]
    n_imu = sum(isinstance(s, ImuSample) for s in stream)
    fixes = [s for s in flight.samples if isinstance(s, GnssFix) and s.receiver_id == 0]
    cfg = CoastConfig.for_grade("tactical")
    g = earth.gravity_ned_mps2(fr.lat0_rad, fr.alt0_m)
    atts = [s for s in stream if isinstance(s, AttitudeSample)]
    best_imu = best_att = math.inf
    for _ in range(3):  # the whole stream, less the attitude samples alone
        c = InertialCoast(cfg, g)
        t = time.perf_counter()
        for s in stream:
            if isinstance(s, ImuSample):
                c.on_imu(s)
            else:
                c.on_attitude(s)
        whole = time.perf_counter() - t
        c = InertialCoast(cfg, g)
        t = time.perf_counter()
        for a in atts:
            c.on_attitude(a)
        att_only = time.perf_counter() - t
        best_imu = min(best_imu, (whole - att_only) / n_imu)
        best_att = min(best_att, att_only / len(atts))
    # a run with anchors from the truth (the cost does not depend on the values), the
    # references and fixes of the last 100 s kept for the monitor
    c = InertialCoast(cfg, g)
    t_end = flight.truth.t_s[-1]
    fix_iter = iter(f for f in fixes if f.t_s > t_end - 100.0)
    nxt = next(fix_iter, None)
    cases: list[tuple[GnssFix, GnssMeasurement, dict[str, NavState]]] = []
    nan3 = np.full(3, np.nan)
    ref_times: list[float] = []
    best_ref = math.inf
    for s in stream:
        if isinstance(s, AttitudeSample):
            c.on_attitude(s)
            continue
        c.on_imu(s)
        if c.anchor_due(s.t_s):
            tr = flight.truth.at(s.t_s)
            c.anchor(NavState(s.t_s, tr.pos_ned_m, tr.vel_ned_mps, np.eye(3) * 4e-4,
                              np.eye(3) * 1e-4))  # fmt: skip
        while nxt is not None and nxt.t_s <= s.t_s:
            t = time.perf_counter()
            refs = c.references(nxt.t_s)
            ref_times.append(time.perf_counter() - t)
            tr = flight.truth.at(nxt.t_s)
            meas = GnssMeasurement(nxt.t_s, tr.pos_ned_m, np.full(3, 9e-4), nan3, nan3,
                                   nxt.fix_type, 0)  # fmt: skip
            cases.append((nxt, meas, dict(refs)))
            nxt = next(fix_iter, None)
    best_ref = float(np.median(ref_times))
    n_slots = max(len(r) for _, _, r in cases)
    best_due = math.inf
    for _ in range(3):
        t = time.perf_counter()
        for f, _, _ in cases:
            c.anchor_due(f.t_s)
        best_due = min(best_due, (time.perf_counter() - t) / len(cases))
    per_fix = {}
    for label, with_refs in (("no references", False), (f"{n_slots} references", True)):
        best = math.inf
        for _ in range(3):
            mon = IntegrityMonitor(config())
            t = time.perf_counter()
            for f, meas, fix_refs in cases:
                mon.on_fix(f, meas, None, references=fix_refs if with_refs else None)
            best = min(best, (time.perf_counter() - t) / len(cases))
        per_fix[label] = best
        if with_refs and mon.stats["fault_fixes"]:
            print(f"  (timing run raised faults: {dict(mon.stats)})")
    print("\nPer-call cost (tactical approach, default CoastConfig; best of 3, references: median)")
    print(f"  InertialCoast.on_imu      {best_imu * 1e6:7.2f} us   (budget 5 us)")
    print(f"  InertialCoast.on_attitude {best_att * 1e6:7.2f} us")
    print(f"  InertialCoast.anchor_due  {best_due * 1e6:7.2f} us")
    print(f"  InertialCoast.references  {best_ref * 1e6:7.2f} us   (budget 40 us), {n_slots} slots")
    for label, v in per_fix.items():
        print(f"  IntegrityMonitor.on_fix   {v * 1e6:7.1f} us   ({label})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20, help="runs per fault case")
    parser.add_argument("--hours", type=float, default=10.0, help="nominal flight hours")
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--ins-runs", type=int, default=3, help="runs per case with the INS")
    parser.add_argument(
        "--ins-hours", type=float, default=0.5, help="nominal hours per INS row (3 rows)"
    )
    parser.add_argument("--jobs", type=int, default=2, help="processes for the INS flights")
    parser.add_argument("--skip-ins", action="store_true", help="only the synthetic sections")
    parser.add_argument("--baro-runs", type=int, default=20, help="runs per barometer case")
    parser.add_argument(
        "--baro-hours", type=float, default=10.0, help="nominal hours with the barometer"
    )
    parser.add_argument("--baro-gap-runs", type=int, default=20, help="20 s gap flights")
    parser.add_argument(
        "--only-baro", action="store_true", help="only the barometer sections (and timing)"
    )
    args = parser.parse_args()
    logging.basicConfig(level=logging.ERROR)  # the monitor logs every fault it sees
    t0 = time.perf_counter()
    if args.only_baro:
        baro_sections(args.baro_runs, args.baro_hours, args.baro_gap_runs, args.jobs, args.seed)
        print(f"\nwall time {time.perf_counter() - t0:.0f} s")
        return
    rows = []
    for i, case in enumerate(CASES):
        print(f"[{i + 1}/{len(CASES)}] {case.label} x {args.runs}", file=sys.stderr)
        mine, plain = run_case(case, args.runs, 2, args.seed + i)
        rows.append((case, mine, plain))
    single = []
    for i, case in enumerate(SINGLE_CASES):
        print(f"[single {i + 1}/{len(SINGLE_CASES)}] {case.label}", file=sys.stderr)
        mine, plain = run_case(case, args.runs, 1, args.seed + 100 + i)
        single.append((case, mine, plain))
    hours, fa_mine, fa_plain, stats = nominal(args.hours, args.seed + 1000)

    print(f"Integrity Monte Carlo (seed {args.seed}, {args.runs} runs per case)")
    print(
        f"required {LIMIT.name}: VAL {LIMIT.val_m} m, HAL {LIMIT.hal_m} m, "
        f"TTA {LIMIT.time_to_alert_s} s (objective {LIMIT.time_to_alert_objective_s} s); "
        "t = time from fault start to first alarm (s), sz = fault size then (m)"
    )
    print_section("Two RTK receivers (navigator fuses the primary)", rows)
    print_section("One RTK receiver", single)

    print("\nTargets")
    for label, section in (("2 rx", rows), ("1 rx", single)):
        for case, mine, _ in section:
            if case.at_limit:
                print(
                    f"  {case.label:<18} ({label}): missed {mine.runs - mine.detected}, "
                    f"within TTA {mine.within_tta}/{mine.runs}, "
                    f"within objective {mine.within_objective}/{mine.runs}"
                )
    for case, mine, _ in rows:
        if case.kind == "ramp":
            print(f"  {case.label:<18} (2 rx): caught before 1 m {mine.before_1m}/{mine.runs}")
    print(
        f"\nNominal: {hours:.2f} h of approaches; alarms: monitor {fa_mine} "
        f"({fa_mine / hours:.3f}/h), plain {fa_plain} ({fa_plain / hours:.3f}/h)"
    )
    print(f"  monitor counters: {stats}")
    sim_flights()
    if not args.skip_ins:
        ins_sections(args.ins_runs, args.ins_hours, args.jobs, args.seed)
        baro_sections(args.baro_runs, args.baro_hours, args.baro_gap_runs, args.jobs, args.seed)
    coast_timing()
    print(f"\nwall time {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()

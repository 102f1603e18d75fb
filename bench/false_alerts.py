"""False alerts per flight hour on nominal realistic flights, beside the integrity bench's
detection times (no detection may get slower).

Run: ``python bench/false_alerts.py`` (``--hours H`` of nominal flight, default 10;
``--jobs J`` processes, default 2; ``--list N`` false alerts listed, default 60;
``--write-baseline`` records this run's detection times in
``bench/false_alerts_baseline.json``). Progress goes to stderr; the tables to stdout,
the command line and the code version at the top. Exit status 1 when a detection is
slower than the baseline's.

**Nominal flights.** Seeded simulated flights (:mod:`companion.sim`) as the realistic
profiles deliver them (:mod:`companion.sim.realism`, docs/simulator.md), replayed through
the whole service (:func:`companion.replay.replay`: decoder, engine, encoder), one
profile per combination of

* the autopilot: ``copter`` (ArduCopter on a serial port), ``copter_radio`` (the same
  through a telemetry radio), ``plane`` (ArduPlane), ``px4`` (PX4; rotorcraft and
  fixed-wing flights in turn);
* the IMU: ``mems`` (the simulator's MEMS grade with the profile's IMU errors; the
  service's default configuration) or ``tact`` (the tactical grade; the profile's IMU
  unit errors, which are those of the autopilots' own MEMS units measured on the real
  logs, are left out, the airframe's vibration and everything else kept; the service
  configured with the tactical preset, ``--grade tactical``);
* the receiver: RTK fixed or a 3-D fix;
* the raw link: none, or a simulated raw receiver (:mod:`companion.sim.raw_receiver`:
  the same flight's receiver on the companion's ``[raw]`` port, its carrier phase from
  the real broadcast ephemerides of the bundled walk cut
  ``tests/data/walk_0827/gnss_1730_cut.ubx``, so every flight is flown at that site,
  with and without the raw receiver alike).

A rotorcraft flight is ``px4_rotorcraft``'s script (take-off, hover turn, cruise with
turns, landing; its 20 s of 3-D fix in the cruise kept), a fixed-wing flight
``nominal``'s (stand, taxi, take-off, climb, cruise with turns, approach, landing),
each with its cruise length, speed, height, bank, turns, parking time, heading and (fixed
wing) wind drawn from the flight's seed. Flights of a profile are added until its share
of ``--hours`` is flown; the flight with and without the raw receiver is the same
(seed, path, every error). The profiles' own windows are real events of the flight:
dropouts of every stream, an autopilot reboot (radio), GNSS gaps, no-fix periods
(garbage coordinates on the copter), the 3-D stretch (an RTK loss with RTK). No
position fault, spoofing or jamming is injected.

**What counts.** Every alert the service raised (:attr:`ReplaySummary.alert_log`:
before the STATUSTEXT rate limit), at its log time less the flight's boot epoch (the
first boot's clock, which the simulator's windows use). An alert for something the
flight really had is real; every other is false:

* ``FAULT``, ``SPOOF``, ``JAM``: false (no position fault, spoofing or jamming is
  injected), except within 1.5 s after a fix whose true error its own reported
  accuracy does not cover (beyond ``chi2.isf(1e-3, 3)`` of ``(e_n/h_acc)^2 +
  (e_e/h_acc)^2 + (e_d/v_acc)^2``: the realistic receiver's accuracies are not exact
  sigmas, and one reporting 0.9 m with 3.7 m of error is caught, rightly);
* ``INTEGRITY`` (a loss; its restoration is a return and not counted): real within
  [start - 0.5 s, end + 5 s] of a window where the receiver gives nothing usable (an
  outage of any cause: the receiver, every stream, the reboot; a no-fix period), or
  when every limit it names is exceeded by the receiver's own protection level too
  (its latest delivered fix's h_acc, v_acc times the monitor's K factors: a receiver
  whose own accuracy cannot support the required category), false otherwise;
* ``GNSS_LOST``: real within such a window or after a misreported fix (as ``FAULT``),
  false elsewhere; counted apart (``LOST
  burst``) when it falls within a burst of the link (every message held up to 1.5 s and
  delivered at the end: none is lost, the receiver is fine); ``GNSS_STALE``: real only in
  a stale window (none in these flights). The margins are ``companion evaluate``'s
  (``companion.evaluate.score``), a burst's 0.5 s either side;
* ``RAW_FAULT``: counted as real. The simulated receiver's carrier phase carries the
  ionospheric drift ``companion.raw.simulate`` injects (2 mm/s per satellite, 1-sigma);
  a single-frequency T-D PRP run of up to 10 min integrates it, and FIS-RAIM's slope
  test sees it as the ramp it is (with the drift set to zero the flights that had
  RAW_FAULT have none);
* ``IMU_GRADE``: counted as real. With the MEMS preset the check is off; with the
  tactical preset it compares the IMU's white noise and innovations with the tactical
  grade, and the airframe vibration the profile keeps is far above a tactical unit's
  noise (docs/simulator.md): the IMU delivered is not of the grade configured.

**Detection times** (the same run; bench/integrity.py's own cases, imported):
synthetic dual- and single-receiver approaches (``--det-runs`` per case, default 20,
seeds as ``bench/integrity.py --seed 2026``), simulated approaches with the inertial
references (``--ins-runs`` per case and row, default 3), the simulator's ramp_fault and
dither_fault flights through the monitor (plain and realistic), and the committed
fixtures ``ramp_fault`` and ``dither_fault`` replayed through the whole service (default
and tactical presets). Per case: detections and their times from the fault's start.
``bench/false_alerts_baseline.json`` holds the same figures of the code before the
false-alert fixes; each case is compared with it: at least as many detections, and the
k-th fastest detection no later than the baseline's k-th fastest (median and maximum
included), or the case is marked SLOWER.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import math
import re
import shlex
import subprocess
import sys
import tempfile
import time
from collections import Counter
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import chi2

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import companion  # noqa: E402
import companion.sim as sim  # noqa: E402
from bench import integrity as ib  # noqa: E402
from companion.sim.realism import Realism, realistic  # noqa: E402

WALK_UBX = ROOT / "tests" / "data" / "walk_0827" / "gnss_1730_cut.ubx"
BASELINE = Path(__file__).with_name("false_alerts_baseline.json")
VEHICLES = ("copter", "copter_radio", "plane", "px4")
GRADES = ("mems", "tact")
ALWAYS_FALSE = ("FAULT", "SPOOF", "JAM")
COLUMNS = (
    "FAULT",
    "INTEGRITY",
    "SPOOF",
    "JAM",
    "GNSS_STALE",
    "GNSS_LOST",
    "IMU_GRADE",
    "RAW_FAULT",
)
EARLY_S = 0.5
"""An alert this long before a window still belongs to it (companion.evaluate.score)."""
LATE_S = 5.0
"""...and this long after it ends."""
IMU_UNIT_FIELDS = (
    "acc_bias_mps2", "acc_scale_sigma", "misalign_sigma_rad", "gyro_bias_radps",
    "gyro_rw_radps_rts", "temp_rise_c", "acc_temp_mps2_per_c", "gyro_temp_radps_per_c",
    "acc_noise_mps2", "gyro_noise_radps",
)  # fmt: skip
"""The realism's errors of the IMU unit itself (a MEMS autopilot unit's): zero for a
tactical unit, whose own errors are the simulator's tactical grade."""


# --------------------------------------------------------------------------- profiles


@dataclass(frozen=True)
class Profile:
    vehicle: str
    grade: str  # "mems" or "tact"
    rtk: bool
    raw: bool

    @property
    def label(self) -> str:
        return (
            f"{self.vehicle:<12} {self.grade:<4} {'rtk' if self.rtk else '3d ':<3} "
            f"{'raw' if self.raw else '-':<3}"
        )


PROFILES = [
    Profile(v, g, rtk, raw)
    for v in VEHICLES
    for g in GRADES
    for rtk in (False, True)
    for raw in (False, True)
]


@dataclass(frozen=True)
class FlightTask:
    profile: Profile
    index: int
    seed: int
    base: str
    overrides: dict[str, Any]
    tow_boot_s: float
    duration_s: float


def _draw_turns(rng: np.random.Generator) -> tuple[float, ...]:
    n = int(rng.integers(1, 5))
    return tuple(float(rng.choice([90.0, -90.0, 135.0, -135.0, 180.0, -180.0])) for _ in range(n))


def _geometry(rng: np.random.Generator, rotor: bool) -> dict[str, Any]:
    """The flight's path, drawn from its seed."""
    if rotor:
        return {
            "cruise_s": float(rng.uniform(100.0, 500.0)),
            "cruise_speed_mps": float(rng.uniform(6.0, 15.0)),
            "cruise_alt_m": float(rng.uniform(25.0, 80.0)),
            "bank_deg": float(rng.uniform(10.0, 25.0)),
            "parked_s": float(rng.uniform(15.0, 60.0)),
            "stand_heading_deg": float(rng.uniform(0.0, 360.0)),
            "cruise_turns_deg": _draw_turns(rng),
        }
    speed = float(rng.uniform(28.0, 50.0))
    wind = float(rng.uniform(0.0, 8.0))
    wdir = float(rng.uniform(0.0, 2.0 * math.pi))
    return {
        "cruise_s": float(rng.uniform(150.0, 500.0)),
        "cruise_speed_mps": speed,
        "cruise_alt_m": float(rng.uniform(150.0, 450.0)),
        "approach_speed_mps": float(rng.uniform(25.0, min(35.0, speed))),
        "bank_deg": float(rng.uniform(10.0, 30.0)),
        "parked_s": float(rng.uniform(20.0, 120.0)),
        "stand_heading_deg": float(rng.uniform(0.0, 360.0)),
        "cruise_turns_deg": _draw_turns(rng),
        "wind_ned_mps": (wind * math.cos(wdir), wind * math.sin(wdir), 0.0),
    }


def _realism_overrides(p: Profile) -> dict[str, Any]:
    """The profile's realism, receiver mode and IMU grade (its autopilot's flavour too)."""
    over = dict(realistic(p.vehicle))
    over["gnss_mode"] = "rtk_fixed" if p.rtk else "3d"
    rl: Realism = over["realism"]
    if p.grade == "tact":
        unit: dict[str, Any] = {f: 0.0 for f in IMU_UNIT_FIELDS}
        over["realism"] = dataclasses.replace(rl, **unit)
        over["imu_grade"] = "tactical"
    else:
        over["imu_grade"] = "mems"
    return over


def plan(hours: float, seed: int, site: Any) -> list[FlightTask]:
    """The flights of every profile: drawn until each has its share of ``hours``."""
    from companion.sim.raw_receiver import site_overrides

    share_s = hours * 3600.0 / len(PROFILES)
    tasks: list[FlightTask] = []
    for vi, vehicle in enumerate(VEHICLES):
        for gi, grade in enumerate(GRADES):
            for ri, rtk in enumerate((False, True)):
                group = (vi * 2 + gi) * 2 + ri
                flown, k = 0.0, 0
                flights: list[tuple[int, int, str, dict[str, Any], float, float]] = []
                while flown < share_s:
                    s = seed * 100_000 + group * 1000 + k
                    rng = np.random.default_rng(s)
                    rotor = vehicle in ("copter", "copter_radio") or (
                        vehicle == "px4" and k % 2 == 0
                    )
                    base = "px4_rotorcraft" if rotor else "nominal"
                    geo = _geometry(rng, rotor)
                    p0 = Profile(vehicle, grade, rtk, False)
                    over = {**geo, **_realism_overrides(p0)}
                    sc = sim.make_scenario(base, **over)
                    dur = float(sc.duration_s or 0.0)
                    first, last = site.tow_first_s, site.tow_last_s - dur - sc.t_boot0_s - 5.0
                    tow_boot = float(rng.uniform(first, last))
                    over.update(site_overrides(site, tow_boot))
                    flights.append((k, s, base, over, tow_boot, dur))
                    flown += dur
                    k += 1
                for raw in (False, True):
                    p = Profile(vehicle, grade, rtk, raw)
                    tasks += [FlightTask(p, k, s, b, o, tb, d) for k, s, b, o, tb, d in flights]
    return tasks


# --------------------------------------------------------------------------- one flight


@dataclass
class FlightOutcome:
    task: FlightTask
    hours: float
    counts: Counter[str]
    """'<CODE> <verdict>' (verdict: false, real, burst) of every counted alert."""
    alerts: list[tuple[float, str, str, str]]
    """(first-boot time s, code, text, verdict) of the counted alerts."""
    all_codes: Counter[str]
    raw_solutions: int = 0
    raw_tested: int = 0
    wall_s: float = 0.0


@dataclass
class Windows:
    """What the flight really had, on the first boot's clock (s)."""

    loss: list[tuple[float, float]]
    """The receiver gives nothing usable: an outage of any cause (the receiver, every
    stream, the reboot), a no-fix period."""
    stale: list[tuple[float, float]]
    burst: list[tuple[float, float]]
    """The link holds every message and delivers them together at the end (none lost)."""
    fix_t_s: np.ndarray
    """Receiver 0's 3-D fixes as delivered: time of validity, h_acc, v_acc (m)."""
    fix_h_acc_m: np.ndarray
    fix_v_acc_m: np.ndarray
    misreport_t_s: np.ndarray
    """Times of the delivered fixes whose true error its reported accuracy does not cover:
    ``(e_n / h_acc)^2 + (e_e / h_acc)^2 + (e_d / v_acc)^2`` beyond ``chi2.isf(MISREPORT_P,
    3)`` (the realistic receiver's accuracies are not exact sigmas)."""

    def misreported(self, t_s: float) -> bool:
        """A fix delivered within :data:`MISREPORT_BEFORE_S` before ``t_s`` was misreported."""
        m = self.misreport_t_s
        i = int(np.searchsorted(m, t_s - MISREPORT_BEFORE_S))
        return i < len(m) and m[i] <= t_s


MISREPORT_P = 1e-3
"""A fix is misreported when its true error lies beyond this tail of its own accuracy."""
MISREPORT_BEFORE_S = 1.5
"""An alert is about the receiver's fixes of the last this long (its loss timeout, 1 s,
and the fix's delivery)."""


def windows(flight: Any) -> Windows:
    loss, stale = [], []
    for e in flight.events:
        if e.receiver_id != 0:
            continue
        if e.kind == "outage" or (e.kind == "downgrade" and e.params.get("mode") == "none"):
            loss.append((e.t_start_s, e.t_end_s))
        elif e.kind == "stale":
            stale.append((e.t_start_s, e.t_end_s))
    rz = flight.errors.realism
    burst = list(rz.bursts) if rz is not None else []
    from companion.sim.raw_receiver import delivered_fixes

    t, h, v = delivered_fixes(flight)
    truth = flight.errors.gnss[0]
    idx = np.clip(np.searchsorted(truth.t_fix_s, t - 1e-4), 0, max(len(truth.t_fix_s) - 1, 0))
    err = truth.pos_err_ned_m[idx] + truth.fault_ned_m[idx] if len(t) else np.zeros((0, 3))
    d2 = (err[:, 0] / h) ** 2 + (err[:, 1] / h) ** 2 + (err[:, 2] / v) ** 2
    bad = np.abs(truth.t_fix_s[idx] - t) < 1e-3 if len(t) else np.zeros(0, bool)
    misreport = t[bad & (d2 > float(chi2.isf(MISREPORT_P, 3)))]
    return Windows(loss, stale, burst, t, h, v, misreport)


def _inside(t: float, wins: list[tuple[float, float]], early: float, late: float) -> bool:
    return any(a - early <= t <= b + late for a, b in wins)


_LIMIT_RE = re.compile(r"([HV])PL ([0-9.]+) m > [HV]AL ([0-9.]+) m")


def receiver_pl(t_s: float, w: Windows) -> tuple[float, float] | None:
    """The receiver's own protection levels (HPL, VPL, m) at its latest delivered fix at or
    before ``t_s``: its reported h_acc and v_acc as the covariance, the monitor's K
    factors (None before its first fix)."""
    from companion.integrity.config import IntegrityConfig
    from companion.integrity.protection.levels import k_horizontal, k_vertical

    i = int(np.searchsorted(w.fix_t_s, t_s, side="right")) - 1
    if i < 0:
        return None
    cfg = IntegrityConfig()
    return (
        k_horizontal(cfg.integrity_risk_horizontal) * float(w.fix_h_acc_m[i]),
        k_vertical(cfg.integrity_risk_vertical) * float(w.fix_v_acc_m[i]),
    )


def _receiver_over_limit(text: str, t_s: float, w: Windows) -> bool:
    """Does the receiver's own protection level (:func:`receiver_pl`) exceed every limit
    the INTEGRITY loss names (and is that all it names)? Then the receiver cannot support
    the required category: the loss is real."""
    problems = text.split(": ", 1)[1].split("; ") if ": " in text else []
    own = receiver_pl(t_s, w)
    if not problems or own is None:
        return False
    for problem in problems:
        m = _LIMIT_RE.fullmatch(problem.strip())
        if m is None:  # navigation lost or initialising, an unresolved fault: not the receiver's
            return False
        if not (own[0] if m.group(1) == "H" else own[1]) > float(m.group(3)):
            return False
    return True


def classify(code: str, text: str, t_s: float, w: Windows) -> str | None:
    """'false', 'real', 'burst' or None (not counted), by the module docstring's rules."""
    if code in ALWAYS_FALSE:
        return "real" if w.misreported(t_s) else "false"
    if code == "INTEGRITY":
        if not text.startswith("lost"):
            return None
        if _inside(t_s, w.loss, EARLY_S, LATE_S) or _receiver_over_limit(text, t_s, w):
            return "real"
        return "false"
    if code == "GNSS_LOST":
        if _inside(t_s, w.loss, EARLY_S, LATE_S) or w.misreported(t_s):
            return "real"
        return "burst" if _inside(t_s, w.burst, EARLY_S, EARLY_S) else "false"
    if code == "GNSS_STALE":
        return "real" if _inside(t_s, w.stale, EARLY_S, LATE_S) else "false"
    if code in ("IMU_GRADE", "RAW_FAULT"):
        return "real"
    return None


_RAW_CACHE: dict[str, Any] = {}


def _raw_setup() -> tuple[Any, list[Any], dict[Any, Any]]:
    """(site, navigation words, ephemerides) of the bundled walk cut (once per process)."""
    if "site" not in _RAW_CACHE:
        from companion.raw.broadcast import collect_ephemerides
        from companion.sim.raw_receiver import site_of
        from companion.ubx.reader import read_file

        epochs, words, pvts, _ = read_file(str(WALK_UBX))
        ephs, _ = collect_ephemerides(words)
        _RAW_CACHE["site"] = site_of(pvts[0], epochs[0].week, ephs)
        _RAW_CACHE["words"] = words
        _RAW_CACHE["ephs"] = ephs
    return _RAW_CACHE["site"], _RAW_CACHE["words"], _RAW_CACHE["ephs"]


def run_flight(task: FlightTask, keep: str = "") -> FlightOutcome:
    """Simulate, replay through the service (with the raw receiver when the profile has
    one) and classify every alert; with ``keep`` (a folder) the flight's files (tlog,
    truth, sidecar) and the replay's output are written to ``keep/<profile>_<seed>/``."""
    from companion.config import Config
    from companion.presets import grade_config
    from companion.replay import replay
    from companion.sim.raw_receiver import raw_receiver_items
    from companion.sim.writer import write_tlog

    logging.disable(logging.WARNING)
    wall0 = time.perf_counter()
    p = task.profile
    sc = sim.make_scenario(task.base, **task.overrides)
    flight = sim.simulate(sc, task.seed)
    cfg = grade_config("tactical") if p.grade == "tact" else Config()
    raw = None
    if p.raw:
        site, words, ephs = _raw_setup()
        rng = np.random.default_rng([task.seed, 7])
        raw = raw_receiver_items(flight, site, task.tow_boot_s, words, ephs, rng)
        cfg = dataclasses.replace(cfg, raw=dataclasses.replace(cfg.raw, file="(replay)"))
    if keep:
        from companion.sim.writer import write_flight

        folder = Path(keep) / f"{'_'.join(task.profile.label.split())}_{task.seed}"
        tlog = write_flight(flight, folder)[0]
        summary = replay(tlog, folder / "out.tlog", cfg, raw=raw)
    else:
        with tempfile.TemporaryDirectory(prefix="false_alerts_") as tmp:
            tlog = write_tlog(flight, Path(tmp) / "in.tlog")
            summary = replay(tlog, Path(tmp) / "out.tlog", cfg, raw=raw)
    w = windows(flight)
    counts: Counter[str] = Counter()
    alerts = []
    all_codes: Counter[str] = Counter()
    for t_rx, alert in summary.alert_log:
        code = alert.code.value
        all_codes[code] += 1
        t_s = t_rx - sc.epoch0_s
        verdict = classify(code, alert.text, t_s, w)
        if verdict is None:
            continue
        counts[f"{code} {verdict}"] += 1
        text = alert.text
        own = receiver_pl(t_s, w) if code == "INTEGRITY" else None
        if own is not None:
            text += f" [receiver's own HPL {own[0]:.1f} m VPL {own[1]:.1f} m]"
        alerts.append((t_s, code, text, verdict))
    hours = float(flight.truth.t_s[-1] - flight.truth.t_s[0]) / 3600.0
    return FlightOutcome(
        task,
        hours,
        counts,
        alerts,
        all_codes,
        summary.raw_solutions,
        summary.integrity_stats.get("raw_reference_tested", 0),
        time.perf_counter() - wall0,
    )


# --------------------------------------------------------------------------- detection


@dataclass
class Detection:
    """One case's detections: runs, and the sorted delays (s) of the detected ones."""

    section: str
    label: str
    runs: int
    delays: list[float] = field(default_factory=list)
    order: int = 0
    """The case's place in its section (bench/integrity.py's list)."""

    def cells(self) -> str:
        if not self.delays:
            return f"{0:>3d}/{self.runs:<3d} {'-':>6} {'-':>6}"
        return (
            f"{len(self.delays):>3d}/{self.runs:<3d} {np.median(self.delays):6.2f} "
            f"{max(self.delays):6.2f}"
        )


def det_synthetic(section: str, index: int, runs: int, seed: int) -> Detection:
    """bench/integrity.py's synthetic case (two receivers: CASES, one: SINGLE_CASES)."""
    logging.disable(logging.WARNING)
    if section == "synthetic 2 rx":
        case, receivers, s = ib.CASES[index], 2, seed + index
    else:
        case, receivers, s = ib.SINGLE_CASES[index], 1, seed + 100 + index
    mine, _ = ib.run_case(case, runs, receivers, s)
    return Detection(section, case.label, runs, sorted(mine.delays or []), index)


def det_ins(row: int, index: int, runs: int, seed: int) -> Detection:
    """bench/integrity.py's simulated approaches with the inertial references (its seeds)."""
    grade, rx = ib.INS_ROWS[row]
    case = ib.INS_CASES[index]
    delays = []
    for k in range(runs):
        s = seed + 10_000 * (row + 1) + 100 * index + k
        out = ib.ins_flight(case, grade, rx, s, False)
        if out.first_s is not None and out.fault is not None:
            delays.append(out.first_s - out.fault.t_start_s)
    return Detection(f"INS {grade} {rx} rx", case.label, runs, sorted(delays), index)


def det_sim_flight(name: str, real: bool) -> Detection:
    """The simulator's fault flight (seed 1) through the monitor, as bench/integrity.py's
    simulator-flights section runs it."""
    from companion.integrity.monitor import IntegrityMonitor
    from companion.sim.integrity_runs import run_samples

    logging.disable(logging.WARNING)
    over = {k: v for k, v in realistic("plane").items() if k != "gnss_mode"} if real else {}
    flight = sim.simulate(sim.make_scenario(name, **over), seed=1)
    res = run_samples(flight.samples, IntegrityMonitor())
    ev = next(e for e in flight.events if e.kind in ("step", "ramp", "dither"))
    after = [a[0] - ev.t_start_s for a in res.alarms if a[0] >= ev.t_start_s]
    label = f"{name}{' realistic' if real else ''}"
    return Detection(
        "simulator flights, monitor", label, 1, after[:1], 2 * (name != "ramp_fault") + real
    )


def det_service(name: str, grade: str) -> Detection:
    """A committed fault fixture replayed through the whole service: the first FAULT or
    INTEGRITY loss from the fault's start (its sidecar's window)."""
    from companion.presets import grade_config
    from companion.replay import replay

    logging.disable(logging.WARNING)
    events = json.loads((ROOT / "sitl_fixtures" / f"{name}.json").read_text())["events"]
    ev = next(e for e in events if e["kind"] in ("step", "ramp", "dither"))
    epoch0 = json.loads((ROOT / "sitl_fixtures" / f"{name}.json").read_text())["epoch0_s"]
    with tempfile.TemporaryDirectory(prefix="false_alerts_") as tmp:
        s = replay(
            ROOT / "sitl_fixtures" / f"{name}.tlog", Path(tmp) / "o.tlog", grade_config(grade)
        )
    hits = [
        t_rx - epoch0 - ev["t_start_s"]
        for t_rx, a in s.alert_log
        if (a.code.value == "FAULT" or (a.code.value == "INTEGRITY" and a.text.startswith("lost")))
        and t_rx - epoch0 >= ev["t_start_s"]
    ]
    order = 2 * (name != "ramp_fault") + (grade != "mems")
    return Detection("fixtures through the service", f"{name} ({grade})", 1, hits[:1], order)


def cost(fn: Any, args: tuple[Any, ...]) -> float:
    """A task's rough CPU cost (s on an idle core), for the progress line's estimate."""
    if fn is run_flight:
        t: FlightTask = args[0]
        return (
            t.duration_s
            / (12.0 if t.profile.vehicle == "px4" else 60.0)
            * (4.0 if t.profile.raw else 1.0)
        )
    if fn is det_synthetic:
        return 0.5 * args[2]
    if fn is det_ins:
        return 5.0 * args[2]
    return 8.0


def detection_tasks(det_runs: int, ins_runs: int, seed: int) -> list[tuple[Any, tuple[Any, ...]]]:
    tasks: list[tuple[Any, tuple[Any, ...]]] = []
    if det_runs > 0:
        tasks += [
            (det_synthetic, ("synthetic 2 rx", i, det_runs, seed)) for i in range(len(ib.CASES))
        ]
        tasks += [
            (det_synthetic, ("synthetic 1 rx", i, det_runs, seed))
            for i in range(len(ib.SINGLE_CASES))
        ]
    if ins_runs > 0:
        tasks += [
            (det_ins, (r, i, ins_runs, seed))
            for r in range(len(ib.INS_ROWS))
            for i in range(len(ib.INS_CASES))
        ]
    tasks += [
        (det_sim_flight, (n, real))
        for n in ("ramp_fault", "dither_fault")
        for real in (False, True)
    ]
    tasks += [
        (det_service, (n, g)) for n in ("ramp_fault", "dither_fault") for g in ("mems", "tactical")
    ]
    return tasks


def compare(det: Detection, base: dict[str, Any] | None) -> str:
    """'' (as fast), 'SLOWER ...' or 'no baseline' against the baseline's case."""
    if base is None:
        return "no baseline"
    if base["runs"] != det.runs:
        return f"not compared (baseline {base['runs']} runs)"
    b = sorted(base["delays"])
    if len(det.delays) < len(b):
        return f"SLOWER: {len(det.delays)} detections < {len(b)}"
    worse = [(new, old) for new, old in zip(det.delays, b, strict=False) if new > old + 1e-6]
    if worse:
        new, old = worse[0]
        return f"SLOWER: a detection at {new:.2f} s where the baseline's was at {old:.2f} s"
    faster = len(det.delays) > len(b) or any(
        new < old - 1e-6 for new, old in zip(det.delays, b, strict=False)
    )
    return "faster" if faster else "same"


# --------------------------------------------------------------------------- output


def code_version() -> str:
    def git(*a: str) -> str:
        try:
            return subprocess.run(
                ["git", *a], cwd=ROOT, capture_output=True, text=True, check=True
            ).stdout.strip()
        except (OSError, subprocess.CalledProcessError):
            return "?"

    return (
        f"companion {companion.__version__}, git {git('rev-parse', '--abbrev-ref', 'HEAD')} "
        f"{git('describe', '--always', '--dirty')}"
    )


SHORT = {
    "FAULT": "FAULT", "INTEGRITY": "INTEGRITY", "SPOOF": "SPOOF", "JAM": "JAM",
    "GNSS_STALE": "STALE", "GNSS_LOST": "LOST", "IMU_GRADE": "IMU_GRADE", "RAW_FAULT": "RAW_FAULT",
}  # fmt: skip


def _cell(c: Counter[str], code: str, hours: float) -> str:
    false, real = c[f"{code} false"], c[f"{code} real"]
    cell = f"{false / hours:.2f}"
    if real:
        cell += f" ({real / hours:.1f})"
    return cell


def print_table(outcomes: list[FlightOutcome]) -> None:
    print(
        "\nNominal realistic flights: false alerts per flight hour (real ones, for what the "
        "flight really had, in brackets; LOST burst: GNSS_LOST in a link burst)"
    )
    head = (
        f"{'vehicle':<12} {'imu':<4} {'gps':<3} {'raw':<3} | {'flts':>4} {'hours':>6} | "
        + " ".join(f"{SHORT[c]:>11}" for c in COLUMNS)
        + f" {'LOST burst':>10} | raw sol/tested"
    )
    print(head)
    print("-" * len(head))
    rows: list[tuple[str, list[FlightOutcome]]] = []
    for p in PROFILES:
        rows.append((p.label, [o for o in outcomes if o.task.profile == p]))
    rows.append(("", []))
    for vehicle in VEHICLES:
        rows.append(
            (f"{vehicle:<12} all", [o for o in outcomes if o.task.profile.vehicle == vehicle])
        )
    rows.append((f"{'total':<12} all", outcomes))
    for label, outs in rows:
        if not label:
            print("-" * len(head))
        if not outs:
            continue
        h = sum(o.hours for o in outs)
        c: Counter[str] = Counter()
        for o in outs:
            c.update(o.counts)
        cells = " ".join(f"{_cell(c, code, h):>11}" for code in COLUMNS)
        burst = f"{c['GNSS_LOST burst'] / h:.1f}"
        sol = sum(o.raw_solutions for o in outs)
        tested = sum(o.raw_tested for o in outs)
        rawc = f"{sol}/{tested}" if any(o.task.profile.raw for o in outs) else "-"
        print(f"{label:<25} | {len(outs):>4d} {h:6.2f} | {cells} {burst:>10} | {rawc}")
    h = sum(o.hours for o in outcomes)
    c = Counter()
    for o in outcomes:
        c.update(o.counts)
    print(f"\nIn {h:.2f} flight hours (false + real):")
    print(
        "  "
        + ", ".join(f"{code} {c[code + ' false']} + {c[code + ' real']}" for code in COLUMNS)
        + f"; GNSS_LOST in bursts {c['GNSS_LOST burst']}"
    )
    allc: Counter[str] = Counter()
    for o in outcomes:
        allc.update(o.all_codes)
    print(
        "every alert raised, per hour: "
        + ", ".join(f"{k} {v / h:.2f}" for k, v in sorted(allc.items()))
    )


def print_false(outcomes: list[FlightOutcome], limit: int) -> None:
    """The false alerts (a list to diagnose from), then each kind's count."""
    rows = [
        (o.task.profile.label, o.task.seed, t, code, text)
        for o in outcomes
        for t, code, text, verdict in o.alerts
        if verdict == "false"
    ]
    kinds: Counter[str] = Counter()
    for _, _, _, code, text in rows:
        kinds[f"{code} {re.sub(r'[-+]?[0-9][0-9.]*', '#', text)[:60]}"] += 1
    print(f"\nFalse alerts by kind ({len(rows)}; numbers as #):")
    for k, n in kinds.most_common():
        print(f"  {n:5d}  {k}")
    print(f"False alerts (the first {min(limit, len(rows))}): profile, seed, time s, text")
    for label, seed, t, code, text in rows[:limit]:
        print(f"  {label} seed {seed} t {t:7.1f}  {code} {text}")


SECTION_ORDER = (
    "synthetic 2 rx", "synthetic 1 rx", "INS tactical 1 rx", "INS mems 1 rx", "INS tactical 2 rx",
    "simulator flights, monitor", "fixtures through the service",
)  # fmt: skip


def print_detection(dets: list[Detection], baseline: dict[str, Any]) -> bool:
    """Print the detection table against the baseline; True when none is slower."""
    print(
        "\nDetection times (bench/integrity.py's cases; s from the fault's start) against "
        f"{BASELINE.name}"
    )
    cols = f"{'det':>7} {'t med':>6} {'t max':>6} | {'baseline':>21}"
    print(f"{'section':<30} {'case':<26} {cols} | verdict")
    ok = True
    for d in sorted(dets, key=lambda d: (SECTION_ORDER.index(d.section), d.order)):
        base = baseline.get(d.section, {}).get(d.label)
        verdict = compare(d, base)
        ok = ok and not verdict.startswith("SLOWER")
        bcell = "-"
        if base is not None:
            bd = base["delays"]
            bcell = Detection(d.section, d.label, base["runs"], sorted(bd)).cells()
        print(f"{d.section:<30} {d.label:<26} {d.cells()} | {bcell:>21} | {verdict}")
    print("detections: " + ("none slower than the baseline" if ok else "SLOWER than the baseline"))
    return ok


# --------------------------------------------------------------------------- main


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=10.0, help="nominal flight hours (all profiles)")
    ap.add_argument("--seed", type=int, default=1, help="seed of the nominal flights")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes")
    ap.add_argument("--det-seed", type=int, default=2026, help="bench/integrity.py's --seed")
    ap.add_argument("--det-runs", type=int, default=20, help="runs per synthetic case (0: none)")
    ap.add_argument("--ins-runs", type=int, default=3, help="runs per INS case and row (0: none)")
    ap.add_argument("--list", type=int, default=60, help="false alerts listed")
    ap.add_argument("--write-baseline", action="store_true", help=f"record {BASELINE.name}")
    ap.add_argument("--only", default="", help="only the profiles whose label has this word")
    ap.add_argument("--keep", default="", help="folder for every flight's files and replay")
    args = ap.parse_args()
    version = code_version()  # now: the checkout may move on during a long run
    print(f"command: python {shlex.join(sys.argv)}")
    print(f"code: {version}")
    logging.basicConfig(level=logging.ERROR)
    t0 = time.perf_counter()
    site, _, _ = _raw_setup()
    tasks = plan(args.hours, args.seed, site) if args.hours > 0 else []
    if args.only:
        tasks = [t for t in tasks if args.only in t.profile.label.split()]
    dets_todo = detection_tasks(args.det_runs, args.ins_runs, args.det_seed)
    total_h = sum(t.duration_s for t in tasks) / 3600.0
    print(
        f"{len(tasks)} nominal flights, {total_h:.2f} flight hours over {len(PROFILES)} profiles "
        f"({total_h / 2:.2f} h of distinct flights: each flown with and without the raw "
        f"receiver); {len(dets_todo)} detection tasks; {args.jobs} processes"
    )
    sys.stdout.flush()
    outcomes: list[FlightOutcome] = []
    dets: list[Detection] = []
    # the longest first (PX4's 250 Hz IMU is the slowest to replay)
    order = sorted(
        tasks, key=lambda t: -t.duration_s * (5.0 if t.profile.vehicle == "px4" else 1.0)
    )
    jobs: list[tuple[Any, tuple[Any, ...]]] = [*dets_todo]
    jobs += [(run_flight, (t, args.keep)) for t in order]
    total_cost = sum(cost(fn, a) for fn, a in jobs)
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        futures: dict[Future[Any], float] = {pool.submit(fn, *a): cost(fn, a) for fn, a in jobs}
        done_h = done_cost = 0.0
        n_det = n_fl = 0
        for fut in as_completed(futures):
            res = fut.result()
            done_cost += futures[fut]
            if isinstance(res, Detection):
                dets.append(res)
                n_det += 1
            else:
                outcomes.append(res)
                n_fl += 1
                done_h += res.hours
            el = time.perf_counter() - t0
            frac = done_cost / total_cost
            eta = el / frac - el if frac > 0 else math.nan
            print(
                f"\rflights {n_fl}/{len(tasks)} ({done_h:.2f}/{total_h:.2f} h), detection "
                f"{n_det}/{len(dets_todo)}, {el:.0f} s, ~{eta:.0f} s left   ",
                end="", file=sys.stderr, flush=True,
            )  # fmt: skip
    print(file=sys.stderr)
    outcomes.sort(key=lambda o: (PROFILES.index(o.task.profile), o.task.index))
    if outcomes:
        print_table(outcomes)
        print_false(outcomes, args.list)
    baseline = json.loads(BASELINE.read_text()) if BASELINE.is_file() else {}
    ok = print_detection(dets, baseline)
    if args.write_baseline:
        data: dict[str, Any] = {"_code": version}
        for d in dets:
            data.setdefault(d.section, {})[d.label] = {"runs": d.runs, "delays": d.delays}
        BASELINE.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")
        print(f"wrote {BASELINE}")
    print(f"\nwall time {time.perf_counter() - t0:.0f} s")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())

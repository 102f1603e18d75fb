"""Spoofing, meaconing and jamming against the service: detection, errors, false alerts.

Run: ``python bench/spoofing.py`` (``--flights N`` seeded flights per case, default 20;
``--hours H`` of spoofer-free flight per profile for the false-alert rates, default 10;
``--jobs J`` processes, default 2). The command line and the code version are printed
first, a progress line goes to stderr, the tables to stdout.

The flights (:mod:`companion.sim`, every one seeded) run through the service's real path:
the simulated autopilot's .tlog through :func:`companion.replay.replay` with the default
configuration (MEMS) or ``--grade tactical``'s preset (:func:`companion.presets.grade_config`),
the same for every flight. Everything scored is read back from what the service
published (its output .tlog) and from the truth:

* profiles: **plane MEMS** (the issue's trial): level cruise at 300 m with turns at 40 m/s
  as a realistic ArduPlane delivers it (:func:`companion.sim.scenarios.spoofing_cruise`:
  RAW_IMU 10 Hz with a MEMS unit's bias, scale, misalignment and aliased vibration,
  ATTITUDE off by a trim tilt and slow errors, GNSS 5 Hz with 0.2 s latency, gaps and a
  velocity bias) with a barometer (SCALED_PRESSURE 10 Hz) and one standalone receiver
  (3D fix); **plane tactical**: the same flights with a tactical IMU (HIGHRES_IMU 50 Hz,
  the grade's errors only: the realistic autopilot's IMU traits and vibration off, a
  tactical unit delivers anti-aliased increments; its ATTITUDE, link, GNSS and barometer
  as realistic as before), ``--grade tactical``; **copter MEMS**: a realistic ArduCopter
  (50 Hz RAW_IMU and SCALED_IMU2, 5-30 s dropouts of every stream, GNSS gaps), take-off,
  hover, 12 m/s forward flight at 40 m, landing, with the same barometer and a 3D fix.
  The autopilot's attitude is never affected by the spoofer.
* cases (flight k of every case is the same simulated flight, seed for seed; the attack
  starts 120 s into the cruise, 40 s for the copter, plus a seeded 0-20 s):
  drags (:mod:`companion.sim.attacks`: position and velocity dragged together, a
  m/s^2 up to 5 m/s, for 120 s, then the spoofer lets go) of 0.5, 0.1 and 0.02 m/s^2
  horizontal in a seeded direction and 0.1 m/s^2 vertical (seeded sign); meaconing (the
  true signal replayed 1 s late, the delay growing 0.02 s per s, for 120 s; ArduPilot's
  GPS_RAW_INT stamp late by as much); jamming (20 s of satellites dropping to 5 and
  accuracies growing 8 times, 30 s without a fix, 10 s of recovery; the ArduPilot
  autopilots relay no receiver flag: what the service sees is MAVLink-level); none (the
  same flights without a spoofer). Then spoofer-free flights of 30 min each until the
  profile has ``--hours`` of spoofer-free flight.

Definitions (every time on the autopilot clock; an alert's time is when the service sent
it, the .tlog record time less the boot epoch):

* **detected**: a SPOOF alert while the drag (or replay) goes on, [onset, let-go);
  **missed** otherwise (also when it comes only after the let-go). **t det** from the
  onset; **offset@det**: how far the spoofer had moved the receiver then; **err@det**: the
  error of the last solution published at or before the alert (horizontal, vertical for
  the vertical drag).
* **published 99 % bound**: from the published accuracies (GPS_INPUT ``horiz_accuracy``,
  the 1-sigma of the covariance's larger horizontal eigenvalue, and ``vert_accuracy``,
  both floored by the encoder): the ellipsoid ``(eN^2 + eE^2) / h_acc^2 + eD^2 / v_acc^2
  <= chi2_3^-1(0.99)`` (11.34), which holds at least 99 % of an honest Gaussian error.
  **>99 % after det**: the fraction of the solutions published from the detection to the
  let-go outside it; **>99 % attack**: the same over the whole attack; **>PL**: the
  fraction with the horizontal error above the published HPL or the vertical above VPL
  (CMP_HPL / CMP_VPL, the latest at or before the solution).
* **re-admitted** (among the detected): a SPOOF_END before the let-go, or the published
  solution following the spoofed receiver again: from 5 s after the detection to the
  let-go, 5 s or more throughout which the solution is closer to what the spoofed
  receiver reports (truth + its noise + the attack's offset, from the simulator) than to
  the truth while the two are at least 10 m apart.
* **FAULT in/let-go**: flights with a FAULT alert during the attack / in the 20 s after
  the let-go (the issue: the honest receiver excluded when the spoofer let go).
* **the service's own bound**: the median of the ``CMP_SPF_A`` it published in the minute
  before the onset (the smallest drag its test says it sees within 10 s, from the IMU
  stream's measured noise and the attitude's measured wander): a drag below it is beyond
  what that stream allows, and the goal line says so.
* **at end**: the last solution before the let-go: its error, the 1-sigma accuracy it
  claimed (horizontal, or vertical for the vertical drag) and the HPL (VPL) then.
* **false alerts**: SPOOF, FAULT and JAM alerts raised (the replay's counts, every one
  raised), and INTEGRITY losses sent ("CMP INTEGRITY lost", at most one per 5 s), per
  hour of spoofer-free flight; **SPOOF before onset**: SPOOF alerts in the attacked
  flights before the attack began.
* jamming: **t JAM** from the jamming's start (JAM before the loss of fix?), GNSS_LOST's
  time, and through [start, end of recovery): the largest horizontal error, the fraction
  outside the 99 % bound, and during the loss the solutions published per second and the
  fraction of them claiming a 3D fix or better.

Goals (the issue's acceptance), PASS/FAIL beside the figure: 0.5 m/s^2 detected within
5 s with a MEMS IMU and an error at detection <= 10 m (every flight); 0.02 m/s^2
detected before the drag reaches 25 m with a tactical IMU (every flight); 0 false SPOOF
per 10 flight hours (UNPROVEN below 10 h); after a detection not re-admitted while the
drag continues, and the error inside the published 99 % bound (at most 1 % outside).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import math
import shlex
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pymap3d
from scipy import stats

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from companion.mavlink.tlog import TlogReader  # noqa: E402
from companion.presets import grade_config  # noqa: E402
from companion.replay import replay  # noqa: E402
from companion.sim import Event, Scenario, SimFlight, make_scenario, simulate  # noqa: E402
from companion.sim.attacks import event_drag, horizontal_direction  # noqa: E402
from companion.sim.realism import realistic  # noqa: E402
from companion.sim.scenarios import (  # noqa: E402
    BARO_REALISM,
    build_script,
    phase_window,
    spoofing_cruise,
)
from companion.sim.writer import tlog_bytes  # noqa: E402

SEED0 = 29_000
ATTACK_S = 120.0
"""How long a drag or a replay lasts before the spoofer lets go, s."""
JAM_DEGRADE_S, JAM_LOSS_S, JAM_RECOVER_S = 20.0, 30.0, 10.0
LONG_CRUISE_S = 1800.0
"""The spoofer-free flights that make up ``--hours``: 30 min of cruise each."""
CHI2_3_99 = float(stats.chi2.ppf(0.99, 3))
"""The published 99 % ellipsoid's bound on (eN^2 + eE^2)/h_acc^2 + eD^2/v_acc^2."""
FOLLOW_S = 5.0
FOLLOW_MIN_SEPARATION_M = 10.0
LET_GO_FAULT_S = 20.0


@dataclass(frozen=True)
class Profile:
    """A vehicle, its IMU and the configuration it is flown with."""

    key: str
    label: str
    grade: str
    base: str
    overrides: dict[str, Any]
    cruise_s: float
    lead_s: float
    """Onset of the attack after the start of the cruise (plus a seeded 0-20 s), s."""
    cost: float
    """Rough CPU s per flight minute (to schedule the long flights first)."""


def _tactical_realism() -> Any:
    rl = spoofing_cruise()["realism"]
    off = (
        "acc_bias_mps2",
        "acc_scale_sigma",
        "misalign_sigma_rad",
        "gyro_bias_radps",
        "gyro_rw_radps_rts",
        "temp_rise_c",
        "acc_noise_mps2",
        "gyro_noise_radps",
        "vibration_mps2",
        "vibration_broadband_mps2",
    )
    return dataclasses.replace(rl, extra_imus=0, **{k: 0.0 for k in off})


def profiles() -> list[Profile]:
    """The three profiles (module docstring)."""
    copter = realistic("copter")
    return [
        Profile(
            "plane-mems",
            "plane, MEMS IMU, default configuration",
            "mems",
            "cruise_spoof_drag",
            {},
            300.0,
            120.0,
            0.35,
        ),
        Profile(
            "plane-tactical",
            "plane, tactical IMU, --grade tactical",
            "tactical",
            "cruise_spoof_drag",
            {
                "imu_grade": "tactical",
                "imu_message": "HIGHRES_IMU",
                "imu_rate_hz": 50.0,
                "realism": _tactical_realism(),
            },
            300.0,
            120.0,
            0.9,
        ),
        Profile(
            "copter-mems",
            "copter, MEMS IMU, default configuration",
            "mems",
            "copter_realistic",
            {"gnss_mode": "3d", "realism": dataclasses.replace(copter["realism"], **BARO_REALISM)},
            230.0,
            40.0,
            0.45,
        ),
    ]


@dataclass(frozen=True)
class Case:
    label: str
    kind: str | None  # drag, meaconing, jamming, None: no spoofer
    accel_mps2: float = 0.0
    axis: str = "h"


CASES = (
    Case("drag 0.5 h", "drag", 0.5),
    Case("drag 0.1 h", "drag", 0.1),
    Case("drag 0.02 h", "drag", 0.02),
    Case("drag 0.1 v", "drag", 0.1, "v"),
    Case("meaconing", "meaconing"),
    Case("jamming", "jamming"),
    Case("none", None),
)


@dataclass(frozen=True)
class Task:
    profile: Profile
    case: Case | None
    """None: a long spoofer-free flight."""
    k: int

    @property
    def minutes(self) -> float:
        return (LONG_CRUISE_S if self.case is None else self.profile.cruise_s) / 60.0 + 2.0


@dataclass
class Outcome:
    """One flight's figures (NaN or None where they do not apply)."""

    profile: str
    case: str
    hours: float
    alerts: dict[str, int]
    integrity_lost: int
    spoof_before_onset: int = 0
    t_det_s: float | None = None
    offset_at_det_m: float = math.nan
    err_at_det_m: float = math.nan
    out99_after_det: float = math.nan
    out99_attack: float = math.nan
    over_pl_attack: float = math.nan
    readmitted: str = ""
    fault_in_attack: bool = False
    fault_at_let_go: bool = False
    end_err_m: float = math.nan
    end_claimed_m: float = math.nan
    end_pl_m: float = math.nan
    jam: dict[str, float] = field(default_factory=dict)
    bound_mps2: float = math.nan
    """The median CMP_SPF_A the service published in the minute before the onset (the
    whole flight without one), m/s^2: the drag it said it could see within 10 s."""
    cpu_s: float = 0.0
    """CPU time of the flight's simulation, replay and scoring, s."""


# --------------------------------------------------------------------------- one flight


def scenario_for(task: Task, events: tuple[Event, ...]) -> Scenario:
    p = task.profile
    over = dict(p.overrides)
    if task.case is None:
        over["cruise_s"] = LONG_CRUISE_S
        over["cruise_turns_deg"] = (180.0, -90.0, 180.0, 90.0) * 4
    else:
        over["cruise_s"] = p.cruise_s
    return make_scenario(p.base, events=events, **over)


def attack_events(task: Task) -> tuple[tuple[Event, ...], float, float]:
    """The case's events, its onset and its end (let-go, or the end of the loss), s."""
    case = task.case
    plain = scenario_for(task, ())
    c0, _ = phase_window(build_script(plain), "cruise")
    rng = np.random.default_rng([SEED0, task.k])
    onset = round(c0 + task.profile.lead_s + float(rng.uniform(0.0, 20.0)), 3)
    if case is None or case.kind is None:
        return (), onset, onset + ATTACK_S
    if case.kind == "drag":
        if case.axis == "v":
            u: tuple[float, ...] = (0.0, 0.0, 1.0 if rng.uniform() < 0.5 else -1.0)
        else:
            u = horizontal_direction(rng)
        return (event_drag(onset, ATTACK_S, case.accel_mps2, u, 5.0),), onset, onset + ATTACK_S
    if case.kind == "meaconing":
        ev = Event(
            "meaconing", onset, onset + ATTACK_S, params={"delay_s": 1.0, "delay_rate": 0.02}
        )
        return (ev,), onset, onset + ATTACK_S
    end = onset + JAM_DEGRADE_S + JAM_LOSS_S
    ev = Event(
        "jamming", onset, end, params={"degrade_s": JAM_DEGRADE_S, "recover_s": JAM_RECOVER_S}
    )
    return (ev,), onset, end


@dataclass
class Published:
    """What the service published, as arrays: solutions (GPS_INPUT), protection levels and
    alerts (code, sent time, text)."""

    t_s: np.ndarray
    ned_m: np.ndarray
    h_acc_m: np.ndarray
    v_acc_m: np.ndarray
    fix_type: np.ndarray
    hpl: tuple[np.ndarray, np.ndarray]
    vpl: tuple[np.ndarray, np.ndarray]
    alerts: list[tuple[str, float, str]]
    spf_a: tuple[np.ndarray, np.ndarray]
    """CMP_SPF_A: the smallest drag the service's test says it sees within 10 s, m/s^2."""

    def times(self, code: str) -> list[float]:
        return [t for c, t, _ in self.alerts if c == code]


def read_published(out: Path, flight: SimFlight) -> Published:
    sol: list[tuple[float, float, float, float, float, float, int]] = []
    pl: dict[str, list[tuple[float, float]]] = {"CMP_HPL": [], "CMP_VPL": [], "CMP_SPF_A": []}
    alerts: list[tuple[str, float, str]] = []
    epoch0 = flight.scenario.epoch0_s
    for t_rec, msg in TlogReader(out):
        kind = msg.get_type()
        if kind == "GPS_INPUT":
            sol.append(
                (
                    msg.time_usec / 1e6,
                    msg.lat / 1e7,
                    msg.lon / 1e7,
                    msg.alt,
                    msg.horiz_accuracy,
                    msg.vert_accuracy,
                    msg.fix_type,
                )
            )
        elif kind == "NAMED_VALUE_FLOAT":
            name = str(msg.name).rstrip("\x00")
            if name in pl:
                pl[name].append((msg.time_boot_ms / 1e3, float(msg.value)))
        elif kind == "STATUSTEXT" and getattr(msg, "chunk_seq", 0) == 0:
            text = str(msg.text).rstrip("\x00")
            words = text.split(maxsplit=2)
            if len(words) >= 2 and words[0] == "CMP":
                alerts.append((words[1], t_rec - epoch0, text))
    a = np.array(sol, dtype=float).reshape(-1, 7)
    f = flight.frame
    n, e, d = pymap3d.geodetic2ned(
        a[:, 1], a[:, 2], a[:, 3], math.degrees(f.lat0_rad), math.degrees(f.lon0_rad), f.alt0_m
    )
    arr = {k: (np.array([x[0] for x in v]), np.array([x[1] for x in v])) for k, v in pl.items()}
    return Published(
        a[:, 0],
        np.column_stack([n, e, d]),
        a[:, 4],
        a[:, 5],
        a[:, 6].astype(int),
        arr["CMP_HPL"],
        arr["CMP_VPL"],
        alerts,
        arr["CMP_SPF_A"],
    )


def _latest(series: tuple[np.ndarray, np.ndarray], t: np.ndarray) -> np.ndarray:
    ts, vs = series
    if len(ts) == 0:
        return np.full(len(t), math.nan)
    i = np.searchsorted(ts, t, side="right") - 1
    return np.where(i >= 0, vs[np.clip(i, 0, None)], math.nan)


def _runs_at_least(mask: np.ndarray, t: np.ndarray, span_s: float) -> bool:
    """True when ``mask`` holds throughout some stretch of at least ``span_s``."""
    start = None
    for ok, tt in zip(mask.tolist(), t.tolist(), strict=True):
        if ok:
            start = tt if start is None else start
            if tt - start >= span_s:
                return True
        else:
            start = None
    return False


def fly(task: Task) -> Outcome:
    """Simulate, replay, score one flight."""
    logging.disable(logging.WARNING)  # the service logs every alert it raises
    cpu0 = time.process_time()
    res = _fly(task)
    res.cpu_s = time.process_time() - cpu0
    return res


def _fly(task: Task) -> Outcome:
    events, onset, end = attack_events(task)
    sc = scenario_for(task, events)
    seed = SEED0 + task.k + (10_000 if task.case is None else 0)
    flight = simulate(sc, seed)
    with tempfile.TemporaryDirectory() as tmp:
        src, out = Path(tmp) / "in.tlog", Path(tmp) / "out.tlog"
        src.write_bytes(tlog_bytes(flight))
        summary = replay(src, out, grade_config(task.profile.grade))
        pub = read_published(out, flight)
    hours = float(flight.truth.t_s[-1] - flight.truth.t_s[0]) / 3600.0
    lost = sum(1 for c, _, text in pub.alerts if c == "INTEGRITY" and " lost" in text[:20])
    res = Outcome(
        task.profile.key,
        "long" if task.case is None else task.case.label,
        hours,
        dict(summary.alerts),
        lost,
    )
    case = task.case
    ts, vs = pub.spf_a
    before = (ts >= onset - 60.0) & (ts < onset) if case is not None and case.kind else ts >= 0
    res.bound_mps2 = float(np.median(vs[before])) if before.any() else math.nan
    if case is None or case.kind is None:
        return res
    res.spoof_before_onset = sum(1 for t in pub.times("SPOOF") if t < onset)
    t = pub.t_s
    inside = (t >= flight.truth.t_s[0]) & (t <= flight.truth.t_s[-1])
    t = t[inside]
    truth = flight.truth.sample(t).pos_ned_m
    err = pub.ned_m[inside] - truth
    eh, ev = np.hypot(err[:, 0], err[:, 1]), np.abs(err[:, 2])
    h_acc, v_acc = pub.h_acc_m[inside], pub.v_acc_m[inside]
    out99 = (eh / h_acc) ** 2 + (ev / v_acc) ** 2 > CHI2_3_99
    over_pl = (eh > _latest(pub.hpl, t)) | (ev > _latest(pub.vpl, t))
    if case.kind == "jamming":
        res.jam = jamming_figures(pub, t, eh, out99, onset, end)
        return res
    vertical = case.axis == "v"
    e_axis = ev if vertical else eh
    att = (t >= onset) & (t < end)
    res.out99_attack = float(np.mean(out99[att])) if att.any() else math.nan
    res.over_pl_attack = float(np.mean(over_pl[att])) if att.any() else math.nan
    faults = pub.times("FAULT")
    res.fault_in_attack = any(onset <= x < end for x in faults)
    res.fault_at_let_go = any(end <= x < end + LET_GO_FAULT_S for x in faults)
    before_end = np.flatnonzero(t < end)
    if len(before_end):
        j = before_end[-1]
        res.end_err_m = float(e_axis[j])
        res.end_claimed_m = float((v_acc if vertical else h_acc)[j])
        res.end_pl_m = float(_latest(pub.vpl if vertical else pub.hpl, t[j : j + 1])[0])
    spoofs = [x for x in pub.times("SPOOF") if onset <= x < end]
    if not spoofs:
        return res
    det = spoofs[0]
    res.t_det_s = det - onset
    # what the spoofed receiver reports: truth + its noise + the attack's offset
    g = flight.errors.gnss[0]
    rx = flight.truth.sample(g.t_fix_s).pos_ned_m + g.pos_err_ned_m + g.fault_ned_m
    rx_t = np.column_stack([np.interp(t, g.t_fix_s, rx[:, i]) for i in range(3)])
    off = np.column_stack([np.interp(t, g.t_fix_s, g.fault_ned_m[:, i]) for i in range(3)])
    at = np.flatnonzero(t <= det)
    if len(at):
        j = at[-1]
        res.err_at_det_m = float(e_axis[j])
        res.offset_at_det_m = float(abs(off[j, 2]) if vertical else np.hypot(*off[j, :2]))
    after = (t >= det) & (t < end)
    res.out99_after_det = float(np.mean(out99[after])) if after.any() else math.nan
    if any(det < x < end for x in pub.times("SPOOF_END")):
        res.readmitted = "SPOOF_END"
    else:
        to_rx = pub.ned_m[inside] - rx_t
        if vertical:
            d_rx, d_truth, sep = np.abs(to_rx[:, 2]), ev, np.abs(off[:, 2])
        else:
            d_rx, d_truth, sep = np.hypot(to_rx[:, 0], to_rx[:, 1]), eh, np.hypot(*off[:, :2].T)
        win = (t >= det + FOLLOW_S) & (t < end)
        follows = (d_rx < d_truth) & (sep >= FOLLOW_MIN_SEPARATION_M)
        res.readmitted = "follows" if _runs_at_least(follows[win], t[win], FOLLOW_S) else "no"
    return res


def jamming_figures(
    pub: Published, t: np.ndarray, eh: np.ndarray, out99: np.ndarray, onset: float, end: float
) -> dict[str, float]:
    """Time to JAM, JAM before the loss, GNSS_LOST, and what was published through it."""
    loss0 = onset + JAM_DEGRADE_S
    stop = end + JAM_RECOVER_S
    jams = [x for x in pub.times("JAM") if x >= onset]
    lost = [x for x in pub.times("GNSS_LOST") if onset <= x < stop]
    win = (t >= onset) & (t < stop)
    loss = (pub.t_s >= loss0) & (pub.t_s < end)
    return {
        "t_jam": jams[0] - onset if jams else math.nan,
        "before_loss": float(bool(jams) and jams[0] < loss0),
        "t_lost": lost[0] - onset if lost else math.nan,
        "max_err": float(eh[win].max()) if win.any() else math.nan,
        "out99": float(np.mean(out99[win])) if win.any() else math.nan,
        "rate_in_loss": float(loss.sum()) / (end - loss0),
        "fix3d_in_loss": float(np.mean(pub.fix_type[loss] >= 3)) if loss.any() else math.nan,
        "jam_end": float(any(x > onset for x in pub.times("JAM_END"))),
    }


# --------------------------------------------------------------------------- tables


def _mm(x: list[float], fmt: str = ".1f") -> str:
    v = [a for a in x if not math.isnan(a)]
    if not v:
        return "-"
    return f"{np.median(v):{fmt}}/{max(v):{fmt}}"


def _pct(x: list[float]) -> str:
    v = [a for a in x if not math.isnan(a)]
    return f"{100.0 * np.mean(v):.0f}%" if v else "-"


def print_profile(p: Profile, outs: list[Outcome], hours_goal: float) -> list[str]:
    """The profile's tables; returns its goal lines."""
    print(f"\n== {p.label} ==")
    head = (
        f"{'case':<12} {'det/N':>6} {'missed':>6} {'t det s':>10} {'offset@det m':>12} "
        f"{'err@det m':>11} {'>99% after':>10} {'>99% att':>8} {'>PL att':>7} "
        f"{'readmit':>8} {'FAULT in/go':>11} {'pre SPOOF':>9} | "
        f"{'end: err m':>10} {'1-sigma m':>9} {'PL m':>7}"
    )
    print(head)
    print("-" * len(head))
    goals: list[str] = []
    by_case = {c.label: [o for o in outs if o.case == c.label] for c in CASES}
    for c in CASES:
        rows = by_case[c.label]
        if c.kind in (None, "jamming") or not rows:
            continue
        det = [o for o in rows if o.t_det_s is not None]
        n = len(rows)
        readmit = sum(1 for o in det if o.readmitted in ("SPOOF_END", "follows"))
        t_det = _mm([o.t_det_s for o in det if o.t_det_s is not None])
        at_det = (
            f"{_mm([o.offset_at_det_m for o in det]):>12} {_mm([o.err_at_det_m for o in det]):>11}"
        )
        out99 = _pct([o.out99_after_det for o in det])
        out99 = f"{out99:>10} {_pct([o.out99_attack for o in rows]):>8}"
        print(
            f"{c.label:<12} {len(det):>3}/{n:<2} {100.0 * (n - len(det)) / n:>5.0f}% "
            f"{t_det:>10} {at_det} {out99} {_pct([o.over_pl_attack for o in rows]):>7} "
            f"{(f'{readmit}/{len(det)}' if det else '-'):>8} "
            f"{sum(o.fault_in_attack for o in rows):>5}/{sum(o.fault_at_let_go for o in rows):<5} "
            f"{sum(o.spoof_before_onset for o in rows):>9} | "
            f"{np.median([o.end_err_m for o in rows]):>10.1f} "
            f"{np.median([o.end_claimed_m for o in rows]):>9.2f} "
            f"{np.nanmedian([o.end_pl_m for o in rows]) if rows else math.nan:>7.1f}"
        )
    jam = by_case["jamming"]
    if jam:
        print(
            f"\n{'jamming':<12} {'JAM':>6} {'t JAM s':>10} {'before loss':>11} "
            f"{'t GNSS_LOST s':>13} {'max err m':>11} {'>99%':>6} {'sol/s in loss':>13} "
            f"{'3D claimed':>10} {'JAM_END':>7} {'pre SPOOF':>9}"
        )
        f = [o.jam for o in jam]
        n_jam = sum(1 for x in f if not math.isnan(x["t_jam"]))
        print(
            f"{'':<12} {n_jam:>3}/{len(f):<2} {_mm([x['t_jam'] for x in f]):>10} "
            f"{int(sum(x['before_loss'] for x in f)):>11} {_mm([x['t_lost'] for x in f]):>13} "
            f"{_mm([x['max_err'] for x in f]):>11} {_pct([x['out99'] for x in f]):>6} "
            f"{np.mean([x['rate_in_loss'] for x in f]):>13.1f} "
            f"{_pct([x['fix3d_in_loss'] for x in f]):>10} {int(sum(x['jam_end'] for x in f)):>7} "
            f"{sum(o.spoof_before_onset for o in jam):>9}"
        )
    bounds = np.array([o.bound_mps2 for o in outs if o.case not in ("none", "long")])
    published = bounds[np.isfinite(bounds)]
    if len(published):
        print(
            "\nthe service's own bound (CMP_SPF_A, the smallest drag its test sees within "
            f"10 s; median over the minute before each onset): median {np.median(published):.2f}"
            f" m/s^2, p10 {np.percentile(published, 10):.2f}, p90 "
            f"{np.percentile(published, 90):.2f} ({len(published)} of {len(bounds)} attacked "
            "flights published one)"
        )
    print()
    for label, kinds in (
        ("the attacked flights without a spoofer", ("none",)),
        (f"{LONG_CRUISE_S / 60:.0f}-min spoofer-free flights", ("long",)),
        ("all spoofer-free flights", ("none", "long")),
    ):
        free = [o for o in outs if o.case in kinds]
        hours = sum(o.hours for o in free)
        counts = {k: sum(o.alerts.get(k, 0) for o in free) for k in ("SPOOF", "FAULT", "JAM")}
        counts["INTEGRITY lost"] = sum(o.integrity_lost for o in free)
        if hours:
            per_h = ", ".join(f"{k} {v} ({v / hours:.2f}/h)" for k, v in counts.items())
            print(f"{label}: {len(free)} flights, {hours:.2f} h: {per_h}")
    # goals
    free = [o for o in outs if o.case in ("none", "long")]
    hours = sum(o.hours for o in free)
    d05 = by_case["drag 0.5 h"]
    if p.grade == "mems" and d05:
        det = [o for o in d05 if o.t_det_s is not None]
        ok = len(det) == len(d05) and all(
            (o.t_det_s or 0) <= 5.0 and o.err_at_det_m <= 10.0 for o in det
        )
        worst = (
            f"worst t det {max(o.t_det_s or 0.0 for o in det):.1f} s, "
            f"err@det {max(o.err_at_det_m for o in det):.1f} m"
            if det
            else "nothing detected"
        )
        bound = float(np.nanmedian([o.bound_mps2 for o in d05]))
        beyond = (
            f"; the service published {bound:.2f} m/s^2 as the smallest drag it sees within"
            " 10 s: beyond what this IMU stream allows"
            if not ok and bound > 0.5
            else ""
        )
        goals.append(
            f"{'PASS' if ok else 'FAIL'}  {p.key}: 0.5 m/s^2 detected within 5 s, "
            f"error at detection <= 10 m: {len(det)}/{len(d05)} detected, {worst}{beyond}"
        )
    d002 = by_case["drag 0.02 h"]
    if p.grade == "tactical" and d002:
        det = [o for o in d002 if o.t_det_s is not None]
        ok = len(det) == len(d002) and all(o.offset_at_det_m <= 25.0 for o in det)
        worst = (
            f"largest offset at detection {max(o.offset_at_det_m for o in det):.1f} m"
            if det
            else "nothing detected"
        )
        goals.append(
            f"{'PASS' if ok else 'FAIL'}  {p.key}: 0.02 m/s^2 detected before the "
            f"drag reaches 25 m: {len(det)}/{len(d002)} detected, {worst}"
        )
    spoof = sum(o.alerts.get("SPOOF", 0) for o in free)
    verdict = "FAIL" if spoof else ("PASS" if hours >= hours_goal else "UNPROVEN")
    goals.append(
        f"{verdict:<4}  {p.key}: 0 false SPOOF per 10 flight hours: {spoof} in "
        f"{hours:.1f} h of spoofer-free flight"
    )
    attacked = [o for c in CASES if c.kind in ("drag", "meaconing") for o in by_case[c.label]]
    det = [o for o in attacked if o.t_det_s is not None]
    if det:
        back = sum(1 for o in det if o.readmitted in ("SPOOF_END", "follows"))
        goals.append(
            f"{'PASS' if back == 0 else 'FAIL'}  {p.key}: not re-admitted while the "
            f"attack goes on: {back} of {len(det)} detected flights re-admitted"
        )
        frac = float(np.nanmean([o.out99_after_det for o in det]))
        goals.append(
            f"{'PASS' if frac <= 0.01 else 'FAIL'}  {p.key}: error inside the "
            f"published 99 % bound after detection: {100 * frac:.1f} % outside"
        )
    else:
        goals.append(
            f"FAIL  {p.key}: not re-admitted / inside the 99 % bound after "
            f"detection: no detection to judge ({len(attacked)} attacked flights)"
        )
    return goals


# --------------------------------------------------------------------------- main


def print_tables(chosen: list[Profile], outs: list[Outcome]) -> None:
    goals: list[str] = []
    for p in chosen:
        goals += print_profile(p, [o for o in outs if o.profile == p.key], 10.0)
    print("\nGoals")
    for line in goals:
        print("  " + line)


def code_version() -> str:
    try:
        rev = subprocess.run(
            ["git", "-C", str(ROOT), "describe", "--always", "--dirty"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        branch = subprocess.run(
            ["git", "-C", str(ROOT), "rev-parse", "--abbrev-ref", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        return f"{branch} {rev}"
    except (OSError, subprocess.CalledProcessError):
        import companion

        return f"companion {getattr(companion, '__version__', '?')} (no git)"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--flights", type=int, default=20, help="seeded flights per case")
    parser.add_argument(
        "--hours",
        type=float,
        default=10.0,
        help="spoofer-free flight hours per profile (false-alert rates)",
    )
    parser.add_argument("--jobs", type=int, default=2, help="processes")
    parser.add_argument("--save", type=Path, help="also write every flight's figures (JSON)")
    parser.add_argument("--tables-from", type=Path, help="print the tables of a --save file")
    parser.add_argument(
        "--profiles",
        default="plane-mems,plane-tactical,copter-mems",
        help="comma-separated subset of the profiles",
    )
    args = parser.parse_args(argv)
    if args.flights < 1 or args.hours < 0 or args.jobs < 1:
        parser.error("--flights and --jobs must be >= 1, --hours >= 0")
    chosen = [p for p in profiles() if p.key in args.profiles.split(",")]
    if args.tables_from is not None:
        saved = json.loads(args.tables_from.read_text())
        print(f"the figures of {args.tables_from}: {saved['command']} at {saved['code']}")
        print_tables(chosen, [Outcome(**o) for o in saved["flights"]])
        return 0
    print("command: python " + " ".join(shlex.quote(a) for a in [sys.argv[0], *sys.argv[1:]]))
    print(f"code: {code_version()}")
    print(
        f"{args.flights} flights per case, {args.hours:g} h spoofer-free per profile, "
        f"{args.jobs} processes"
    )
    tasks: list[Task] = []
    for p in chosen:
        tasks += [Task(p, c, k) for c in CASES for k in range(args.flights)]
        # the none case's flights and the long ones last at least their cruise
        short_h = args.flights * p.cruise_s / 3600.0
        n_long = max(0, math.ceil((args.hours - short_h) / (LONG_CRUISE_S / 3600.0)))
        tasks += [Task(p, None, k) for k in range(n_long)]
    tasks.sort(key=lambda x: -x.minutes * x.profile.cost)
    outs: list[Outcome] = []
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        futures = [pool.submit(fly, task) for task in tasks]
        for done, fut in enumerate(as_completed(futures), 1):
            outs.append(fut.result())
            el = time.perf_counter() - t0
            left = el / done * (len(tasks) - done)
            print(
                f"\r{done}/{len(tasks)} flights, {el:.0f} s, ~{left:.0f} s left   ",
                end="",
                file=sys.stderr,
                flush=True,
            )
    print(file=sys.stderr)
    if args.save is not None:
        command = " ".join(shlex.quote(a) for a in sys.argv)
        flights = [dataclasses.asdict(o) for o in outs]
        args.save.write_text(
            json.dumps(
                {"command": command, "code": code_version(), "flights": flights}, allow_nan=True
            )
        )
    print_tables(chosen, outs)
    cpu = sum(o.cpu_s for o in outs)
    print(
        f"\n{len(tasks)} flights: wall time {time.perf_counter() - t0:.0f} s; CPU time "
        f"{cpu:.0f} s (about {cpu / args.jobs:.0f} s of wall time on {args.jobs} idle cores)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

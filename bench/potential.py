"""Benchmark of the position-potential filter (Grzegorzewski 2005): accuracy through gaps
and cost per call.

Run: ``python bench/potential.py`` (all parts, several minutes), or
``--part A|timing|B``, ``--seeds N`` (part A), ``--b-seeds N`` (part B, default 10).

Part A (the paper's case, 2-s gaps): closed-form kinematic descents generated here
(no simulator needed) -- level flight, approach entry (deceleration from
80 to 60 m/s while the flight-path angle goes from 0 to -3 deg), a stable
3-deg glide, a flare (-3 deg to 0 with deceleration) -- with DGPS-like fixes
(white noise 0.5 m horizontal, 1.0 m vertical per axis, 5 Hz) and horizontal
velocity from the receiver (0.1 m/s noise; no vertical velocity, as in
MAVLink's GPS_RAW_INT). Every 0.5 s a 2-s gap starts: the filters predict to
its end from the fixes before it. Gaps are labelled by the script segment they
fall in. Rows: the potential filter with the receiver's horizontal velocity,
the potential filter from positions only, and the baseline: constant velocity
from a least-squares line through the last second of fixes (same fixes, same
run). Errors are 3-D position errors at the end of each gap [m].

Timing: per-call cost of test_fix, predict, add_fix and a fit at 10 Hz with a
full window, beside the constant-velocity extrapolator's cost in the same run.

Part B: the project simulator's approach (RTK fixed, 10 Hz), tactical
and MEMS IMU, all GNSS withheld for 5, 10, 20 s from 40 s into the glide
(``bench/outage.py``'s flights, gap placement and driver ``run_one``). Through
the gap at 10 Hz: constant velocity, the potential filter alone, the INS blend
alone (adaptive, strapdown), INS and potential combined by their covariances
(``combine_predictions``): as independent (``cov``) and with the error they
share at the gap start, the newest fix's variance, as cross-covariance
(``cov,sh``), and the potential prediction fed to the blend as a position
pseudo-measurement (1 Hz, the blend's own gate; blend.py unchanged). NEES is
the mean normalised error squared against each method's own covariance
(3 when calibrated; CV has none).
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from outage import outage_start_s, run_one, simulate_flight  # noqa: E402  (bench/outage.py)

from companion.nav.blend import BlendConfig, BlendNavigator  # noqa: E402
from companion.nav.frames import LocalFrame  # noqa: E402
from companion.nav.navigator import GnssMeasurement, GnssUpdate, NavState  # noqa: E402
from companion.nav.potential import (  # noqa: E402
    PotentialConfig,
    PotentialFilter,
    combine_predictions,
    combine_with_ins,
)
from companion.sim import SimFlight  # noqa: E402
from companion.types import AttitudeSample, FixType, FloatArray, ImuSample  # noqa: E402


def _progress(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# --------------------------------------------------------------------------- flights


@dataclass(frozen=True, slots=True)
class Flight:
    """Fixes and truth of one flight (NED, m; s)."""

    name: str
    t_s: FloatArray
    truth_pos_m: FloatArray
    fix_pos_m: FloatArray
    fix_var_m2: FloatArray
    fix_vel_mps: FloatArray  # NaN where the receiver gives none
    truth_at: Callable[[FloatArray], FloatArray]
    label_at: Callable[[float, float], str]


def _smooth(x: FloatArray) -> FloatArray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def kinematic_descent(seed: int, rate_hz: float = 5.0) -> Flight:
    """A TS-11 descent like the paper's: level, approach entry, stable glide, flare, level-off."""
    # segments: (name, duration s, speed at end m/s, flight-path angle at end deg)
    segs = [
        ("level", 20.0, 80.0, 0.0),
        ("entry", 12.0, 60.0, -3.0),
        ("stable", 45.0, 60.0, -3.0),
        ("flare", 8.0, 54.0, 0.0),
        ("level", 15.0, 54.0, 0.0),
    ]
    dt = 0.01
    t_end = sum(s[1] for s in segs)
    tt = np.arange(0.0, t_end + dt, dt)
    v = np.empty_like(tt)
    gam = np.empty_like(tt)
    lab = np.empty(tt.size, dtype=object)
    t0, v0, g0 = 0.0, segs[0][2], segs[0][3]
    for name, dur, v1, g1 in segs:
        m = (tt >= t0 - 1e-9) & (tt <= t0 + dur + 1e-9)
        x = _smooth((tt[m] - t0) / dur)
        v[m] = v0 + (v1 - v0) * x
        gam[m] = np.deg2rad(g0 + (g1 - g0) * x)
        lab[m] = name
        t0, v0, g0 = t0 + dur, v1, g1
    track = np.deg2rad(30.0)
    vel = np.column_stack(
        [v * np.cos(gam) * np.cos(track), v * np.cos(gam) * np.sin(track), -v * np.sin(gam)]
    )
    pos = np.cumsum(np.vstack([np.zeros(3), 0.5 * (vel[1:] + vel[:-1]) * dt]), axis=0)
    pos[:, 2] -= 600.0

    def truth_at(t: FloatArray) -> FloatArray:
        t = np.atleast_1d(t)
        return np.column_stack([np.interp(t, tt, pos[:, k]) for k in range(3)])

    def label_at(ta: float, tb: float) -> str:
        m = (tt >= ta) & (tt <= tb)
        names = set(lab[m])
        return names.pop() if len(names) == 1 else "/".join(sorted(names))

    rng = np.random.default_rng(seed)
    t_fix = np.arange(0.0, t_end, 1.0 / rate_hz)
    tp = truth_at(t_fix)
    sig = np.array([0.5, 0.5, 1.0])
    fix = tp + rng.normal(0.0, 1.0, tp.shape) * sig
    vt = np.column_stack([np.interp(t_fix, tt, vel[:, k]) for k in range(3)])
    fvel = vt + rng.normal(0.0, 0.1, vt.shape)
    fvel[:, 2] = np.nan
    var = np.tile(sig**2, (t_fix.size, 1))
    return Flight("kinematic", t_fix, tp, fix, var, fvel, truth_at, label_at)


# --------------------------------------------------------------------------- runs


def cv_predict(t: FloatArray, pos: FloatArray, k_last: int, t_pred: float) -> FloatArray:
    """Least-squares line through the fixes of the last second up to index ``k_last``."""
    m = (t <= t[k_last]) & (t >= t[k_last] - 1.0 + 1e-9)
    tt = t[m] - t[k_last]
    a = np.column_stack([np.ones(tt.size), tt])
    coef, *_ = np.linalg.lstsq(a, pos[m], rcond=None)
    return coef[0] + coef[1] * (t_pred - t[k_last])


@dataclass
class Result:
    errors: dict[tuple[str, str, float], list[float]] = field(default_factory=dict)
    fits: dict[str, list[tuple[float, float]]] = field(default_factory=dict)
    fit_times_s: list[float] = field(default_factory=list)
    rejections: dict[str, dict[str, int]] = field(default_factory=dict)
    n_fixes: int = 0

    def add(self, method: str, label: str, gap: float, err: float) -> None:
        self.errors.setdefault((method, label, gap), []).append(err)


def run_flight(
    fl: Flight,
    gaps: tuple[float, ...],
    start_every_s: float,
    t_first_gap_s: float,
    res: Result,
    labels_ok: Callable[[str], bool],
    seed: int,
) -> None:
    """Run both potential variants through a flight; evaluate gaps against CV."""
    variants = {
        "potential+vel": PotentialFilter(PotentialConfig(seed=seed)),
        "potential(pos)": PotentialFilter(PotentialConfig(seed=seed)),
    }
    next_gap = t_first_gap_s
    for k in range(fl.t_s.size):
        tk = float(fl.t_s[k])
        for name, f in variants.items():
            vel = fl.fix_vel_mps[k] if name == "potential+vel" else None
            f.add_fix(tk, fl.fix_pos_m[k], fl.fix_var_m2[k], vel, refit=False)
            t0 = time.perf_counter()
            out = f.refit()
            if out is not None:
                res.fit_times_s.append(time.perf_counter() - t0)
                res.fits.setdefault(fl.label_at(tk - 1.0, tk), []).append(out)
        if tk + 1e-9 < next_gap:
            continue
        next_gap += start_every_s
        for gap in gaps:
            t_end = tk + gap
            if t_end > fl.t_s[-1]:
                continue
            label = fl.label_at(tk, t_end)
            if not labels_ok(label):
                continue
            truth = fl.truth_at(np.array([t_end]))[0]
            for name, f in variants.items():
                p = f.predict(t_end).pos_ned_m
                res.add(name, label, gap, float(np.linalg.norm(p - truth)))
            pc = cv_predict(fl.t_s, fl.fix_pos_m, k, t_end)
            res.add("const-vel", label, gap, float(np.linalg.norm(pc - truth)))
    res.n_fixes += fl.t_s.size
    for name, f in variants.items():
        tot = res.rejections.setdefault(name, {})
        for why, n in f.rejections.items():
            tot[why] = tot.get(why, 0) + n


def table(res: Result, gaps: tuple[float, ...], title: str) -> None:
    print(f"\n{title}")
    labels = sorted({k[1] for k in res.errors})
    hdr = (
        f"{'gap s':>5} {'segment':<22} {'n':>4} {'CV mean':>8} {'CV max':>7} "
        f"{'pot+vel mean':>12} {'max':>7} {'ratio':>6} "
        f"{'pot(pos) mean':>13} {'max':>7} {'ratio':>6}"
    )
    print(hdr)
    print("-" * len(hdr))
    for gap in gaps:
        for lab in labels:
            cv = res.errors.get(("const-vel", lab, gap))
            if not cv:
                continue
            pv = res.errors[("potential+vel", lab, gap)]
            pp = res.errors[("potential(pos)", lab, gap)]
            print(
                f"{gap:5.0f} {lab:<22} {len(cv):4d} {np.mean(cv):8.2f} {np.max(cv):7.2f} "
                f"{np.mean(pv):12.2f} {np.max(pv):7.2f} {np.mean(pv) / np.mean(cv):6.2f} "
                f"{np.mean(pp):13.2f} {np.max(pp):7.2f} {np.mean(pp) / np.mean(cv):6.2f}"
            )


def fits_table(res: Result) -> None:
    print("\nfitted alpha [1/s] and G [1/s^2] by segment (median, 10-90 %), both variants")
    for lab, vals in sorted(res.fits.items()):
        a = np.array([v[0] for v in vals])
        g = np.array([v[1] for v in vals])
        print(
            f"  {lab:<22} n={a.size:4d}  alpha {np.median(a):7.3f} "
            f"[{np.percentile(a, 10):.3f}, {np.percentile(a, 90):.3f}]  "
            f"G {np.median(g):9.4g} [{np.percentile(g, 10):.3g}, {np.percentile(g, 90):.3g}]"
        )
    for name, rej in res.rejections.items():
        print(f"  {name}: fixes rejected by the chi2 test / restarts: {rej} of {res.n_fixes}")
    ft = np.array(res.fit_times_s)
    if ft.size:
        print(
            f"  run time per fit: mean {1e3 * ft.mean():.0f} ms, median "
            f"{1e3 * np.median(ft):.0f} ms, max {1e3 * ft.max():.0f} ms over {ft.size} fits"
        )


# --------------------------------------------------------------------------- timing


def timing_section(seed: int, rate_hz: float = 10.0) -> None:
    """Per-call cost of the filter on a 10 Hz kinematic descent with a full window.

    Per fix, in the engine's order: ``test_fix`` at the fix time, ``predict``
    0.5 s ahead (a gap step; it also evicts the one-entry prediction memo, so
    that ``add_fix`` pays its own test), ``add_fix`` without a fit, then the
    fit when due (``refit()`` with the default interval) and, every 10 s, a
    forced fit (the engine forces one at the start of a gap). The baseline is
    the constant-velocity extrapolator of this bench (least-squares line
    through the last second of fixes, one prediction), timed on the same fixes.
    """
    fl = kinematic_descent(seed, rate_hz=rate_hz)
    cfg = PotentialConfig(seed=seed)
    f = PotentialFilter(cfg)
    perf = time.perf_counter
    t_add: list[float] = []
    t_test: list[float] = []
    t_pred: list[float] = []
    t_cv: list[float] = []
    t_fit_cold: list[float] = []
    t_fit_warm: list[float] = []
    fit_total = 0.0
    n_full = 0
    next_forced = 30.0
    for k in range(fl.t_s.size):
        tk = float(fl.t_s[k])
        pos, var, vel = fl.fix_pos_m[k], fl.fix_var_m2[k], fl.fix_vel_mps[k]
        full = f.n_sources >= cfg.max_sources or (
            f.t_last_s is not None and tk - fl.t_s[0] > cfg.window_s
        )
        if full and f.calibrated:
            t0 = perf()
            f.test_fix(tk, pos, var)
            t_test.append(perf() - t0)
            t0 = perf()
            f.predict(tk + 0.5)
            t_pred.append(perf() - t0)
        t0 = perf()
        f.add_fix(tk, pos, var, vel, refit=False)
        dt_add = perf() - t0
        if full and f.calibrated:
            t_add.append(dt_add)
            n_full += 1
            t0 = perf()
            cv_predict(fl.t_s, fl.fix_pos_m, k, tk + 0.5)
            t_cv.append(perf() - t0)
        forced = tk >= next_forced
        cold = f.fit_count == 0
        t0 = perf()
        out = f.refit(force=forced)
        dt_fit = perf() - t0
        if forced:
            next_forced += 10.0
        if out is not None:
            (t_fit_cold if cold else t_fit_warm).append(dt_fit)
            if not forced:
                fit_total += dt_fit
    us = 1e6
    cv_us = us * float(np.median(t_cv))
    print(f"\nPer-call cost, {rate_hz:.0f} Hz fixes, full window ({cfg.max_sources} sources)")
    print(f"{'call':<34} {'median':>9} {'p90':>9} {'/ CV':>7}   (n)")
    rows = [
        ("CV extrapolation (LSQ 1 s, baseline)", t_cv),
        ("test_fix", t_test),
        ("predict (0.5 s ahead)", t_pred),
        ("add_fix (no fit)", t_add),
    ]
    for name, vals in rows:
        med = us * float(np.median(vals))
        p90 = us * float(np.percentile(vals, 90))
        print(f"{name:<34} {med:7.1f}us {p90:7.1f}us {med / cv_us:7.2f}   ({len(vals)})")
    for name, vals in (("fit, first (cold)", t_fit_cold), ("fit, warm-started", t_fit_warm)):
        if vals:
            med = 1e3 * float(np.median(vals))
            mx = 1e3 * float(np.max(vals))
            print(f"{name:<34} {med:7.1f}ms {mx:7.1f}ms max        ({len(vals)})")
    span = fl.t_s[-1] - fl.t_s[0]
    per_fix = us * fit_total / max(fl.t_s.size, 1)
    per_s = 1e3 * fit_total / span
    print(
        f"fits due every refit_interval_s = {cfg.refit_interval_s:g} s: {per_s:.2f}"
        f" ms per second of flight, {per_fix:.1f} us per fix amortised"
    )


# --------------------------------------------------------------------------- part B


METHODS = (
    "cv",
    "potential",
    "ins",
    "ins+pot(cov)",
    "ins+pot(cov,sh)",
    "ins+pot(gated)",
    "ins+pot(pseudo)",
)


class GapRecorder:
    """A :class:`Navigator` wrapper for ``bench/outage.py``'s ``run_one``.

    It forwards every sample to the INS blend and feeds the same fixes to a
    potential filter and to the constant-velocity line. In the gap (no fixes
    reach it: ``run_one`` withholds them) it forces a fit once, as the engine
    does, and at each evaluation time records the INS, the potential, the
    constant-velocity and the covariance-combined predictions. With
    ``pseudo_rate_hz`` it instead feeds the potential prediction to the blend
    as a position measurement at that rate during the gap (no edit of the
    blend: a :class:`GnssMeasurement` with the potential's covariance, gated
    by the blend's own NIS test) and records the blend's state.
    """

    def __init__(
        self,
        inner: BlendNavigator,
        t_gap0: float,
        seed: int,
        pseudo_rate_hz: float | None = None,
    ) -> None:
        self.inner = inner
        self.pot = PotentialFilter(PotentialConfig(seed=seed))
        self.t_gap0 = t_gap0
        self.pseudo_dt = None if pseudo_rate_hz is None else 1.0 / pseudo_rate_hz
        self.next_pseudo = t_gap0 + (self.pseudo_dt or 0.0)
        self.fix_t: list[float] = []
        self.fix_pos: list[FloatArray] = []
        self.fix_type = FixType.FIX_3D
        self.in_gap = False
        self.disagreed = False
        self.gate = float(stats.chi2.isf(self.pot.config.false_alarm_prob, 3))
        self.pseudo_sent = 0
        self.pseudo_fused = 0
        self.rec: dict[str, list[tuple[float, FloatArray, FloatArray]]] = {m: [] for m in METHODS}

    @property
    def initialised(self) -> bool:
        return self.inner.initialised

    def _gap_started(self) -> None:
        if not self.in_gap:
            self.in_gap = True
            self.pot.refit(force=True)

    def on_imu(self, sample: ImuSample) -> None:
        self.inner.on_imu(sample)
        if self.pseudo_dt is None or sample.t_s < self.next_pseudo or not self.fix_t:
            return
        if sample.t_s < self.t_gap0:
            return
        self._gap_started()
        self.next_pseudo += self.pseudo_dt
        pred = self.pot.predict(sample.t_s)
        nan3 = np.full(3, np.nan)
        meas = GnssMeasurement(
            sample.t_s, pred.pos_ned_m, np.diag(pred.cov_ned_m2).copy(), nan3, nan3,
            self.fix_type, 0,
        )  # fmt: skip
        self.pseudo_sent += 1
        self.pseudo_fused += self.inner.on_gnss(meas).fused

    def on_attitude(self, sample: AttitudeSample, yaw_correction_rad: float) -> None:
        self.inner.on_attitude(sample, yaw_correction_rad)

    def on_gnss(self, meas: GnssMeasurement, *, gate: bool = True) -> GnssUpdate:
        self.fix_t.append(meas.t_s)
        self.fix_pos.append(meas.pos_ned_m)
        self.fix_type = meas.fix_type
        self.pot.add_fix(meas.t_s, meas.pos_ned_m, meas.pos_var_ned_m2, meas.vel_ned_mps)
        return self.inner.on_gnss(meas, gate=gate)

    def predict(self, t_s: float) -> NavState | None:
        st = self.inner.predict(t_s)
        if st is None or t_s < self.t_gap0 or not self.fix_t:
            return st
        self._gap_started()
        if self.pseudo_dt is not None:
            self.rec["ins+pot(pseudo)"].append((t_s, st.pos_ned_m, st.pos_cov_ned_m2))
            return st
        pot = self.pot.predict(t_s)
        t = np.array(self.fix_t)
        cv = cv_predict(t, np.vstack(self.fix_pos), t.size - 1, t_s)
        comb, comb_cov = combine_predictions(
            st.pos_ned_m, st.pos_cov_ned_m2, pot.pos_ned_m, pot.cov_ned_m2
        )
        self.rec["ins"].append((t_s, st.pos_ned_m, st.pos_cov_ned_m2))
        self.rec["potential"].append((t_s, pot.pos_ned_m, pot.cov_ned_m2))
        self.rec["cv"].append((t_s, cv, np.full((3, 3), np.nan)))
        self.rec["ins+pot(cov)"].append((t_s, comb, comb_cov))
        # both are carried from the same fixes: their error at the gap start is shared
        comb, comb_cov, _ = combine_with_ins(st.pos_ned_m, st.pos_cov_ned_m2, pot, math.inf)
        self.rec["ins+pot(cov,sh)"].append((t_s, comb, comb_cov))
        # the engine's rule: the same, while the two agree (chi2 gate), then INS to the end
        if not self.disagreed:
            comb, comb_cov, c2 = combine_with_ins(st.pos_ned_m, st.pos_cov_ned_m2, pot, self.gate)
            self.disagreed = c2 > self.gate
        if self.disagreed:
            comb, comb_cov = st.pos_ned_m, st.pos_cov_ned_m2
        self.rec["ins+pot(gated)"].append((t_s, comb, comb_cov))
        return st

    def reset(self) -> None:
        self.inner.reset()
        self.pot.reset()

    def reset_heading(self, yaw_sigma_rad: float) -> None:
        self.inner.reset_heading(yaw_sigma_rad)

    def shift_frame(self, old: LocalFrame, new: LocalFrame) -> None:
        self.inner.shift_frame(old, new)


@dataclass
class GapErrors:
    """Per (grade, gap, method): per-run mean and max of 3-D, 2-D, vertical error [m]
    and per-run mean normalised error squared (3 dof) of the method's covariance."""

    runs: list[tuple[float, float, float, float, float, float, float]] = field(default_factory=list)


def _errors(
    rec: list[tuple[float, FloatArray, FloatArray]], truth: Callable[[float], FloatArray]
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    t = np.array([r[0] for r in rec])
    e = np.vstack([r[1] - truth(r[0]) for r in rec])
    nees = np.array([float(ei @ np.linalg.solve(r[2], ei)) if np.all(np.isfinite(r[2])) else
                     np.nan for ei, r in zip(e, rec, strict=True)])  # fmt: skip
    return t, np.linalg.norm(e, axis=1), np.hypot(e[:, 0], e[:, 1]), np.abs(e[:, 2]), nees


def part_b(
    seeds: int,
    gaps: tuple[float, ...],
    grades: tuple[str, ...],
    pseudo_hz: float,
    kind: str = "approach",
    realistic_seeds: int = 0,
) -> None:
    """5/10/20-s gaps (all GNSS withheld) in the glide of simulated approaches, or in the
    turning cruise of simulated cruises (``kind``); ``realistic_seeds`` more flights as the
    realistic ArduPlane autopilot delivers them (``bench/outage.py``'s realistic flights)."""
    cells: dict[tuple[str, float, str], GapErrors] = {}
    fusion: dict[str, list[int]] = {g: [0, 0] for g in grades}
    alphas: dict[str, list[tuple[float, float]]] = {g: [] for g in grades}
    rcells: dict[tuple[str, float, str], GapErrors] = {}
    rfusion: dict[str, list[int]] = {g: [0, 0] for g in grades}
    ralphas: dict[str, list[tuple[float, float]]] = {g: [] for g in grades}
    max_gap = max(gaps)
    runs = [(False, s) for s in range(seeds)] + [(True, s) for s in range(realistic_seeds)]
    for grade in grades:
        for real, seed in runs:
            _progress(f"part B: {grade} {kind}, seed {seed}{' (realistic)' if real else ''}")
            flight = simulate_flight(kind, grade, seed, max_gap, realistic=real)
            t_gap0 = outage_start_s(flight, kind)
            _part_b_flight(
                flight, grade, seed, t_gap0, max_gap, gaps, pseudo_hz,
                rcells if real else cells, rfusion if real else fusion,
                ralphas if real else alphas,
            )  # fmt: skip
    _part_b_tables(kind, seeds, gaps, grades, pseudo_hz, cells, fusion, alphas, rcells)


def _part_b_flight(
    flight: SimFlight,
    grade: str,
    seed: int,
    t_gap0: float,
    max_gap: float,
    gaps: tuple[float, ...],
    pseudo_hz: float,
    cells: dict[tuple[str, float, str], GapErrors],
    fusion: dict[str, list[int]],
    alphas: dict[str, list[tuple[float, float]]],
) -> None:
    def truth(t: float, fl: SimFlight = flight) -> FloatArray:
        return np.asarray(fl.truth.at(t).pos_ned_m)

    cfg = BlendConfig.for_grade(grade, mode="strapdown", adaptive=True)
    rec = GapRecorder(BlendNavigator(cfg, flight.frame), t_gap0, seed)
    run_one(rec, flight, t_gap0, max_gap, None)
    alphas[grade].append((rec.pot.alpha_ps, rec.pot.g_ps2))
    pse = GapRecorder(BlendNavigator(cfg, flight.frame), t_gap0, seed, pseudo_hz)
    run_one(pse, flight, t_gap0, max_gap, None)
    fusion[grade][0] += pse.pseudo_fused
    fusion[grade][1] += pse.pseudo_sent
    for method in METHODS:
        src = pse if method == "ins+pot(pseudo)" else rec
        t, e3, e2, ev, nees = _errors(src.rec[method], truth)
        for gap in gaps:
            m = (t - t_gap0) <= gap + 1e-9
            row = (
                float(e3[m].mean()), float(e3[m].max()), float(e2[m].mean()),
                float(e2[m].max()), float(ev[m].mean()), float(ev[m].max()),
                float(np.nanmean(nees[m])) if np.any(np.isfinite(nees[m])) else np.nan,
            )  # fmt: skip
            cells.setdefault((grade, gap, method), GapErrors()).runs.append(row)


def _part_b_tables(
    kind: str,
    seeds: int,
    gaps: tuple[float, ...],
    grades: tuple[str, ...],
    pseudo_hz: float,
    cells: dict[tuple[str, float, str], GapErrors],
    fusion: dict[str, list[int]],
    alphas: dict[str, list[tuple[float, float]]],
    rcells: dict[tuple[str, float, str], GapErrors],
) -> None:
    print(
        f"\nPart B - {kind} flights (simulator), {seeds} seeds per cell: "
        "all GNSS withheld\n(approach: 40 s into the glide; cruise: 70 s into the turning "
        "cruise); errors through the gap at 10 Hz [m]: "
        "mean over seeds of the per-run\nmean / max over seeds of the per-run max. ratio = "
        "3-D mean / CV's; vs best = 3-D mean / the\nbetter of INS and potential alone; "
        "NEES = mean normalised error squared (expect 3)."
    )
    for grade in grades:
        a = np.array(alphas[grade])
        print(
            f"\n## {grade} IMU  (alpha at the gap: median {np.median(a[:, 0]):.2f} 1/s, "
            f"G {np.median(a[:, 1]):.3g} 1/s^2; pseudo-measurements fused "
            f"{fusion[grade][0]}/{fusion[grade][1]} at {pseudo_hz:g} Hz)"
        )
        hdr = (
            f"{'gap s':>5} {'method':<16} {'3-D mean':>9} {'3-D max':>8} {'2-D mean':>9} "
            f"{'2-D max':>8} {'V mean':>7} {'V max':>7} {'ratio':>6} {'vs best':>7} {'NEES':>7}"
            + (f" | {'real. 3-D mean':>14} {'V mean':>7} {'NEES':>8}" if rcells else "")
        )
        print(hdr)
        for gap in gaps:
            agg = {}
            for method in METHODS:
                r = np.array(cells[(grade, gap, method)].runs)
                agg[method] = (
                    r[:, 0].mean(), r[:, 1].max(), r[:, 2].mean(), r[:, 3].max(),
                    r[:, 4].mean(), r[:, 5].max(),
                    np.nanmean(r[:, 6]) if np.any(np.isfinite(r[:, 6])) else np.nan,
                )  # fmt: skip
            best = min(agg["ins"][0], agg["potential"][0])
            for method in METHODS:
                v = agg[method]
                vs = f"{v[0] / best:7.2f}" if method.startswith("ins+") else f"{'':7}"
                print(
                    f"{gap:5.0f} {method:<16} {v[0]:9.3f} {v[1]:8.3f} {v[2]:9.3f} {v[3]:8.3f} "
                    f"{v[4]:7.3f} {v[5]:7.3f} {v[0] / agg['cv'][0]:6.2f} {vs} {v[6]:7.2f}"
                    + _real_cells(rcells, (grade, gap, method))
                )
    if rcells:
        n_r = len(next(iter(rcells.values())).runs)
        print(
            f"realistic: {n_r} flights per cell as the realistic ArduPlane autopilot delivers "
            "them (RAW_IMU 10 Hz, bias, vibration, ATTITUDE trim, GNSS 5 Hz, 0.2 s latency)"
        )


def _real_cells(
    rcells: dict[tuple[str, float, str], GapErrors], key: tuple[str, float, str]
) -> str:
    if not rcells or key not in rcells:
        return ""
    r = np.array(rcells[key].runs)
    nees = np.nanmean(r[:, 6]) if np.any(np.isfinite(r[:, 6])) else np.nan
    return f" | {r[:, 0].mean():14.3f} {r[:, 4].mean():7.3f} {nees:8.3g}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", choices=["all", "A", "timing", "B"], default="all")
    ap.add_argument("--seeds", type=int, default=3, help="part A flights (default 3)")
    ap.add_argument("--b-seeds", type=int, default=10, help="part B flights per IMU grade")
    ap.add_argument("--gaps", type=float, nargs="+", default=[5.0, 10.0, 20.0])
    ap.add_argument("--grades", nargs="+", default=["tactical", "mems"])
    ap.add_argument("--flights", nargs="+", default=["approach", "cruise"], help="part B")
    ap.add_argument("--pseudo-hz", type=float, default=1.0, help="pseudo-measurement rate")
    ap.add_argument(
        "--b-realistic-seeds", type=int, default=3, help="part B realistic flights per grade"
    )
    args = ap.parse_args(argv)
    # rejections are counted and printed below instead of logged one by one
    logging.getLogger("companion.nav.potential").setLevel(logging.ERROR)
    logging.getLogger("companion.nav.blend").setLevel(logging.ERROR)

    if args.part in ("all", "A"):
        res_a = Result()
        for s in range(args.seeds):
            _progress(f"part A: kinematic descent, seed {s}")
            fl = kinematic_descent(s)
            run_flight(fl, (2.0,), 0.5, 25.0, res_a, lambda lab: True, seed=s)
        table(
            res_a,
            (2.0,),
            "Part A - the paper's case: 2-s gaps on a kinematic descent (DGPS-like, 5 Hz)",
        )
        fits_table(res_a)
    if args.part in ("all", "timing"):
        _progress("timing")
        timing_section(0)
    if args.part in ("all", "B"):
        for kind in args.flights:
            part_b(
                args.b_seeds, tuple(args.gaps), tuple(args.grades), args.pseudo_hz, kind,
                args.b_realistic_seeds,
            )  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

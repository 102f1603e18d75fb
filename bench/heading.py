"""Bench: taxi heading correction on seeded simulated taxis, against a one-shot baseline.

The correction is that of Markelov et al., "INS course correction from
satellite navigation before take-off" (:mod:`companion.nav.heading`). Each run
simulates a taxi with the project simulator (``companion.sim``, scenario
``taxi``: RTK fixed positions) with drawn overrides: initial heading error
U(-3, 3) deg, taxi speed U(3, 10) m/s, GNSS velocity noise U(0.05, 0.2) m/s
(1 sigma per axis, 10 Hz), 3-6 straight legs of 20-60 s joined by turns of
45-180 deg. The samples go through :class:`companion.nav.heading.HeadingCorrector`
exactly as the engine would feed them, once per configuration (``CONFIGS``).

Error rows, per configuration:

* ``mean-inj``: the correction at HDG_READY minus the injected constant
  heading error (what "error < 0.1 deg with a 1 deg injected error" means);
* ``heading``: the corrected heading error at the READY instant, i.e. the
  simulator's actual ATTITUDE yaw error then minus the correction (it
  includes the simulated autopilot's slow yaw wander, 0.2 deg 1 sigma, 60 s);
* ``estimator``: the correction minus the mean actual yaw error over the
  cycles it used (the estimator alone, without the wander);

and ``one-shot course`` (what ArduPilot does: the GNSS course of the first
fix above 5 m/s taken as the heading; its error against the true heading
then) and ``uncorrected`` (the ATTITUDE yaw error at the default READY instant).

Time to READY is given both as the straight-taxi time used (cycles x cycle
period) and as the taxi time since the taxi began. The bench also prints the
time the sufficiency rule of Markelov et al. needs in theory,
``(1.96 sigma / eps)^2`` cycles with ``sigma^2`` the expected track variance
plus the INS term, so a run that cannot be ready in 60 s is told apart from an
implementation shortfall.

Realistic columns (``real.``): the same draws for the first ``--realistic-runs``
seeds (default 20), flown as the realistic ArduPlane autopilot delivers them
(:func:`companion.sim.realism.realistic` ``"plane"``: ATTITUDE with a trim tilt, a
3 deg (1 sigma, 120 s) yaw wander and 50 ms lag, GNSS at 5 Hz with 0.2 s latency, a
velocity bias, varying satellites and accuracies; the receiver stays RTK fixed and
the drawn velocity noise is kept).

Run: ``python bench/heading.py [--runs 100] [--seed 1]`` (a few minutes;
progress on stderr).
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from companion.nav.grades import ATTITUDE_ERROR_BY_GRADE  # noqa: E402
from companion.nav.heading import HeadingConfig, HeadingCorrector  # noqa: E402
from companion.nav.rotations import wrap_pi  # noqa: E402
from companion.sim import SimFlight, make_scenario, simulate  # noqa: E402
from companion.sim.realism import realistic as _realistic  # noqa: E402
from companion.types import (  # noqa: E402
    Alert,
    AlertCode,
    AttitudeSample,
    GnssFix,
    LandedState,
    LandedStateSample,
    VfrHudSample,
)

BASELINE_SPEED_MPS = 5.0
"""ArduPilot-style one-shot alignment: the GNSS course above this ground speed."""
TARGET_MAX_ERR_DEG = 10.0 / 60.0
TARGET_READY_S = 60.0
GNSS_RATE_HZ = 10.0


@dataclass
class CorrectorResult:
    """One configuration on one flight."""

    pred_ready_s: float
    ready: bool = False
    rejects: list[str] = field(default_factory=list)
    err_mean_deg: float = math.nan
    err_heading_deg: float = math.nan
    err_estimator_deg: float = math.nan
    err_uncorrected_deg: float = math.nan
    straight_s: float = math.nan
    taxi_s: float = math.nan


@dataclass
class RunResult:
    seed: int
    speed_mps: float
    noise_mps: float
    err_inj_deg: float
    total_straight_s: float
    by_config: dict[str, CorrectorResult]
    base_err_deg: float = math.nan
    base_taxi_s: float = math.nan


def draw_scenario(rng: np.random.Generator) -> dict[str, object]:
    speed = float(rng.uniform(3.0, 10.0))
    n_legs = int(rng.integers(3, 7))
    legs = []
    for _ in range(n_legs):
        straight_s = float(rng.uniform(20.0, 60.0))
        turn = float(rng.uniform(45.0, 180.0)) * (1.0 if rng.random() < 0.5 else -1.0)
        legs.append((speed * straight_s, turn))
    return {
        "heading_error_deg": float(rng.uniform(-3.0, 3.0)),
        "taxi_speed_mps": speed,
        "gnss_vel_noise_mps": float(rng.uniform(0.05, 0.2)),
        "taxi_legs": tuple(legs),
        "stand_heading_deg": float(rng.uniform(-180.0, 180.0)),
        "gnss_rate_hz": GNSS_RATE_HZ,
        "imu_rate_hz": 10.0,  # the corrector does not use the IMU: keep the simulation light
    }


def uses_position_track(config: HeadingConfig) -> bool:
    """The bench's taxis are RTK fixed throughout, so ``auto`` takes the position track."""
    return config.track_source in ("position", "auto")


def cycle_period_s(config: HeadingConfig) -> float:
    """Time between two cycles on a straight leg, s."""
    return config.pos_baseline_s if uses_position_track(config) else 1.0 / GNSS_RATE_HZ


def predicted_ready_s(config: HeadingConfig, speed_mps: float, noise_mps: float) -> float:
    """Straight-taxi time the sufficiency rule needs with white noise, s."""
    if uses_position_track(config):
        dist = speed_mps * config.pos_baseline_s
        sig2 = 2.0 * config.pos_diff_sigma_m**2 / dist**2
    else:
        sig2 = (noise_mps / speed_mps) ** 2
    sig2 += math.radians(config.ins_yaw_noise_deg) ** 2
    cycles = (config.z_score * math.sqrt(sig2) / math.radians(config.eps_limit_deg)) ** 2 + 1.0
    min_cycles = config.pos_min_cycles if uses_position_track(config) else config.min_cycles
    return max(cycles, min_cycles) * cycle_period_s(config)


def run_corrector(
    flight: SimFlight, config: HeadingConfig, speed: float, noise: float
) -> CorrectorResult:
    sc = flight.scenario
    res = CorrectorResult(pred_ready_s=predicted_ready_s(config, speed, noise))
    taxi_start = next((t0 for ph, t0, _ in flight.phases if ph == "taxi"), math.nan)
    att_t = flight.errors.attitude_t_s
    att_yaw_err = flight.errors.attitude_err_rad[:, 2]

    def att_err_at(t_s: float | np.ndarray) -> np.ndarray:
        return np.asarray(np.interp(t_s, att_t, att_yaw_err))

    hc = HeadingCorrector(config)
    for s in flight.samples:
        if isinstance(s, AttitudeSample):
            hc.on_attitude(s)
        elif isinstance(s, LandedStateSample):
            ls = s.landed_state
            hc.on_landed_state(None if ls is LandedState.UNDEFINED else ls is LandedState.ON_GROUND)
        elif isinstance(s, VfrHudSample):
            hc.on_vfr_hud(s)
        elif isinstance(s, GnssFix):
            for o in hc.on_gnss(s):
                if not isinstance(o, Alert):
                    continue
                if o.code is AlertCode.HDG_REJECT:
                    res.rejects.append(o.text)
                elif o.code is AlertCode.HDG_READY and hc.candidate is not None:
                    c = hc.candidate
                    corr_deg = math.degrees(c.correction_rad)
                    err_now_deg = math.degrees(float(att_err_at(o.t_s)))
                    used = hc.cycle_times_s()
                    res.ready = True
                    res.err_mean_deg = corr_deg - sc.heading_error_deg
                    res.err_heading_deg = err_now_deg - corr_deg
                    res.err_uncorrected_deg = err_now_deg
                    res.err_estimator_deg = corr_deg - math.degrees(
                        float(np.mean(att_err_at(used)))
                    )
                    res.straight_s = c.n * cycle_period_s(config)
                    res.taxi_s = o.t_s - taxi_start
            if res.ready:
                break
    return res


def one_run(seed: int, configs: dict[str, HeadingConfig], realistic: bool = False) -> RunResult:
    rng = np.random.default_rng(seed)
    over = draw_scenario(rng)
    if realistic:
        keep = ("gnss_mode", "gnss_vel_noise_mps")
        over.update({k: v for k, v in _realistic("plane").items() if k not in keep})
    sc = make_scenario("taxi", **over)
    flight = simulate(sc, seed)
    speed = sc.taxi_speed_mps
    noise = sc.gnss_vel_noise_mps
    res = RunResult(
        seed=seed,
        speed_mps=speed,
        noise_mps=noise,
        err_inj_deg=sc.heading_error_deg,
        total_straight_s=sum(length for length, _ in sc.taxi_legs) / speed,
        by_config={name: run_corrector(flight, cfg, speed, noise) for name, cfg in configs.items()},
    )
    # baseline: the GNSS course of the first fix above 5 m/s becomes the heading
    taxi_start = next((t0 for ph, t0, _ in flight.phases if ph == "taxi"), math.nan)
    for s in flight.samples:
        if (
            isinstance(s, GnssFix)
            and s.course_rad is not None
            and s.ground_speed_mps > BASELINE_SPEED_MPS
        ):
            true_yaw = float(flight.truth.sample(np.array([s.t_s])).euler_rad[0, 2])
            res.base_err_deg = math.degrees(wrap_pi(s.course_rad - true_yaw))
            res.base_taxi_s = s.t_s - taxi_start
            break
    return res


def pct(x: np.ndarray, q: float) -> float:
    return float(np.percentile(x, q)) if x.size else math.nan


def amax(x: np.ndarray) -> float:
    return float(np.max(x)) if x.size else math.nan


def real_cols(err: np.ndarray | None, n_total: int) -> str:
    """The realistic columns of an error row."""
    if err is None:
        return ""
    a = np.abs(err[np.isfinite(err)])
    return f" | {a.size:>4}/{n_total:<4} {pct(a, 50):>8.3f} {pct(a, 95):>8.3f} {amax(a):>8.3f}"


def err_row(name: str, err: np.ndarray, n_total: int, base_max: float) -> str:
    a = np.abs(err[np.isfinite(err)])
    mx = amax(a)
    ratio = mx / base_max if base_max > 0 else math.nan
    return (
        f"{name:<46} {a.size:>4}/{n_total:<4} {pct(a, 50):>8.3f} {pct(a, 95):>8.3f} {mx:>8.3f}"
        f" {ratio:>9.3f}"
    )


def time_row(name: str, t: np.ndarray) -> str:
    return f"{name:<54} {pct(t, 50):>8.1f} {pct(t, 95):>8.1f} {amax(t):>8.1f}"


GRADE = make_scenario("taxi").imu_grade
"""IMU grade of the simulated taxis (and so of the autopilot's heading error model)."""

CONFIGS: dict[str, HeadingConfig] = {
    "default (auto: RTK position track)": HeadingConfig(),
    "velocity track, eps<=0.05": HeadingConfig(track_source="velocity"),
    "velocity track, eps<=0.085": HeadingConfig(
        track_source="velocity", eps_limit_deg=TARGET_MAX_ERR_DEG / 1.96
    ),
}
"""Configurations run on the same flights: the service's default (``auto``: the
track from the RTK displacement over 1 s while fixes are RTK fixed, as they are
in these taxis), the method as published by Markelov et al. (the track from
each fix's Doppler velocity), and the same with the sufficiency limit that makes
its 95 % accuracy match the bench's error target."""


def main() -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--realistic-runs", type=int, default=20)
    args = ap.parse_args()
    if args.runs < 1:
        print("--runs must be >= 1", file=sys.stderr)
        return 2
    # rejections are counted in the tables; keep the per-run log lines off the console
    logging.getLogger("companion").setLevel(logging.ERROR)
    results: list[RunResult] = []
    t_start = time.perf_counter()
    for k in range(args.runs):
        results.append(one_run(args.seed * 100_000 + k, CONFIGS))
        if (k + 1) % 5 == 0 or k + 1 == args.runs:
            el = time.perf_counter() - t_start
            print(f"[heading bench] {k + 1}/{args.runs} runs, {el:.0f} s", file=sys.stderr)

    real: list[RunResult] = []
    for k in range(min(args.realistic_runs, args.runs)):
        real.append(one_run(args.seed * 100_000 + k, CONFIGS, realistic=True))
    print(f"[heading bench] {len(real)} realistic runs", file=sys.stderr)
    nr = len(real)

    n = len(results)
    base = np.array([r.base_err_deg for r in results])
    base_max = float(np.nanmax(np.abs(base))) if np.isfinite(base).any() else math.nan
    print()
    print(
        f"Taxi heading correction (Markelov et al.), {n} seeded simulated taxis "
        f"(seed base {args.seed})"
    )
    print("draws: heading error U(-3,3) deg, speed U(3,10) m/s, GNSS velocity noise")
    print("U(0.05,0.2) m/s (1 sigma/axis) at 10 Hz, 3-6 legs of 20-60 s, turns 45-180 deg;")
    sigma_rad, tau_s = ATTITUDE_ERROR_BY_GRADE[GRADE]
    print(
        f"simulated ATTITUDE yaw also wanders (Gauss-Markov {math.degrees(sigma_rad[2]):.2f} deg, "
        f"{tau_s:.0f} s: the {GRADE} grade's autopilot heading)"
    )
    print()
    print("|error| in deg over the runs that produced a heading; ratio = max / one-shot max")
    print(
        f"{'method':<46} {'runs':>9} {'median':>8} {'95 %':>8} {'max':>8} {'max/base':>9}"
        + (f" | {'real. runs':>9} {'median':>8} {'95 %':>8} {'max':>8}" if nr else "")
    )
    for name in CONFIGS:
        rs = [r.by_config[name] for r in results]
        rr = [r.by_config[name] for r in real]

        def col(attr: str, rs: list[CorrectorResult] = rs) -> np.ndarray:
            return np.array([getattr(x, attr) for x in rs], dtype=float)

        for label, attr in (
            ("mean-inj", "err_mean_deg"), ("heading", "err_heading_deg"),
            ("estimator", "err_estimator_deg"),
        ):  # fmt: skip
            print(
                err_row(f"{name} {label}", col(attr), n, base_max)
                + (real_cols(col(attr, rr), nr) if nr else "")
            )
    name0 = next(iter(CONFIGS))
    unc = np.array([r.by_config[name0].err_uncorrected_deg for r in results])
    unc_r = np.array([r.by_config[name0].err_uncorrected_deg for r in real])
    print(err_row("uncorrected (at default READY)", unc, n, base_max) + real_cols(
        unc_r if nr else None, nr))  # fmt: skip
    base_r = np.array([r.base_err_deg for r in real])
    print(err_row("one-shot course > 5 m/s", base, n, base_max) + real_cols(
        base_r if nr else None, nr))  # fmt: skip
    print()
    print("time to a heading, s (runs that produced one)")
    print(f"{'method':<54} {'median':>8} {'95 %':>8} {'max':>8}")
    for name in CONFIGS:
        rs = [r.by_config[name] for r in results if r.by_config[name].ready]
        print(time_row(f"{name}: straight taxi used", np.array([x.straight_s for x in rs])))
        print(time_row(f"{name}: since taxi start", np.array([x.taxi_s for x in rs])))
    bt = base[np.isfinite(base)]
    print(
        time_row(
            "one-shot: since taxi start",
            np.array([r.base_taxi_s for r in results if math.isfinite(r.base_taxi_s)]),
        )
    )
    print(f"one-shot never aligned (taxi never above 5 m/s): {n - bt.size}/{n}")
    print()
    for name, cfg in CONFIGS.items():
        rs = [r.by_config[name] for r in results]
        ready = np.array([x.ready for x in rs])
        in60 = np.array([x.ready and x.straight_s <= TARGET_READY_S for x in rs])
        feasible = np.array([x.pred_ready_s <= TARGET_READY_S for x in rs])
        rejected = sum(1 for x in rs if x.rejects)
        errs = np.abs(np.array([x.err_mean_deg for x in rs if x.ready]))
        print(
            f"{name}: READY {int(ready.sum())}/{n}; within {TARGET_READY_S:.0f} s of "
            f"straight taxi {int(in60.sum())}/{n} ({100.0 * in60.mean():.0f} %); "
            f"runs with HDG_REJECT {rejected}"
        )
        print(
            f"  theory (white noise): {int(feasible.sum())}/{n} runs can reach eps <= "
            f"{cfg.eps_limit_deg:.3f} deg in {TARGET_READY_S:.0f} s; of those ready in time: "
            f"{int(in60[feasible].sum())}/{int(feasible.sum())}"
        )
        print(
            f"  mean-inj |error| <= {TARGET_MAX_ERR_DEG:.3f} deg: "
            f"{int((errs <= TARGET_MAX_ERR_DEG).sum())}/{errs.size} READY runs"
        )
        reasons: dict[str, int] = {}
        for x in rs:
            for t in x.rejects:
                reasons[t.split()[0]] = reasons.get(t.split()[0], 0) + 1
        if reasons:
            print(
                "  HDG_REJECT reasons: "
                + ", ".join(f"{k} x{v}" for k, v in sorted(reasons.items()))
            )
    for name in CONFIGS if nr else ():
        rr = [r.by_config[name] for r in real]
        reasons_r: dict[str, int] = {}
        for x in rr:
            for t in x.rejects:
                reasons_r[t.split()[0]] = reasons_r.get(t.split()[0], 0) + 1
        print(
            f"realistic, {name}: READY {sum(x.ready for x in rr)}/{nr}; runs with HDG_REJECT "
            f"{sum(1 for x in rr if x.rejects)}"
            + ("; reasons: " + ", ".join(f"{k} x{v}" for k, v in sorted(reasons_r.items()))
               if reasons_r else "")
        )  # fmt: skip
    print(f"wall time {time.perf_counter() - t_start:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())

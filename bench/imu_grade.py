"""The IMU grade self-check: simulated flights with truth and the real logs.

Run: ``python bench/imu_grade.py [--seeds N]`` (default 3 seeds per flight; about a
minute). Progress goes to stderr; the tables to stdout.

**Simulated** (the ``approach`` and ``cruise_gnss_loss`` flights, seeded), through the
engine with the tactical grade's configuration (``sitl_fixtures/tactical.toml``'s blend):

* ``right``: a tactical IMU (the check must stay silent);
* ``mems``: a MEMS IMU, both checks on (the white-noise test is expected first);
* ``mems innov``: the same with the white-noise test off: the innovations alone;
* ``gyro bias``: a tactical IMU's white noise with a MEMS gyro's turn-on bias
  (0.05 deg/s) and rate random walk (3e-5 rad/s/sqrt(s)): white noise cannot show it.

Per run: the first ``IMU_GRADE`` alert (time after the first fix, and which test), the
windows judged before it, their mean and largest NIS per degree of freedom, the
navigator resets to the receiver (``FAULT ... reset to it``) before and after.

**Real logs** (``../shared/realdata/flights``, absent: skipped with the reason): each
replayed with the default MEMS configuration, where the check does not run (no wider
grade to fall back to), with the check attached as an observer that never acts: the
windows' NIS per degree of freedom and when 3 of 6 would have failed (what the check
would say of a correct grade on a real aircraft); then with ``tactical.toml``, whose
grade is wrong for these MEMS autopilots: the ``IMU_GRADE`` alert.
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import companion.sim as sim  # noqa: E402
from companion.config import Config, load_config  # noqa: E402
from companion.engine import Engine  # noqa: E402
from companion.engine.config import EngineConfig  # noqa: E402
from companion.mavlink.decode import LIGHT_MESSAGE_IDS  # noqa: E402
from companion.mavlink.logs import open_flight_log  # noqa: E402
from companion.nav.imu_innovations import ImuInnovationCheck, ImuInnovationConfig  # noqa: E402
from companion.pipeline import Pipeline  # noqa: E402
from companion.sim.realism import Realism  # noqa: E402
from companion.types import Alert, AlertCode, GnssFix  # noqa: E402

FLIGHTS_DIR = ROOT.parent / "shared" / "realdata" / "flights"
TACTICAL_TOML = ROOT / "sitl_fixtures" / "tactical.toml"
GYRO_BIAS = Realism(gyro_bias_radps=0.05 * math.pi / 180.0, gyro_rw_radps_rts=3e-5)


@dataclass
class Run:
    alert_s: float | None
    test: str
    windows: list[float]
    resets_before: int
    resets_after: int


def fly(samples: list, engine: Engine, noise_test: bool) -> Run:
    """The samples through the engine; the windows judged before the first IMU_GRADE."""
    if not noise_test:
        engine.imu_check = None
    first_fix: float | None = None
    alert: Alert | None = None
    ratios: list[float] = []
    judged = 0
    resets = [0, 0]
    for s in samples:
        if first_fix is None and isinstance(s, GnssFix):
            first_fix = s.t_s
        for out in engine.handle(s):
            if not isinstance(out, Alert):
                continue
            if out.code is AlertCode.IMU_GRADE and alert is None:
                alert = out
            elif out.code is AlertCode.FAULT and "reset to it" in out.text:
                resets[alert is not None] += 1
        check = engine.imu_innovations
        if check is not None and check.judged > judged:
            judged = check.judged
            ratios.append(check.windows[-1].ratio)
    if alert is None:
        return Run(None, "-", ratios, resets[0], resets[1])
    test = "innovations" if alert.text.startswith("IMU innovations") else "white noise"
    return Run(alert.t_s - (first_fix or 0.0), test, ratios, resets[0], resets[1])


def simulated(seeds: int) -> None:
    from companion.nav.blend import BlendConfig

    tactical = BlendConfig.for_grade("tactical", mode="strapdown")
    cases = (
        ("right", "tactical", None, True),
        ("mems", "mems", None, True),
        ("mems innov", "mems", None, False),
        ("gyro bias", "tactical", GYRO_BIAS, False),
    )
    print("Simulated flights, tactical configuration (IMU_GRADE: s after the first fix)")
    header = (
        f"{'flight':18s} {'seed':>4s} {'case':11s} {'IMU_GRADE':>9s} {'by':12s} "
        f"{'windows':>7s} {'NIS/dof mean':>12s} {'max':>5s} {'resets b/a':>10s}"
    )
    print(header)
    print("-" * len(header))
    for name in ("approach", "cruise_gnss_loss"):
        for seed in range(1, seeds + 1):
            for label, grade, realism, noise_test in cases:
                print(f"{name} {seed} {label}", file=sys.stderr)
                sc = sim.make_scenario(name, imu_grade=grade, realism=realism)
                flight = sim.simulate(sc, seed=seed)
                run = fly(flight.samples, Engine(EngineConfig(), blend=tactical), noise_test)
                w = np.array(run.windows) if run.windows else np.array([math.nan])
                when = "-" if run.alert_s is None else f"{run.alert_s:.1f}"
                print(
                    f"{name:18s} {seed:4d} {label:11s} {when:>9s} {run.test:12s} "
                    f"{len(run.windows):7d} {np.nanmean(w):12.2f} {np.nanmax(w):5.2f} "
                    f"{run.resets_before:>5d}/{run.resets_after:<4d}"
                )


def replay_log(path: Path, config: Config, observe: bool) -> tuple[list[float], list[Alert]]:
    """``path`` through a pipeline (messages only, no timers); with ``observe`` the in-flight
    check attached as an observer that never doubts: every window it judged."""
    pipeline = Pipeline(config)
    engine = pipeline.engine
    if observe:
        engine.imu_innovations = ImuInnovationCheck(
            ImuInnovationConfig(windows_needed=10_000, windows_span=10_000)
        )
    alerts: list[Alert] = []
    for t_rx_s, msg in open_flight_log(path, light_ids=LIGHT_MESSAGE_IDS):
        pipeline.on_message(msg, t_rx_s)
    alerts = list(pipeline.alerts)
    check = engine.imu_innovations
    ratios = [w.ratio for w in check.windows] if observe and check is not None else []
    return ratios, alerts


def would_fire(ratios: list[float], cfg: ImuInnovationConfig) -> int | None:
    """The window at which ``windows_needed`` of the last ``windows_span`` exceed the margin
    (the chi-square bound of a 10 s window is below it), or None."""
    failed = [r > cfg.min_ratio for r in ratios]
    for k in range(len(failed)):
        if sum(failed[max(0, k - cfg.windows_span + 1) : k + 1]) >= cfg.windows_needed:
            return k + 1
    return None


def real_logs() -> None:
    tlogs = sorted(FLIGHTS_DIR.glob("*/*.tlog")) if FLIGHTS_DIR.is_dir() else []
    if not tlogs:
        print(f"\nReal logs: skipped, none under {FLIGHTS_DIR}")
        return
    cfg = ImuInnovationConfig()
    default, tactical = load_config(None), load_config(TACTICAL_TOML)
    print("\nReal logs: default (MEMS) configuration, the check as an observer")
    header = (
        f"{'flight':40s} {'windows':>7s} {'NIS/dof mean':>12s} {'max':>5s} "
        f"{'over 1.5':>8s} {'3 of 6 at':>9s}   tactical.toml: IMU_GRADE"
    )
    print(header)
    print("-" * (len(header) + 20))
    for tlog in tlogs:
        print(tlog.stem, file=sys.stderr)
        ratios, alerts = replay_log(tlog, default, observe=True)
        grade = [a for a in alerts if a.code is AlertCode.IMU_GRADE]
        assert not grade, "the check must not act on the default configuration"
        _, alerts_t = replay_log(tlog, tactical, observe=False)
        grade_t = [a for a in alerts_t if a.code is AlertCode.IMU_GRADE]
        w = np.array(ratios) if ratios else np.array([math.nan])
        k = would_fire(ratios, cfg)
        at = "-" if k is None else f"window {k}"
        tac = f"{grade_t[0].t_s:.1f} s {grade_t[0].text[:44]}" if grade_t else "none"
        print(
            f"{tlog.stem[:40]:40s} {len(ratios):7d} {np.nanmean(w):12.2f} {np.nanmax(w):5.2f} "
            f"{int(np.sum(w > cfg.min_ratio)):8d} {at:>9s}   {tac}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=3)
    args = parser.parse_args()
    logging.disable(logging.WARNING)
    simulated(args.seeds)
    real_logs()


if __name__ == "__main__":
    main()

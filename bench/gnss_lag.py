"""The GNSS lag measured in turns: solved jointly with the heading error, against the heading
trusted (in a steady turn at rate w a heading error d looks exactly like a lag d/w).

The flights (those of ``tests/test_self_change.py``): a simulated MEMS aircraft at 45 m/s
banked 13 deg (2.9 deg/s), RTK fixed (15 mm), HIGHRES_IMU at 100 Hz, a receiver velocity
good to 5 mm/s (``--vel-noise``); a steady turn (1440 deg) or alternating turns (270, -270,
270, -270 deg with straights between); the fixes stamped 0 or 80 ms late; seeds 1..N.

Part 1, the lag measurement alone (:class:`~companion.engine.gnss_lag.LagTracker` fed the
flight's samples, the lag it switches in taken at once): per flight and model the windows
that gave an estimate, the RMS of ``(estimate - truth) / sigma`` over them (1: honest), and
what was switched in (lag +/- sigma at t). Models: ``trusted``, the heading's prior at 1e-9
rad (the heading held, as before; this version's sigma and switching rule), and
``joint`` (the default: a heading error per block solved for with the lag). Copied into
the ``bench/`` of a checkout from before the heading term it prints that
checkout's measurement as ``as is``, and its service in part 2.

Part 2 (``--pipeline``): each flight through the service as a replay: FAULT and GNSS_LOST
alerts, the lag switched in and how long it took to carry in, the published horizontal
error (mean, max) and the share of positions beyond 2.45 times the published 1-sigma,
before the switch and from 10 s after it was carried in.

Run: ``python bench/gnss_lag.py [--seeds 3] [--pipeline] [--vel-noise 0.005]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from companion.engine.gnss_lag import LagTracker  # noqa: E402
from companion.mavlink.logs import open_flight_log  # noqa: E402
from companion.nav.gnss_lag import LagConfig  # noqa: E402
from companion.pipeline import Pipeline  # noqa: E402
from companion.sim import make_scenario, simulate  # noqa: E402
from companion.sim.flight import SimFlight  # noqa: E402
from companion.sim.writer import write_tlog  # noqa: E402
from companion.types import (  # noqa: E402
    AttitudeSample,
    GnssFix,
    ImuSample,
    NavMode,
    NavSolution,
    Output,
    Sample,
)

FLIGHTS = {"steady turn": (1440.0,), "alternating turns": (270.0, -270.0, 270.0, -270.0)}
LAGS_S = (0.0, 0.08)
MODELS: tuple[tuple[str, float | None], ...] = (
    (("trusted", 1e-9), ("joint", None))
    if hasattr(LagConfig, "heading_prior_rad")
    else (("as is", None),)  # a checkout from before the heading was solved for
)
EARTH_M = 6_378_137.0


def scenario(turns: tuple[float, ...], vel_noise_mps: float) -> object:
    return make_scenario(
        "nominal",
        flight="cruise",
        imu_grade="mems",
        imu_message="HIGHRES_IMU",
        imu_rate_hz=100.0,
        gnss_mode="rtk_fixed",
        gnss_vel_noise_mps=vel_noise_mps,
        cruise_speed_mps=45.0,
        bank_deg=13.0,
        cruise_s=560.0,
        cruise_turns_deg=turns,
    )


def tracker_run(flight: SimFlight, lag_s: float, heading_prior_rad: float | None) -> str:
    """The lag measurement alone over the flight's samples; one table row's cells."""
    tracker = LagTracker()
    if heading_prior_rad is not None:
        est = tracker.estimator
        est.config = dataclasses.replace(est.config, heading_prior_rad=heading_prior_rad)
    switched = []
    for s in sorted(flight.samples, key=lambda s: s.t_rx_s):
        if isinstance(s, AttitudeSample):
            tracker.on_attitude(s)
        elif isinstance(s, ImuSample):
            tracker.on_imu(s)
        elif isinstance(s, GnssFix) and s.receiver_id == 0:
            tracker.on_fix(dataclasses.replace(s, t_s=s.t_s + lag_s - tracker.lag_in_use_s))
            m = tracker.take()
            if m is not None:
                switched.append(f"{m.lag_s * 1e3:.0f}+/-{m.sigma_s * 1e3:.0f} at {s.t_s:.0f}")
                tracker.restart(m.lag_s)
    w = np.array(tracker._windows) if tracker._windows else np.zeros((0, 2))  # noqa: SLF001
    z = (w[:, 0] - lag_s) / w[:, 1] if len(w) else np.array([math.nan])
    z_rms = float(np.sqrt(np.mean(z * z)))
    return f"{len(w):7d} {z_rms:6.2f}  {'; '.join(switched) or '-'}"


def pipeline_run(flight: SimFlight, lag_s: float, tmp: Path) -> str:
    """The flight through the service; one table row's cells."""
    for _, msg in flight.messages:
        if msg.get_type() == "GPS_RAW_INT":
            msg.time_usec += round(lag_s * 1e6)
    path = write_tlog(flight, tmp / "flight.tlog")
    pipeline = Pipeline()
    engine = pipeline.engine
    handle = engine.handle
    rows: list[tuple[float, float, float, float]] = []

    def published(sample: Sample) -> list[Output]:
        outs = handle(sample)
        for out in outs:
            if isinstance(out, NavSolution) and out.mode is NavMode.NORMAL:
                truth = flight.truth.at(out.t_s)
                dn = (out.lat_rad - truth.lat_rad) * EARTH_M
                de = (out.lon_rad - truth.lon_rad) * EARTH_M * math.cos(truth.lat_rad)
                rows.append(
                    (out.t_s, math.hypot(dn, de), out.h_acc_m, pipeline.decoder.gnss.delay_s[0])
                )
        return outs

    engine.handle = published  # type: ignore[method-assign]
    for t_rx, msg in open_flight_log(path):
        pipeline.on_message(msg, t_rx)
    for _, msg in flight.messages:  # the flight's messages back as they were
        if msg.get_type() == "GPS_RAW_INT":
            msg.time_usec -= round(lag_s * 1e6)
    a = np.array(rows)
    alarms = sum(x.code.value in ("FAULT", "GNSS_LOST") for x in pipeline.alerts)
    lags = a[:, 3]
    moved = np.nonzero(np.diff(lags))[0]

    def part(mask: np.ndarray) -> str:
        if not mask.any():
            return f"{'-':>22s}"
        err, sd = a[mask, 1], a[mask, 2]
        return f"{err.mean():7.3f} {err.max():6.3f} {np.mean(err > 2.45 * sd):6.1%}"

    if len(moved):
        t_start, t_done = a[moved[0] + 1, 0], a[moved[-1] + 1, 0]
        said = f"{lags[-1] * 1e3:5.1f} at {t_start:4.0f} s in {t_done - t_start:4.0f} s"
        before, after = a[:, 0] < t_start, a[:, 0] > t_done + 10.0
    else:
        said, before, after = f"{'-':>21s}", np.ones(len(a), bool), np.zeros(len(a), bool)
    return f"{alarms:6d}  {said}  {part(before)}  {part(after)}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--pipeline", action="store_true", help="also through the service")
    parser.add_argument("--vel-noise", type=float, default=0.005, help="receiver velocity, m/s")
    args = parser.parse_args()
    logging.disable(logging.WARNING)
    flights = {
        (name, seed): simulate(scenario(turns, args.vel_noise), seed)
        for name, turns in FLIGHTS.items()
        for seed in range(1, args.seeds + 1)
    }
    print("The lag measurement alone (windows: that gave an estimate; z: their RMS error/sigma)")
    head = f"{'flight':18s} {'seed':>4s} {'lag':>4s} {'model':8s} {'windows':>7s} {'z':>6s}"
    print(f"{head}  switched")
    for (name, seed), flight in flights.items():
        for lag_s in LAGS_S:
            for model, prior in MODELS:
                cells = tracker_run(flight, lag_s, prior)
                print(f"{name:18s} {seed:4d} {lag_s * 1e3:4.0f} {model:8s} {cells}", flush=True)
    if not args.pipeline:
        return
    print("\nThrough the service (error m: mean, max, share beyond 2.45 sigma)")
    print(
        f"{'flight':18s} {'seed':>4s} {'lag':>4s} {'alarms':>6s}  "
        f"{'switched (ms), carried in':21s}  {'before the switch':>22s}  {'10 s after':>22s}"
    )
    with tempfile.TemporaryDirectory() as tmp:
        for (name, seed), flight in flights.items():
            for lag_s in LAGS_S:
                cells = pipeline_run(flight, lag_s, Path(tmp))
                print(f"{name:18s} {seed:4d} {lag_s * 1e3:4.0f} {cells}", flush=True)


if __name__ == "__main__":
    main()

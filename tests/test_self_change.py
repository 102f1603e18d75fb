"""The service's changes to itself (companion.engine.self_change and the parts it re-seeds):
never blamed on a receiver; a new lag carried in by steps the navigator cannot see.

The end-to-end flights (``slow``): a simulated MEMS aircraft in a steady 13 deg banked
turn with an RTK-fixed receiver, where a heading error looks like a lag, and
the same aircraft in alternating turns with fixes stamped 80 ms late."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as apm

from companion.engine import Engine
from companion.engine.lag_ramp import LagRamp
from companion.integrity.monitor import IntegrityMonitor
from companion.mavlink.logs import open_flight_log
from companion.nav.outage import OutageMonitor
from companion.pipeline import Pipeline
from companion.sim import make_scenario, simulate
from companion.sim.writer import write_tlog
from companion.types import AlertCode, NavMode, NavSolution, Output, Sample
from tests.integrity.test_monitor import alerts, fix, meas, update
from tests.nav.test_outage import rx_fix, used_until

# ----------------------------------------------------------------------------- integrity


def test_an_innovation_failure_after_a_self_change_is_not_blamed_on_the_receiver() -> None:
    """Within one separation window of the change: counted, logged, no exclusion, no
    FAULT; after it, the same failure excludes the receiver."""
    mon = IntegrityMonitor()
    pos = np.zeros(3)
    mon.on_fix(fix(0.0), meas(0.0, pos), update(0.0, 2.0))
    mon.service_changed(0.05, "lag: rx0 placed 35 ms earlier", [0])
    outs = mon.on_fix(fix(0.1), meas(0.1, pos), update(0.1, 18_759.0, fused=False))
    assert alerts(outs, AlertCode.FAULT) == [] and not mon.exclude(0)
    assert mon.stats["self_change_excused"] == 1 and mon.stats["fault_fixes"] == 0
    assert mon.stats["series_restarted_self_change"] == 1
    t = 0.05 + mon.config.separation_window_s + 0.1
    outs = mon.on_fix(fix(t), meas(t, pos), update(t, 18_759.0, fused=False))
    assert len(alerts(outs, AlertCode.FAULT)) == 1 and mon.exclude(0)


def test_a_self_change_of_one_receiver_leaves_the_other_blamable() -> None:
    mon = IntegrityMonitor()
    pos = np.zeros(3)
    mon.service_changed(0.0, "lag: rx0", [0])
    outs = mon.on_fix(fix(0.1, 1), meas(0.1, pos, 1), update(0.1, 500.0, fused=False))
    assert len(alerts(outs, AlertCode.FAULT)) == 1 and mon.exclude(1)


# ----------------------------------------------------------------------------- outage


def _reset_after_rejections(mon: OutageMonitor, t: float) -> tuple[AlertCode, ...]:
    for k in range(4):
        f = rx_fix(t + k * 0.2)
        v = mon.assess(f)
        if v.reinitialise:
            return tuple(a.code for a in v.alerts)
        mon.rejected(f)
        mon.gate_result(f.t_s, False)
    raise AssertionError("no reset")


def test_a_reset_after_a_self_change_is_not_alerted() -> None:
    """The navigator reset to a receiver it rejected: a FAULT normally; within the
    horizon of a change of the service's own, counted and logged only."""
    mon = OutageMonitor()
    t = used_until(mon, 4.0)
    mon.service_changed(t, None, 10.0)
    assert _reset_after_rejections(mon, t) == ()
    assert mon.resets == 1 and mon.resets_self_change == 1
    alone = OutageMonitor()
    t = used_until(alone, 4.0)
    assert _reset_after_rejections(alone, t) == (AlertCode.FAULT,)


# ----------------------------------------------------------------------------- the ramp


def test_a_new_lag_is_carried_in_by_quarter_sigma_steps() -> None:
    """35 ms at 45 m/s (1.6 m) against a 2 cm innovation sigma: steps of 5 mm of fix
    motion, 0.11 ms each; at rest, or with nothing to compare the fix with, at once."""
    ramp = LagRamp()
    ramp.start(0.0, 0.035)
    steps = []
    while ramp.active:
        before = ramp.in_use_s
        steps.append(ramp.step(45.0, 0.02) - before)
    assert abs(len(steps) - math.ceil(0.035 / (0.25 * 0.02 / 45.0))) <= 1
    assert max(abs(s) * 45.0 for s in steps) <= 0.25 * 0.02 + 1e-12
    assert ramp.in_use_s == 0.035
    ramp.start(0.035, 0.0)
    assert ramp.step(0.1, 0.02) == 0.0  # 3.5 mm at 0.1 m/s: within a quarter sigma
    ramp.start(0.0, 0.08)
    assert ramp.step(45.0, math.inf) == 0.08  # no solution yet
    ramp.start(0.0, 0.08)
    assert ramp.step(45.0, 15.0) == 0.08  # in a gap: the solution's metres
    assert ramp.placed_for(10.0) == 10.0


def test_unknown_self_change_is_refused() -> None:
    with pytest.raises(ValueError, match="unknown self-change"):
        Engine().self_change(1.0, "mood", "")


# ----------------------------------------------------------------------------- flights

TURN = {
    "flight": "cruise",
    "imu_grade": "mems",
    "imu_message": "HIGHRES_IMU",
    "imu_rate_hz": 100.0,
    "gnss_mode": "rtk_fixed",
    "gnss_vel_noise_mps": 0.005,
    "cruise_speed_mps": 45.0,
    "bank_deg": 13.0,
    "cruise_s": 560.0,
}
"""A MEMS aircraft at 45 m/s banked 13 deg (2.9 deg/s), RTK fixed (15 mm), a receiver
velocity good to 5 mm/s, HIGHRES_IMU at 100 Hz: in the steady turn (``cruise_turns_deg``
1440) the lag measurement before the heading term switched in 281 ms at 310 s (seed 1),
then FAULT, GNSS_LOST and a re-initialisation 12.6 m off."""


def _fly(tmp: Path, turns: tuple[float, ...], lag_s: float, seed: int) -> Flown:
    """The flight through a pipeline (as a replay), its fixes stamped ``lag_s`` late."""
    flight = simulate(make_scenario("nominal", cruise_turns_deg=turns, **TURN), seed)
    for _, msg in flight.messages:
        if isinstance(msg, apm.MAVLink_gps_raw_int_message):
            msg.time_usec += round(lag_s * 1e6)
    path = write_tlog(flight, tmp / "turn.tlog")
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
                rows.append((out.t_s, math.hypot(dn, de), out.h_acc_m, pipeline.lags.delay_s[0]))
        return outs

    engine.handle = published  # type: ignore[method-assign]
    for t_rx, msg in open_flight_log(path):
        pipeline.on_message(msg, t_rx)
    return Flown(pipeline, np.array(rows))


EARTH_M = 6_378_137.0


@dataclass
class Flown:
    pipeline: Pipeline
    rows: np.ndarray
    """(t_s, horizontal error m, published 1-sigma m, receiver 0's lag in use s) per
    published solution in normal navigation."""

    def codes(self, *names: str) -> list[str]:
        return [
            f"{a.t_s:.1f} {a.code.value} {a.text}"
            for a in self.pipeline.alerts
            if a.code.value in names
        ]


@pytest.mark.slow
def test_steady_banked_turn_switches_no_lag_and_raises_nothing(tmp_path: Path) -> None:
    """The steady turn: a heading error there is a lag, so none is measured
    (the heading is solved for with it), none is switched in, nothing is alerted, and the
    published error stays within the published accuracy."""
    flown = _fly(tmp_path, (1440.0,), 0.0, seed=1)
    p = flown.pipeline
    assert flown.codes("FAULT", "GNSS_LOST", "INTEGRITY", "GNSS_STALE") == []
    assert p.lags.measured_s is None and p.engine.integrity.stats["self_change_lag"] == 0
    err, sigma = flown.rows[:, 1], flown.rows[:, 2]
    assert len(err) > 5000
    assert np.mean(err > 2.45 * sigma) <= 0.05, np.max(err / sigma)


@pytest.mark.slow
def test_a_real_lag_is_measured_in_turns_and_carried_in_without_an_alarm(tmp_path: Path) -> None:
    """Alternating 13 deg turns, fixes stamped 80 ms late: the lag is measured from the
    turns' entries and exits, switched in on six windows and carried in by quarter-sigma
    steps; no FAULT or GNSS_LOST, every fix fused."""
    flown = _fly(tmp_path, (270.0, -270.0, 270.0, -270.0), 0.08, seed=1)
    p = flown.pipeline
    assert flown.codes("FAULT", "GNSS_LOST", "INTEGRITY", "GNSS_STALE") == []
    measured = p.lags.measured_s
    assert measured is not None and abs(measured - 0.08) < 0.006, measured
    lags = flown.rows[:, 3]
    assert lags[0] == 0.0 and lags[-1] == measured  # carried in by the end
    steps = p.engine.integrity.stats["self_change_lag"]
    assert steps > 100  # 3.6 m at 45 m/s, in steps of a quarter of ~2 cm
    assert p.engine.stats.gnss["gate_rejected"] == 0 and p.engine.stats.gnss["excluded"] == 0
    # once carried in, the error is the measurement's (45 m/s x its few ms), not 3.6 m
    done = flown.rows[lags == measured]
    assert np.max(done[:, 1]) < 45.0 * abs(measured - 0.08) + 0.05

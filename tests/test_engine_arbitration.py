"""The engine's arbitration: a receiver judged by its own evidence, rejection bounded,
and a slow IMU not used to dead-reckon (constructed streams with known truth)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from companion.engine.config import EngineConfig
from companion.engine.core import Engine
from companion.types import Alert, AlertCode, GnssFix, ImuSample, NavSolution
from tests.helpers import ORIGIN, Line, line_stream

LINE = Line((30.0, 10.0, -1.0))


def run(stream, engine):
    outs = []
    for sample in stream:
        outs += engine.handle(sample)
    return outs


def errors_m(outs, t0_s=10.0):
    """(t, horizontal error) of every published solution against the line."""
    res = []
    for s in outs:
        if isinstance(s, NavSolution):
            pos = ORIGIN.lla_to_ned(s.lat_rad, s.lon_rad, s.alt_msl_m)
            res.append((s.t_s, float(np.hypot(*(pos - LINE.pos_ned_m(s.t_s, t0_s))[:2]))))
    return res


def codes(outs):
    return [o.code for o in outs if isinstance(o, Alert)]


def _imu_error(stream, t_from_s, t_to_s, accel_error_mps2):
    """The IMU's specific force off by ``accel_error_mps2`` (north) between two times."""
    for s in stream:
        if isinstance(s, ImuSample) and t_from_s <= s.t_s < t_to_s:
            s = replace(s, acc_b_mps2=s.acc_b_mps2 + np.array([accel_error_mps2, 0, 0]))
        yield s


def test_a_healthy_receiver_against_a_drifting_prediction_stays_in_use():
    """The IMU is 3 m/s^2 off for 3 s: the blend's prediction drifts metres from the
    receiver, whose fixes move exactly as its velocity says. The receiver is never
    called stale, never excluded for long: the solution is back on it within a second
    of the IMU recovering and its fixes are used (fused, vouched or reset to) >= 98 %."""
    engine = Engine(EngineConfig(navigator="blend"))
    stream = line_stream(40.0, line=LINE, gnss_hz=5.0, noise_m=0.01, seed=1)
    outs = run(_imu_error(stream, 25.0, 28.0, 3.0), engine)
    stats = engine.stats.gnss
    assert AlertCode.GNSS_STALE not in codes(outs)
    used = stats["fused"] + stats["fused_vouched"] + stats["reinitialised"]
    offered = used + stats["excluded"] + stats["gate_rejected"] - stats["fused_vouched"]
    assert used / offered >= 0.98, dict(stats)
    late = [e for t, e in errors_m(outs) if t > 29.0]
    assert max(late) < 1.0


def test_a_glitch_with_a_clean_second_receiver_is_never_reset_to():
    """Receiver 0 steps 40 m for 15 s; receiver 1 stays on the line: no reset to the
    glitch, the solution stays on the line (the second receiver shows the first wrong)."""

    def two_receivers(stream):
        for s in stream:
            if isinstance(s, GnssFix):
                yield replace(s, receiver_id=1, t_rx_s=s.t_rx_s)
                if 20.0 <= s.t_s < 35.0:
                    n, e, d = ORIGIN.lla_to_ned(s.lat_rad, s.lon_rad, s.alt_msl_m)
                    lat, lon, alt = ORIGIN.ned_to_lla(np.array([n + 40.0, e, d]))
                    s = replace(s, lat_rad=lat, lon_rad=lon, alt_msl_m=alt)
            yield s

    engine = Engine(EngineConfig(navigator="blend"))
    stream = line_stream(45.0, line=LINE, gnss_hz=5.0, noise_m=0.01, seed=2)
    outs = run(two_receivers(stream), engine)
    texts = [o.text for o in outs if isinstance(o, Alert)]
    assert not any("reset to it" in t for t in texts), texts
    assert max(e for _, e in errors_m(outs)) < 5.0


def test_a_slow_imu_is_not_used_to_dead_reckon():
    """A 10 Hz IMU: the pass-through carries from the first measured window on, and the
    blend never takes over (one switch at most: at start-up, before the rate is known)."""
    engine = Engine(EngineConfig(navigator="blend"))
    run(line_stream(30.0, line=LINE, imu_hz=10.0, gnss_hz=5.0), engine)
    navs = engine.navigators
    assert navs.imu_rate.rate_hz is not None and 9.0 < navs.imu_rate.rate_hz < 11.0
    assert not navs.imu_rate.usable
    assert navs.navigator is navs.fallback
    assert navs.switches <= 2


def test_a_slow_imu_stays_slow_across_a_restart():
    """A 10 Hz IMU, then 4 s of silence of every stream: the navigation restarts, and the
    pass-through carries from the first fix after it (before, the restart forgot the
    measured rate and the blend carried a radio's 1.3 Hz IMU until its first window
    closed: copter_radio_realistic's first fix after a silence excluded as a FAULT)."""
    engine = Engine(EngineConfig(navigator="blend"))
    stream = line_stream(40.0, line=LINE, imu_hz=10.0, gnss_hz=5.0)
    outs = run((s for s in stream if not 25.0 <= s.t_s < 29.0), engine)
    assert AlertCode.DATA_BACK in codes(outs)
    navs = engine.navigators  # the restarted navigation's
    assert navs.switches == 0 and navs.navigator is navs.fallback
    assert not navs.imu_rate.usable


def test_a_fast_imu_is_used():
    engine = Engine(EngineConfig(navigator="blend"))
    run(line_stream(20.0, line=LINE, imu_hz=50.0, gnss_hz=5.0), engine)
    navs = engine.navigators
    assert navs.imu_rate.usable and navs.navigator is navs.primary


def test_an_imu_rate_wavering_around_the_minimum_does_not_flap():
    """The IMU alternates 4 s at 50 Hz and 4 s at 10 Hz: once found slow it must hold
    imu_rate_hold_s (5 s) before the blend carries again, which never happens: the
    carrying navigator changes at most twice in 60 s (the phoenix log switched 400 times)."""

    def wavering(stream):
        for s in stream:
            if isinstance(s, ImuSample) and int((s.t_s - 10.0) // 4.0) % 2 == 1:
                if round((s.t_s - 10.0) * 50.0) % 5:
                    continue
            yield s

    engine = Engine(EngineConfig(navigator="blend"))
    outs = run(wavering(line_stream(60.0, line=LINE, imu_hz=50.0, gnss_hz=5.0)), engine)
    navs = engine.navigators
    assert navs.switches <= 2
    assert navs.navigator is navs.fallback
    # the pass-through carries honestly: every published error within 3 sigma of its own
    for s in outs:
        if isinstance(s, NavSolution) and s.t_s > 20.0:
            pos = ORIGIN.lla_to_ned(s.lat_rad, s.lon_rad, s.alt_msl_m)
            err = float(np.hypot(*(pos - LINE.pos_ned_m(s.t_s, 10.0))[:2]))
            sigma = float(np.sqrt(s.pos_cov_ned_m2[0, 0] + s.pos_cov_ned_m2[1, 1]))
            assert err <= 3.0 * sigma + 0.05


def test_a_min_rate_of_zero_disables_the_check():
    engine = Engine(EngineConfig(navigator="blend", min_imu_rate_hz=0.0))
    run(line_stream(20.0, line=LINE, imu_hz=10.0, gnss_hz=5.0), engine)
    assert engine.navigators.navigator is engine.navigators.primary


def test_a_height_fault_is_not_vouched_for_by_horizontal_evidence():
    """The receiver's height steps 30 m while its horizontal track stays consistent: its
    own evidence (horizontal increments against its velocity) does not cover the height,
    so no rejected fix is fused ungated and no early reset happens; the published height
    stays on the truth until the bounded rejection time has passed."""

    def height_step(stream):
        for s in stream:
            if isinstance(s, GnssFix) and s.t_s >= 25.0:
                s = replace(s, alt_msl_m=s.alt_msl_m + 30.0)
            yield s

    engine = Engine(EngineConfig(navigator="blend"))
    stream = line_stream(35.0, line=LINE, gnss_hz=5.0, noise_m=0.01, seed=3)
    outs = run(height_step(stream), engine)
    assert engine.stats.gnss["fused_vouched"] == 0
    bound_s = engine.outage.config.reset_after_rejection_s
    for s in outs:
        if isinstance(s, NavSolution) and 25.0 <= s.t_s < 25.0 + bound_s - 0.2:
            pos = ORIGIN.lla_to_ned(s.lat_rad, s.lon_rad, s.alt_msl_m)
            assert abs(pos[2] - LINE.pos_ned_m(s.t_s, 10.0)[2]) < 2.0, s.t_s


def _vibrating(stream, sigma_mps2, seed):
    """The IMU's specific force with white vibration of ``sigma_mps2`` per sample."""
    rng = np.random.default_rng(seed)
    for s in stream:
        if isinstance(s, ImuSample):
            s = replace(s, acc_b_mps2=s.acc_b_mps2 + rng.normal(0.0, sigma_mps2, 3))
        yield s


def test_a_reset_within_the_solutions_bound_is_not_alerted():
    """A vibrating IMU (its noise measured) and a 0.4 s transient of 2 m/s^2 (a take-off's
    spool-up): the velocity fails the gate, the navigator is reset to the receiver, but
    its position never left the bound it published: no FAULT (an alert must be true)."""
    engine = Engine(EngineConfig(navigator="blend"))
    stream = line_stream(40.0, line=LINE, gnss_hz=5.0, noise_m=0.01, seed=2)
    outs = run(_imu_error(_vibrating(stream, 0.7, 3), 25.0, 25.4, 2.0), engine)
    assert engine.stats.gnss["reinitialised"] == 1, dict(engine.stats.gnss)
    assert engine.outage.resets_within_bound == 1
    assert AlertCode.FAULT not in codes(outs)


def test_a_reset_beyond_the_solutions_bound_is_alerted():
    """The same IMU 3 m/s^2 off for 3 s: the prediction leaves its own bound, and the
    reset to the receiver says so."""
    engine = Engine(EngineConfig(navigator="blend"))
    stream = line_stream(40.0, line=LINE, gnss_hz=5.0, noise_m=0.01, seed=2)
    outs = run(_imu_error(_vibrating(stream, 0.7, 3), 25.0, 28.0, 3.0), engine)
    assert engine.outage.resets > engine.outage.resets_within_bound
    assert AlertCode.FAULT in codes(outs)

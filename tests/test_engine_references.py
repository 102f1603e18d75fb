"""The engine's second opinions: the position-potential filter (Grzegorzewski 2005) and
the coasting inertial references (the separation set of Kim, Walter and Powell), on
synthetic straight flights with known truth."""

from __future__ import annotations

import dataclasses
from dataclasses import replace

import numpy as np
import pytest

from companion.engine import Engine, EngineConfig
from companion.integrity.coast import CoastConfig
from companion.nav.blend import BlendConfig
from companion.types import (
    Alert,
    AlertCode,
    GnssFix,
    ImuSample,
    NamedValue,
    NavMode,
    NavSolution,
)
from tests.helpers import ORIGIN, Line, line_stream

GAP = (20.0, 25.0)
"""A 5 s GNSS gap, seconds after the stream's start."""


def run(stream, engine):
    outs = []
    for sample in stream:
        outs += engine.handle(sample)
    return outs


def bridged(outs):
    return [o for o in outs if isinstance(o, NavSolution) and o.mode is NavMode.BRIDGING]


def error_m(sol: NavSolution, line: Line) -> np.ndarray:
    return ORIGIN.lla_to_ned(sol.lat_rad, sol.lon_rad, sol.alt_msl_m) - line.pos_ned_m(sol.t_s)


def no_imu(stream):
    """The stream without its IMU samples (ATTITUDE still clocks publication)."""
    return (s for s in stream if not isinstance(s, ImuSample))


def test_without_imu_the_potential_filter_bridges_a_gap():
    line = Line()
    engine = Engine(EngineConfig(potential_bridge=True))
    # the stream ends inside the gap: the filter's state is the gap's
    stream = line_stream(GAP[1], line=line, gaps=((GAP[0], GAP[1] + 1.0),), noise_m=0.02, seed=3)
    outs = run(no_imu(stream), engine)
    gap = bridged(outs)
    assert len(gap) >= 35
    assert engine.navigators.navigator is engine.navigators.fallback and engine.frame is not None
    pot = engine.bridge.potential
    assert pot is not None and pot.fit_count >= 1
    for sol in gap[::7]:  # what was published is the potential prediction
        pred = pot.predict(sol.t_s)
        published = engine.frame.lla_to_ned(sol.lat_rad, sol.lon_rad, sol.alt_msl_m)
        np.testing.assert_allclose(published, pred.pos_ned_m, atol=2e-3)
        # its covariance, or the pass-through's where that is larger (the filter's knows
        # nothing of a manoeuvre begun in the gap)
        cv = engine.navigators.fallback.predict(sol.t_s)
        assert cv is not None
        larger = max(pred.cov_ned_m2, cv.pos_cov_ned_m2, key=lambda c: np.trace(c[:2, :2]))
        np.testing.assert_allclose(sol.pos_cov_ned_m2, larger)
    # on a straight line constant velocity is the exact model: the field must not pull
    # the particle off it (a few cm of fix noise over 5 s)
    err = np.array([error_m(s, line) for s in gap])
    assert np.max(np.linalg.norm(err, axis=1)) < 0.5
    names = {o.name for o in outs if isinstance(o, NamedValue)}
    assert {"CMP_PALPHA", "CMP_PG"} <= names


def test_combination_with_the_ins_is_no_worse_and_no_less_certain_than_claimed():
    line = Line()
    stream = list(line_stream(30.0, line=line, gaps=(GAP,), noise_m=0.02, seed=4))
    ins_only = bridged(run(stream, Engine(EngineConfig())))
    combined = bridged(run(stream, Engine(EngineConfig(potential_combine=True))))
    assert len(combined) == len(ins_only) >= 35
    e_ins = np.array([np.linalg.norm(error_m(s, line)) for s in ins_only])
    e_comb = np.array([np.linalg.norm(error_m(s, line)) for s in combined])
    assert np.mean(e_comb) <= np.mean(e_ins) + 0.02
    for a, b in zip(ins_only, combined, strict=True):
        assert np.trace(b.pos_cov_ned_m2) <= np.trace(a.pos_cov_ned_m2) + 1e-12


def test_potential_fix_test_flags_a_jump():
    line = Line()

    def jumped(stream):
        for s in stream:
            if isinstance(s, GnssFix) and 20.0 <= s.t_s - 10.0 < 20.3:
                lat, lon, alt = s.lat_rad, s.lon_rad, s.alt_msl_m
                n, e, d = ORIGIN.lla_to_ned(lat, lon, alt)
                lat, lon, alt = ORIGIN.ned_to_lla(np.array([n + 3.0, e, d]))
                s = replace(s, lat_rad=lat, lon_rad=lon, alt_msl_m=alt)
            yield s

    cfg = EngineConfig(navigator="passthrough", potential_fix_test=True)
    engine = Engine(cfg)
    outs = run(jumped(line_stream(30.0, line=line, noise_m=0.02, seed=5)), engine)
    faults = [o for o in outs if isinstance(o, Alert) and o.code is AlertCode.FAULT]
    assert faults and "potential ellipsoid" in faults[0].text
    assert 20.0 <= faults[0].t_s - 10.0 < 20.3


def ramped(stream, start_s: float, rate_mps: float):
    """Receiver 0's fixes drift down at ``rate_mps`` from ``start_s`` (a satellite clock
    ramp as it reaches the position: mostly vertical)."""
    for s in stream:
        if isinstance(s, GnssFix) and s.t_s - 10.0 >= start_s:
            n, e, d = ORIGIN.lla_to_ned(s.lat_rad, s.lon_rad, s.alt_msl_m)
            drift = rate_mps * (s.t_s - 10.0 - start_s)
            lat, lon, alt = ORIGIN.ned_to_lla(np.array([n, e, d + drift]))
            s = replace(s, lat_rad=lat, lon_rad=lon, alt_msl_m=alt)
        yield s


@pytest.mark.parametrize("inertial_reference", [True, False])
def test_one_receiver_ramp_is_caught_only_against_the_inertial_reference(inertial_reference):
    """One receiver, tactical IMU, a vertical 4 cm/s ramp from 100 s: against the coasting
    INS it is flagged before it reaches 1 m (Kim, Walter and Powell's target); without a
    reference nothing sees it. (Horizontal ramps of 4 cm/s are not caught in time with one
    receiver: tilt and horizontal accelerometer bias let the coast drift too fast;
    bench/integrity.py.)"""
    start_s, rate = 100.0, 0.04
    stream = line_stream(160.0, noise_m=0.01, seed=6)
    engine = Engine(
        EngineConfig(inertial_reference=inertial_reference),
        blend=BlendConfig.for_grade("tactical"),
        coast=CoastConfig.for_grade("tactical"),
    )
    outs = run(ramped(stream, start_s, rate), engine)
    faults = [o for o in outs if isinstance(o, Alert) and o.code is AlertCode.FAULT]
    if not inertial_reference:
        assert not faults
        return
    assert faults, "ramp not detected"
    t_detect = faults[0].t_s - 10.0
    assert t_detect >= start_s, f"false alert at {t_detect:.1f} s"
    assert rate * (t_detect - start_s) < 1.0


def test_no_inertial_reference_on_the_ground_before_the_heading_is_trusted(tmp_path):
    """The bundled taxi (tactical IMU, the autopilot's heading 1 deg off until the taxi
    heading correction corrects it) with the tactical configuration, inertial references
    on: taxi turns with a wrong heading would put the coast metres off and exclude the only
    receiver. While the autopilot says it is on the ground the references are neither
    anchored nor tested."""
    from pathlib import Path

    from companion.config import load_config
    from companion.replay import replay

    root = Path(__file__).resolve().parent.parent / "sitl_fixtures"
    config = load_config(root / "tactical.toml")
    assert config.engine.inertial_reference
    summary = replay(root / "taxi.tlog", tmp_path / "out.tlog", config)
    assert summary.alerts.get("FAULT", 0) == 0, summary.alerts
    assert summary.alerts.get("GNSS_LOST", 0) == 0, summary.alerts
    assert summary.alerts.get("HDG_READY", 0) == 1


def test_a_receiver_excluded_on_old_references_alone_comes_back(tmp_path):
    """The bundled MEMS cruise replayed with the tactical configuration (a wrong IMU grade
    in the [coast] block): the references' covariance is far too small, they blame the
    only receiver and, no longer re-anchored while it is excluded, used to keep it out
    for the rest of the flight while the free inertial solution drifted kilometres
    (normal-flight H RMS 7.2 km). References older than ``reference_max_age_s`` are not
    tested against, so every exclusion ends: GNSS_BACK follows each within the age limit,
    the slots' life, the recovery time and a few reacquisition fixes (plus the fixture's
    own GNSS outage where it falls inside)."""
    from pathlib import Path

    from companion.config import load_config
    from companion.evaluate import evaluate
    from companion.replay import replay

    root = Path(__file__).resolve().parent.parent / "sitl_fixtures"
    config = load_config(root / "tactical.toml")
    # without the IMU self-check, which widens the grade before the references can blame
    # the receiver (tests/test_engine_baro.py): the bound on a wrong exclusion still holds
    config = dataclasses.replace(
        config, engine=dataclasses.replace(config.engine, imu_grade_check=False)
    )
    out = tmp_path / "out.tlog"
    replay(root / "cruise_gnss_loss.tlog", out, config)
    ev = evaluate(out, root / "cruise_gnss_loss.truth.csv")
    exclusions = [a.t_s for a in ev.alerts if a.code == "FAULT" and "excluded" in a.text]
    backs = [a.t_s for a in ev.alerts if a.code == "GNSS_BACK"]
    (gap,) = [e for e in ev.events if e.kind == "outage"]
    assert exclusions, "the mis-configured references no longer blame the receiver"
    bound_s = (
        config.integrity.reference_max_age_s
        + config.coast.life_s
        + config.integrity.recovery_s
        + 5.0
    )
    for t_x in exclusions:
        end = t_x + bound_s
        if end > gap.t_start_s and t_x < gap.t_end_s:
            end += gap.t_end_s - gap.t_start_s
        if end > ev.t_last_s:
            continue
        assert any(t_x < t <= end for t in backs), (t_x, backs)
    assert ev.normal.h_rms_m < 1000.0  # 7.2 km when the receiver stayed out

"""The engine on synthetic straight flights with known truth."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2

from companion.engine import Engine, EngineConfig
from companion.types import (
    Alert,
    AlertCode,
    FixType,
    NamedValue,
    NavMode,
    NavSolution,
    RebootEvent,
)
from tests.helpers import ORIGIN, Line, fix_at, line_stream


def run(stream, engine=None):
    engine = engine or Engine()
    outs = []
    for sample in stream:
        outs += engine.handle(sample)
    return engine, outs


def solutions(outs):
    return [o for o in outs if isinstance(o, NavSolution)]


def alerts(outs, code=None):
    return [o for o in outs if isinstance(o, Alert) and (code is None or o.code is code)]


def test_publishes_at_the_configured_rate_including_through_a_gap():
    _, outs = run(line_stream(30.0, gaps=((10.0, 20.0),)))
    sols = solutions(outs)
    times = np.array([s.t_s for s in sols])
    gaps = np.diff(times)
    # on each fused fix (10 Hz); a missing fix is waited for 1.5 fix intervals, then the
    # IMU stream clocks the publications at publish_rate_hz through the gap
    assert len(sols) == pytest.approx(300, abs=8)
    assert gaps.max() <= 0.15 + 1.0 / 50.0 + 1e-9  # and the next IMU sample (50 Hz)
    assert gaps.min() >= EngineConfig().min_publish_interval_s - 1e-9
    in_gap = [s for s in sols if 21.5 < s.t_s < 29.5]
    assert len(in_gap) >= 75
    assert all(s.mode is NavMode.BRIDGING for s in in_gap)


def test_publishes_each_fused_fix_at_once():
    engine = Engine()
    published_at_fix = 0
    fixes = 0
    for sample in line_stream(20.0):
        outs = engine.handle(sample)
        if type(sample).__name__ == "GnssFix" and sample.t_s > 11.0:
            fixes += 1
            published_at_fix += bool(solutions(outs))
    assert fixes > 90 and published_at_fix == fixes


@pytest.mark.parametrize("gnss_hz", [5.0, 10.0])
def test_a_slower_receiver_is_published_on_each_fix_and_between_at_the_rate(gnss_hz):
    engine = Engine()
    times, at_fix, fixes = [], 0, 0
    for sample in line_stream(20.0, gnss_hz=gnss_hz):
        outs = solutions(engine.handle(sample))
        times += [o.t_s for o in outs]
        if type(sample).__name__ == "GnssFix" and sample.t_s > 11.0:
            fixes += 1
            at_fix += bool(outs)
    assert at_fix == fixes > 4 * gnss_hz
    gaps = np.diff([t for t in times if t > 11.0])
    # 10 Hz either way: a 5 Hz receiver's fixes and a prediction half-way between
    assert np.allclose(gaps, 0.1, atol=1e-6)


def test_on_the_tick_without_publish_on_fix():
    _, outs = run(
        line_stream(30.0, gaps=((10.0, 20.0),)), Engine(EngineConfig(publish_on_fix=False))
    )
    times = np.array([s.t_s for s in solutions(outs)])
    assert len(times) == pytest.approx(300, abs=2)
    assert np.diff(times).max() <= 0.1 + 1e-9


@pytest.mark.parametrize("navigator", ["blend", "passthrough"])
def test_a_straight_line_is_carried_through_a_gap(navigator):
    line = Line()
    engine = Engine(EngineConfig(navigator=navigator))
    _, outs = run(line_stream(30.0, line=line, gaps=((10.0, 20.0),)), engine)
    errors, normalised = {}, []
    for s in solutions(outs):
        err = ORIGIN.lla_to_ned(s.lat_rad, s.lon_rad, s.alt_msl_m) - line.pos_ned_m(s.t_s)
        errors[s.t_s] = float(np.linalg.norm(err))
        if s.t_s >= 12.0:
            normalised.append(float(err @ np.linalg.solve(s.pos_cov_ned_m2, err)))
    late = max(e for t, e in errors.items() if t >= 12.0)
    if navigator == "blend":
        # the INS carries the gap on its estimated velocity (sigma ~7 mm/s after 10 s of
        # RTK fixes): centimetres, and inside the published covariance (3-dof chi-square
        # at 0.999: the error is one smooth drift, not independent draws)
        assert late < 0.1
        assert max(normalised) < chi2.ppf(0.999, 3)
    else:
        # constant velocity is the exact model of a straight line
        assert late < 0.02
        # GPS_RAW_INT has no vertical velocity, so an extrapolation in the first 0.1 s
        # after the first fix would use vd = 0 (0.2 m at 2 m/s climb); published on each
        # fix as it comes, nothing is extrapolated then
        assert max(e for t, e in errors.items() if t < 10.15) < 1e-3


GNSS_AND_DATA_CODES = frozenset(
    {AlertCode.NO_GNSS, AlertCode.GNSS_LOST, AlertCode.GNSS_BACK, AlertCode.NO_DATA}
    | {AlertCode.DATA_BACK, AlertCode.RTK_LOST, AlertCode.RTK_BACK, AlertCode.GNSS_STALE}
)
"""What the service says of its receivers and data streams (not CAT, INTEGRITY ...)."""


def test_gap_raises_lost_then_back():
    _, outs = run(line_stream(30.0, gaps=((10.0, 20.0),)))
    lost = alerts(outs, AlertCode.GNSS_LOST)
    back = alerts(outs, AlertCode.GNSS_BACK)
    assert len(lost) == 1 and lost[0].text.endswith(": bridging")
    # one alert per gap and one return: nothing else is said of the GNSS or the data
    said = [o.code for o in outs if isinstance(o, Alert) and o.code in GNSS_AND_DATA_CODES]
    assert said == [AlertCode.GNSS_LOST, AlertCode.GNSS_BACK]
    assert 20.9 < lost[0].t_s < 21.2  # 1 s timeout after the last fix at t0 + 9.9 s
    assert len(back) == 1 and 30.0 <= back[0].t_s < 30.5
    outg = [o.value for o in outs if isinstance(o, NamedValue) and o.name == "CMP_OUTG"]
    assert max(outg) == pytest.approx(10.0, abs=1.1)


def test_fix_type_published_is_honest():
    def fix_type_at(rel):
        return FixType.RTK_FIXED if rel < 5.0 else FixType.FIX_3D

    engine, outs = run(line_stream(20.0, gaps=((10.0, 15.0),), fix_type_at=fix_type_at))
    sols = solutions(outs)
    assert {s.fix_type for s in sols if 11 < s.t_s < 14.9} == {FixType.RTK_FIXED}
    assert {s.fix_type for s in sols if 21.5 < s.t_s < 24.9} == {FixType.FIX_3D}
    assert len(alerts(outs, AlertCode.RTK_LOST)) == 1
    # never RTK while bridging
    assert all(s.fix_type <= FixType.FIX_3D for s in sols if s.mode is NavMode.BRIDGING)


def test_rtk_outage_raises_rtk_lost_then_rtk_back():
    """A synthetic 8 s RTK-correction outage (RTK fixed -> 3D -> RTK fixed) in a flight with
    continuous GNSS: one RTK_LOST at its start, one RTK_BACK at its end, no GNSS_LOST."""

    def fix_type_at(rel):
        return FixType.FIX_3D if 6.0 <= rel < 14.0 else FixType.RTK_FIXED

    _, outs = run(line_stream(20.0, fix_type_at=fix_type_at))
    lost = alerts(outs, AlertCode.RTK_LOST)
    back = alerts(outs, AlertCode.RTK_BACK)
    assert [a.text for a in lost] == ["rx0 -> FIX_3D"]
    assert [a.text for a in back] == ["rx0 -> RTK_FIXED after 8.0 s"]
    assert lost[0].t_s == pytest.approx(16.0) and back[0].t_s == pytest.approx(24.0)
    assert not alerts(outs, AlertCode.GNSS_LOST)


def test_stale_repeated_fixes_are_flagged_and_never_fused():
    engine = Engine()
    line = Line()
    stale_from = 20.0
    frozen = None
    outs = []
    for sample in line_stream(20.0, line=line):
        if hasattr(sample, "fix_type") and sample.t_s >= stale_from:
            frozen = frozen or sample
            sample = fix_at(sample.t_s, line.pos_ned_m(frozen.t_s), np.array(line.vel_ned_mps))
        outs += engine.handle(sample)
    stale = alerts(outs, AlertCode.GNSS_STALE)
    assert stale and stale[0].t_s - stale_from < 2.0
    assert engine.stats.gnss["stale"] >= 90
    # the solution kept moving: error at the end far below the 400 m the frozen fix would give
    end = solutions(outs)[-1]
    pos = ORIGIN.lla_to_ned(end.lat_rad, end.lon_rad, end.alt_msl_m)
    assert np.linalg.norm(pos - line.pos_ned_m(end.t_s)) < 1.0


def test_reboot_restarts_navigation():
    engine, _ = run(line_stream(5.0))
    assert engine.navigators.navigator.initialised
    engine.handle(RebootEvent(1.0, 100.0, 15.0))
    assert not engine.navigators.navigator.initialised
    assert engine.stats.reboots == 1
    assert engine.outage.mode is NavMode.INIT


def test_same_inputs_same_outputs():
    samples = list(line_stream(15.0, gaps=((5.0, 8.0),), noise_m=0.02, seed=3))
    _, a = run(samples)
    _, b = run(samples)
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        assert type(x) is type(y)
        if isinstance(x, NavSolution):
            assert (x.lat_rad, x.lon_rad, x.alt_msl_m) == (y.lat_rad, y.lon_rad, y.alt_msl_m)
            assert np.array_equal(x.pos_cov_ned_m2, y.pos_cov_ned_m2)


def test_reanchors_far_from_origin_without_a_jump():
    engine = Engine(EngineConfig(reanchor_distance_m=1000.0))
    line = Line((60.0, 0.0, 0.0))
    _, outs = run(line_stream(40.0, line=line), engine)
    assert engine.stats.reanchors >= 2
    for s in solutions(outs):
        pos = ORIGIN.lla_to_ned(s.lat_rad, s.lon_rad, s.alt_msl_m)
        assert np.linalg.norm(pos - line.pos_ned_m(s.t_s)) < 0.05


def test_bad_config_is_rejected_with_the_key():
    with pytest.raises(ValueError, match="publish_rate_hz"):
        EngineConfig(publish_rate_hz=0.0)
    assert math.isfinite(EngineConfig().publish_rate_hz)


def test_gnss_back_beyond_the_gate_reinitialises_instead_of_bridging_forever():
    """Without an IMU, a 20 s gap during which the fixes move 500 m off the carried line
    (a turn the pass-through cannot know): every returning fix fails the gate. The engine
    must re-initialise from GNSS after ``reacquire_max_rejects`` fixes and say GNSS_BACK,
    not stay in BRIDGING with the receiver excluded for disagreeing with a stale guess."""
    from dataclasses import replace as dc_replace

    from companion.types import GnssFix, ImuSample

    line = Line()

    def shifted(stream):
        for s in stream:
            if isinstance(s, ImuSample):
                continue
            if isinstance(s, GnssFix) and s.t_s - 10.0 >= 30.0:
                n, e, d = ORIGIN.lla_to_ned(s.lat_rad, s.lon_rad, s.alt_msl_m)
                lat, lon, alt = ORIGIN.ned_to_lla(np.array([n, e + 500.0, d]))
                s = dc_replace(s, lat_rad=lat, lon_rad=lon, alt_msl_m=alt)
            yield s

    engine = Engine(EngineConfig(navigator="passthrough"))
    _, outs = run(shifted(line_stream(45.0, line=line, gaps=((10.0, 30.0),))), engine)
    back = alerts(outs, AlertCode.GNSS_BACK)
    assert back, "never re-acquired"
    assert 30.0 <= back[0].t_s - 10.0 < 30.0 + 0.1 * 30
    assert engine.outage.mode is NavMode.NORMAL
    last = solutions(outs)[-1]
    err = ORIGIN.lla_to_ned(last.lat_rad, last.lon_rad, last.alt_msl_m) - (
        line.pos_ned_m(last.t_s) + np.array([0.0, 500.0, 0.0])
    )
    assert np.linalg.norm(err) < 0.5


def _imu_stops(stream, after_s):
    """The stream with no IMU sample after ``after_s`` (absolute time)."""
    from companion.types import ImuSample

    for s in stream:
        if isinstance(s, ImuSample) and s.t_s > after_s:
            continue
        yield s


def _eager_fallback(engine):
    """The engine with its fallback fed at every fix (the reference the lazy feed must match)."""
    navs = engine.navigators
    navs.defer_to_fallback = lambda meas, gate: navs.fallback.on_gnss(meas, gate=gate)
    return engine


@pytest.mark.parametrize("backlog", [None, 25])
def test_the_fallback_fed_lazily_takes_over_as_if_fed_at_every_fix(backlog):
    """While the blend carries the solution the pass-through fallback only collects the
    fixes; when the IMU stops it must take over with the state it would have had if it
    had taken every fix (exactly; after a backlog overflow, to the vertical velocity
    average's remaining weight 0.7^25), and carry the flight on."""
    from collections import deque

    line = Line((30.0, 10.0, -2.0))
    outs = {}
    for name in ("lazy", "eager"):
        engine = Engine(EngineConfig(navigator="blend", reanchor_distance_m=1000.0))
        if backlog is not None:
            engine.navigators.backlog = deque(maxlen=backlog)
        if name == "eager":
            _eager_fallback(engine)
        noisy = line_stream(60.0, line=line, noise_m=0.02, seed=3)
        # the frame is re-anchored near t = 41.5 s, while the blend carries the solution
        _, outs[name] = run(_imu_stops(noisy, 55.0), engine)
        assert engine.navigators.navigator is engine.navigators.fallback
        assert engine.stats.reanchors == 1
        assert not alerts(outs[name], AlertCode.FAULT)  # the IMU stopping is no GNSS fault
    lazy, eager = solutions(outs["lazy"]), solutions(outs["eager"])
    assert [s.t_s for s in lazy] == [s.t_s for s in eager]
    after = [(x, y) for x, y in zip(lazy, eager, strict=True) if x.t_s > 56.0]
    assert len(after) > 100
    for x, y in after:
        if backlog is None:
            assert (x.lat_rad, x.lon_rad, x.alt_msl_m) == (y.lat_rad, y.lon_rad, y.alt_msl_m)
            assert np.array_equal(x.vel_ned_mps, y.vel_ned_mps)
        else:
            assert np.allclose(x.vel_ned_mps, y.vel_ned_mps, atol=0.7**25 * 5.0)
        err = ORIGIN.lla_to_ned(x.lat_rad, x.lon_rad, x.alt_msl_m) - line.pos_ned_m(x.t_s)
        assert np.linalg.norm(err) < 0.3

"""The raw link's signal tests (companion.raw.signal) against truth: the real walk and
clean simulated flights raise nothing; each simulated signature (a spoofer's capture, a
clock step, a code drag, jamming) is seen, and seen only after it starts."""

from __future__ import annotations

import dataclasses
import math
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from companion.nav.frames import geodetic_to_ecef_m
from companion.raw.broadcast import collect_ephemerides
from companion.raw.geometry import enu_rotation
from companion.raw.obs import PvtFix, RawEpoch
from companion.raw.signal import (
    SignalTestConfig,
    SignalTests,
    SignalVerdict,
    median_limit,
    uniformity_limit_dbhz,
)
from companion.raw.simulate import Cn0Model, Jamming, RawSimConfig, SpoofCapture, simulate_flight
from companion.types import InterferenceState
from companion.ubx.reader import read_file

from .helpers import UBX, walk

DETECTED = InterferenceState.DETECTED
CLEAN = InterferenceState.CLEAN
FULL_WALK = Path(__file__).resolve().parents[3] / "shared" / "realdata" / "gnss_imu" / "walk_0827"
START_S = 40.0
"""When the simulated signatures start (s of the flight)."""
RATE_HZ = 4.0


def _receiver_positions(epochs: list[RawEpoch], pvt: list[PvtFix]) -> list[np.ndarray | None]:
    """Each epoch's receiver solution (NAV-PVT of the same epoch, within 20 ms), ECEF."""
    by_ms = {round(p.itow_s * 1000.0): p for p in pvt}
    out: list[np.ndarray | None] = []
    for e in epochs:
        ms = round(e.tow_s * 1000.0)
        p = next((by_ms[k] for k in range(ms - 20, ms + 21) if k in by_ms), None)
        if p is None:
            out.append(None)
            continue
        lat, lon = math.radians(p.lat_deg), math.radians(p.lon_deg)
        out.append(np.array(geodetic_to_ecef_m(lat, lon, p.height_m)))
    return out


def _run_file(path: str) -> tuple[list[SignalVerdict], SignalTests]:
    epochs, nav, pvt, _ = read_file(path)
    ephs, _ = collect_ephemerides(nav)
    tests = SignalTests()
    positions = _receiver_positions(epochs, pvt)
    return [tests.on_epoch(e, x, ephs) for e, x in zip(epochs, positions, strict=True)], tests


def _path(t: float) -> np.ndarray:
    """A cruise at 40 m/s, 300 m above the walk's start, with a gentle turn."""
    s = walk()
    r = _rotation()
    enu = np.array([40.0 * t, 200.0 * (1.0 - math.cos(t / 50.0)), 300.0])
    return np.asarray(s.x0_ecef_m + r.T @ enu)


@lru_cache(maxsize=1)
def _rotation() -> np.ndarray:
    from companion.nav.frames import ecef_to_geodetic

    lat, lon, _ = ecef_to_geodetic(*walk().x0_ecef_m)
    return enu_rotation(lat, lon)


@lru_cache(maxsize=16)
def _flight(
    seed: int,
    spoof: SpoofCapture | None = None,
    jam: Jamming | None = None,
    duration_s: float = 100.0,
) -> tuple[list[SignalVerdict], dict[str, int]]:
    """The tests' verdicts on a simulated flight with realistic C/N0, 4 Hz."""
    s = walk()
    cfg = RawSimConfig(rate_hz=RATE_HZ, cn0=Cn0Model(), spoof=spoof, jam=jam)
    epochs, truth = simulate_flight(
        s.ephemerides, s.epochs[0].tow_s, duration_s, _path, np.random.default_rng(seed), cfg
    )
    tests = SignalTests()
    verdicts = [tests.on_epoch(e, x, s.ephemerides) for e, x in zip(epochs, truth, strict=True)]
    return verdicts, dict(tests.trips)


def _t(v: SignalVerdict) -> float:
    """The flight time of a verdict's epoch (its receiver time less the clock's bias)."""
    return round((v.tow_s - walk().epochs[0].tow_s) * RATE_HZ) / RATE_HZ


def _first(verdicts: list[SignalVerdict], word: str) -> float | None:
    """Flight time of the first verdict citing ``word`` in its evidence."""
    for v in verdicts:
        if any(word in e for e in v.spoofing_evidence + v.jamming_evidence):
            return _t(v)
    return None


# --------------------------------------------------------------------------- real data


def test_the_bundled_walk_raises_nothing() -> None:
    verdicts, tests = _run_file(str(UBX))
    assert len(verdicts) == 161
    assert tests.trips == {}
    assert all(v.jamming is CLEAN and v.spoofing is CLEAN for v in verdicts)
    # its L1/E1 C/N0 spread never comes near the uniformity limit
    spreads = [v.spread_dbhz for v in verdicts]
    assert min(spreads) > 3.0 and all(v.signals >= 10 for v in verdicts)


@pytest.mark.skipif(not FULL_WALK.is_dir(), reason="the full walk is not beside this clone")
def test_the_whole_walk_raises_nothing() -> None:
    verdicts, tests = _run_file(str(FULL_WALK / "gnss_1730.ubx"))
    assert len(verdicts) == 536
    assert tests.trips == {}
    assert all(v.jamming is CLEAN and v.spoofing is CLEAN for v in verdicts)


# --------------------------------------------------------------------------- thresholds


def test_the_limits_are_the_false_alarm_quantiles() -> None:
    p = 1e-6
    for n in (5, 10, 20):
        lim = uniformity_limit_dbhz(n, 4.1, p)
        # (n - 1) s² / σ² at the limit is the lower p quantile of χ²(n - 1)
        assert math.isclose((n - 1) * lim**2 / 4.1**2, chi2.ppf(p, n - 1), rel_tol=1e-9)
    assert uniformity_limit_dbhz(5, 4.1, p) < uniformity_limit_dbhz(20, 4.1, p) < 4.1
    assert median_limit(16, 2.0, p, two_sided=True) > median_limit(16, 2.0, p, two_sided=False)
    assert math.isclose(median_limit(16, 2.0, p, True), 2 * median_limit(64, 2.0, p, True))


def test_a_config_out_of_range_is_refused() -> None:
    with pytest.raises(ValueError):
        SignalTestConfig(false_alarm_per_epoch=0.0)
    with pytest.raises(ValueError):
        SignalTestConfig(min_signals=3)


# --------------------------------------------------------------------------- simulated truth


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_clean_simulated_flights_raise_nothing(seed: int) -> None:
    verdicts, trips = _flight(seed)
    assert trips == {}
    assert all(v.jamming is CLEAN and v.spoofing is CLEAN for v in verdicts[1:])
    assert np.median([v.spread_dbhz for v in verdicts]) > 3.0  # a sky's spread, not a spoofer's


def test_a_spoofer_capture_shows_its_jump_clock_step_and_uniform_power() -> None:
    verdicts, trips = _flight(4, spoof=SpoofCapture(start_s=START_S))
    before = [v for v in verdicts if _t(v) < START_S - 1e-6]
    assert all(v.spoofing is CLEAN for v in before[1:])
    jump, clock, uniform = (_first(verdicts, w) for w in ("C/N0 up", "clock step", "spread"))
    assert jump is not None and START_S <= jump < START_S + 0.3  # the capture's epoch
    assert clock is not None and START_S <= clock < START_S + 0.3
    # the C/N0 converge to one level (time constant 3 s), then the spread test holds 1 s
    assert uniform is not None and START_S < uniform < START_S + 15.0
    after = [v for v in verdicts if _t(v) >= START_S]
    assert all(v.spoofing is DETECTED for v in after)  # the steps held 10 s, then the spread
    assert all(v.jamming is CLEAN for v in verdicts[1:])
    assert {"cn0_up", "clock", "uniform"} <= set(trips)


def test_a_clock_step_alone_is_seen_and_a_flagged_reset_is_not() -> None:
    step = SpoofCapture(
        start_s=START_S, jump_dbhz=0.0, converge_s=math.inf, spread_dbhz=0.0, clock_step_m=30.0
    )
    verdicts, trips = _flight(5, spoof=step)
    assert set(trips) == {"clock"} and trips["clock"] == 1
    t = _first(verdicts, "clock step")
    assert t is not None and START_S <= t < START_S + 0.3
    # the same epochs with the receiver's own clock-reset flag on the step: excused
    s = walk()
    cfg = RawSimConfig(rate_hz=RATE_HZ, cn0=Cn0Model(), spoof=step)
    epochs, truth = simulate_flight(
        s.ephemerides, s.epochs[0].tow_s, 60.0, _path, np.random.default_rng(5), cfg
    )
    k = round(START_S * RATE_HZ)  # the step's epoch
    epochs[k] = dataclasses.replace(epochs[k], clock_reset=True)
    tests = SignalTests()
    for e, x in zip(epochs, truth, strict=True):
        tests.on_epoch(e, x, s.ephemerides)
    assert tests.trips == {}


def test_a_code_drag_the_doppler_does_not_follow_is_seen_within_the_window() -> None:
    drag = SpoofCapture(
        start_s=START_S,
        jump_dbhz=0.0,
        converge_s=math.inf,
        spread_dbhz=0.0,
        clock_step_m=0.0,
        code_drag_enu_mps=(3.0, 0.0, 0.0),
    )
    verdicts, trips = _flight(6, spoof=drag)
    assert set(trips) == {"doppler"}
    t = _first(verdicts, "code moves")
    window = SignalTestConfig().doppler_window_s
    assert t is not None and START_S < t <= START_S + window + SignalTestConfig().persistence_s
    assert all(v.spoofing is CLEAN for v in verdicts[1:] if _t(v) < START_S)


def test_jamming_drops_every_c_n0_then_lock_and_ends_clean() -> None:
    jam = Jamming(start_s=START_S, end_s=START_S + 40.0, ramp_dbhz_per_s=1.0)
    verdicts, trips = _flight(7, jam=jam, duration_s=130.0)
    assert all(v.jamming is CLEAN for v in verdicts[1:] if _t(v) < START_S)
    first = _first(verdicts, "below its baseline")
    assert first is not None and START_S < first < START_S + 12.0
    lost = _first(verdicts, "lock lost")
    assert lost is not None and first < lost
    during = [v for v in verdicts if first <= _t(v) < START_S + 40.0]
    assert all(v.jamming is DETECTED for v in during)
    assert min(v.signals for v in during) < 5  # the receiver lost lock on most signals
    # the jammer gone, the signals back at their baselines: clean again within seconds
    end = [v for v in verdicts if _t(v) > START_S + 50.0]
    assert end and all(v.jamming is CLEAN for v in end)
    assert all(v.spoofing is not DETECTED for v in verdicts)
    assert "level" in trips

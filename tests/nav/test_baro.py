"""The barometer's height: standard atmosphere, calibration against GNSS, bad readings."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest

from companion.nav.baro import BaroConfig, BaroHeight, isa_height_m
from companion.types import BaroSample

P0 = 101_325.0


def pressure_at(h_m: float) -> float:
    """The standard troposphere's pressure at ``h_m`` (the inverse of isa_height_m)."""
    return P0 * (1.0 - 0.0065 * h_m / 288.15) ** 5.255877


def test_isa_height_closed_form_and_table() -> None:
    assert isa_height_m(P0) == 0.0
    # U.S. Standard Atmosphere 1976 table: 1000 m -> 89 874.6 Pa, 3000 m -> 70 108.5 Pa
    assert isa_height_m(89_874.6) == pytest.approx(1000.0, abs=0.5)
    assert isa_height_m(70_108.5) == pytest.approx(3000.0, abs=1.0)
    for h in (-300.0, 0.0, 250.0, 5000.0):
        assert isa_height_m(pressure_at(h)) == pytest.approx(h, abs=1e-6)
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ValueError):
            isa_height_m(bad)


def fly(
    baro: BaroHeight,
    seconds: float,
    *,
    t0: float = 0.0,
    offset_m: float = 12.0,
    drift_mps: float = 0.002,
    noise_m: float = 0.2,
    seed: int = 1,
    calibrate: bool = True,
) -> float:
    """10 Hz readings of a climb at 1.5 m/s with an offset and a weather drift, calibrated
    against exact GNSS heights (variance 0.03^2) at 10 Hz; returns the last time."""
    rng = np.random.default_rng(seed)
    t = t0
    for k in range(int(seconds * 10)):
        t = t0 + 0.1 * k
        h_true = 100.0 + 1.5 * t
        h_baro = h_true + offset_m + drift_mps * t + noise_m * rng.standard_normal()
        baro.on_sample(BaroSample(t, t, pressure_at(h_baro), 20.0))
        if calibrate:
            baro.calibrate(t, h_true, 0.03**2)
    return t


def test_calibration_learns_offset_and_drift_with_honest_sigma() -> None:
    errors, sigmas = [], []
    for seed in range(40):
        baro = BaroHeight()
        t = fly(baro, 120.0, seed=seed)
        assert baro.calibrated
        # 20 s later, no calibration since (a GNSS gap): the reference carries the drift
        t_gap = t + 20.0
        fly(baro, 0.3, t0=t_gap, seed=seed + 100, calibrate=False)
        ref = baro.reference(t_gap, 0.2)
        assert ref is not None
        h_true = 100.0 + 1.5 * t_gap
        errors.append(ref.alt_msl_m - h_true)
        sigmas.append(math.sqrt(ref.var_m2))
        assert ref.white_var_m2 == pytest.approx(0.04, rel=0.3)  # measured, not the floor
    z = np.array(errors) / np.array(sigmas)
    # the white noise of one reading dominates: errors within 3 sigma, none absurd
    assert np.all(np.abs(z) < 3.5)
    assert 0.5 < float(np.std(z)) < 1.3


def test_not_calibrated_or_stale_gives_no_reference() -> None:
    baro = BaroHeight()
    fly(baro, 5.0, calibrate=False)
    assert baro.reference(4.9, 0.2) is None  # never calibrated
    fly(baro, 20.0, t0=5.0)
    assert baro.reference(24.9, 0.2) is not None
    assert baro.reference(30.0, 0.2) is None  # no reading near that time


def test_a_jump_is_rejected_and_counted_a_new_level_restarts_the_calibration() -> None:
    stats: Counter[str] = Counter()
    baro = BaroHeight(BaroConfig(), stats)
    t = fly(baro, 30.0, noise_m=0.05)
    epoch = baro.epoch
    # one glitch of 20 m: turned away, the track goes on
    assert not baro.on_sample(BaroSample(t + 0.1, 0.0, pressure_at(100 + 1.5 * t + 32.0), None))
    assert stats["baro_jump"] == 1 and baro.epoch == epoch
    assert baro.reference(t, 0.2) is not None
    # the sensor's level moves by 20 m for good: after max_consecutive_jumps, restart
    for k in range(2, 10):
        tk = t + 0.1 * k
        baro.on_sample(BaroSample(tk, 0.0, pressure_at(100 + 1.5 * tk + 32.0), None))
    assert stats["baro_restarted"] == 1 and baro.epoch > epoch
    assert baro.reference(t + 0.9, 0.2) is None  # to be calibrated again
    # a bad pressure is counted, never raised
    assert not baro.on_sample(BaroSample(t + 2.0, 0.0, math.nan, None))
    assert stats["baro_bad"] == 1

"""Vertical separation against the barometer: thresholds, ramps and dithers, the monitor."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2, norm

from companion.integrity.fde.vertical import (
    VerticalSeparation,
    dt_grid_ms,
    rho_grid,
    vertical_thresholds,
)
from companion.integrity.monitor import IntegrityMonitor
from companion.nav.baro import BaroReference
from companion.types import Alert, AlertCode, FixType, GnssFix
from tests.integrity.test_monitor import cat2_config, meas, solution

P = 1e-7


def test_white_limit_is_the_papers_formulas() -> None:
    n, dt = 200, 0.1
    sb, k_s, rss = vertical_thresholds(n, 100, 1e-9, P, P)
    sxx = n * (n * n - 1) / 12.0 * dt * dt
    assert sb == pytest.approx(1.0 / math.sqrt(sxx), rel=1e-3)
    assert k_s == pytest.approx(norm.isf(P / 2.0))
    assert rss == pytest.approx(chi2.isf(P, n - 2), rel=2e-3)
    # a correlated part only raises both
    sb2, _, rss2 = vertical_thresholds(n, 100, 1.0, P, P)
    assert sb2 > sb and rss2 > rss


def test_grids_round_towards_the_conservative_side() -> None:
    assert rho_grid(0.02) >= 0.02 and rho_grid(0.02) < 0.02 * 1.34
    assert rho_grid(0.0) == pytest.approx(1e-3)
    for dt in (0.1, 0.2, 0.203, 0.0999, 1.0):
        assert dt_grid_ms(dt) <= dt * 1e3 + 1e-9 and dt_grid_ms(dt) > 0.92 * dt * 1e3


def run(series: np.ndarray, t: np.ndarray, gnss_var: float = 0.03**2) -> list[float | None]:
    """Feed a separation series; the time of the first failure per test kind."""
    vs = VerticalSeparation(20.0, 5, P, P, P)
    first: dict[str, float] = {}
    for tk, sk in zip(t.tolist(), series.tolist(), strict=True):
        res = vs.update(tk, sk, gnss_var, 0.2**2, 0.03**2, 1e-6)
        for r in res.reasons:
            first.setdefault(r.split()[0], tk)
    return [first.get(k) for k in ("separation", "slope", "residual")]


def test_noise_alone_passes_a_ramp_and_a_dither_do_not() -> None:
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 600.0, 0.1)
    white = 0.2 * rng.standard_normal(t.size)
    # receiver error: Gauss-Markov 3 cm, 30 s
    gm = np.zeros(t.size)
    a = math.exp(-0.1 / 30.0)
    for k in range(1, t.size):
        gm[k] = a * gm[k - 1] + 0.03 * math.sqrt(1 - a * a) * rng.standard_normal()
    noise = white + gm
    assert run(noise, t) == [None, None, None]
    onset = 300.0
    ramp = noise + np.where(t > onset, 0.04 * (t - onset), 0.0)
    _, t_slope, _ = run(ramp, t)
    assert t_slope is not None and 0.04 * (t_slope - onset) < 1.0
    dither = noise + np.where(t > onset, 1.0 * np.sin(2 * math.pi * (t - onset) / 20.0), 0.0)
    found = [x for x in run(dither, t) if x is not None]
    assert found and min(found) - onset < 10.0


def fix_at(t: float, alt: float) -> GnssFix:
    return GnssFix(
        t, t, 0, FixType.RTK_FIXED, 0.0, 0.0, alt, None, None, 0.0, None,
        None, None, None, None, None, None,
    )  # fmt: skip


def baro_at(t: float, alt: float, epoch: int = 1) -> BaroReference:
    return BaroReference(t, alt, 0.2**2, 0.03**2, 1e-6, epoch)


def test_monitor_a_disagreement_with_the_barometer_is_unresolved_not_an_exclusion() -> None:
    mon = IntegrityMonitor(cat2_config())
    rng = np.random.default_rng(5)
    alerts: list[Alert] = []
    for k in range(600):
        t = 100.0 + 0.1 * k
        h_true = 400.0
        ramp = 0.04 * max(0.0, t - 130.0)
        alt = h_true + ramp
        mon.on_solution(solution(t, height=alt - 110.0))
        out = mon.on_fix(
            fix_at(t, alt),
            meas(t, np.array([0.0, 0.0, -alt])),
            None,
            baro=baro_at(t, h_true + 0.2 * rng.standard_normal()),
        )
        alerts += [o for o in out if isinstance(o, Alert)]
    faults = [a for a in alerts if a.code is AlertCode.FAULT]
    assert faults and faults[0].text.startswith("unresolved") and "ref:baro" in faults[0].text
    assert faults[0].t_s - 130.0 < 25.0  # before the ramp reached 1 m
    assert not mon.exclude(0)
    assert mon.stats["baro_disagrees"] > 0


def test_monitor_skips_the_barometer_near_the_field_and_on_a_bad_input() -> None:
    mon = IntegrityMonitor(cat2_config())
    t = 100.0
    mon.on_solution(solution(t, height=5.0))
    mon.on_fix(fix_at(t, 116.0), meas(t, np.zeros(3)), None, baro=baro_at(t, 116.0))
    assert mon.stats["baro_not_used_low"] == 1
    bad = BaroReference(t + 0.1, 400.0, math.nan, 0.01, 0.0, 1)
    mon.on_solution(solution(t + 0.1, height=290.0))
    out = mon.on_fix(fix_at(t + 0.1, 400.0), meas(t + 0.1, np.zeros(3)), None, baro=bad)
    assert out == [] and mon.stats["bad_separation"] == 1

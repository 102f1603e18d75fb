"""The autopilot's attitude against its own body rates (:mod:`companion.nav.blend.rate_drift`)."""

from __future__ import annotations

import math

import pytest

from companion.nav.blend.rate_drift import RateDrift
from companion.nav.rotations import euler_to_quat_values, quat_from_rotvec, quat_mul


def _feed(drift: RateDrift, extra_radps: tuple[float, float, float], n: int, dt: float) -> None:
    """Attitude samples turning at ``rates`` plus ``extra_radps`` (body) that the reported
    rates do not show."""
    rates = [0.05, -0.02, 0.1]
    q = euler_to_quat_values(0.1, -0.05, 1.0)
    for k in range(n):
        drift.on_sample(k * dt, q, rates)
        step = [(rates[i] + extra_radps[i]) * dt for i in range(3)]
        q = quat_mul(q, quat_from_rotvec(*step))


def test_an_attitude_straying_from_its_rates_bounds_their_bias() -> None:
    drift = RateDrift(60.0)
    assert drift.bias_variance() is None
    extra = (math.radians(0.02), -math.radians(0.01), 0.0)
    _feed(drift, extra, 1500, 0.04)
    var = drift.bias_variance()
    assert var is not None
    # to first order in dt: the rotations do not commute, a residual of at most
    # |rates| |extra| dt / 2 per unit of time
    second_order = math.hypot(0.05, 0.02, 0.1) * math.hypot(*extra) * 0.04 / 2.0
    for v, e in zip(var, extra, strict=True):
        assert math.sqrt(v) == pytest.approx(abs(e), abs=second_order)


def test_rates_that_explain_the_attitude_leave_no_bias() -> None:
    drift = RateDrift(60.0)
    _feed(drift, (0.0, 0.0, 0.0), 500, 0.04)
    var = drift.bias_variance()
    assert var is not None and max(var) < 1e-16


def test_jumps_and_gaps_are_not_taken_as_drift() -> None:
    drift = RateDrift(60.0)
    rates = [0.0, 0.0, 0.0]
    q0 = euler_to_quat_values(0.0, 0.0, 0.0)
    drift.on_sample(0.0, q0, rates)
    drift.on_sample(0.04, euler_to_quat_values(0.0, 0.0, math.radians(5.0)), rates)  # a reset
    drift.on_sample(2.0, q0, rates)  # 1.96 s later: a gap in the stream
    assert drift.skipped == 2
    assert drift.bias_variance() is None
    drift.restart()
    drift.on_sample(2.04, euler_to_quat_values(0.0, 0.0, 1.0), rates)  # not compared
    assert drift.skipped == 2 and drift.bias_variance() is None

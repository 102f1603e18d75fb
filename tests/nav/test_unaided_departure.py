"""The autopilot's heading departure from its own body rates through a gap (closed forms)."""

from __future__ import annotations

import math

import pytest

from companion.nav.blend.unaided import SMOOTH_S, UnaidedDeparture
from companion.nav.rotations import euler_to_quat_values

_DEG = math.pi / 180.0
HZ = 25.0


def _run(
    dep: UnaidedDeparture,
    duration_s: float,
    rate_bias_z: float,
    heading_offset,  # noqa: ANN001 - t -> rad
    yaw_rate: float = 0.1,
) -> float:
    """A level turn at ``yaw_rate``; the rates carry ``rate_bias_z``, the reported heading
    is the truth plus ``heading_offset(t)``. Returns the peak smoothed departure, rad."""
    n = int(duration_s * HZ)
    for k in range(n + 1):
        t = k / HZ
        q = euler_to_quat_values(0.0, 0.0, yaw_rate * t + heading_offset(t))
        dep.on_sample(t, q, [0.0, 0.0, yaw_rate + rate_bias_z])
        dep.on_sample(t, q, [0.0, 0.0, yaw_rate + rate_bias_z])  # a repeat: ignored
    return math.sqrt(dep.peak_sq_rad2)


def test_aiding_that_carries_on_departs_by_nothing_and_stopped_aiding_by_the_bias() -> None:
    """Rates biased by b: an autopilot whose heading stays true departs from them by -b t;
    corrected by its mean departure while aided (-b), by nothing."""
    b = 0.05 * _DEG
    dep = UnaidedDeparture()
    dep.start([0.0, 0.0, -b])
    assert _run(dep, 30.0, b, lambda t: 0.0) == pytest.approx(0.0, abs=1e-6)
    dep.start()
    # the smoothed ramp trails the ramp by SMOOTH_S: b (t - SMOOTH_S (1 - e^(-t/SMOOTH_S)))
    t = 30.0
    expected = b * (t - SMOOTH_S * (1.0 - math.exp(-t / SMOOTH_S)))
    assert _run(dep, t, b, lambda t: 0.0) == pytest.approx(expected, rel=2e-3)


def test_a_pulled_heading_counts_and_a_roll_transient_hardly() -> None:
    """A heading pulled 1 deg by the aiding and kept counts as 1 deg; the same 1 deg for
    0.4 s (the rates trailing the attitude through a roll) counts as a fraction."""
    dep = UnaidedDeparture()
    dep.start()
    kept = _run(dep, 20.0, 0.0, lambda t: 1.0 * _DEG if t > 5.0 else 0.0)
    assert kept == pytest.approx(1.0 * _DEG, rel=1e-3)
    dep.start()
    blip = _run(dep, 20.0, 0.0, lambda t: 1.0 * _DEG if 5.0 < t <= 5.4 else 0.0)
    assert blip < 0.2 * _DEG
    assert blip == pytest.approx(1.0 * _DEG * (1.0 - math.exp(-0.4 / SMOOTH_S)), rel=0.1)


def test_a_gap_in_the_attitude_stream_restarts_the_carry_and_keeps_the_peak() -> None:
    dep = UnaidedDeparture()
    dep.start()
    b = 0.1 * _DEG
    _run(dep, 10.0, b, lambda t: 0.0)
    peak = dep.peak_sq_rad2
    assert peak > 0.0
    q = euler_to_quat_values(0.0, 0.0, 0.0)
    assert dep.on_sample(100.0, q, [0.0, 0.0, 0.0]) == 0.0
    assert dep.restarts == 1
    assert dep.peak_sq_rad2 == peak

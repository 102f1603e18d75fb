"""Is the vehicle standing still when the blend starts? Then the receiver's velocity is
its error.

A receiver's Doppler velocity can carry a slowly varying bias beyond its reported
accuracy (:mod:`.velocity_error`); its positions measure it, but only after a few
seconds of baselines. Before that, at the start, the blend fused a realistic receiver's
0.15 m/s at rest as good to 2 cm/s: within a second the prediction had moved 9 cm off
the parked receiver's RTK fixes and the receiver was excluded as faulty
(``bench/false_alerts.py``, the copter). A vehicle at rest needs no positions to tell
the error: its velocity is zero, so what the receiver reports is what it errs by
(a zero-velocity update, Groves, 2nd ed., sec. 15.3.1).

The window is the IMU samples the blend holds before its first fix; it is rest when the
receiver says the vehicle stands still and the accelerometer and gyro are quiet (the
coarse aligner's thresholds, :class:`~companion.nav.blend.alignment.CoarseAligner`): a
slow, smooth motion is quiet too, which is why the receiver's own speed must be small.
Pure: no I/O, no clock.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

STILL_SPEED_MPS = 0.5
"""Below this GNSS ground speed the vehicle may stand still (the phase logic's
stationary speed, ``PhaseConfig.stationary_speed_mps``)."""
MIN_SAMPLES = 10
"""Fewer IMU samples say nothing about the window."""


def at_rest(
    samples: Sequence[tuple[float, list[float], list[float]]],
    ground_speed_mps: float,
    acc_std_max_mps2: float,
    gyro_std_max_radps: float,
) -> bool:
    """Do the IMU ``samples`` ((t_s, acc_b m/s^2, gyro_b rad/s) each) and the receiver's
    ``ground_speed_mps`` say the vehicle stands still: the speed below
    :data:`STILL_SPEED_MPS` and every accelerometer and gyro axis's standard deviation
    within its limit (module docstring)?"""
    n = len(samples)
    if n < MIN_SAMPLES or not ground_speed_mps < STILL_SPEED_MPS:
        return False
    mean = [0.0] * 6
    sq = [0.0] * 6
    for _, acc, gyro in samples:
        for i, v in enumerate((*acc, *gyro)):
            mean[i] += v
            sq[i] += v * v
    for i in range(6):
        m = mean[i] / n
        var = max(sq[i] / n - m * m, 0.0)
        if math.sqrt(var) > (acc_std_max_mps2 if i < 3 else gyro_std_max_radps):
            return False
    return True

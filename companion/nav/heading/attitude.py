"""The INS heading at a fix's time, and whether the vehicle was on a straight section.

GNSS is delayed, so a few seconds of :class:`~companion.types.AttitudeSample` are
buffered; the INS heading of a cycle is the yaw interpolated (angle-aware) at the
fix's time of validity. The section is straight when the INS heading rate stayed
at or below ``max_turn_rate_dps`` for the last ``settle_time_s``: a turn ends a
leg, and the turn's cycles and the settling ones after it (while the receiver's
velocity filter catches up) are not used (Markelov et al., the straight-section
rule of the taxi heading correction).
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable

from companion.nav.heading.config import HeadingConfig
from companion.nav.rotations import wrap_pi
from companion.types import AttitudeSample

RATE_BASELINE_S = 0.5
"""Baseline of the finite-difference heading rate, s: long enough that 0.01 deg of
heading noise stays far below the 1 deg/s turn limit."""


def yaw_rate_radps(sample: AttitudeSample) -> float:
    """Heading (yaw) rate from the body rates, rad/s.

    ``psi_dot = (q sin(roll) + r cos(roll)) / cos(pitch)`` (ZYX Euler kinematics);
    NaN when the rates are not finite.
    """
    rate = sample.rate_b_radps
    if rate is None or len(rate) != 3:
        return math.nan
    q, r = float(rate[1]), float(rate[2])
    c_pitch = math.cos(sample.pitch_rad)
    if abs(c_pitch) < 1e-6:
        return math.nan
    return (q * math.sin(sample.roll_rad) + r * math.cos(sample.roll_rad)) / c_pitch


class AttitudeHistory:
    """The last ``attitude_buffer_s`` of INS heading (rad, wrapped), its rate (rad/s)
    and whether each sample was turning.

    ``reject`` is called with the reason of every sample or query not used.
    """

    def __init__(self, config: HeadingConfig, reject: Callable[[str], None]) -> None:
        self.config = config
        self._reject = reject
        self._turn_rate_radps = math.radians(config.max_turn_rate_dps)
        self._t: list[float] = []
        self._yaw: list[float] = []
        self._turning: list[bool] = []
        self._rate: list[float] = []

    def add(self, sample: AttitudeSample) -> None:
        """Buffer the INS heading ``yaw_rad`` and its rate (turn detection)."""
        if not (math.isfinite(sample.t_s) and math.isfinite(sample.yaw_rad)):
            self._reject("attitude_not_finite")
            return
        if self._t and sample.t_s <= self._t[-1]:
            if sample.t_s < self._t[-1] - self.config.attitude_buffer_s:
                # the clock restarted (autopilot reboot): the old history is meaningless
                self.clear()
            else:
                self._reject("attitude_out_of_order")
                return
        rate = yaw_rate_radps(sample)
        diff_rate = self._yaw_diff_rate(sample)
        if not math.isfinite(rate):
            rate = diff_rate
        turning = (not math.isfinite(rate)) or abs(rate) > self._turn_rate_radps
        # also the heading change over the last RATE_BASELINE_S: catches a stream whose
        # body rates are missing or zero while the heading turns
        if math.isfinite(diff_rate) and abs(diff_rate) > self._turn_rate_radps:
            turning = True
        self._t.append(sample.t_s)
        self._yaw.append(wrap_pi(sample.yaw_rad))
        self._turning.append(turning)
        self._rate.append(rate if math.isfinite(rate) else 0.0)
        horizon = sample.t_s - self.config.attitude_buffer_s
        if len(self._t) > 64 and self._t[32] < horizon:
            k = bisect.bisect_left(self._t, horizon)
            del self._t[:k], self._yaw[:k], self._turning[:k], self._rate[:k]

    def _yaw_diff_rate(self, sample: AttitudeSample) -> float:
        """Heading rate from the heading change since the sample RATE_BASELINE_S earlier, rad/s."""
        if not self._t:
            return math.nan
        k = bisect.bisect_right(self._t, sample.t_s - RATE_BASELINE_S) - 1
        if k < 0:
            k = 0
        dt = sample.t_s - self._t[k]
        if dt <= 0.0 or dt > self.config.max_attitude_gap_s + RATE_BASELINE_S:
            return math.nan
        return wrap_pi(sample.yaw_rad - self._yaw[k]) / dt

    def clear(self) -> None:
        """Forget the history."""
        self._t.clear()
        self._yaw.clear()
        self._turning.clear()
        self._rate.clear()

    def yaw_at(self, t_s: float) -> tuple[float, bool] | None:
        """INS heading (rad) interpolated at ``t_s`` and whether the last settle_time_s
        was straight; ``None`` (rejected) when the history does not cover ``t_s``."""
        ts = self._t
        if not ts:
            self._reject("no_attitude")
            return None
        k = bisect.bisect_right(ts, t_s)  # ts[k-1] <= t_s < ts[k]
        if k == 0:
            self._reject("attitude_too_new")
            return None
        if k == len(ts):
            dt = t_s - ts[-1]
            if dt > self.config.max_extrapolation_s:
                self._reject("attitude_too_old")
                return None
            yaw = wrap_pi(self._yaw[-1] + self._rate[-1] * dt)
        else:
            t0, t1 = ts[k - 1], ts[k]
            if t1 - t0 > self.config.max_attitude_gap_s:
                self._reject("attitude_gap")
                return None
            frac = (t_s - t0) / (t1 - t0)
            y0 = self._yaw[k - 1]
            yaw = wrap_pi(y0 + frac * wrap_pi(self._yaw[k] - y0))
        # straight: no turning sample in [t_s - settle, t_s] (and the bracketing one),
        # and the history reaches back that far
        start = t_s - self.config.settle_time_s
        if ts[0] > start:
            return yaw, False
        j = max(bisect.bisect_left(ts, start) - 1, 0)
        k_end = min(k + 1, len(ts))
        straight = not any(self._turning[j:k_end])
        return yaw, straight

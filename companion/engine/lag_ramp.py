"""A new receiver lag carried in without moving a fix by more than the navigator can absorb.

A fix is placed at its stamp less the lag in use. Changing the lag by ``dl`` moves where
the navigator believes the receiver was by ``v dl`` at the speed ``v``: 35 ms at 45 m/s is
1.6 m, and against an RTK fix's 14 mm the navigator's innovation test sees a fault
(chi-square 18,759). So a new lag is carried in by steps, one per fix, each moving the
fix by at most ``step_sigmas`` of the horizontal innovation's 1-sigma (the fix's accuracy
and the solution's combined: what the navigator's gate measures it against), and all at
once where that covers what is left:

* on the ground, or hovering, where ``v dl`` is nothing;
* in a gap, where the solution's own uncertainty has grown beyond it;
* with a receiver whose accuracy (a 3-D fix's metres) dwarfs it.

At 45 m/s with RTK fixes at 10 Hz (a 2-3 cm innovation sigma) a quarter-sigma step moves
the fix 6 mm a fix, 6 cm/s: 35 ms in about 25 s. Every step is a change of the service's
own (:mod:`companion.engine.self_change`).

Pure: numbers in, the lag to use out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class LagRampConfig:
    step_sigmas: float = 0.25
    """A step may move a fix by this many of the horizontal innovation's 1-sigma: the
    navigator's innovations stay within a quarter of their noise, which its chi-square
    tests (at a 1e-7 false-alarm probability, 40.9 for 6 components) cannot tell."""


class LagRamp:
    """The lag in use, carried towards a target (:meth:`start`) one step a fix (:meth:`step`)."""

    def __init__(self, config: LagRampConfig | None = None) -> None:
        self.config = config or LagRampConfig()
        self.in_use_s = 0.0
        self.target_s = 0.0

    @property
    def active(self) -> bool:
        """A target not reached yet."""
        return self.in_use_s != self.target_s

    def start(self, in_use_s: float, target_s: float) -> None:
        """Carry the lag from ``in_use_s`` (what the fixes are placed with now) to
        ``target_s``."""
        self.in_use_s = in_use_s
        self.target_s = target_s

    def step(self, speed_mps: float, innovation_sigma_m: float) -> float:
        """The lag to place the next fixes with, after a fix at ``speed_mps`` whose
        horizontal innovation has a 1-sigma of ``innovation_sigma_m`` (inf: nothing to
        compare it with, e.g. before the navigation starts): towards the target by at most
        ``step_sigmas`` of it over the speed, all the way when that covers the rest."""
        left = self.target_s - self.in_use_s
        if left == 0.0:
            return self.in_use_s
        speed = abs(speed_mps) if math.isfinite(speed_mps) else math.inf
        reach_m = self.config.step_sigmas * innovation_sigma_m
        if not math.isfinite(reach_m) or speed * abs(left) <= reach_m:
            self.in_use_s = self.target_s
        else:
            self.in_use_s += math.copysign(reach_m / speed, left)
        return self.in_use_s

    def placed_for(self, t_s: float) -> float:
        """A fix time placed with the lag in use, as the target would place it (what the
        lag measurement compares with the IMU: it measures against the target)."""
        return t_s + self.in_use_s - self.target_s

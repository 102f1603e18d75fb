"""Running statistics of the heading mismatch and the cycles of the current sample.

Per cycle ``i`` (Markelov et al., "INS course correction from satellite
navigation before take-off")::

    dphi_i = psi_ins,i - atan2(V_E,i, V_N,i) - crab         (wrapped to +-180 deg)
    mean_i = mean_{i-1} + (dphi_i - mean_{i-1}) / i
    var_i  = var_{i-1} (i-2)/(i-1) + (dphi_i - mean_{i-1})^2 / i
    eps_i  = z_{95} sqrt(var_i / (i-1))                     (z_{95} = 1.96)

The correction is the mean mismatch ``mean``; ``eps`` its two-sided accuracy.
The same recursion applied to the running mean (from the ``spread_start``-th
cycle on) gives the spread of the running mean, one of the acceptance criteria
(:mod:`companion.nav.heading.criteria`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from companion.nav.rotations import wrap_pi


@dataclass(frozen=True, slots=True)
class RunningStats:
    """Recursive mean and (n-1) variance of a scalar sequence.

    References
    ----------
    Markelov et al., the recursions for the mean
    ``mean_i = mean_{i-1} + (x_i - mean_{i-1})/i`` and the variance
    ``var_i = var_{i-1} (i-2)/(i-1) + (x_i - mean_{i-1})^2 / i``.
    """

    n: int = 0
    mean: float = 0.0
    var: float = 0.0

    def update(self, x: float) -> RunningStats:
        """Return the statistics with ``x`` added (the recursions above)."""
        i = self.n + 1
        if i == 1:
            return RunningStats(1, x, 0.0)
        d = x - self.mean
        return RunningStats(i, self.mean + d / i, self.var * (i - 2) / (i - 1) + d * d / i)


@dataclass(frozen=True, slots=True)
class HeadingEstimate:
    """The current estimate, all angles in radians.

    ``correction_rad`` is the mean mismatch (INS heading minus GNSS track),
    ``sigma_rad`` the sample standard deviation of one mismatch, ``eps_rad`` the
    95 % accuracy of the mean (``inf`` below two cycles), ``n`` the cycles used,
    ``legs`` the straight legs they came from.
    """

    correction_rad: float
    sigma_rad: float
    eps_rad: float
    n: int
    legs: int


class CycleSample:
    """The cycles of the current sample: their running statistics and, per cycle,
    the time of validity (s), the mismatch (rad, unwrapped about the running mean),
    its expected 1-sigma scatter (rad) and the straight leg it belongs to.

    A leg is a run of consecutive cycles on one straight section; ``full_legs``
    counts the legs of at least ``min_leg_cycles`` cycles.
    """

    def __init__(self) -> None:
        self.stats = RunningStats()
        self.mean_stats = RunningStats()
        """Statistics of the running mean from the ``spread_start``-th cycle on."""
        self.t_s: list[float] = []
        self.x_rad: list[float] = []
        self.sigma_rad: list[float] = []
        self.leg: list[int] = []
        self.leg_id = 0
        """Number of the current (or last) leg; kept across :meth:`clear`."""
        self.n_legs = 0
        self.leg_cycles = 0
        self.full_legs = 0
        self.in_leg = False

    def clear(self) -> None:
        """Drop every cycle (a new sample begins); leg numbers keep counting."""
        self.stats = RunningStats()
        self.mean_stats = RunningStats()
        self.t_s.clear()
        self.x_rad.clear()
        self.sigma_rad.clear()
        self.leg.clear()
        self.n_legs = 0
        self.full_legs = 0
        self.in_leg = False

    def end_leg(self) -> None:
        """The straight section ended: the next cycle starts a new leg."""
        self.in_leg = False

    def add(
        self,
        t_s: float,
        dphi_rad: float,
        sigma_rad: float,
        *,
        spread_start: int,
        min_leg_cycles: int,
    ) -> None:
        """Add one cycle: mismatch ``dphi_rad`` (wrapped), expected scatter ``sigma_rad``."""
        if not self.in_leg:
            self.leg_id += 1
            self.n_legs += 1
            self.leg_cycles = 0
            self.in_leg = True
        self.leg_cycles += 1
        if self.leg_cycles == min_leg_cycles:
            self.full_legs += 1
        # unwrap about the running mean so that a mismatch near +-180 deg stays continuous
        x = dphi_rad if self.stats.n == 0 else self.stats.mean + wrap_pi(dphi_rad - self.stats.mean)
        self.stats = self.stats.update(x)
        if self.stats.n >= spread_start:
            self.mean_stats = self.mean_stats.update(self.stats.mean)
        self.t_s.append(t_s)
        self.x_rad.append(x)
        self.sigma_rad.append(sigma_rad)
        self.leg.append(self.leg_id)

    def estimate(self, z: float) -> HeadingEstimate:
        """The running estimate, ``eps`` at the two-sided normal quantile ``z``."""
        s = self.stats
        eps = z * math.sqrt(s.var / (s.n - 1)) if s.n >= 2 else math.inf
        return HeadingEstimate(wrap_pi(s.mean), math.sqrt(s.var), eps, s.n, self.n_legs)

    def mean_spread_rad(self) -> float:
        """Spread (1 sigma) of the running mean since the ``spread_start``-th cycle, rad."""
        return math.sqrt(self.mean_stats.var) if self.mean_stats.n >= 2 else 0.0

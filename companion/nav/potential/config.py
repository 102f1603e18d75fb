"""Configuration of the position-potential filter.

Each field states its range beside it (:mod:`companion.ranges`); the checks
that relate several fields follow in ``__post_init__``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from companion.ranges import check_ranges, ranged


@dataclass(frozen=True, slots=True)
class PotentialConfig:
    """Configuration of :class:`PotentialFilter` (validated on construction)."""

    window_s: float = ranged(10.0, gt=0.0)
    """Span of past fixes kept as sources and used by the fit [s]."""
    max_sources: int = ranged(60, ge=1)
    """At most this many (newest) fixes are sources."""
    weight_floor: float = ranged(1e-12, gt=0.0, lt=1.0)
    """A source is dropped once ``e^{α(t_i − t_n)}`` falls below this."""
    alpha0_ps: float = ranged(2.84, gt=0.0)
    """Starting α [1/s]: the stable-descent value of Grzegorzewski 2005, which keeps its
    meaning with the relative weights at σ ≈ 1 m."""
    g0_ps2: float = ranged(0.35, gt=0.0)
    """Starting G [1/s²]: the paper's stable-descent value, as for ``alpha0_ps``."""
    alpha_bounds_ps: tuple[float, float] = ranged((0.5, 10.0), gt=0.0, length=2)
    """Bounds of the fit of α [1/s] (searched in log10). The closed form is sound
    for any α ≥ 0, but below 0.5 1/s the field barely dissipates, the particle is
    pulled towards the centroid of the whole window (seconds behind the aircraft)
    and 5-20 s predictions collapse, while the one-step objective hardly notices
    (Grzegorzewski 2005: α = 2.7-3.8 fitted, α = 0.2 "diverged badly")."""
    g_bounds_ps2: tuple[float, float] = ranged((1e-6, 1e2), gt=0.0, length=2)
    """Bounds of the fit of G [1/s²] (searched in log10). The ceiling keeps
    ``G·A·Δt² ≲ 1`` with ``A ≈ 2/(1 − e^{−αΔt})`` of 2-40 at 5-10 Hz: a stiffer
    field swings the particle within one fix interval (a parked window's fit
    otherwise runs to any ceiling)."""
    refit_interval_s: float = ranged(5.0, gt=0.0)
    """Minimum fix time between two fits [s]: the real-time budget. A warm
    fit costs tens of milliseconds (``python bench/potential.py`` prints it);
    shorter intervals fit decelerating and flight-path-changing phases a
    little better, longer ones noticeably worse. The engine also forces a fit at the
    start of a gap."""
    min_fit_fixes: int = ranged(6, ge=3)
    """Fewest fixes in the window for a fit."""
    first_fit_span_s: float = ranged(2.0, gt=0.0)
    """The first fit (and the first after a restart) waits until the window
    spans this much fix time (or ``refit_interval_s`` if shorter) [s]."""
    refit_speed_change_mps: float = ranged(1.0, gt=0.0)
    """A fit is also due, before ``refit_interval_s``, once the particle's
    speed differs from its speed at the last fit by more than
    ``refit_speed_change_mps + refit_speed_change_rel · v_fit`` [m/s], [-]:
    α and G fitted while parked or taxiing are not carried into flight."""
    refit_speed_change_rel: float = ranged(0.2, ge=0.0)
    """A fit is also due, before ``refit_interval_s``, once the particle's
    speed differs from its speed at the last fit by more than
    ``refit_speed_change_mps + refit_speed_change_rel · v_fit`` [m/s], [-]:
    α and G fitted while parked or taxiing are not carried into flight."""
    refit_min_interval_s: float = ranged(1.0, gt=0.0)
    """Fewest seconds of fix time between two such speed-triggered fits [s];
    also between a fit and the one a first inconsistent fix runs before
    it is rejected (the model is refitted on the window, the fix tested
    again)."""
    de_maxiter: int = ranged(20, ge=1)
    """Differential-evolution generations and population multiplier."""
    de_popsize: int = ranged(8, ge=3)
    """Differential-evolution generations and population multiplier."""
    de_tol: float = ranged(1e-3, gt=0.0)
    """Differential-evolution relative tolerance."""
    de_grid_points: int = ranged(6, ge=2)
    """Points per axis of the coarse log grid that seeds the population."""
    de_warm_popsize: int = ranged(8, ge=0)
    """Population of the warm-started fits after the first (0: every fit
    cold, as the first; otherwise ≥ 5)."""
    velocity_weights: tuple[float, ...] = ranged(
        (0.0, 0.25, 0.5, 0.75, 1.0), ge=0.0, le=1.0, nonempty=True
    )
    """Candidate weights β in [0, 1] of the fix's measured velocity in the
    particle's velocity at a fix, ``β v_meas + (1 − β) v_lsq`` (``v_lsq``:
    the least-squares slope through the last ``velocity_span_s`` of fixes,
    which also fills components the receiver does not give). Each fit
    keeps the candidate with the smallest objective over the window;
    ``(1.0,)`` is the paper's measured velocity. The filter starts with the largest."""
    velocity_fit_orders: tuple[int, ...] = ranged((1, 2), choices=(1, 2), nonempty=True)
    """Candidate orders (1: line, 2: parabola) of the least-squares fit that
    gives ``v_lsq``. A line's slope is the velocity at the middle of the
    span, half a span (0.5 s of turn or acceleration) late; a parabola's
    slope at the newest fix is not late but noisier. Each fit keeps the
    (β, order) pair with the smallest objective; the filter starts (and
    restarts) with the largest β and order, the least-lagging velocity."""
    fit_horizons_s: tuple[float, ...] = ranged((0.5, 1.0, 2.0, 4.0), gt=0.0)
    """Gap-prediction horizons [s] whose squared errors (from the particle at
    fixes every ``fit_start_every_s``, field frozen) join the paper's one-step sum
    in the fit objective; empty for the paper's objective alone. With the
    particle's velocity reset at every fix, the one-step sum barely sees
    the field's pull (metres over a gap, millimetres over one fix
    interval): the multi-step terms fit α and G to the use they are put to."""
    fit_start_every_s: float = ranged(0.5, gt=0.0)
    """Spacing of the start fixes of those terms [s]."""
    de_warm_spread_dex: float = ranged(0.15, gt=0.0)
    """Spread (1σ, decades of α and G) of the warm members around the last
    solution."""
    adopt_replay_state: bool = True
    """After a fit, move the particle to the fitted model's replayed state at
    the newest fix (True, the default) or keep the carried particle and
    change only the field (False)."""
    position_update: bool = True
    """At each fix, move the particle's carried position towards the fix by
    the per-axis gain ``K = P/(P + R)`` (``P`` the predicted position
    variance, ``R`` the fix's) (True, the default), or keep the carried
    position (False, the paper's filter). Without it, the particle's position is tied
    to the fixes only through the field, whose centre (the weighted
    centroid of the recent fixes) trails a moving aircraft by ~1/α of
    motion: any G strong enough to hold the particle drags it towards
    that centroid, and the fit's only escape is G → 0, pure coasting,
    whose position error then grows without bound."""
    false_alarm_prob: float = ranged(1e-3, gt=0.0, lt=1.0)
    """False-alarm probability of the χ² (3 dof) fix test."""
    fix_resolution_m: tuple[float, float, float] = ranged((0.0112, 0.0112, 0.001), gt=0.0, length=3)
    """Resolution of the fixes' N, E, D positions [m], > 0: the fix test's
    innovation variance ``S`` is at least ``res²/12`` per axis, the
    rounding variance of the new fix's position (one 1.11 cm step of a
    parked receiver then gives χ² = 12, below the 1e-3 quantile). The
    defaults are those of a latitude/longitude given to 1e-7° (1.11 cm of
    latitude; longitude's step is smaller) and an altitude in mm, as
    MAVLink's GPS_RAW_INT gives them: a parked RTK receiver's residuals are
    millimetres, so one rounding step would otherwise fail the test."""
    min_test_fixes: int = ranged(3, ge=2)
    """Fixes needed before new fixes are tested."""
    max_consecutive_inconsistent: int = ranged(3, ge=1)
    """After this many consecutive inconsistent fixes the filter restarts
    from them and the next one (the model, not the fixes, is then taken to
    be wrong); α, G and the covariance calibration are kept."""
    velocity_mode: Literal["measured", "carried"] = ranged(
        "measured", choices=("measured", "carried")
    )
    """Velocity of the particle at a fix: the fix's (derived where absent),
    or the carried particle's (the paper's particle)."""
    velocity_span_s: float = ranged(1.0, gt=0.0)
    """Span of the least-squares line giving velocity components the fix lacks [s]."""
    prior_vel_sigma_mps: float = ranged(1.0, gt=0.0)
    """Prior 1σ velocity and acceleration error of the particle, used for the
    predicted covariance before calibration."""
    prior_acc_sigma_mps2: float = ranged(1.0, gt=0.0)
    """Prior 1σ velocity and acceleration error of the particle, used for the
    predicted covariance before calibration."""
    calib_min_residuals: int = ranged(30, ge=3)
    """Residual pairs needed in a fit window before its calibration is used."""
    calib_forgetting: float = ranged(0.25, gt=0.0, le=1.0)
    """Factor in (0, 1] by which the binned residual sums of earlier fits decay
    at each fit. A manoeuvre's window (the push-over into a glide: metres
    at 5 s) outweighs a steady window's (centimetres) by 10⁴ in e²: 0.25
    leaves it 1/4096 after six fits, where 0.5 let it rule the gap covariance
    half a minute later."""
    seed: int = 0
    """Seed of the optimiser (each fit uses ``seed + fit count``)."""

    def __post_init__(self) -> None:
        check_ranges(self)
        if 0 < self.de_warm_popsize < 5:
            raise ValueError(f"de_warm_popsize must be 0 or >= 5, got {self.de_warm_popsize!r}")
        for name in ("alpha_bounds_ps", "g_bounds_ps2"):
            lo, hi = getattr(self, name)
            if not lo < hi:
                raise ValueError(f"{name} must be increasing (lo < hi), got {(lo, hi)!r}")
        if not self.alpha_bounds_ps[0] <= self.alpha0_ps <= self.alpha_bounds_ps[1]:
            raise ValueError(
                f"alpha0_ps must lie within alpha_bounds_ps {self.alpha_bounds_ps!r}, "
                f"got {self.alpha0_ps!r}"
            )
        if not self.g_bounds_ps2[0] <= self.g0_ps2 <= self.g_bounds_ps2[1]:
            raise ValueError(
                f"g0_ps2 must lie within g_bounds_ps2 {self.g_bounds_ps2!r}, got {self.g0_ps2!r}"
            )

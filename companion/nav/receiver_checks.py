"""A receiver judged by its own evidence, never by the estimate it is meant to correct.

What a fix says about itself: its type, satellites, HDOP and reported accuracy
(the quality checks), and whether its position moved as its own velocity says it
should (the consistency checks):

* **increment**: between consecutive fixes ``dt`` apart, the horizontal position
  increment against the trapezoid of the two reported velocities,
  ``|dp - (v0 + v1) dt / 2| <= increment_tol_m + increment_tol_mps * dt``: a glitch
  (a step), a frozen or repeated position while the velocity says moving, a
  velocity that contradicts the track all fail it;
* **chain**: the same residual summed since the chain began (it telescopes to the
  displacement less the integrated velocity), within ``chain_tol_m +
  chain_tol_mps * T``: a slow position ramp that the velocity does not show.

A failed check restarts the chain at that fix; a receiver is *self-consistent*
once its chain spans ``consistency_window_s`` and ``consistency_min_fixes``.
A fix with the time stamp of the previous one is a repeat, never evidence.

Real receivers (the flights under ``../shared/realdata``): the increment residual
stays below 2.1 m at dt <= 1.5 s (0.64 m at 5 Hz), the chain below 3.9 m over
3 s and 3.7 m over 10 s; the tolerances sit above those.

Compare PX4 EKF2's GNSS quality checks (``gps_checks.cpp``: satellites, PDOP,
eph/epv, speed accuracy, drift rates at rest) and the glitch test of a new
position against the previous one carried by its velocity (the position
increment above). Pure: no I/O, no clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from companion.nav.earth import radii_of_curvature_m
from companion.ranges import check_ranges, ranged
from companion.types import FixType, GnssFix


@dataclass(frozen=True, slots=True)
class ReceiverCheckConfig:
    """Thresholds of a receiver's own quality and consistency (part of ``[outage]``)."""

    min_satellites: int = ranged(6, ge=0)
    """Fewer satellites than this (when reported) fails the quality check (PX4: 6)."""
    max_hdop: float = ranged(4.0, gt=0.0, finite=False)
    """HDOP above this (when reported) fails it. Looser than PX4's pre-flight PDOP 2.5:
    this decides whether to re-admit a receiver in flight, not whether to arm (the
    plane's receiver flies at HDOP up to 2.6)."""
    max_h_acc_m: float = ranged(10.0, gt=0.0, finite=False)
    """Reported horizontal 1-sigma above this (when reported) fails it."""
    increment_tol_m: float = ranged(1.0, gt=0.0)
    """Constant part of the increment tolerance, m (position noise between fixes)."""
    increment_tol_mps: float = ranged(2.0, ge=0.0)
    """Part of the increment tolerance growing with the fix interval, m/s (velocity
    noise and quantisation, acceleration within the interval)."""
    chain_tol_m: float = ranged(4.0, gt=0.0)
    """Constant part of the chain tolerance, m."""
    chain_tol_mps: float = ranged(0.5, ge=0.0)
    """Drift rate of the chain residual allowed, m/s (velocity bias integrated)."""
    max_increment_dt_s: float = ranged(2.0, gt=0.0)
    """Fixes further apart than this are not compared: the chain restarts (a gap is no
    inconsistency, and says nothing either)."""
    consistency_window_s: float = ranged(2.0, ge=0.0)
    """A receiver is self-consistent once its chain spans this long ..."""
    consistency_min_fixes: int = ranged(3, ge=1)
    """... and this many fixes."""

    def __post_init__(self) -> None:
        check_ranges(self)


@dataclass(slots=True)
class ReceiverConsistency:
    """One receiver's chain of self-consistent fixes (see the module docstring). The
    thresholds are passed with each call (the configuration may change while running)."""

    last: GnssFix | None = None
    chain_start_t_s: float | None = None
    """Time of the first fix of the current chain (None: no chain)."""
    chain_fixes: int = 0
    chain_resid_n_m: float = 0.0
    chain_resid_e_m: float = 0.0
    last_failure: str = ""
    """Why the chain last restarted ('' if it never failed)."""

    def quality_failure(self, fix: GnssFix, cfg: ReceiverCheckConfig) -> str:
        """Why the fix fails the quality checks, or ''."""
        if int(fix.fix_type) < int(FixType.FIX_3D):
            return f"fix type {int(fix.fix_type)}"
        if fix.satellites is not None and fix.satellites < cfg.min_satellites:
            return f"{fix.satellites} satellites"
        if fix.hdop is not None and fix.hdop > cfg.max_hdop:
            return f"HDOP {fix.hdop:.1f}"
        if fix.h_acc_m is not None and fix.h_acc_m > cfg.max_h_acc_m:
            return f"h_acc {fix.h_acc_m:.1f} m"
        return ""

    def on_fix(self, fix: GnssFix, cfg: ReceiverCheckConfig) -> str:
        """Take the receiver's next fix; returns why it broke the chain ('' if it did not).

        A fix with the previous fix's time stamp returns ``'repeat'`` and is not taken.
        A fix failing the quality checks ends the chain; one failing the consistency
        checks starts a new chain (after a step, the receiver may be consistent again).
        """
        prev = self.last
        if prev is not None and fix.t_s <= prev.t_s:
            return "repeat"
        self.last = fix
        failure = self.quality_failure(fix, cfg)
        if failure:
            self.last_failure = failure
            self.chain_start_t_s = None
            self.chain_fixes = 0
            return failure
        if prev is None or self.chain_start_t_s is None:
            self._restart(fix.t_s)
            return ""
        dt = fix.t_s - prev.t_s
        if dt > cfg.max_increment_dt_s:
            self._restart(fix.t_s)
            return ""
        failure = self._increment(prev, fix, dt, cfg)
        if failure:
            self.last_failure = failure
            self._restart(fix.t_s)
            return failure
        self.chain_fixes += 1
        return ""

    def consistent(self, t_s: float, cfg: ReceiverCheckConfig) -> bool:
        """Is the receiver self-consistent at ``t_s`` (its chain long enough)?"""
        start = self.chain_start_t_s
        return (
            start is not None
            and t_s - start >= cfg.consistency_window_s
            and self.chain_fixes >= cfg.consistency_min_fixes
        )

    def _restart(self, t_s: float) -> None:
        self.chain_start_t_s = t_s
        self.chain_fixes = 1
        self.chain_resid_n_m = self.chain_resid_e_m = 0.0

    def _increment(self, prev: GnssFix, fix: GnssFix, dt: float, cfg: ReceiverCheckConfig) -> str:
        dn, de = horizontal_offset_m(prev, fix)
        v0, v1 = prev.vel_ne_mps, fix.vel_ne_mps
        if v0 is None or v1 is None:
            # no velocity to compare with: only the ground speed's bound on the distance
            speed = 0.5 * (prev.ground_speed_mps + fix.ground_speed_mps)
            moved = math.hypot(dn, de)
            tol = cfg.increment_tol_m + cfg.increment_tol_mps * dt
            if abs(moved - speed * dt) > tol:
                return f"moved {moved:.1f} m in {dt:.2f} s at {speed:.1f} m/s"
            return ""
        rn = dn - 0.5 * float(v0[0] + v1[0]) * dt
        re = de - 0.5 * float(v0[1] + v1[1]) * dt
        resid = math.hypot(rn, re)
        tol = cfg.increment_tol_m + cfg.increment_tol_mps * dt
        if resid > tol:
            return f"moved {math.hypot(dn, de):.1f} m, velocity says {resid:.1f} m otherwise"
        self.chain_resid_n_m += rn
        self.chain_resid_e_m += re
        span = fix.t_s - (self.chain_start_t_s if self.chain_start_t_s is not None else fix.t_s)
        chain = math.hypot(self.chain_resid_n_m, self.chain_resid_e_m)
        if chain > cfg.chain_tol_m + cfg.chain_tol_mps * span:
            return f"drifted {chain:.1f} m from its velocity in {span:.1f} s"
        return ""


def horizontal_offset_m(a: GnssFix, b: GnssFix) -> tuple[float, float]:
    """North and east offset of fix ``b`` from fix ``a`` (small distances), m."""
    m_m, n_m = radii_of_curvature_m(a.lat_rad)
    dn = (b.lat_rad - a.lat_rad) * (m_m + a.alt_msl_m)
    de = (b.lon_rad - a.lon_rad) * (n_m + a.alt_msl_m) * math.cos(a.lat_rad)
    return dn, de

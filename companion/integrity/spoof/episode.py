"""A spoofing episode: the reference a spoofed receiver is held against until it agrees.

When :class:`~companion.integrity.spoof.drag.DragTest` finds a receiver moving unlike the
IMU, the reference that saw it (the drag test's filter kept before the drag began, and
the navigator's state at that anchor) is frozen: from then on the receiver is judged
against that reference carried forward by the IMU alone, never against a solution that
has taken its fixes, and never on its own self-consistency. :class:`Reference` carries
it:

    v(t) = v_a + V(t) - V(t_a) - tau b_n - (W(t) - W(t_a)) b_b
    p(t) = p_a + v_a tau + P(t) - P(t_a) - V(t_a) tau
           - tau^2 / 2 b_n - (WW(t) - WW(t_a) - W(t_a) tau) b_b          (north, east)

(the increments of :mod:`.inertial`; ``b_n``, ``b_b`` the drag test's bias estimates at
the anchor), with the covariance of the navigator's state at the anchor, of the bias
estimates, of their random walk and of the IMU's white noise carried the same way, scaled
by what the drag test measured of its own misfit in flight. The down axis is the
navigator's (a horizontal drag does not move it; the barometer tests the height).

Pure: no I/O, no clock.

References
----------
Tanil, Khanafseh, Joerger and Pervan (2018), the INS monitor against spoofers that track
the vehicle; Kim, Walter and Powell (solution separation against a coasting solution).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from companion.integrity.spoof.inertial import Increments
from companion.nav.navigator import NavState
from companion.types import FloatArray


@dataclass(frozen=True, slots=True)
class Reference:
    """The navigator's state and the drag test's filter at an anchor, to be carried by
    the IMU (see the module docstring). ``x`` (7,) and ``p`` (7, 7) are the drag test's
    state and covariance; ``nav`` the navigator's state at ``inc.t_s``."""

    nav: NavState
    inc: Increments
    x: FloatArray
    p: FloatArray
    wander_m2ps5: float = 0.0
    """The apparent bias's random walk the drag test measured, (m/s^2)^2/s."""
    inflation: float = 1.0
    """The drag test's in-flight calibration of its longest windows: the model's
    variances are scaled by it, as the test's are."""

    def at(self, inc: Increments, vrw_m2ps3: float) -> NavState | None:
        """The reference carried to ``inc.t_s`` (None across an IMU gap): north and east
        from the IMU since the anchor, down the navigator's at the anchor carried by its
        velocity (the caller replaces it with the navigator's own where it has one)."""
        a = self.inc
        if inc.epoch != a.epoch:
            return None
        tau = inc.t_s - a.t_s
        bn, bb = self.x[2:4], self.x[4:7]
        dw = inc.w - a.w
        dww = inc.ww - a.ww - a.w * tau
        v0, p0 = self.nav.vel_ned_mps, self.nav.pos_ned_m
        vel = v0 + (inc.vel - a.vel)
        pos = p0 + v0 * tau + (inc.pos - a.pos - a.vel * tau)
        vel[:2] -= tau * bn + dw @ bb
        pos[:2] -= 0.5 * tau * tau * bn + dww @ bb
        # covariance: the anchor's position and velocity (independent), the biases'
        # (x[2:7]) through the same maps, the IMU's white noise
        jp = np.zeros((2, 5))
        jp[:, 0:2] = -0.5 * tau * tau * np.eye(2)
        jp[:, 2:5] = -dww
        jv = np.zeros((2, 5))
        jv[:, 0:2] = -tau * np.eye(2)
        jv[:, 2:5] = -dw
        pb = self.p[2:7, 2:7]
        pos_cov = np.array(self.nav.pos_cov_ned_m2, dtype=float) + tau * tau * np.array(
            self.nav.vel_cov_ned_m2ps2, dtype=float
        )
        vel_cov = np.array(self.nav.vel_cov_ned_m2ps2, dtype=float).copy()
        q = self.wander_m2ps5
        k = self.inflation
        pos_cov[:2, :2] += k * (
            jp @ pb @ jp.T + (vrw_m2ps3 * tau**3 / 3.0 + q * tau**5 / 20.0) * np.eye(2)
        )
        vel_cov[:2, :2] += k * (jv @ pb @ jv.T + (vrw_m2ps3 * tau + q * tau**3 / 3.0) * np.eye(2))
        return NavState(inc.t_s, pos, vel, pos_cov, vel_cov)


def horizontal_distance2(sep_ne_m: FloatArray, cov_ne_m2: FloatArray) -> float:
    """``sep^T cov^-1 sep`` of a (2,) separation and its (2, 2) covariance (inf when the
    covariance is singular or not finite)."""
    a, b, d = float(cov_ne_m2[0, 0]), float(cov_ne_m2[0, 1]), float(cov_ne_m2[1, 1])
    det = a * d - b * b
    if not (math.isfinite(det) and det > 0.0):
        return math.inf
    x, y = float(sep_ne_m[0]), float(sep_ne_m[1])
    return (d * x * x - 2.0 * b * x * y + a * y * y) / det


@dataclass(slots=True)
class Episode:
    """One receiver held out: since ``start_t_s``, against ``reference``; the largest
    horizontal separation from it so far ``max_sep_m``; the time its fixes began to
    agree again (``agree_since_s``, None while they do not)."""

    receiver_id: int
    start_t_s: float
    reference: Reference
    max_sep_m: float = 0.0
    last_sep_m: float = 0.0
    agree_since_s: float | None = None
    unverified: bool = False
    """Re-admitted because the reference could no longer tell (the protection level keeps
    ``max_sep_m``)."""

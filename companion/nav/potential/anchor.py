"""The particle right after a fix (an anchor) and its fast closed-form propagation.

An anchor keeps the particle's state, the frozen field seen from the fix and
the per-axis constants of the Bessel form at ``s0``, so that a prediction from
it costs four Bessel calls on a 3-vector (:func:`anchor_propagate`); the
general :func:`~companion.nav.potential.bessel.propagate_state` takes over
where those constants do not apply.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import special

from companion.nav.potential.bessel import (
    EULER_GAMMA,
    TWO_OVER_PI,
    X_ASYM,
    X_SMALL,
    bessel_at,
    propagate_state,
)
from companion.nav.potential.window import NAN3
from companion.types import FloatArray


@dataclass(slots=True)
class Anchor:
    """Particle state right after a fix, the frozen field seen from there, and the
    per-axis constants of its closed-form propagation (see :func:`make_anchor`).
    Never mutated (not frozen only because frozen construction costs microseconds)."""

    t_s: float
    pos_ned_m: FloatArray
    vel_ned_mps: FloatArray
    alpha_ps: float
    g_ps2: float
    a_rel: FloatArray
    b_m: FloatArray
    vel_known: bool
    centre_m: FloatArray
    s0: FloatArray
    ln_s0: FloatArray | None
    c_y0: FloatArray
    c_j0: FloatArray
    bessel_ok: bool


def make_anchor(
    t_s: float,
    pos: FloatArray,
    vel: FloatArray,
    alpha: float,
    g: float,
    a: FloatArray,
    b: FloatArray,
    vel_known: bool = True,
) -> Anchor:
    """An anchor with the constants of the Bessel form precomputed (pure arithmetic).

    With ``u0 = pos − B/A``, ``s0 = 2√(G A)/α`` and ``s = s0 e^{−αh/2}`` the
    general form of :func:`~companion.nav.potential.bessel._mid_form` regroups to

        u(h) = c_y0 Y0(s) + c_j0 J0(s),   u̇(h) = (α/2) (c_y0 s Y1(s) + c_j0 s J1(s)),
        c_y0 = (π s0/2) J1(s0) u0 − (π/α) J0(s0) u̇0,
        c_j0 = (π/α) Y0(s0) u̇0 − (π s0/2) Y1(s0) u0,

    so a prediction costs four Bessel calls on a 3-vector (scipy's between
    ``X_SMALL`` and ``X_ASYM``, the series below). Axes whose ``s`` is at or
    above ``X_ASYM`` (where the Hankel form must difference the phases), α = 0
    or G·A = 0 take the general :func:`propagate_state`.

    References
    ----------
    Grzegorzewski (2005), the constants a1, a2 of the Bessel solution;
    Abramowitz & Stegun 9.1.10-9.1.11, 9.2.28-9.2.31 (via :func:`bessel_at`).
    """
    if min(a.tolist()) > 0.0:
        centre = b / a
    else:
        has = a > 0.0
        centre = np.where(has, b / np.where(has, a, 1.0), pos)
    ga = g * a
    s0 = c_y0 = c_j0 = NAN3
    ln_s0: FloatArray | None = None
    ok = alpha > 0.0 and min(ga.tolist()) > 0.0
    if ok:
        s0 = (2.0 / alpha) * np.sqrt(ga)
        s0_list = s0.tolist()
        if X_SMALL <= min(s0_list) and max(s0_list) < X_ASYM:
            # ln_s0 stays None: log(s0) only when the series needs it
            j0s0, y0s0 = special.j0(s0), special.y0(s0)
            xj1s0, xy1s0 = s0 * special.j1(s0), s0 * special.y1(s0)
        else:
            # s0 may under- or overflow: from logarithms
            ln_s0 = np.log(2.0 * np.sqrt(ga)) - math.log(alpha)
            s0 = np.exp(ln_s0)
            b0 = bessel_at(s0, ln_s0)
            j0s0, y0s0, xj1s0, xy1s0 = b0["j0"], b0["y0"], b0["xj1"], b0["xy1"]
        u0h = (0.5 * np.pi) * (pos - centre)
        vk = (np.pi / alpha) * vel
        c_y0 = xj1s0 * u0h - j0s0 * vk
        c_j0 = y0s0 * vk - xy1s0 * u0h
        ok = math.isfinite(float(c_y0.sum() + c_j0.sum()))
    return Anchor(t_s, pos, vel, alpha, g, a, b, vel_known, centre, s0, ln_s0, c_y0, c_j0, ok)


_SERIES_LG = EULER_GAMMA - math.log(2.0)


def anchor_propagate(anc: Anchor, h_s: float) -> tuple[FloatArray, FloatArray]:
    """Particle position [m] and velocity [m/s] ``h_s`` ≥ 0 after the anchor's fix."""
    if anc.bessel_ok:
        half_ah = 0.5 * anc.alpha_ps * h_s
        s = anc.s0 * math.exp(-half_ah)
        s_list = s.tolist()
        lo, hi = min(s_list), max(s_list)
        if X_SMALL <= lo and hi < X_ASYM:
            y0, j0 = special.y0(s), special.j0(s)
            sy1, sj1 = s * special.y1(s), s * special.j1(s)
        elif hi < X_SMALL:
            # the coasting end: small-argument series in ln s (s may underflow)
            ln_s0 = anc.ln_s0 if anc.ln_s0 is not None else np.log(anc.s0)
            lg = ln_s0 + (_SERIES_LG - half_ah)
            x2 = s * s
            j0 = 1.0 - 0.25 * x2
            y0 = TWO_OVER_PI * (lg * j0 + 0.25 * x2)
            sj1 = 0.5 * x2
            sy1 = -TWO_OVER_PI + (x2 / np.pi) * (lg - 0.5)
        else:
            return propagate_state(
                anc.pos_ned_m, anc.vel_ned_mps, anc.a_rel, anc.b_m, anc.g_ps2,
                anc.alpha_ps, h_s,
            )  # fmt: skip
        pos = anc.centre_m + anc.c_y0 * y0 + anc.c_j0 * j0
        vel = (0.5 * anc.alpha_ps) * (anc.c_y0 * sy1 + anc.c_j0 * sj1)
        return pos, vel
    return propagate_state(
        anc.pos_ned_m, anc.vel_ned_mps, anc.a_rel, anc.b_m, anc.g_ps2, anc.alpha_ps, h_s
    )

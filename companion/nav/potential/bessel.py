"""Closed form of the particle's motion in the potential field, each NED axis on its own.

With the time origin at the newest source, axis ``k`` of the particle obeys
``k̈(t) = −G A_k e^{−α t} (k − B_k/A_k)`` (Grzegorzewski 2005, the corrected
equation of motion; ``A_k``, ``B_k`` from :func:`field_sums`). With
``u = k − B_k/A_k`` and ``ω = √(G A_k)`` the solution is a Bessel function of
order 0 in ``s = (2ω/α) e^{−αt/2}`` (the paper's (4.55)-(4.62), corrected to
give each axis its own velocity), linear in the offset and velocity at the
origin::

    [u(t), u̇(t)] = Φ(t; ω², α) · [u0, u̇0]

:func:`transition_axis` evaluates Φ, numerically sound from the
harmonic-oscillator limit (α → 0, huge Bessel arguments: a Hankel
modulus/phase form that never subtracts two large phases) to the coasting
limit (G·A → 0 or αt → ∞, tiny arguments: power series written in ``ln s`` so
that nothing underflows).

References
----------
Grzegorzewski, "Navigating by a position potential in 3-D", Annual of
Navigation 9/2005: the potential, the equation of motion, the Bessel solution
(4.55)-(4.62). Abramowitz & Stegun 9.2.28-9.2.31 (modulus and phase),
9.1.10-9.1.11 (small-argument series).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy import special

from companion.types import FloatArray

X_ASYM = 200.0
"""Bessel argument beyond which the Hankel modulus/phase expansion (4 terms each)
is used: its truncation error there is below 1e-16 (next term ~ x^-8 / x^-9)."""
X_SMALL = 1e-6
"""Bessel argument below which the small-argument series is used (dropped terms
~ x^4 ln x < 1e-22)."""
EULER_GAMMA = float(np.euler_gamma)
TWO_OVER_PI = 2.0 / np.pi


# --------------------------------------------------------------------------- Bessel pieces


def _hankel_modulus_phase(x: FloatArray, nu: int) -> tuple[FloatArray, FloatArray]:
    """Normalised modulus and phase correction of J_ν, Y_ν for large ``x``.

    ``J_ν(x) = √(2/(πx)) m cos(x − (ν/2 + 1/4)π + φ)``,
    ``Y_ν(x) = √(2/(πx)) m sin(x − (ν/2 + 1/4)π + φ)``.

    Parameters
    ----------
    x : ndarray
        Arguments, all ≥ ``X_ASYM``.
    nu : int
        Order, 0 or 1.

    Returns
    -------
    m, phi : ndarray
        ``m`` → 1 and ``φ`` → 0 as ``x`` → ∞ (dimensionless, rad).

    References
    ----------
    Abramowitz & Stegun 9.2.28-9.2.31.
    """
    mu = 4.0 * nu * nu
    z2 = 1.0 / (2.0 * x) ** 2
    m2 = 1.0 + z2 * (
        0.5 * (mu - 1.0)
        + z2
        * (
            0.375 * (mu - 1.0) * (mu - 9.0)
            + z2
            * (
                0.3125 * (mu - 1.0) * (mu - 9.0) * (mu - 25.0)
                + z2 * (35.0 / 128.0) * (mu - 1.0) * (mu - 9.0) * (mu - 25.0) * (mu - 49.0)
            )
        )
    )
    w = 1.0 / (4.0 * x)
    w2 = w * w
    phi = w * (
        (mu - 1.0) / 2.0
        + w2
        * (
            (mu - 1.0) * (mu - 25.0) / 6.0
            + w2
            * (
                (mu - 1.0) * (mu * mu - 114.0 * mu + 1073.0) / 5.0
                + w2 * (mu - 1.0) * (5.0 * mu**3 - 1535.0 * mu**2 + 54703.0 * mu - 375733.0) / 14.0
            )
        )
    )
    return np.sqrt(m2), phi


def _bessel_large(x: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """J0, J1, Y0, Y1 for ``x ≥ X_ASYM`` without losing the phase of a huge ``x``.

    ``cos(x − c + φ)`` is expanded as ``cos x cos(c − φ) + sin x sin(c − φ)``:
    ``cos x`` and ``sin x`` of an exact double are correctly reduced by libm.

    References
    ----------
    Abramowitz & Stegun 9.2.28-9.2.31.
    """
    amp = np.sqrt(TWO_OVER_PI / x)
    cx, sx = np.cos(x), np.sin(x)
    m0, p0 = _hankel_modulus_phase(x, 0)
    m1, p1 = _hankel_modulus_phase(x, 1)
    c0 = 0.25 * np.pi - p0
    c1 = 0.75 * np.pi - p1
    cos0 = cx * np.cos(c0) + sx * np.sin(c0)  # cos(x − c0)
    sin0 = sx * np.cos(c0) - cx * np.sin(c0)  # sin(x − c0)
    cos1 = cx * np.cos(c1) + sx * np.sin(c1)
    sin1 = sx * np.cos(c1) - cx * np.sin(c1)
    return amp * m0 * cos0, amp * m1 * cos1, amp * m0 * sin0, amp * m1 * sin1


def bessel_at(x: FloatArray, ln_x: FloatArray) -> dict[str, FloatArray]:
    """J0, Y0 and the scaled ``x·J1``, ``x·Y1`` at ``x = exp(ln_x)`` for any ``x > 0``.

    Series for ``x < X_SMALL`` (written in ``ln_x``: ``x`` may underflow),
    scipy's ``j0, j1, y0, y1`` in between, the Hankel form above ``X_ASYM``.

    Returns
    -------
    dict
        Keys ``j0``, ``y0``, ``xj1``, ``xy1`` (dimensionless), shapes as ``x``.

    References
    ----------
    Abramowitz & Stegun 9.1.10-9.1.11 (series), 9.2.28-9.2.31 (large x).
    """
    j0 = np.empty_like(x)
    y0 = np.empty_like(x)
    xj1 = np.empty_like(x)
    xy1 = np.empty_like(x)
    small = ln_x < np.log(X_SMALL)
    large = x >= X_ASYM
    mid = ~(small | large)
    if np.any(small):
        xs = x[small]
        x2 = xs * xs  # may underflow to 0: harmless
        lg = ln_x[small] - np.log(2.0) + EULER_GAMMA
        j0s = 1.0 - 0.25 * x2
        j0[small] = j0s
        y0[small] = TWO_OVER_PI * (lg * j0s + 0.25 * x2)
        xj1[small] = 0.5 * x2
        xy1[small] = -TWO_OVER_PI + (x2 / np.pi) * (lg - 0.5)
    if np.any(mid):
        xm = x[mid]
        j0[mid] = special.j0(xm)
        y0[mid] = special.y0(xm)
        xj1[mid] = xm * special.j1(xm)
        xy1[mid] = xm * special.y1(xm)
    if np.any(large):
        xl = x[large]
        a, b, c, d = _bessel_large(xl)
        j0[large] = a
        y0[large] = c
        xj1[large] = xl * b
        xy1[large] = xl * d
    return {"j0": j0, "y0": y0, "xj1": xj1, "xy1": xy1}


# --------------------------------------------------------------------------- closed form


def _mid_form(
    al: FloatArray, s0: FloatArray, s: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The paper's general Bessel form with scipy's j0, j1, y0, y1 (``X_SMALL ≤ s ≤ s0 < X_ASYM``).

    References
    ----------
    Grzegorzewski (2005), the constants a1, a2 of the Bessel solution.
    """
    j0s0, j1s0, y0s0, y1s0 = special.j0(s0), special.j1(s0), special.y0(s0), special.y1(s0)
    j0s, j1s, y0s, y1s = special.j0(s), special.j1(s), special.y0(s), special.y1(s)
    half_pi_s0 = 0.5 * np.pi * s0
    pj1 = half_pi_s0 * j1s0  # (π s0/2) J1(s0)
    py1 = half_pi_s0 * y1s0  # (π s0/2) Y1(s0)
    tfac = 0.5 * al * s  # T = √(G A) e^{−αt/2} = α s / 2
    tj1 = tfac * j1s
    ty1 = tfac * y1s
    k = np.pi / al
    return (
        pj1 * y0s - py1 * j0s,
        k * (y0s0 * j0s - j0s0 * y0s),
        pj1 * ty1 - py1 * tj1,
        k * (y0s0 * tj1 - j0s0 * ty1),
    )


def transition_axis(
    ga_ps2: ArrayLike, alpha_ps: ArrayLike, t_s: ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """State-transition matrix of ``ü = −G·A e^{−αt} u`` from 0 to ``t``.

    ``u(t) = W1 u0 + W2 u̇0`` and ``u̇(t) = W1' u0 + W2' u̇0``. ``W1`` and ``W2``
    are Grzegorzewski's (2005) weights of the large-α form ``k(t) = k_0n + W1(t)Δk_n + W2(t)k̇_n``.

    Parameters
    ----------
    ga_ps2 : array_like
        ``G·A_k`` ≥ 0 [1/s²].
    alpha_ps : array_like
        Dissipation rate α ≥ 0 [1/s] (0 gives the harmonic oscillator).
    t_s : array_like
        Time since the origin (the newest source), ≥ 0 [s].
        The three inputs broadcast together.

    Returns
    -------
    w1, w2, w1dot, w2dot : ndarray
        ``W1`` [-], ``W2`` [s], ``W1'`` [1/s], ``W2'`` [-], broadcast shape.

    Raises
    ------
    ValueError
        If an input is negative or not finite.

    References
    ----------
    Grzegorzewski (2005), the Bessel solution (4.55)-(4.62) with each axis' own
    velocity (corrected); the limits are the oscillator (α = 0) and free
    coasting (G·A = 0).
    """
    ga, al, tt = np.broadcast_arrays(
        np.asarray(ga_ps2, dtype=np.float64),
        np.asarray(alpha_ps, dtype=np.float64),
        np.asarray(t_s, dtype=np.float64),
    )
    if not (np.all(np.isfinite(ga)) and np.all(np.isfinite(al)) and np.all(np.isfinite(tt))):
        raise ValueError("transition_axis: inputs must be finite")
    if np.any(ga < 0.0) or np.any(al < 0.0) or np.any(tt < 0.0):
        raise ValueError("transition_axis: G·A, α and t must be non-negative")
    return transition_core(ga, al, tt)


def transition_core(
    ga: FloatArray, al: FloatArray, tt: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """:func:`transition_axis` on validated, same-shape arrays (no checks)."""
    shape = ga.shape
    if ga.min() > 0.0 and al.min() > 0.0:
        # fast path: every argument in scipy's comfortable range (the usual case)
        s0_f = 2.0 * np.sqrt(ga) / al
        s_f = s0_f * np.exp(-0.5 * al * tt)
        if s0_f.max() < X_ASYM and s_f.min() >= X_SMALL:
            return _mid_form(al, s0_f, s_f)
    ga, al, tt = ga.ravel(), al.ravel(), tt.ravel()
    n = ga.size
    w1 = np.empty(n)
    w2 = np.empty(n)
    w1d = np.empty(n)
    w2d = np.empty(n)
    omega = np.sqrt(ga)

    coast = ga == 0.0
    if np.any(coast):
        w1[coast] = 1.0
        w2[coast] = tt[coast]
        w1d[coast] = 0.0
        w2d[coast] = 1.0

    osc = (~coast) & (al == 0.0)
    if np.any(osc):
        om, t = omega[osc], tt[osc]
        c, s = np.cos(om * t), np.sin(om * t)
        w1[osc] = c
        w2[osc] = s / om
        w1d[osc] = -om * s
        w2d[osc] = c

    gen = ~(coast | osc)
    if np.any(gen):
        om, a, t = omega[gen], al[gen], tt[gen]
        ln_s0 = np.log(2.0 * om) - np.log(a)
        half = 0.5 * a * t
        ln_s = ln_s0 - half
        s0 = np.exp(ln_s0)
        s = np.exp(ln_s)
        r1 = np.empty(om.size)
        r2 = np.empty(om.size)
        r1d = np.empty(om.size)
        r2d = np.empty(om.size)

        # Both arguments large: Hankel form, phases differenced analytically.
        both = s >= X_ASYM
        if np.any(both):
            x0, x = s0[both], s[both]
            ob, hb = om[both], half[both]
            m00, p00 = _hankel_modulus_phase(x0, 0)
            m10, p10 = _hankel_modulus_phase(x0, 1)
            m0, p0 = _hankel_modulus_phase(x, 0)
            m1, p1 = _hankel_modulus_phase(x, 1)
            dx = x0 * np.expm1(-hb)  # s − s0, no cancellation
            q = np.exp(0.5 * hb)  # e^{αt/4}
            r1[both] = q * m10 * m0 * np.cos(dx + p0 - p10)
            r2[both] = q / ob * m00 * m0 * np.sin(-dx + p00 - p0)
            r1d[both] = -ob / q * m10 * m1 * np.sin(-dx + p10 - p1)
            r2d[both] = m00 * m1 * np.cos(-dx + p00 - p1) / q

        mid = (~both) & (s0 < X_ASYM) & (ln_s >= np.log(X_SMALL))
        if np.any(mid):
            m1, m2, m3, m4 = _mid_form(a[mid], s0[mid], s[mid])
            r1[mid], r2[mid], r1d[mid], r2d[mid] = m1, m2, m3, m4

        rest = ~(both | mid)
        if np.any(rest):
            a_r = a[rest]
            b0 = bessel_at(s0[rest], ln_s0[rest])
            b = bessel_at(s[rest], ln_s[rest])
            # (π s0 / 2)·J1(s0), (π s0 / 2)·Y1(s0)
            pj1 = 0.5 * np.pi * b0["xj1"]
            py1 = 0.5 * np.pi * b0["xy1"]
            # T·J1(s), T·Y1(s) with T = α s / 2
            tj1 = 0.5 * a_r * b["xj1"]
            ty1 = 0.5 * a_r * b["xy1"]
            k = np.pi / a_r
            r1[rest] = pj1 * b["y0"] - py1 * b["j0"]
            r2[rest] = k * (b0["y0"] * b["j0"] - b0["j0"] * b["y0"])
            r1d[rest] = pj1 * ty1 - py1 * tj1
            r2d[rest] = k * (b0["y0"] * tj1 - b0["j0"] * ty1)

        w1[gen], w2[gen], w1d[gen], w2d[gen] = r1, r2, r1d, r2d

    return (
        w1.reshape(shape),
        w2.reshape(shape),
        w1d.reshape(shape),
        w2d.reshape(shape),
    )


def propagate_axis(
    u0_m: ArrayLike, udot0_mps: ArrayLike, ga_ps2: ArrayLike, alpha_ps: ArrayLike, t_s: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Closed-form offset and velocity of one axis of the particle at ``t``.

    Parameters
    ----------
    u0_m : array_like
        Offset from the field's centre ``B_k/A_k`` at the origin [m].
    udot0_mps : array_like
        Velocity at the origin [m/s].
    ga_ps2 : array_like
        ``G·A_k`` ≥ 0 [1/s²].
    alpha_ps : array_like
        α ≥ 0 [1/s].
    t_s : array_like
        Time since the origin ≥ 0 [s]. All inputs broadcast.

    Returns
    -------
    u_m, udot_mps : ndarray
        Offset [m] and velocity [m/s] at ``t``.

    References
    ----------
    Grzegorzewski (2005): ``u = a1 J0(s) + a2 Y0(s)``, ``u̇ = T (a1 J1(s) + a2 Y1(s))``.
    """
    w1, w2, w1d, w2d = transition_axis(ga_ps2, alpha_ps, t_s)
    u0 = np.asarray(u0_m, dtype=np.float64)
    v0 = np.asarray(udot0_mps, dtype=np.float64)
    return w1 * u0 + w2 * v0, w1d * u0 + w2d * v0


def field_sums(
    t_src_s: FloatArray,
    pos_src_m: FloatArray,
    p_src_pm2: FloatArray,
    alpha_ps: float,
    t0_s: float,
    weight_floor: float = 0.0,
) -> tuple[FloatArray, FloatArray]:
    """The field sums ``A_k`` and ``B_k`` of a set of sources with the time origin at ``t0_s``.

    The weights are relative to the newest source (the last row): per axis
    ``p_ki / p_kn = σ²_kn / σ²_ki``, so ``A_k`` is dimensionless and ``G·A_k``
    does not depend on the receiver's accuracy class (see :mod:`companion.nav.potential`).

    Parameters
    ----------
    t_src_s : ndarray, shape (n,)
        Source times ≤ ``t0_s`` [s], the newest last.
    pos_src_m : ndarray, shape (n, 3)
        Source positions (NED) [m].
    p_src_pm2 : ndarray, shape (n, 3)
        Weights ``1/σ²`` [1/m²]; only their ratios to the last row matter.
    alpha_ps : float
        α [1/s].
    t0_s : float
        Time origin [s].
    weight_floor : float
        Sources whose weight ``e^{α(t_i − t0)}`` is below this are dropped.

    Returns
    -------
    a, b_m : ndarray, shape (3,)
        ``A_k`` [-] and ``B_k`` [m].

    References
    ----------
    Grzegorzewski (2005), the sums with the time origin at the newest fix; the
    weights made relative to the newest fix's (:mod:`companion.nav.potential`).
    """
    p = np.asarray(p_src_pm2, dtype=np.float64)
    w = np.exp(alpha_ps * (np.asarray(t_src_s) - t0_s))
    w = np.where(w < weight_floor, 0.0, w)
    wp = 2.0 * w[:, None] * (p / p[-1])
    return wp.sum(axis=0), (wp * pos_src_m).sum(axis=0)


def propagate_state(
    pos_ned_m: FloatArray,
    vel_ned_mps: FloatArray,
    a_rel: FloatArray,
    b_m: FloatArray,
    g_ps2: float,
    alpha_ps: float,
    dt_s: float,
) -> tuple[FloatArray, FloatArray]:
    """Carry the particle ``dt_s`` through a frozen field given by ``A``, ``B``.

    Parameters
    ----------
    pos_ned_m, vel_ned_mps : ndarray, shape (3,)
        Particle position [m] and velocity [m/s] at the field's origin.
    a_rel, b_m : ndarray, shape (3,)
        Field sums ``A_k`` [-] and ``B_k`` [m] at that origin (relative weights,
        :func:`field_sums`; A = 0: no field).
    g_ps2 : float
        G [1/s²].
    alpha_ps : float
        α [1/s].
    dt_s : float
        Time since the origin ≥ 0 [s].

    Returns
    -------
    pos_ned_m, vel_ned_mps : ndarray, shape (3,)

    References
    ----------
    Grzegorzewski (2005).
    """
    has = a_rel > 0.0
    centre = np.where(has, b_m / np.where(has, a_rel, 1.0), pos_ned_m)
    u, ud = propagate_axis(pos_ned_m - centre, vel_ned_mps, g_ps2 * a_rel, alpha_ps, dt_s)
    return centre + u, ud

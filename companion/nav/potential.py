"""Position-potential filter with self-learned dissipation α and coupling G (S0).

Every accepted GNSS fix ``i`` (time ``t_i``, position ``r_0i``, per-axis
variances ``σ²_ki``, weights ``p_ki = 1/σ²_ki`` in 1/m²) is the source of an
attracting potential that dissipates in time. With the time origin at the
newest source (``t_n = 0``), each NED axis ``k`` of the particle obeys

    k̈(t) = −G A_k e^{−α t} (k − B_k/A_k),
    A_k = 2 Σ_i e^{α(t_i − t_n)} p_ki,   B_k = 2 Σ_i e^{α(t_i − t_n)} p_ki k_0i,

so ``G`` is in m²/s², ``A_k`` in 1/m² and ``G·A_k`` in 1/s². With
``u = k − B_k/A_k`` and ``ω = √(G A_k)`` the solution is a Bessel function of
order 0 in ``s = (2ω/α) e^{−αt/2}``; it is linear in the particle's offset and
velocity at the origin::

    [u(t), u̇(t)] = Φ(t; ω², α) · [u0, u̇0]

:func:`transition_axis` evaluates Φ in closed form, numerically sound from the
harmonic-oscillator limit (α → 0, huge Bessel arguments: a Hankel
modulus/phase form that never subtracts two large phases) to the coasting
limit (G·A → 0 or αt → ∞, tiny arguments: power series written in ``ln s`` so
that nothing underflows).

The filter (:class:`PotentialFilter`)

* carries the particle from fix to fix through the field of the fixes it has
  accepted; at each fix the particle keeps its carried *position* (its offset
  from the fix is S0's ``Δk_n``) and, in the default ``velocity_mode="measured"``,
  takes the fix's measured velocity (S0 predicts from ``k̇_n``, the fix's
  velocity), with the components the receiver did not give (GPS_RAW_INT has
  no vertical velocity) taken from a least-squares line through the last
  ``velocity_span_s`` of fixes; ``velocity_mode="carried"`` keeps the pure
  particle velocity instead;
* predicts position and velocity at any later time with the field frozen
  (no new sources), with a covariance that grows with the horizon ``h``::

      σ²_k(h) = q_pos,k + q_vel,k h² + q_acc,k h⁴ / 4

  (an unknown position, velocity and constant-acceleration error of the
  particle). The three coefficients per axis are calibrated from the filter's
  own prediction residuals: after every fit the window is replayed with the
  fitted α, G and, from the particle's state at each fix, the frozen-field
  prediction to every later fix in the window is compared with that fix
  (horizons from one fix interval to ``window_s``). The residuals ``e²`` and
  the fixes' variances are summed in horizon bins (older fits' sums decay by
  ``calib_forgetting`` per fit), and ``mean(e²) − mean(σ²_fix)`` is regressed on
  ``[1, h², h⁴/4]`` by non-negative least squares, each bin weighted by
  ``√count / (σ²_fix + model)`` (two passes, the first with the prior). Until
  the first fit the prior (the newest fix's variance, ``prior_vel_sigma_mps``,
  ``prior_acc_sigma_mps2``) is used and fixes are not tested;
* learns α and G by minimising ``Σ_i |r(t_i) − r_0i|²`` over the window
  (the particle replayed through the window from the oldest fix's position
  and the particle's velocity there, the sources added one by one) with
  :func:`scipy.optimize.differential_evolution` in ``(log10 α, log10 G)``:
  bounded, seeded (``seed + fit count``), warm-started (the current values
  plus the best quarter of a coarse log grid seed the population) and
  vectorised over the population; a refit runs at most every
  ``refit_interval_s`` of fix time. After a fit the particle takes the fitted
  model's replayed state at the newest fix (``adopt_replay_state``);
* tests each new fix against the prediction: ``χ² = dᵀ (P_pred + R)⁻¹ d``
  with 3 degrees of freedom against ``chi2.ppf(1 − false_alarm_prob, 3)``;
  an inconsistent fix is not made a source; after
  ``max_consecutive_inconsistent`` of them in a row the filter restarts from
  them.

Known limits: without the receiver's velocity (velocity from the fixes
only) the carried particle integrates noisy velocities and predicts worse than
constant-velocity extrapolation (see ``bench/potential.py``); the fit can
settle in the broad basin at the α upper bound when the true α is small
(≲ 1.5 1/s), where the global valley is narrower than the seeding grid.

References
----------
S0: Grzegorzewski, "Navigating by a position potential in 3-D", Annual of
Navigation 9/2005 (SEEDS.md §S0: the potential, the corrected equation of
motion, the Bessel solution (4.55)-(4.62) corrected, the self-learning
objective, the χ² consistency test). Bessel asymptotics: Abramowitz & Stegun
9.2.28-9.2.31 (modulus and phase), 9.1.10-9.1.11 (small-argument series).
"""

from __future__ import annotations

import logging
from collections import deque
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike
from scipy import special, stats
from scipy.optimize import differential_evolution, nnls

from companion.types import FloatArray, NamedValue

_log = logging.getLogger(__name__)

# Bessel argument beyond which the Hankel modulus/phase expansion (4 terms each)
# is used: its truncation error there is below 1e-16 (next term ~ x^-8 / x^-9).
_X_ASYM = 200.0
# Bessel argument below which the small-argument series is used (dropped terms
# ~ x^4 ln x < 1e-22).
_X_SMALL = 1e-6
_EULER_GAMMA = float(np.euler_gamma)
# Horizon bins of the covariance calibration [s].
_CALIB_EDGES_S = np.array([0.0, 0.3, 0.6, 1.0, 1.5, 2.0, 3.0, 4.5, 6.5, 9.0, 13.0, 20.0, 30.0, 1e9])
_TWO_OVER_PI = 2.0 / np.pi

NAME_ALPHA = "CMP_PALPHA"
NAME_G = "CMP_PG"


# --------------------------------------------------------------------------- Bessel pieces


def _hankel_modulus_phase(x: FloatArray, nu: int) -> tuple[FloatArray, FloatArray]:
    """Normalised modulus and phase correction of J_ν, Y_ν for large ``x``.

    ``J_ν(x) = √(2/(πx)) m cos(x − (ν/2 + 1/4)π + φ)``,
    ``Y_ν(x) = √(2/(πx)) m sin(x − (ν/2 + 1/4)π + φ)``.

    Parameters
    ----------
    x : ndarray
        Arguments, all ≥ ``_X_ASYM``.
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
    """J0, J1, Y0, Y1 for ``x ≥ _X_ASYM`` without losing the phase of a huge ``x``.

    ``cos(x − c + φ)`` is expanded as ``cos x cos(c − φ) + sin x sin(c − φ)``:
    ``cos x`` and ``sin x`` of an exact double are correctly reduced by libm.

    References
    ----------
    Abramowitz & Stegun 9.2.28-9.2.31.
    """
    amp = np.sqrt(_TWO_OVER_PI / x)
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


def _bessel_at(x: FloatArray, ln_x: FloatArray) -> dict[str, FloatArray]:
    """J0, Y0 and the scaled ``x·J1``, ``x·Y1`` at ``x = exp(ln_x)`` for any ``x > 0``.

    Series for ``x < _X_SMALL`` (written in ``ln_x``: ``x`` may underflow),
    scipy's ``j0, j1, y0, y1`` in between, the Hankel form above ``_X_ASYM``.

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
    small = ln_x < np.log(_X_SMALL)
    large = x >= _X_ASYM
    mid = ~(small | large)
    if np.any(small):
        xs = x[small]
        x2 = xs * xs  # may underflow to 0: harmless
        lg = ln_x[small] - np.log(2.0) + _EULER_GAMMA
        j0s = 1.0 - 0.25 * x2
        j0[small] = j0s
        y0[small] = _TWO_OVER_PI * (lg * j0s + 0.25 * x2)
        xj1[small] = 0.5 * x2
        xy1[small] = -_TWO_OVER_PI + (x2 / np.pi) * (lg - 0.5)
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
    """S0's general Bessel form with scipy's j0, j1, y0, y1 (``_X_SMALL ≤ s ≤ s0 < _X_ASYM``).

    References
    ----------
    S0 (SEEDS.md §S0), the constants a1, a2 of the Bessel solution.
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
    are S0's weights of the large-α form ``k(t) = k_0n + W1(t)Δk_n + W2(t)k̇_n``.

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
    S0 (SEEDS.md §S0), the Bessel solution (4.55)-(4.62) with each axis' own
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
    return _transition_core(ga, al, tt)


def _transition_core(
    ga: FloatArray, al: FloatArray, tt: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """:func:`transition_axis` on validated, same-shape arrays (no checks)."""
    shape = ga.shape
    if ga.min() > 0.0 and al.min() > 0.0:
        # fast path: every argument in scipy's comfortable range (the usual case)
        s0_f = 2.0 * np.sqrt(ga) / al
        s_f = s0_f * np.exp(-0.5 * al * tt)
        if s0_f.max() < _X_ASYM and s_f.min() >= _X_SMALL:
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
        both = s >= _X_ASYM
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

        mid = (~both) & (s0 < _X_ASYM) & (ln_s >= np.log(_X_SMALL))
        if np.any(mid):
            m1, m2, m3, m4 = _mid_form(a[mid], s0[mid], s[mid])
            r1[mid], r2[mid], r1d[mid], r2d[mid] = m1, m2, m3, m4

        rest = ~(both | mid)
        if np.any(rest):
            a_r = a[rest]
            b0 = _bessel_at(s0[rest], ln_s0[rest])
            b = _bessel_at(s[rest], ln_s[rest])
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
    S0 (SEEDS.md §S0): ``u = a1 J0(s) + a2 Y0(s)``, ``u̇ = T (a1 J1(s) + a2 Y1(s))``.
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
    """S0's ``A_k`` and ``B_k`` of a set of sources with the time origin at ``t0_s``.

    Parameters
    ----------
    t_src_s : ndarray, shape (n,)
        Source times ≤ ``t0_s`` [s].
    pos_src_m : ndarray, shape (n, 3)
        Source positions (NED) [m].
    p_src_pm2 : ndarray, shape (n, 3)
        Weights ``1/σ²`` [1/m²].
    alpha_ps : float
        α [1/s].
    t0_s : float
        Time origin [s].
    weight_floor : float
        Sources whose weight ``e^{α(t_i − t0)}`` is below this are dropped.

    Returns
    -------
    a_pm2, b_pm : ndarray, shape (3,)
        ``A_k`` [1/m²] and ``B_k`` [1/m].

    References
    ----------
    S0 (SEEDS.md §S0), the sums with the time origin at the newest fix.
    """
    w = np.exp(alpha_ps * (np.asarray(t_src_s) - t0_s))
    w = np.where(w < weight_floor, 0.0, w)
    wp = 2.0 * w[:, None] * p_src_pm2
    return wp.sum(axis=0), (wp * pos_src_m).sum(axis=0)


def propagate_state(
    pos_ned_m: FloatArray,
    vel_ned_mps: FloatArray,
    a_pm2: FloatArray,
    b_pm: FloatArray,
    g_m2ps2: float,
    alpha_ps: float,
    dt_s: float,
) -> tuple[FloatArray, FloatArray]:
    """Carry the particle ``dt_s`` through a frozen field given by ``A``, ``B``.

    Parameters
    ----------
    pos_ned_m, vel_ned_mps : ndarray, shape (3,)
        Particle position [m] and velocity [m/s] at the field's origin.
    a_pm2, b_pm : ndarray, shape (3,)
        Field sums ``A_k`` [1/m²], ``B_k`` [1/m] at that origin (A = 0: no field).
    g_m2ps2 : float
        G [m²/s²].
    alpha_ps : float
        α [1/s].
    dt_s : float
        Time since the origin ≥ 0 [s].

    Returns
    -------
    pos_ned_m, vel_ned_mps : ndarray, shape (3,)

    References
    ----------
    S0 (SEEDS.md §S0).
    """
    has = a_pm2 > 0.0
    centre = np.where(has, b_pm / np.where(has, a_pm2, 1.0), pos_ned_m)
    u, ud = propagate_axis(pos_ned_m - centre, vel_ned_mps, g_m2ps2 * a_pm2, alpha_ps, dt_s)
    return centre + u, ud


def combine_predictions(
    pos_a: FloatArray, cov_a: FloatArray, pos_b: FloatArray, cov_b: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Combine two independent predictions of the same position by their covariances.

    ``x = a + K (b − a)``, ``P = (I − K) P_a`` with ``K = P_a (P_a + P_b)⁻¹``:
    the minimum-variance combination of two unbiased, uncorrelated estimates
    (equal to ``(P_a⁻¹ + P_b⁻¹)⁻¹`` but without inverting either).

    Parameters
    ----------
    pos_a, pos_b : ndarray, shape (n,)
        The two predictions (e.g. INS and potential, NED) [m].
    cov_a, cov_b : ndarray, shape (n, n)
        Their covariances [m²], symmetric positive semi-definite, with a
        positive-definite sum.

    Returns
    -------
    pos, cov : ndarray, shapes (n,), (n, n)

    Raises
    ------
    ValueError
        On mismatched shapes, non-finite values or a singular ``P_a + P_b``.

    References
    ----------
    S0 (SEEDS.md §S0, its place in the bridge); the Kalman update with
    ``H = I`` (Bar-Shalom, Li & Kirubarajan, Estimation with Applications to
    Tracking and Navigation, §5.2).
    """
    a = np.asarray(pos_a, dtype=np.float64)
    b = np.asarray(pos_b, dtype=np.float64)
    pa = np.asarray(cov_a, dtype=np.float64)
    pb = np.asarray(cov_b, dtype=np.float64)
    n = a.size
    if a.shape != (n,) or b.shape != (n,) or pa.shape != (n, n) or pb.shape != (n, n):
        raise ValueError("combine_predictions: need vectors (n,) and covariances (n, n)")
    if not all(np.all(np.isfinite(x)) for x in (a, b, pa, pb)):
        raise ValueError("combine_predictions: inputs must be finite")
    s = pa + pb
    try:
        c = np.linalg.cholesky(0.5 * (s + s.T))
    except np.linalg.LinAlgError as exc:
        raise ValueError("combine_predictions: P_a + P_b is not positive definite") from exc
    # K = P_a S⁻¹  ->  K^T = S⁻¹ P_a^T
    kt = np.linalg.solve(c.T, np.linalg.solve(c, pa.T))
    k = kt.T
    pos = a + k @ (b - a)
    ik = np.eye(n) - k
    # Joseph form keeps P symmetric positive semi-definite
    cov = ik @ pa @ ik.T + k @ pb @ k.T
    return pos, 0.5 * (cov + cov.T)


# --------------------------------------------------------------------------- configuration


@dataclass(frozen=True, slots=True)
class PotentialConfig:
    """Configuration of :class:`PotentialFilter` (validated on construction).

    Attributes
    ----------
    window_s : float
        Span of past fixes kept as sources and used by the fit [s].
    max_sources : int
        At most this many (newest) fixes are sources.
    weight_floor : float
        A source is dropped once ``e^{α(t_i − t_n)}`` falls below this.
    alpha0_ps, g0_m2ps2 : float
        Starting α [1/s] and G [m²/s²] (S0's stable-descent values).
    alpha_bounds_ps, g_bounds_m2ps2 : tuple of float
        Bounds of the fit [1/s], [m²/s²] (searched in log10). The closed form
        is sound for any α ≥ 0, but the fit's α floor is 0.5 1/s: below it the
        field barely dissipates, the particle is pulled towards the centroid
        of the whole window (seconds behind the aircraft) and 5-20 s
        predictions collapse, while the one-step objective hardly notices
        (S0: α = 2.7-3.8 fitted, α = 0.2 "diverged badly").
    refit_interval_s : float
        Minimum fix time between two fits [s] (the real-time budget).
    min_fit_fixes : int
        Fewest fixes in the window for a fit.
    de_maxiter, de_popsize : int
        Differential-evolution generations and population multiplier.
    de_tol : float
        Differential-evolution relative tolerance.
    de_grid_points : int
        Points per axis of the coarse log grid that seeds the population.
    adopt_replay_state : bool
        After a fit, move the particle to the fitted model's replayed state at
        the newest fix (True) or keep the carried particle and change only the
        field (False, the default: the replay starts ``window_s`` back and
        its drift would be injected into the prediction).
    false_alarm_prob : float
        False-alarm probability of the χ² (3 dof) fix test.
    min_test_fixes : int
        Fixes needed before new fixes are tested.
    max_consecutive_inconsistent : int
        After this many consecutive inconsistent fixes the filter restarts
        from them and the next one (the model, not the fixes, is then taken to
        be wrong); α, G and the covariance calibration are kept.
    velocity_mode : {"measured", "carried"}
        Velocity of the particle at a fix: the fix's (derived where absent),
        or the carried particle's (pure S0 particle).
    velocity_span_s : float
        Span of the least-squares line giving velocity components the fix lacks [s].
    prior_vel_sigma_mps, prior_acc_sigma_mps2 : float
        Prior 1σ velocity and acceleration error of the particle, used for the
        predicted covariance before calibration.
    calib_min_residuals : int
        Residual pairs needed in a fit window before its calibration is used.
    calib_forgetting : float
        Factor in (0, 1] by which the binned residual sums of earlier fits decay
        at each fit.
    seed : int
        Seed of the optimiser (each fit uses ``seed + fit count``).
    """

    window_s: float = 10.0
    max_sources: int = 60
    weight_floor: float = 1e-12
    alpha0_ps: float = 2.84
    g0_m2ps2: float = 0.35
    alpha_bounds_ps: tuple[float, float] = (0.5, 10.0)
    g_bounds_m2ps2: tuple[float, float] = (1e-6, 1e3)
    refit_interval_s: float = 2.0
    min_fit_fixes: int = 6
    de_maxiter: int = 20
    de_popsize: int = 8
    de_tol: float = 1e-3
    de_grid_points: int = 6
    adopt_replay_state: bool = True
    false_alarm_prob: float = 1e-3
    min_test_fixes: int = 3
    max_consecutive_inconsistent: int = 3
    velocity_mode: Literal["measured", "carried"] = "measured"
    velocity_span_s: float = 1.0
    prior_vel_sigma_mps: float = 1.0
    prior_acc_sigma_mps2: float = 1.0
    calib_min_residuals: int = 30
    calib_forgetting: float = 0.5
    seed: int = 0

    def __post_init__(self) -> None:
        def pos(name: str) -> None:
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"PotentialConfig.{name} must be finite and > 0, got {v!r}")

        for name in (
            "window_s",
            "alpha0_ps",
            "g0_m2ps2",
            "refit_interval_s",
            "de_tol",
            "velocity_span_s",
            "prior_vel_sigma_mps",
            "prior_acc_sigma_mps2",
        ):
            pos(name)
        for name, lo in (
            ("max_sources", 1),
            ("min_fit_fixes", 3),
            ("de_maxiter", 1),
            ("de_popsize", 3),
            ("de_grid_points", 2),
            ("min_test_fixes", 2),
            ("max_consecutive_inconsistent", 1),
            ("calib_min_residuals", 3),
        ):
            if int(getattr(self, name)) < lo:
                raise ValueError(f"PotentialConfig.{name} must be >= {lo}")
        if not 0.0 < self.calib_forgetting <= 1.0:
            raise ValueError("PotentialConfig.calib_forgetting must be in (0, 1]")
        if not 0.0 < self.weight_floor < 1.0:
            raise ValueError("PotentialConfig.weight_floor must be in (0, 1)")
        if not 0.0 < self.false_alarm_prob < 1.0:
            raise ValueError("PotentialConfig.false_alarm_prob must be in (0, 1)")
        for name in ("alpha_bounds_ps", "g_bounds_m2ps2"):
            lo, hi = getattr(self, name)
            if not (np.isfinite(lo) and np.isfinite(hi) and 0.0 < lo < hi):
                raise ValueError(f"PotentialConfig.{name} must satisfy 0 < lo < hi")
        if not self.alpha_bounds_ps[0] <= self.alpha0_ps <= self.alpha_bounds_ps[1]:
            raise ValueError("PotentialConfig.alpha0_ps must lie within alpha_bounds_ps")
        if not self.g_bounds_m2ps2[0] <= self.g0_m2ps2 <= self.g_bounds_m2ps2[1]:
            raise ValueError("PotentialConfig.g0_m2ps2 must lie within g_bounds_m2ps2")
        if self.velocity_mode not in ("measured", "carried"):
            raise ValueError("PotentialConfig.velocity_mode must be 'measured' or 'carried'")


# --------------------------------------------------------------------------- results


@dataclass(frozen=True, slots=True)
class FixTest:
    """Result of testing (and possibly adding) a fix.

    ``chi2`` is ``dᵀ (P_pred + R)⁻¹ d`` (NaN when not tested), ``threshold``
    the χ²(3) quantile at ``1 − false_alarm_prob``; ``consistent`` is
    ``chi2 ≤ threshold`` (True when untested); ``accepted`` says whether the
    fix became a source; ``reason`` is empty or names why it did not.
    """

    t_s: float
    chi2: float
    threshold: float
    consistent: bool
    tested: bool
    accepted: bool = False
    reason: str = ""


@dataclass(frozen=True, slots=True)
class PotentialPrediction:
    """Prediction of the potential filter at ``t_s``.

    ``pos_ned_m``, ``vel_ned_mps`` shape (3,); ``cov_ned_m2`` and
    ``vel_cov_ned_m2ps2`` diagonal (3, 3); ``horizon_s`` = ``t_s`` − newest fix.
    """

    t_s: float
    pos_ned_m: FloatArray
    vel_ned_mps: FloatArray
    cov_ned_m2: FloatArray
    vel_cov_ned_m2ps2: FloatArray
    horizon_s: float


@dataclass(frozen=True, slots=True)
class _Fix:
    t_s: float
    pos_ned_m: FloatArray
    p_pm2: FloatArray  # 1/σ² per axis
    vel_reset_ned_mps: FloatArray  # NaN where the particle keeps its carried velocity


@dataclass(frozen=True, slots=True)
class _Anchor:
    """Particle state right after a fix, and the frozen field seen from there."""

    t_s: float
    pos_ned_m: FloatArray
    vel_ned_mps: FloatArray
    alpha_ps: float
    g_m2ps2: float
    a_pm2: FloatArray
    b_pm: FloatArray
    vel_known: bool = True


# --------------------------------------------------------------------------- the filter


class PotentialFilter:
    """S0's position-potential filter: carry, predict, self-learn α and G, test fixes.

    Pure: no clock, no I/O; time enters only as the fixes' ``t_s``.

    Parameters
    ----------
    config : PotentialConfig

    References
    ----------
    S0 (SEEDS.md §S0).
    """

    def __init__(self, config: PotentialConfig | None = None) -> None:
        self.config = config if config is not None else PotentialConfig()
        self._alpha = self.config.alpha0_ps
        self._g = self.config.g0_m2ps2
        self._threshold = float(stats.chi2.ppf(1.0 - self.config.false_alarm_prob, 3))
        self.rejections: dict[str, int] = {}
        self.fit_count = 0
        self.last_fit_cost_m2: float | None = None
        self._reset_state()

    # ----------------------------------------------------------------- state

    def _reset_state(self) -> None:
        self._fixes: deque[_Fix] = deque()
        self._anchors: deque[_Anchor] = deque()
        # binned residual sums: count, Σh, Σe² (3), Σσ²_fix (3) per horizon bin
        self._bins: FloatArray | None = None
        self._q: FloatArray | None = None  # (3, 3): rows q_pos, q_vel, q_acc; cols axes
        self._q_dirty = True
        self._last_fit_t: float | None = None
        self._inconsistent_run = 0
        self._pending: list[tuple[float, FloatArray, FloatArray, FloatArray]] = []
        self._vel_known = np.zeros(3, dtype=bool)
        self._last_var: FloatArray = np.ones(3)

    def reset(self) -> None:
        """Forget every fix and the particle (α and G are kept)."""
        self._reset_state()

    @property
    def alpha_ps(self) -> float:
        """Current dissipation rate α [1/s]."""
        return self._alpha

    @property
    def g_m2ps2(self) -> float:
        """Current coupling G [m²/s²]."""
        return self._g

    @property
    def threshold(self) -> float:
        """χ²(3) threshold of the fix test."""
        return self._threshold

    @property
    def t_last_s(self) -> float | None:
        """Time of the newest accepted fix [s], None before the first."""
        return self._anchors[-1].t_s if self._anchors else None

    @property
    def n_sources(self) -> int:
        """Number of fixes currently acting as sources."""
        return len(self._fixes)

    def _reject(self, reason: str, t_s: float) -> None:
        self.rejections[reason] = self.rejections.get(reason, 0) + 1
        _log.warning("potential: fix at t=%.3f s rejected: %s", t_s, reason)

    # ----------------------------------------------------------------- prediction

    def _q_coeffs(self) -> FloatArray:
        if self._q_dirty or self._q is None:
            self._q = self._calibrate()
            self._q_dirty = False
        return self._q

    @property
    def calibrated(self) -> bool:
        """True once the predicted covariance comes from the filter's own residuals."""
        return self._bins is not None

    def _prior_q(self) -> FloatArray:
        c = self.config
        return np.vstack(
            [
                self._last_var,
                np.full(3, c.prior_vel_sigma_mps**2),
                np.full(3, c.prior_acc_sigma_mps2**2),
            ]
        )

    def _calibrate(self) -> FloatArray:
        """Per-axis ``q_pos, q_vel, q_acc`` (rows) from the binned residual sums."""
        prior = self._prior_q()
        if self._bins is None:
            return prior
        cnt_all = self._bins[:, 0]
        used = cnt_all >= 1.0
        if np.count_nonzero(used) < 3:
            return prior
        b = self._bins[used]
        cnt = b[:, 0]
        hb = b[:, 1] / cnt
        design = np.column_stack([np.ones(hb.size), hb**2, 0.25 * hb**4])
        q = np.empty((3, 3))
        for k in range(3):
            e2b = b[:, 2 + k] / cnt
            varb = b[:, 5 + k] / cnt
            target = e2b - varb
            coef = prior[:, k]
            for _ in range(2):
                # E[e²] = σ²_fix + model(h); sd of a bin mean ∝ E[e²]/√count
                wrow = np.sqrt(cnt) / (varb + design @ coef)
                sol, _res = nnls(design * wrow[:, None], target * wrow)
                coef = sol
            q[:, k] = coef
        # a position floor keeps the covariance positive definite at h = 0
        q[0] = np.maximum(q[0], 1e-4)
        return q

    def _predict_from(self, anc: _Anchor, t_s: float) -> tuple[FloatArray, FloatArray]:
        return propagate_state(
            anc.pos_ned_m, anc.vel_ned_mps, anc.a_pm2, anc.b_pm, anc.g_m2ps2, anc.alpha_ps,
            t_s - anc.t_s,
        )  # fmt: skip

    def predict(self, t_s: float) -> PotentialPrediction:
        """Position, velocity and their covariances at ``t_s`` without new fixes.

        Parameters
        ----------
        t_s : float
            Time ≥ the newest accepted fix [s].

        Returns
        -------
        PotentialPrediction

        Raises
        ------
        ValueError
            Before the first fix, or for a time before the newest fix.

        References
        ----------
        S0 (SEEDS.md §S0); the covariance model is described in the module docstring.
        """
        if not self._anchors:
            raise ValueError("PotentialFilter.predict: no fix yet")
        anc = self._anchors[-1]
        h = float(t_s) - anc.t_s
        if not np.isfinite(h) or h < 0.0:
            raise ValueError(f"PotentialFilter.predict: t_s={t_s!r} is before the newest fix")
        pos, vel = self._predict_from(anc, float(t_s))
        q = self._q_coeffs()
        var_pos = q[0] + q[1] * h * h + 0.25 * q[2] * h**4
        var_vel = q[1] + q[2] * h * h
        return PotentialPrediction(
            t_s=float(t_s),
            pos_ned_m=pos,
            vel_ned_mps=vel,
            cov_ned_m2=np.diag(var_pos),
            vel_cov_ned_m2ps2=np.diag(var_vel),
            horizon_s=h,
        )

    # ----------------------------------------------------------------- fix test

    @staticmethod
    def _validate(
        t_s: float, pos_ned_m: ArrayLike, var_ned_m2: ArrayLike
    ) -> tuple[FloatArray, FloatArray, str]:
        pos = np.asarray(pos_ned_m, dtype=np.float64)
        var = np.asarray(var_ned_m2, dtype=np.float64)
        if pos.shape != (3,) or var.shape != (3,):
            return pos, var, "bad_shape"
        if not np.isfinite(t_s):
            return pos, var, "bad_time"
        if not np.all(np.isfinite(pos)):
            return pos, var, "non_finite_position"
        if not (np.all(np.isfinite(var)) and np.all(var > 0.0)):
            return pos, var, "bad_variance"
        return pos, var, ""

    def test_fix(self, t_s: float, pos_ned_m: ArrayLike, var_ned_m2: ArrayLike) -> FixTest:
        """χ² (3 dof) test of a fix against the predicted position and its ellipsoid.

        Parameters
        ----------
        t_s : float
            Fix time [s].
        pos_ned_m : array_like, shape (3,)
            Fix position (NED) [m].
        var_ned_m2 : array_like, shape (3,)
            Per-axis fix variance [m²].

        Returns
        -------
        FixTest
            ``tested`` is False (and ``consistent`` True) while the filter has
            fewer than ``min_test_fixes`` fixes or its covariance is not yet
            calibrated (before the first fit).

        Raises
        ------
        ValueError
            On malformed input (``add_fix`` counts and rejects it instead).

        References
        ----------
        S0 (SEEDS.md §S0, error detection).
        """
        pos, var, why = self._validate(t_s, pos_ned_m, var_ned_m2)
        if why:
            raise ValueError(f"PotentialFilter.test_fix: {why}")
        return self._test(float(t_s), pos, var)

    def _test(self, t_s: float, pos: FloatArray, var: FloatArray) -> FixTest:
        thr = self._threshold
        if len(self._fixes) < self.config.min_test_fixes or not self._anchors or self._bins is None:
            # no calibrated covariance yet: the test would only test the prior
            return FixTest(t_s, float("nan"), thr, True, False)
        pred = self.predict(t_s)
        d = pos - pred.pos_ned_m
        s = pred.cov_ned_m2 + np.diag(var)
        chi2 = float(d @ np.linalg.solve(s, d))
        return FixTest(t_s, chi2, thr, chi2 <= thr, True)

    # ----------------------------------------------------------------- adding fixes

    def add_fix(
        self,
        t_s: float,
        pos_ned_m: ArrayLike,
        var_ned_m2: ArrayLike,
        vel_ned_mps: ArrayLike | None = None,
        *,
        force: bool = False,
        refit: bool = True,
    ) -> FixTest:
        """Test a fix, then (if consistent or forced) carry the particle to it and add it.

        Parameters
        ----------
        t_s : float
            Fix time, strictly after the newest accepted fix [s].
        pos_ned_m : array_like, shape (3,)
            Position (NED) [m].
        var_ned_m2 : array_like, shape (3,)
            Per-axis variance, > 0 [m²].
        vel_ned_mps : array_like, shape (3,), optional
            Measured velocity (NED) [m/s]; NaN for components not measured.
        force : bool
            Add the fix even when inconsistent.
        refit : bool
            Run :meth:`refit` afterwards if it is due.

        Returns
        -------
        FixTest
            ``accepted`` False with a ``reason`` for malformed, out-of-order
            and inconsistent fixes (counted in :attr:`rejections`).

        References
        ----------
        S0 (SEEDS.md §S0).
        """
        pos, var, why = self._validate(t_s, pos_ned_m, var_ned_m2)
        t_s = float(t_s)
        thr = self._threshold
        vel = np.full(3, np.nan)
        if not why and vel_ned_mps is not None:
            v = np.asarray(vel_ned_mps, dtype=np.float64)
            if v.shape != (3,) or np.any(np.isinf(v)):
                why = "bad_velocity"
            else:
                vel = v
        if not why and self._anchors and t_s <= self._anchors[-1].t_s:
            why = "time_not_increasing"
        if why:
            self._reject(why, t_s)
            return FixTest(t_s, float("nan"), thr, False, False, False, why)

        test = self._test(t_s, pos, var)
        if test.tested and not test.consistent and not force:
            self._inconsistent_run += 1
            if self._inconsistent_run <= self.config.max_consecutive_inconsistent:
                self._pending.append((t_s, pos, var, vel))
                self._reject("inconsistent", t_s)
                return FixTest(t_s, test.chi2, thr, False, True, False, "inconsistent")
            _log.warning(
                "potential: %d consecutive inconsistent fixes: restarting at t=%.3f s",
                self._inconsistent_run,
                t_s,
            )
            self.rejections["restart"] = self.rejections.get("restart", 0) + 1
            # The model, not the fixes, is taken to be wrong: restart the field
            # and the particle from the run of inconsistent fixes (they agree
            # with each other), keeping α, G and the covariance calibration.
            pending = self._pending
            bins, q = self._bins, self._q
            self._reset_state()
            self._bins, self._q, self._q_dirty = bins, q, True
            for tp, pp, vp, vv in pending:
                self._accept(tp, pp, vp, vv)
        self._inconsistent_run = 0
        self._pending = []
        self._accept(t_s, pos, var, vel)
        if refit:
            self.refit()
        return FixTest(t_s, test.chi2, thr, test.consistent, test.tested, True, "")

    def _derived_velocity(self, t_s: float, pos: FloatArray) -> FloatArray:
        """Least-squares slope through the fixes of the last ``velocity_span_s`` (and this one)."""
        span = self.config.velocity_span_s
        ts = [f.t_s for f in self._fixes if t_s - f.t_s <= span + 1e-9]
        if len(ts) < 1:
            return np.full(3, np.nan)
        ps = [f.pos_ned_m for f in self._fixes if t_s - f.t_s <= span + 1e-9]
        tt = np.array([*ts, t_s])
        pp = np.vstack([*ps, pos])
        tc = tt - tt.mean()
        den = float(tc @ tc)
        if den <= 0.0:
            return np.full(3, np.nan)
        return (tc @ (pp - pp.mean(axis=0))) / den

    def _accept(self, t_s: float, pos: FloatArray, var: FloatArray, vel: FloatArray) -> None:
        c = self.config
        if self._anchors:
            ppos, pvel = self._predict_from(self._anchors[-1], t_s)
            # axes whose velocity was still unknown: the particle starts here
            ppos = np.where(self._vel_known, ppos, pos)
        else:
            ppos, pvel = pos.copy(), np.zeros(3)
        reset = np.full(3, np.nan)
        if c.velocity_mode == "measured" or not np.all(self._vel_known):
            reset = vel.copy()
            missing = np.isnan(reset)
            if np.any(missing):
                derived = self._derived_velocity(t_s, pos)
                reset[missing] = derived[missing]
        self._vel_known = self._vel_known | ~np.isnan(reset)
        pvel = np.where(np.isnan(reset), pvel, reset)
        pvel = np.where(self._vel_known, pvel, 0.0)  # placeholder until known
        self._fixes.append(_Fix(t_s, pos, 1.0 / var, reset))
        self._last_var = var
        self._drop_old(t_s)
        a, b = self._sums(t_s)
        known = bool(np.all(self._vel_known))
        self._anchors.append(_Anchor(t_s, ppos, pvel, self._alpha, self._g, a, b, known))
        while self._anchors and t_s - self._anchors[0].t_s > c.window_s:
            self._anchors.popleft()

    def _drop_old(self, t_s: float) -> None:
        c = self.config
        while self._fixes and (
            len(self._fixes) > c.max_sources or t_s - self._fixes[0].t_s > c.window_s
        ):
            self._fixes.popleft()

    def _sums(self, t0_s: float) -> tuple[FloatArray, FloatArray]:
        ts = np.array([f.t_s for f in self._fixes])
        ps = np.vstack([f.pos_ned_m for f in self._fixes])
        ws = np.vstack([f.p_pm2 for f in self._fixes])
        return field_sums(ts, ps, ws, self._alpha, t0_s, self.config.weight_floor)

    def _update_calibration(
        self,
        alpha: float,
        g: float,
        t: FloatArray,
        pos: FloatArray,
        p: FloatArray,
        vreset: FloatArray,
        p0: FloatArray,
        v0: FloatArray,
    ) -> None:
        """Add the fitted model's gap-prediction residuals over the window to the bins."""
        c = self.config
        apos, avel, aa, bb = replay_anchors(alpha, g, t, pos, p, vreset, p0, v0, c.weight_floor)
        jj, kk = np.triu_indices(t.size, 1)
        h = t[kk] - t[jj]
        keep = h <= c.window_s
        jj, kk, h = jj[keep], kk[keep], h[keep]
        if h.size < c.calib_min_residuals:
            return
        centre = bb[jj] / aa[jj]
        u, _ud = propagate_axis(apos[jj] - centre, avel[jj], g * aa[jj], alpha, h[:, None])
        e = pos[kk] - (centre + u)
        var = 1.0 / p[kk]
        nb = _CALIB_EDGES_S.size
        idx = np.digitize(h, _CALIB_EDGES_S) - 1
        new = np.zeros((nb, 8))
        new[:, 0] = np.bincount(idx, minlength=nb)
        new[:, 1] = np.bincount(idx, weights=h, minlength=nb)
        for k in range(3):
            new[:, 2 + k] = np.bincount(idx, weights=e[:, k] ** 2, minlength=nb)
            new[:, 5 + k] = np.bincount(idx, weights=var[:, k], minlength=nb)
        self._bins = new if self._bins is None else c.calib_forgetting * self._bins + new
        self._q_dirty = True

    # ----------------------------------------------------------------- self-learning

    def _window_arrays(
        self,
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        # the replay starts at the oldest fix where the particle's velocity was known
        known_t = {a.t_s: a for a in self._anchors if a.vel_known}
        fx = list(self._fixes)
        i0 = next((i for i, f in enumerate(fx) if f.t_s in known_t), 0)
        fx = fx[i0:]
        first = known_t.get(fx[0].t_s)
        t = np.array([f.t_s for f in fx])
        pos = np.vstack([f.pos_ned_m for f in fx])
        p = np.vstack([f.p_pm2 for f in fx])
        vreset = np.vstack([f.vel_reset_ned_mps for f in fx])
        p0 = pos[0]
        v0 = first.vel_ned_mps if first is not None else np.nan_to_num(vreset[0])
        return t, pos, p, vreset, p0, v0

    def refit(self, *, force: bool = False) -> tuple[float, float] | None:
        """Fit α and G on the window if a fit is due (or ``force``).

        Runs bounded, seeded, warm-started differential evolution on
        :func:`replay_cost` in ``(log10 α, log10 G)``; the particle then takes
        the replayed state at the newest fix.

        Returns
        -------
        (alpha_ps, g_m2ps2) or None
            The new values, or None when no fit was due or possible.

        References
        ----------
        S0 (SEEDS.md §S0, self-learning).
        """
        c = self.config
        if len(self._fixes) < c.min_fit_fixes or not self._anchors:
            return None
        t_new = self._anchors[-1].t_s
        if not force and self._last_fit_t is not None:
            if t_new - self._last_fit_t < c.refit_interval_s:
                return None
        if not force and self._fixes[-1].t_s - self._fixes[0].t_s < c.refit_interval_s:
            return None
        t, pos, p, vreset, p0, v0 = self._window_arrays()
        if t.size < c.min_fit_fixes:
            return None
        lo = np.log10([c.alpha_bounds_ps[0], c.g_bounds_m2ps2[0]])
        hi = np.log10([c.alpha_bounds_ps[1], c.g_bounds_m2ps2[1]])
        x0 = np.clip(np.log10([self._alpha, self._g]), lo, hi)

        def cost(x: FloatArray) -> FloatArray:
            xx = np.asarray(x, dtype=np.float64).reshape(2, -1)
            out = replay_cost(
                10.0 ** xx[0], 10.0 ** xx[1], t, pos, p, vreset, p0, v0, c.weight_floor
            )
            return out if np.ndim(x) > 1 else out[0]

        # Initial population: the warm start, the best quarter from a coarse
        # log grid (one vectorised replay) so that a narrow global valley is
        # seeded even when the warm start sits in another basin, and the rest
        # spread uniformly (seeded) to keep the population diverse.
        n_pop = 2 * c.de_popsize
        ga_ = np.linspace(lo[0], hi[0], c.de_grid_points)
        gg_ = np.linspace(lo[1], hi[1], c.de_grid_points)
        grid = np.array(np.meshgrid(ga_, gg_)).reshape(2, -1)
        order = np.argsort(cost(grid), kind="stable")
        n_best = max(1, n_pop // 4)
        rng = np.random.default_rng(c.seed + self.fit_count)
        init = np.vstack(
            [
                x0,
                grid[:, order[:n_best]].T,
                rng.uniform(lo, hi, size=(n_pop - 1 - n_best, 2)),
            ]
        )
        res = differential_evolution(
            cost,
            bounds=list(zip(lo, hi, strict=True)),
            maxiter=c.de_maxiter,
            tol=c.de_tol,
            seed=c.seed + self.fit_count,
            polish=False,
            init=init,
            updating="deferred",
            vectorized=True,
        )
        self.fit_count += 1
        self._last_fit_t = t_new
        alpha, g = (float(v) for v in 10.0 ** np.asarray(res.x))
        self.last_fit_cost_m2 = float(res.fun)
        self._alpha, self._g = alpha, g
        last = self._anchors[-1]
        if c.adopt_replay_state:
            # the fitted model's own trajectory: replayed state at the newest fix
            ppos, pvel = replay_state(alpha, g, t, pos, p, vreset, p0, v0, c.weight_floor)
        else:
            # the carried particle continues; only the field changes
            ppos, pvel = last.pos_ned_m, last.vel_ned_mps
        a, b = self._sums(t_new)
        self._anchors[-1] = _Anchor(t_new, ppos, pvel, alpha, g, a, b)
        self._update_calibration(alpha, g, t, pos, p, vreset, p0, v0)
        _log.debug("potential: fit %d alpha=%.4g 1/s G=%.4g m2/s2", self.fit_count, alpha, g)
        return alpha, g

    def outputs(self, t_s: float) -> list[NamedValue]:
        """The fitted α [1/s] and G [m²/s²] as NAMED_VALUE_FLOAT ``CMP_PALPHA``, ``CMP_PG``."""
        return [NamedValue(t_s, NAME_ALPHA, self._alpha), NamedValue(t_s, NAME_G, self._g)]


# --------------------------------------------------------------------------- replay (fit)


def _replay(
    alpha_ps: FloatArray,
    g_m2ps2: FloatArray,
    t_s: FloatArray,
    pos_m: FloatArray,
    p_pm2: FloatArray,
    vel_reset_mps: FloatArray,
    pos0_m: FloatArray,
    vel0_mps: FloatArray,
    weight_floor: float = 0.0,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    al = np.asarray(alpha_ps, dtype=np.float64).reshape(-1, 1)  # (P, 1)
    g = np.asarray(g_m2ps2, dtype=np.float64).reshape(-1, 1)
    npop = al.shape[0]
    ppos = np.broadcast_to(pos0_m, (npop, 3)).copy()
    pvel = np.broadcast_to(vel0_mps, (npop, 3)).copy()
    cost = np.zeros(npop)
    n = t_s.size
    wp = 2.0 * p_pm2  # (n, 3)
    wpx = wp * pos_m
    for i in range(1, n):
        dt = t_s[i] - t_s[i - 1]
        # field of sources 0..i-1 with origin at t_{i-1}: weights (P, i)
        w = np.exp(al * (t_s[:i] - t_s[i - 1]))
        w = np.where(w < weight_floor, 0.0, w)
        a = w @ wp[:i]  # (P, 3)
        b = w @ wpx[:i]
        centre = b / a
        ga = g * a
        w1, w2, w1d, w2d = _transition_core(
            ga, np.broadcast_to(al, ga.shape), np.full(ga.shape, dt)
        )
        u0 = ppos - centre
        ppos = centre + w1 * u0 + w2 * pvel
        ud = w1d * u0 + w2d * pvel
        res = ppos - pos_m[i]
        cost += np.einsum("ij,ij->i", res, res)
        reset = vel_reset_mps[i]
        pvel = np.where(np.isnan(reset), ud, reset)
    return cost, ppos, pvel


def replay_cost(
    alpha_ps: FloatArray,
    g_m2ps2: FloatArray,
    t_s: FloatArray,
    pos_m: FloatArray,
    p_pm2: FloatArray,
    vel_reset_mps: FloatArray,
    pos0_m: FloatArray,
    vel0_mps: FloatArray,
    weight_floor: float = 0.0,
) -> FloatArray:
    """S0's self-learning objective ``Σ_i |r(t_i) − r_0i|²`` for many (α, G) at once.

    The particle starts at ``pos0_m``, ``vel0_mps`` at ``t_s[0]`` and is carried
    from fix to fix through the field of the fixes before it; at each fix its
    velocity components are replaced where ``vel_reset_mps`` is finite.

    Parameters
    ----------
    alpha_ps, g_m2ps2 : ndarray, shape (P,)
        Candidate α [1/s] and G [m²/s²].
    t_s : ndarray, shape (n,)
        Fix times, increasing [s].
    pos_m : ndarray, shape (n, 3)
        Fix positions (NED) [m].
    p_pm2 : ndarray, shape (n, 3)
        Fix weights ``1/σ²`` [1/m²].
    vel_reset_mps : ndarray, shape (n, 3)
        Velocity taken by the particle at each fix, NaN to keep its own [m/s].
    pos0_m, vel0_mps : ndarray, shape (3,)
        Particle state at ``t_s[0]``.
    weight_floor : float
        Sources with weight below this are dropped (as in the filter).

    Returns
    -------
    ndarray, shape (P,)
        Sum of squared position residuals [m²] (``inf`` where not finite).

    References
    ----------
    S0 (SEEDS.md §S0, self-learning: ``f(α, G) = Σ_i |r(t_i) − r_0i|² → min``).
    """
    cost, _p, _v = _replay(
        alpha_ps, g_m2ps2, t_s, pos_m, p_pm2, vel_reset_mps, pos0_m, vel0_mps, weight_floor
    )
    return np.where(np.isfinite(cost), cost, np.inf)


def replay_state(
    alpha_ps: float,
    g_m2ps2: float,
    t_s: FloatArray,
    pos_m: FloatArray,
    p_pm2: FloatArray,
    vel_reset_mps: FloatArray,
    pos0_m: FloatArray,
    vel0_mps: FloatArray,
    weight_floor: float = 0.0,
) -> tuple[FloatArray, FloatArray]:
    """Particle state at the last fix after :func:`replay_cost`'s replay (one α, G).

    Returns
    -------
    pos_ned_m, vel_ned_mps : ndarray, shape (3,)

    References
    ----------
    S0 (SEEDS.md §S0).
    """
    _c, ppos, pvel = _replay(
        np.array([alpha_ps]), np.array([g_m2ps2]), t_s, pos_m, p_pm2, vel_reset_mps, pos0_m,
        vel0_mps, weight_floor,
    )  # fmt: skip
    return ppos[0], pvel[0]


def replay_anchors(
    alpha_ps: float,
    g_m2ps2: float,
    t_s: FloatArray,
    pos_m: FloatArray,
    p_pm2: FloatArray,
    vel_reset_mps: FloatArray,
    pos0_m: FloatArray,
    vel0_mps: FloatArray,
    weight_floor: float = 0.0,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The replay of :func:`replay_cost` (one α, G), keeping the state at every fix.

    Returns
    -------
    pos_ned_m, vel_ned_mps : ndarray, shape (n, 3)
        Particle position (carried) and velocity (after the reset) at each fix.
    a_pm2, b_pm : ndarray, shape (n, 3)
        Field sums at each fix with the time origin there (that fix included).

    References
    ----------
    S0 (SEEDS.md §S0).
    """
    n = t_s.size
    apos = np.empty((n, 3))
    avel = np.empty((n, 3))
    aa = np.empty((n, 3))
    bb = np.empty((n, 3))
    ppos = np.asarray(pos0_m, dtype=np.float64).copy()
    pvel = np.asarray(vel0_mps, dtype=np.float64).copy()
    for i in range(n):
        if i > 0:
            ppos, ud = propagate_state(
                ppos, pvel, aa[i - 1], bb[i - 1], g_m2ps2, alpha_ps, t_s[i] - t_s[i - 1]
            )
            reset = vel_reset_mps[i]
            pvel = np.where(np.isnan(reset), ud, reset)
        a, b = field_sums(
            t_s[: i + 1], pos_m[: i + 1], p_pm2[: i + 1], alpha_ps, t_s[i], weight_floor
        )
        apos[i], avel[i], aa[i], bb[i] = ppos, pvel, a, b
    return apos, avel, aa, bb

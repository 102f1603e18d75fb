"""Position-potential filter with self-learned dissipation α and coupling G (S0).

Every accepted GNSS fix ``i`` (time ``t_i``, position ``r_0i``, per-axis
variances ``σ²_ki``) is the source of an attracting potential that dissipates
in time. With the time origin at the newest source (``t_n = 0``), each NED
axis ``k`` of the particle obeys

    k̈(t) = −G A_k e^{−α t} (k − B_k/A_k),
    A_k = 2 Σ_i e^{α(t_i − t_n)} p_ki,   B_k = 2 Σ_i e^{α(t_i − t_n)} p_ki k_0i.

**Weights relative to the newest fix** (issue 5): S0's weights are
``p = 1/σ²``, so ``G·A`` scales with the receiver's accuracy class: S0 flew
DGPS (σ ≈ 1 m, p ≈ 1 m⁻²) and found G ≈ 0.2-0.5; RTK's σ = 1.5 cm makes
p ≈ 4400 m⁻² and the same G a field thousands of times stiffer, which holds
the particle on the centroid of the recent fixes (0.3-0.5 s of motion
behind). Here ``p_ki = σ²_nk / σ²_ki``, the newest fix's variance over the
source's, per axis: ``A_k`` is dimensionless (``2 Σ e^{α(t_i − t_n)}`` for
fixes of equal accuracy), ``G`` and ``G·A_k`` are in 1/s², and S0's α and G
keep their meaning at σ ≈ 1 m for DGPS and RTK alike; the relative weighting
of sources of different accuracy is S0's. With ``u = k − B_k/A_k`` and
``ω = √(G A_k)`` the solution is a Bessel function of order 0 in
``s = (2ω/α) e^{−αt/2}``; it is linear in the particle's offset and velocity
at the origin::

    [u(t), u̇(t)] = Φ(t; ω², α) · [u0, u̇0]

:func:`transition_axis` evaluates Φ in closed form, numerically sound from the
harmonic-oscillator limit (α → 0, huge Bessel arguments: a Hankel
modulus/phase form that never subtracts two large phases) to the coasting
limit (G·A → 0 or αt → ∞, tiny arguments: power series written in ``ln s`` so
that nothing underflows).

The filter (:class:`PotentialFilter`)

* carries the particle from fix to fix through the field of the fixes it has
  accepted. At each fix the particle's carried position (its offset from the
  fix is S0's ``Δk_n``) moves towards the fix by ``K = P/(P + R)`` per axis
  (``position_update``; P the predicted variance, R the fix's): with the
  position carried only, the particle is tied to the fixes by the field
  alone, whose centre trails a moving aircraft by ~1/α of motion, so any G
  that holds the particle drags it back, and the fit's only way out, G → 0,
  lets it drift. In the default ``velocity_mode="measured"`` it takes the
  velocity ``β v_meas + (1 − β) v_lsq``: the fix's measured velocity (S0
  predicts from ``k̇_n``, β = 1) weighed against a least-squares velocity
  through the last ``velocity_span_s`` of fixes, which also gives the
  components the receiver does not (GPS_RAW_INT has no vertical velocity):
  a line's slope (precise, but the velocity at mid-span: half a second late
  in a turn or an acceleration) or a parabola's slope at the newest fix (not
  late, noisier). β and the order are chosen at each fit from
  ``velocity_weights`` and ``velocity_fit_orders`` by the same objective as
  α and G (precise RTK positions make the slope better than a receiver's
  velocity; DGPS-level positions the reverse). ``velocity_mode="carried"``
  keeps the pure particle velocity instead;
* predicts position and velocity at any later time with the field frozen
  (no new sources). The fixes' innovations (fix − prediction) are binned by
  horizon ``h`` and fitted by ``q(h) = q_pos + q_vel h² + q_acc h⁴/4`` per
  axis, to which the known error of coasting through the current
  acceleration ``a`` is added, ``(|a| (λh + h²/2))²`` (``a²`` from the
  parabola less its noise variance, ``λ`` the age of the velocity used):
  ``q(h)`` is the variance of ``fix − prediction``, the fix test's ``S``
  (``innov_cov_ned_m2``; at least the rounding variance of the fixes'
  positions, ``fix_resolution_m``). The error against the truth is
  ``P = q(h) + R − 2 r_w`` with ``r_w = min(R, q_pos)`` the fix's white part:
  the prediction is made of earlier fixes and shares their slowly varying
  error (RTK and DGPS errors are correlated over tens of seconds), which
  the innovations cannot see and ``P`` must carry (``≈ q + R``), while a
  white fix error is in ``q`` but not in the prediction (``q − R``). The
  residuals come from the fitted model's replay of the window after every
  fit: from the particle's state at each fix, the frozen-field prediction to
  every later fix in the window (horizons from one fix interval to the
  window's span); the binned sums of older fits decay by
  ``calib_forgetting`` per fit, and ``mean(e²)`` is regressed on
  ``[1, h², h⁴/4]`` by non-negative least squares, each bin weighted by
  ``√count / model`` (two passes, the first with the prior). Until the first
  fit the prior (``prior_vel_sigma_mps``, ``prior_acc_sigma_mps2``) is used
  and fixes are not tested;
* learns α and G by minimising over the window S0's objective
  ``Σ_i |r(t_i) − r_0i|²`` (the particle replayed through the window from the
  oldest fix's position and the particle's velocity there, the sources added
  one by one, the position updated at each fix as above) plus the squared
  errors of gap predictions from the particle at fixes every
  ``fit_start_every_s``, field frozen, over ``fit_horizons_s``
  (:func:`fit_pairs`): the one-step sum barely sees the field's pull, which
  over a 5-20 s gap moves the prediction by metres. The optimiser is
  :func:`scipy.optimize.differential_evolution` in ``(log10 α, log10 G)``:
  bounded, seeded (``seed + fit count``), vectorised over the population (all
  transition matrices of a replay in one call, the particle's 2 × 2
  recursion fix by fix); the first fit seeds its population with the best
  quarter of a coarse log grid, later ones are warm-started (the last
  solution, the grid's best, draws around the last). A refit runs every
  ``refit_interval_s`` of fix time, sooner when the particle's speed has
  left a band around its speed at the last fit (a fit made parked or
  taxiing is not carried into flight) and before the first inconsistent fix
  of a run is rejected; the engine forces one at the start of a gap. After a
  fit the particle takes the fitted model's replayed state at the newest fix
  (``adopt_replay_state``);
* tests each new fix against the prediction: ``χ² = dᵀ S⁻¹ d`` with 3
  degrees of freedom against ``chi2.ppf(1 − false_alarm_prob, 3)`` (``S``:
  see above; plus the excess of the fix's variance over the calibration's
  fixes'). An inconsistent fix is not made a source; after
  ``max_consecutive_inconsistent`` of them in a row the filter restarts from
  them (the model, not the fixes, is taken to be wrong) with the
  least-lagging velocity (largest β and order), a field no stiffer than
  ``g0_ps2``, and declares itself uncalibrated: no fix is tested and the
  prior covariance is used until the restarted window is refitted, which is
  due as soon as it spans ``first_fit_span_s``. A restart therefore always
  leads to a fit before the next test (no restart loop).

Cost: the window lives in preallocated arrays, each anchor (the particle
after a fix) keeps its Bessel constants at ``s0``, so a prediction is four
Bessel calls on a 3-vector; the last prediction is memoised (the engine
predicts at a fix's time, then adds the fix, which tests it there). See the
timing section of ``bench/potential.py``.

Known limits: the fit can settle in the broad basin at the α upper bound when
the true α is small (≲ 1.5 1/s), where the global valley is narrower than
the seeding grid; the multi-step terms trade the field's smoothing of noisy
fixes (which helps over 1-2 s with metre-level white noise) against its pull
on 5-20 s predictions (``fit_horizons_s`` sets the balance). On precise,
slowly varying fixes (RTK) the fit mostly drives G to its floor (the position
update does the tying, the field would only lag) and α is then immaterial.
The particle has no acceleration: at the onset of a turn or of the take-off
roll its one-step error grows faster than the calibration and the
acceleration estimate follow, so a manoeuvre's onset can cost a few rejected
fixes and a restart (13 restarts in the simulator's 931-s nominal flight,
one per onset; ``tests/nav/test_potential.py``).

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
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import numpy.typing as npt
from numpy.typing import ArrayLike
from scipy import special, stats
from scipy.optimize import differential_evolution, nnls

from companion.types import FloatArray, NamedValue

IntArray = npt.NDArray[np.intp]

_log = logging.getLogger(__name__)

# Bessel argument beyond which the Hankel modulus/phase expansion (4 terms each)
# is used: its truncation error there is below 1e-16 (next term ~ x^-8 / x^-9).
_X_ASYM = 200.0
# Bessel argument below which the small-argument series is used (dropped terms
# ~ x^4 ln x < 1e-22).
_X_SMALL = 1e-6
_EULER_GAMMA = float(np.euler_gamma)
# Horizon bins of the covariance calibration [s].
_CALIB_EDGES_S = np.array(
    [0.0, 0.15, 0.3, 0.6, 1.0, 1.5, 2.0, 3.0, 4.5, 6.5, 9.0, 13.0, 20.0, 30.0, 1e9]
)
_TWO_OVER_PI = 2.0 / np.pi

_NAN3 = np.full(3, np.nan)
_NAN3.setflags(write=False)
_ZERO3 = np.zeros(3)
# Fraction of velocity_span_s the fixes must span before a parabola is fitted
# (its slope's noise grows as span^-1.5).
_PARABOLA_MIN_SPAN = 0.75
_ZERO3.setflags(write=False)

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

    The weights are relative to the newest source (the last row): per axis
    ``p_ki / p_kn = σ²_kn / σ²_ki``, so ``A_k`` is dimensionless and ``G·A_k``
    does not depend on the receiver's accuracy class (see the module docstring).

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
    S0 (SEEDS.md §S0), the sums with the time origin at the newest fix; the
    weights made relative to the newest fix's (module docstring).
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
    S0 (SEEDS.md §S0).
    """
    has = a_rel > 0.0
    centre = np.where(has, b_m / np.where(has, a_rel, 1.0), pos_ned_m)
    u, ud = propagate_axis(pos_ned_m - centre, vel_ned_mps, g_ps2 * a_rel, alpha_ps, dt_s)
    return centre + u, ud


def combine_predictions(
    pos_a: FloatArray,
    cov_a: FloatArray,
    pos_b: FloatArray,
    cov_b: FloatArray,
    cov_ab: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Combine two predictions of the same position by their covariances.

    ``x = a + K (b − a)`` with ``K = (P_a − P_ab) S⁻¹``,
    ``S = P_a + P_b − P_ab − P_abᵀ``: the minimum-variance combination of two
    unbiased estimates whose errors have cross-covariance
    ``P_ab = E[e_a e_bᵀ]`` (zero by default: ``K = P_a (P_a + P_b)⁻¹``, equal to
    ``(P_a⁻¹ + P_b⁻¹)⁻¹`` weighting but without inverting either). Two
    predictions carried from the same fixes share those fixes' error: pass it
    as ``cov_ab`` (e.g. ``PotentialPrediction.anchor_var_ned_m2`` on the
    diagonal) or the combination counts it twice.

    Parameters
    ----------
    pos_a, pos_b : ndarray, shape (n,)
        The two predictions (e.g. INS and potential, NED) [m].
    cov_a, cov_b : ndarray, shape (n, n)
        Their covariances [m²], symmetric positive semi-definite.
    cov_ab : ndarray, shape (n, n), optional
        Cross-covariance of their errors [m²]; ``S`` must be positive definite.

    Returns
    -------
    pos, cov : ndarray, shapes (n,), (n, n)
        ``cov = (I − K) P_a (I − K)ᵀ + K P_b Kᵀ + (I − K) P_ab Kᵀ + K P_abᵀ (I − K)ᵀ``.

    Raises
    ------
    ValueError
        On mismatched shapes, non-finite values or a singular ``S``.

    References
    ----------
    S0 (SEEDS.md §S0, its place in the bridge); Bar-Shalom, Li & Kirubarajan,
    Estimation with Applications to Tracking and Navigation, §5.2 (the update
    with ``H = I``) and Bar-Shalom & Campo, "The effect of the common process
    noise on the two-sensor fused-track covariance", IEEE TAES 22(6), 1986
    (the correlated case).
    """
    a = np.asarray(pos_a, dtype=np.float64)
    b = np.asarray(pos_b, dtype=np.float64)
    pa = np.asarray(cov_a, dtype=np.float64)
    pb = np.asarray(cov_b, dtype=np.float64)
    n = a.size
    pab = np.zeros((n, n)) if cov_ab is None else np.asarray(cov_ab, dtype=np.float64)
    if (
        a.shape != (n,)
        or b.shape != (n,)
        or pa.shape != (n, n)
        or pb.shape != (n, n)
        or pab.shape != (n, n)
    ):
        raise ValueError("combine_predictions: need vectors (n,) and covariances (n, n)")
    if not all(np.all(np.isfinite(x)) for x in (a, b, pa, pb, pab)):
        raise ValueError("combine_predictions: inputs must be finite")
    s = pa + pb - pab - pab.T
    try:
        c = np.linalg.cholesky(0.5 * (s + s.T))
    except np.linalg.LinAlgError as exc:
        raise ValueError(
            "combine_predictions: P_a + P_b − P_ab − P_abᵀ is not positive definite"
        ) from exc
    # K = (P_a − P_ab) S⁻¹  ->  Kᵀ = S⁻¹ (P_a − P_ab)ᵀ
    kt = np.linalg.solve(c.T, np.linalg.solve(c, (pa - pab).T))
    k = kt.T
    pos = a + k @ (b - a)
    ik = np.eye(n) - k
    # valid for any K: keeps P symmetric positive semi-definite
    cross = ik @ pab @ k.T
    cov = ik @ pa @ ik.T + k @ pb @ k.T + cross + cross.T
    return pos, 0.5 * (cov + cov.T)


def combine_with_ins(
    ins_pos_ned_m: FloatArray,
    ins_cov_ned_m2: FloatArray,
    pred: PotentialPrediction,
    threshold: float,
) -> tuple[FloatArray, FloatArray, float]:
    """The INS and potential predictions through a gap, combined only while they agree.

    Both are carried from the same last fixes, so they share that fix's error: the
    cross-covariance is taken as the newest fix's variance, at most either's own
    (:func:`combine_predictions` with ``cov_ab``). The disagreement ``d = b − a`` is
    tested first: ``χ² = dᵀ S⁻¹ d`` with ``S = P_a + P_b − 2 P_ab``; above ``threshold``
    (a χ²(3) quantile) one of the two covariances is lying — in practice the potential
    one, whose calibration comes from horizons of seconds, in turns the particle cannot
    know — and the INS alone is returned.

    Parameters
    ----------
    ins_pos_ned_m, ins_cov_ned_m2 : ndarray, shapes (3,), (3, 3)
        The INS prediction [m], [m²].
    pred : PotentialPrediction
        The potential prediction at the same time.
    threshold : float
        χ²(3) gate of the disagreement.

    Returns
    -------
    pos_ned_m, cov_ned_m2, chi2 : ndarray (3,), ndarray (3, 3), float
        The combination (or the INS prediction when ``chi2 > threshold``) and the
        disagreement's χ².

    References
    ----------
    S0 (SEEDS.md §S0, its place in the bridge); Bar-Shalom & Campo 1986 (correlated
    track fusion); the track-to-track association test, Bar-Shalom, Li & Kirubarajan §11.
    """
    shared = np.minimum(
        pred.anchor_var_ned_m2,
        np.minimum(np.diag(ins_cov_ned_m2), np.diag(pred.cov_ned_m2)),
    )
    cov_ab = np.diag(shared)
    d = pred.pos_ned_m - ins_pos_ned_m
    s = ins_cov_ned_m2 + pred.cov_ned_m2 - 2.0 * cov_ab
    try:
        chi2 = float(d @ np.linalg.solve(s, d))
    except np.linalg.LinAlgError:
        chi2 = math.inf
    if not math.isfinite(chi2) or chi2 > threshold:
        return ins_pos_ned_m, ins_cov_ned_m2, chi2
    pos, cov = combine_predictions(
        ins_pos_ned_m, ins_cov_ned_m2, pred.pos_ned_m, pred.cov_ned_m2, cov_ab
    )
    return pos, cov, chi2


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
    alpha0_ps, g0_ps2 : float
        Starting α [1/s] and G [1/s²] (S0's stable-descent values, which
        keep their meaning with the relative weights at σ ≈ 1 m).
    alpha_bounds_ps, g_bounds_ps2 : tuple of float
        Bounds of the fit [1/s], [1/s²] (searched in log10). G's ceiling
        keeps ``G·A·Δt² ≲ 1`` with ``A ≈ 2/(1 − e^{−αΔt})`` of 2-40 at 5-10 Hz:
        a stiffer field swings the particle within one fix interval (a parked
        window's fit otherwise runs to any ceiling). The closed form
        is sound for any α ≥ 0, but the fit's α floor is 0.5 1/s: below it the
        field barely dissipates, the particle is pulled towards the centroid
        of the whole window (seconds behind the aircraft) and 5-20 s
        predictions collapse, while the one-step objective hardly notices
        (S0: α = 2.7-3.8 fitted, α = 0.2 "diverged badly").
    refit_interval_s : float
        Minimum fix time between two fits [s]: the real-time budget. A warm
        fit costs ~10-25 ms (``bench/potential.py`` prints it), so 5 s costs
        2-5 ms per second of flight; 2 s fits the decelerating and
        flight-path-changing phases a little better (bench part A), 10 s
        noticeably worse. The engine also forces a fit at the start of a gap.
    min_fit_fixes : int
        Fewest fixes in the window for a fit.
    first_fit_span_s : float
        The first fit (and the first after a restart) waits until the window
        spans this much fix time (or ``refit_interval_s`` if shorter) [s].
    refit_speed_change_mps, refit_speed_change_rel : float
        A fit is also due, before ``refit_interval_s``, once the particle's
        speed differs from its speed at the last fit by more than
        ``refit_speed_change_mps + refit_speed_change_rel · v_fit`` [m/s], [-]:
        α and G fitted while parked or taxiing are not carried into flight.
    refit_min_interval_s : float
        Fewest seconds of fix time between two such speed-triggered fits [s];
        also between a fit and the one a first inconsistent fix runs before
        it is rejected (the model is refitted on the window, the fix tested
        again).
    de_maxiter, de_popsize : int
        Differential-evolution generations and population multiplier.
    de_tol : float
        Differential-evolution relative tolerance.
    de_grid_points : int
        Points per axis of the coarse log grid that seeds the population.
    de_warm_popsize : int
        Population of the warm-started fits after the first (0: every fit
        cold, as the first; otherwise ≥ 5).
    velocity_weights : tuple of float
        Candidate weights β in [0, 1] of the fix's measured velocity in the
        particle's velocity at a fix, ``β v_meas + (1 − β) v_lsq`` (``v_lsq``:
        the least-squares slope through the last ``velocity_span_s`` of fixes,
        which also fills components the receiver does not give). Each fit
        keeps the candidate with the smallest objective over the window;
        ``(1.0,)`` is S0's measured velocity. The filter starts with the largest.
    velocity_fit_orders : tuple of int
        Candidate orders (1: line, 2: parabola) of the least-squares fit that
        gives ``v_lsq``. A line's slope is the velocity at the middle of the
        span, half a span (0.5 s of turn or acceleration) late; a parabola's
        slope at the newest fix is not late but noisier. Each fit keeps the
        (β, order) pair with the smallest objective; the filter starts (and
        restarts) with the largest β and order, the least-lagging velocity.
    fit_horizons_s : tuple of float
        Gap-prediction horizons [s] whose squared errors (from the particle at
        fixes every ``fit_start_every_s``, field frozen) join S0's one-step sum
        in the fit objective; empty for S0's objective alone. With the
        particle's velocity reset at every fix, the one-step sum barely sees
        the field's pull (metres over a gap, millimetres over one fix
        interval): the multi-step terms fit α and G to the use they are put to.
    fit_start_every_s : float
        Spacing of the start fixes of those terms [s].
    de_warm_spread_dex : float
        Spread (1σ, decades of α and G) of the warm members around the last
        solution.
    adopt_replay_state : bool
        After a fit, move the particle to the fitted model's replayed state at
        the newest fix (True, the default) or keep the carried particle and
        change only the field (False).
    position_update : bool
        At each fix, move the particle's carried position towards the fix by
        the per-axis gain ``K = P/(P + R)`` (``P`` the predicted position
        variance, ``R`` the fix's) (True, the default), or keep the carried
        position (False, pure S0). Without it, the particle's position is tied
        to the fixes only through the field, whose centre (the weighted
        centroid of the recent fixes) trails a moving aircraft by ~1/α of
        motion: any G strong enough to hold the particle drags it towards
        that centroid, and the fit's only escape is G → 0, pure coasting,
        whose position error then grows without bound.
    false_alarm_prob : float
        False-alarm probability of the χ² (3 dof) fix test.
    fix_resolution_m : tuple of float
        Resolution of the fixes' N, E, D positions [m], > 0: the fix test's
        innovation variance ``S`` is at least ``res²/12`` per axis, the
        rounding variance of the new fix's position (one 1.11 cm step of a
        parked receiver then gives χ² = 12, below the 1e-3 quantile). The
        defaults are those of a latitude/longitude given to 1e-7° (1.11 cm of
        latitude; longitude's step is smaller) and an altitude in mm, as
        MAVLink's GPS_RAW_INT gives them: a parked RTK receiver's residuals are
        millimetres, so one rounding step would otherwise fail the test.
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
        at each fit. A manoeuvre's window (the push-over into a glide: metres
        at 5 s) outweighs a steady window's (centimetres) by 10⁴ in e²: at
        0.5 per fit it still ruled the 20-s gap covariance half a minute later
        (Part B of ``bench/potential.py``); 0.25 leaves it 1/4096 after six fits.
    seed : int
        Seed of the optimiser (each fit uses ``seed + fit count``).
    """

    window_s: float = 10.0
    max_sources: int = 60
    weight_floor: float = 1e-12
    alpha0_ps: float = 2.84
    g0_ps2: float = 0.35
    alpha_bounds_ps: tuple[float, float] = (0.5, 10.0)
    g_bounds_ps2: tuple[float, float] = (1e-6, 1e2)
    refit_interval_s: float = 5.0
    min_fit_fixes: int = 6
    first_fit_span_s: float = 2.0
    refit_speed_change_mps: float = 1.0
    refit_speed_change_rel: float = 0.2
    refit_min_interval_s: float = 1.0
    de_maxiter: int = 20
    de_popsize: int = 8
    de_tol: float = 1e-3
    de_grid_points: int = 6
    de_warm_popsize: int = 8
    velocity_weights: tuple[float, ...] = (0.0, 0.25, 0.5, 0.75, 1.0)
    velocity_fit_orders: tuple[int, ...] = (1, 2)
    fit_horizons_s: tuple[float, ...] = (0.5, 1.0, 2.0, 4.0)
    fit_start_every_s: float = 0.5
    de_warm_spread_dex: float = 0.15
    adopt_replay_state: bool = True
    position_update: bool = True
    false_alarm_prob: float = 1e-3
    fix_resolution_m: tuple[float, float, float] = (0.0112, 0.0112, 0.001)
    min_test_fixes: int = 3
    max_consecutive_inconsistent: int = 3
    velocity_mode: Literal["measured", "carried"] = "measured"
    velocity_span_s: float = 1.0
    prior_vel_sigma_mps: float = 1.0
    prior_acc_sigma_mps2: float = 1.0
    calib_min_residuals: int = 30
    calib_forgetting: float = 0.25
    seed: int = 0

    def __post_init__(self) -> None:
        def pos(name: str) -> None:
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"PotentialConfig.{name} must be finite and > 0, got {v!r}")

        for name in (
            "window_s",
            "alpha0_ps",
            "g0_ps2",
            "refit_interval_s",
            "first_fit_span_s",
            "refit_speed_change_mps",
            "refit_min_interval_s",
            "de_tol",
            "velocity_span_s",
            "de_warm_spread_dex",
            "fit_start_every_s",
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
            ("de_warm_popsize", 0),
        ):
            if int(getattr(self, name)) < lo:
                raise ValueError(f"PotentialConfig.{name} must be >= {lo}")
        if not all(np.isfinite(h) and h > 0.0 for h in self.fit_horizons_s):
            raise ValueError("PotentialConfig.fit_horizons_s must be finite and > 0")
        if not self.velocity_fit_orders or not set(self.velocity_fit_orders) <= {1, 2}:
            raise ValueError("PotentialConfig.velocity_fit_orders must be non-empty, in {1, 2}")
        if not self.velocity_weights or not all(0.0 <= b <= 1.0 for b in self.velocity_weights):
            raise ValueError("PotentialConfig.velocity_weights must be non-empty, in [0, 1]")
        if 0 < self.de_warm_popsize < 5:
            raise ValueError("PotentialConfig.de_warm_popsize must be 0 or >= 5")
        if not (math.isfinite(self.refit_speed_change_rel) and self.refit_speed_change_rel >= 0.0):
            raise ValueError("PotentialConfig.refit_speed_change_rel must be finite and >= 0")
        if not 0.0 < self.calib_forgetting <= 1.0:
            raise ValueError("PotentialConfig.calib_forgetting must be in (0, 1]")
        if not 0.0 < self.weight_floor < 1.0:
            raise ValueError("PotentialConfig.weight_floor must be in (0, 1)")
        if len(self.fix_resolution_m) != 3 or not all(
            math.isfinite(r) and r > 0.0 for r in self.fix_resolution_m
        ):
            raise ValueError("PotentialConfig.fix_resolution_m must be 3 finite values > 0")
        if not 0.0 < self.false_alarm_prob < 1.0:
            raise ValueError("PotentialConfig.false_alarm_prob must be in (0, 1)")
        for name in ("alpha_bounds_ps", "g_bounds_ps2"):
            lo, hi = getattr(self, name)
            if not (np.isfinite(lo) and np.isfinite(hi) and 0.0 < lo < hi):
                raise ValueError(f"PotentialConfig.{name} must satisfy 0 < lo < hi")
        if not self.alpha_bounds_ps[0] <= self.alpha0_ps <= self.alpha_bounds_ps[1]:
            raise ValueError("PotentialConfig.alpha0_ps must lie within alpha_bounds_ps")
        if not self.g_bounds_ps2[0] <= self.g0_ps2 <= self.g_bounds_ps2[1]:
            raise ValueError("PotentialConfig.g0_ps2 must lie within g_bounds_ps2")
        if self.velocity_mode not in ("measured", "carried"):
            raise ValueError("PotentialConfig.velocity_mode must be 'measured' or 'carried'")


# --------------------------------------------------------------------------- results


@dataclass(frozen=True, slots=True)
class FixTest:
    """Result of testing (and possibly adding) a fix.

    ``chi2`` is ``dᵀ S⁻¹ d``, ``S`` the calibrated innovation covariance
    (``PotentialPrediction.innov_cov_ned_m2`` plus any excess of the fix's
    variance over the calibration's fixes'; NaN when not tested), ``threshold``
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
    ``vel_cov_ned_m2ps2`` diagonal (3, 3); ``horizon_s`` = ``t_s`` − newest fix;
    ``innov_cov_ned_m2`` diagonal (3, 3) the covariance of ``fix − prediction``
    for a fix as accurate as the newest (the fix test's ``S``; see
    :meth:`PotentialFilter.test_fix`: with slowly varying fix errors it is far
    smaller than ``cov_ned_m2 + R``);
    ``anchor_var_ned_m2`` (3,) the newest fix's reported variance, the part of
    ``cov_ned_m2`` that any other estimate anchored on the same fixes shares.
    """

    t_s: float
    pos_ned_m: FloatArray
    vel_ned_mps: FloatArray
    cov_ned_m2: FloatArray
    vel_cov_ned_m2ps2: FloatArray
    horizon_s: float
    anchor_var_ned_m2: FloatArray = field(default_factory=lambda: np.zeros(3))
    innov_cov_ned_m2: FloatArray = field(default_factory=lambda: np.zeros((3, 3)))


# position, velocity, position variance, velocity variance (per axis), horizon
# and the calibrated innovation variance q(h) (per axis)
_Raw = tuple[FloatArray, FloatArray, FloatArray, FloatArray, float, FloatArray]
# per (anchor, calibration) constants of a prediction (see _predict_raw)
_PerAnchor = tuple["_Anchor", FloatArray, FloatArray, FloatArray, FloatArray, bool, FloatArray]


class _Window:
    """The fixes acting as sources (oldest first) and the particle's velocity at each.

    Rows ``i0:i1`` of preallocated arrays: appending is O(1) (the rows are moved
    down when the end is reached) and every window quantity is a view.
    """

    __slots__ = (
        "acc2", "i0", "i1", "known", "lag1", "pos", "pvel", "span_i0", "t", "vder", "vder2",
        "vmeas", "wp", "wpx",
    )  # fmt: skip

    def __init__(self, capacity: int) -> None:
        self.t = np.empty(capacity)
        self.pos = np.empty((capacity, 3))
        self.wp = np.empty((capacity, 3))  # 2p [1/m²]: a source's term of A at weight 1
        self.wpx = np.empty((capacity, 3))  # 2p · pos [1/m]: its term of B
        # measured and position-derived velocity (NaN where none: the particle keeps its own)
        self.vmeas = np.empty((capacity, 3))
        self.vder = np.empty((capacity, 3))  # slope of a line (velocity at mid-span)
        self.vder2 = np.empty((capacity, 3))  # slope of a parabola at the newest fix
        self.acc2 = np.zeros((capacity, 3))  # squared acceleration, noise removed [m²/s⁴]
        self.lag1 = np.zeros(capacity)  # age of the line's slope (fix time − span mean) [s]
        self.pvel = np.empty((capacity, 3))
        self.known = np.zeros(capacity, dtype=bool)  # particle velocity known there
        self.i0 = 0
        self.i1 = 0
        self.span_i0 = 0  # first row of the last velocity span (moves forward only)

    def __len__(self) -> int:
        return self.i1 - self.i0

    def append(self, t_s: float, pos: FloatArray, wp: FloatArray) -> int:
        """Add a row (state columns filled by the caller); returns its index."""
        if self.i1 == self.t.size:
            n = self.i1 - self.i0
            if n == self.t.size:
                self.i0 += 1  # full: the oldest goes (the caller's limits prevent this)
                n -= 1
            for arr in (
                self.t,
                self.pos,
                self.wp,
                self.wpx,
                self.vmeas,
                self.vder,
                self.vder2,
                self.acc2,
                self.lag1,
                self.pvel,
                self.known,
            ):
                arr[:n] = arr[self.i0 : self.i1]
            self.span_i0 = max(self.span_i0 - self.i0, 0)
            self.i0, self.i1 = 0, n
        i = self.i1
        self.t[i] = t_s
        self.pos[i] = pos
        self.wp[i] = wp
        self.wpx[i] = wp * pos
        self.i1 = i + 1
        return i


@dataclass(slots=True)
class _Anchor:
    """Particle state right after a fix, the frozen field seen from there, and the
    per-axis constants of its closed-form propagation (see :func:`_make_anchor`).
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


def _make_anchor(
    t_s: float,
    pos: FloatArray,
    vel: FloatArray,
    alpha: float,
    g: float,
    a: FloatArray,
    b: FloatArray,
    vel_known: bool = True,
) -> _Anchor:
    """An anchor with the constants of S0's Bessel form precomputed (pure arithmetic).

    With ``u0 = pos − B/A``, ``s0 = 2√(G A)/α`` and ``s = s0 e^{−αh/2}`` the
    general form of :func:`_mid_form` regroups to

        u(h) = c_y0 Y0(s) + c_j0 J0(s),   u̇(h) = (α/2) (c_y0 s Y1(s) + c_j0 s J1(s)),
        c_y0 = (π s0/2) J1(s0) u0 − (π/α) J0(s0) u̇0,
        c_j0 = (π/α) Y0(s0) u̇0 − (π s0/2) Y1(s0) u0,

    so a prediction costs four Bessel calls on a 3-vector (scipy's between
    ``_X_SMALL`` and ``_X_ASYM``, the series below). Axes whose ``s`` is at or
    above ``_X_ASYM`` (where the Hankel form must difference the phases), α = 0
    or G·A = 0 take the general :func:`propagate_state`.

    References
    ----------
    S0 (SEEDS.md §S0), the constants a1, a2 of the Bessel solution;
    Abramowitz & Stegun 9.1.10-9.1.11, 9.2.28-9.2.31 (via :func:`_bessel_at`).
    """
    if min(a.tolist()) > 0.0:
        centre = b / a
    else:
        has = a > 0.0
        centre = np.where(has, b / np.where(has, a, 1.0), pos)
    ga = g * a
    s0 = c_y0 = c_j0 = _NAN3
    ln_s0: FloatArray | None = None
    ok = alpha > 0.0 and min(ga.tolist()) > 0.0
    if ok:
        s0 = (2.0 / alpha) * np.sqrt(ga)
        s0_list = s0.tolist()
        if _X_SMALL <= min(s0_list) and max(s0_list) < _X_ASYM:
            # ln_s0 stays None: log(s0) only when the series needs it
            j0s0, y0s0 = special.j0(s0), special.y0(s0)
            xj1s0, xy1s0 = s0 * special.j1(s0), s0 * special.y1(s0)
        else:
            # s0 may under- or overflow: from logarithms
            ln_s0 = np.log(2.0 * np.sqrt(ga)) - math.log(alpha)
            s0 = np.exp(ln_s0)
            b0 = _bessel_at(s0, ln_s0)
            j0s0, y0s0, xj1s0, xy1s0 = b0["j0"], b0["y0"], b0["xj1"], b0["xy1"]
        u0h = (0.5 * np.pi) * (pos - centre)
        vk = (np.pi / alpha) * vel
        c_y0 = xj1s0 * u0h - j0s0 * vk
        c_j0 = y0s0 * vk - xy1s0 * u0h
        ok = math.isfinite(float(c_y0.sum() + c_j0.sum()))
    return _Anchor(t_s, pos, vel, alpha, g, a, b, vel_known, centre, s0, ln_s0, c_y0, c_j0, ok)


_LN_X_SMALL = math.log(_X_SMALL)
_SERIES_LG = _EULER_GAMMA - math.log(2.0)


def _anchor_propagate(anc: _Anchor, h_s: float) -> tuple[FloatArray, FloatArray]:
    """Particle position [m] and velocity [m/s] ``h_s`` ≥ 0 after the anchor's fix."""
    if anc.bessel_ok:
        half_ah = 0.5 * anc.alpha_ps * h_s
        s = anc.s0 * math.exp(-half_ah)
        s_list = s.tolist()
        lo, hi = min(s_list), max(s_list)
        if _X_SMALL <= lo and hi < _X_ASYM:
            y0, j0 = special.y0(s), special.j0(s)
            sy1, sj1 = s * special.y1(s), s * special.j1(s)
        elif hi < _X_SMALL:
            # the coasting end: small-argument series in ln s (s may underflow)
            ln_s0 = anc.ln_s0 if anc.ln_s0 is not None else np.log(anc.s0)
            lg = ln_s0 + (_SERIES_LG - half_ah)
            x2 = s * s
            j0 = 1.0 - 0.25 * x2
            y0 = _TWO_OVER_PI * (lg * j0 + 0.25 * x2)
            sj1 = 0.5 * x2
            sy1 = -_TWO_OVER_PI + (x2 / np.pi) * (lg - 0.5)
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


def _white_var(q0: FloatArray, var: FloatArray) -> FloatArray:
    """The part of a fix's variance that is white (not shared with the prediction).

    The innovation ``e = fix − prediction`` has ``Var(e) = P + R − 2C``, ``C``
    the covariance of the prediction's and the fix's errors, which is the
    fix's slowly varying part ``R − r_w`` (the prediction is made of earlier
    fixes that carry it too). The calibration's zero-horizon intercept ``q0``
    is at least ``r_w`` (the new fix's white error plus the prediction's own);
    ``r_w = min(R, q0)`` gives ``P = q(h) + R − 2 r_w``: ``q(h) − R`` for white
    fixes (DGPS-like noise), ``≈ q(h) + R`` for RTK's errors, which barely
    change from fix to fix.
    """
    return np.minimum(var, q0)


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
        self._g = self.config.g0_ps2
        self._beta = max(self.config.velocity_weights)
        self._order = max(self.config.velocity_fit_orders)
        self._threshold = float(stats.chi2.ppf(1.0 - self.config.false_alarm_prob, 3))
        # the rounding variance of a fix's position
        self._innov_floor = np.asarray(self.config.fix_resolution_m, dtype=np.float64) ** 2 / 12.0
        self._ln_floor = math.log(self.config.weight_floor)
        self.rejections: dict[str, int] = {}
        self.fit_count = 0
        self.inconsistency_refits = 0  # fits run by a first inconsistent fix
        self.last_fit_cost_m2: float | None = None
        self._reset_state()

    # ----------------------------------------------------------------- state

    def _reset_state(self) -> None:
        self._win = _Window(2 * (self.config.max_sources + 1))
        self._anchor: _Anchor | None = None
        # binned residual sums: count, Σh, Σe² (3), Σσ²_fix (3) per horizon bin
        self._bins: FloatArray | None = None
        self._q: FloatArray | None = None  # (3, 3): rows q_pos, q_vel, q_acc; cols axes
        self._q_dirty = True
        self._r_cal: FloatArray | None = None  # mean fix variance behind the calibration
        # per (anchor, calibration): truth offset, manoeuvre a², λ, λ used, and
        # the newest fix's variance over the calibration's fixes'
        self._pc: _PerAnchor | None = None
        self._last_fit_t: float | None = None
        self._last_fit_speed: float | None = None  # particle speed at the last fit [m/s]
        # after a restart the model is suspect: no fix is tested until it is refitted
        self._await_fit = False
        self._last_fit_x: FloatArray | None = None  # (log10 α, log10 G) of the last fit
        self._inconsistent_run = 0
        self._pending: list[tuple[float, FloatArray, FloatArray, FloatArray]] = []
        self._vel_known = np.zeros(3, dtype=bool)
        self._all_known = False
        self._last_var: FloatArray = np.ones(3)
        # the last prediction (anchor, time, coefficients) -> result: the engine
        # predicts at a fix's time, then adds the fix, which tests it there
        self._memo: tuple[_Anchor, float, FloatArray, _Raw] | None = None

    def reset(self) -> None:
        """Forget every fix and the particle (α and G are kept)."""
        self._reset_state()

    @property
    def alpha_ps(self) -> float:
        """Current dissipation rate α [1/s]."""
        return self._alpha

    @property
    def g_ps2(self) -> float:
        """Current coupling G [1/s²] (with the weights relative to the newest fix's)."""
        return self._g

    @property
    def g_m2ps2(self) -> float:
        """Former name of :attr:`g_ps2` (G is in 1/s² since the weights are relative)."""
        return self._g

    @property
    def velocity_weight(self) -> float:
        """Weight of the fix's measured velocity against the position-derived one [-]."""
        return self._beta

    @property
    def velocity_fit_order(self) -> int:
        """Order (1 line, 2 parabola) of the position-derived velocity in use."""
        return self._order

    @property
    def threshold(self) -> float:
        """χ²(3) threshold of the fix test."""
        return self._threshold

    @property
    def t_last_s(self) -> float | None:
        """Time of the newest accepted fix [s], None before the first."""
        return self._anchor.t_s if self._anchor is not None else None

    @property
    def n_sources(self) -> int:
        """Number of fixes currently acting as sources."""
        return len(self._win)

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
        """True when the predicted covariance comes from the filter's own residuals.

        False before the first fit and, after a restart, until the restarted
        window is refitted: the calibration belonged to the model the restart
        declared wrong, so the prediction carries the prior covariance and
        no fix is tested against it (by the filter or, through this flag, by
        the caller).
        """
        return self._bins is not None and not self._await_fit

    def _prior_q(self) -> FloatArray:
        c = self.config
        return np.vstack(
            [
                np.zeros(3),
                np.full(3, c.prior_vel_sigma_mps**2),
                np.full(3, c.prior_acc_sigma_mps2**2),
            ]
        )

    def _manoeuvre(self) -> tuple[FloatArray, FloatArray, bool]:
        """The manoeuvre term's ``a²`` [m²/s⁴] and ``λ`` [s] (per axis) at the newest fix.

        Coasting ``h`` through the current acceleration ``a`` with a velocity
        ``λ`` seconds old errs by ``|a| (λ h + h²/2)``; the prediction's
        variance gets its square. ``a²`` is the newest fix's parabola estimate
        less its noise variance; ``λ`` is the line's age where the line's slope
        is used (weighted by ``1 − β`` on axes the receiver measures), 0 for
        the parabola's slope. ``h`` is capped at ``velocity_span_s``: the
        acceleration is known over the span it was measured on, not beyond
        (longer horizons are the calibration's ``q_acc h⁴/4``).
        """
        w = self._win
        i = w.i1 - 1
        if i < w.i0:
            return _ZERO3, _ZERO3, False
        if self._order == 1:
            lam = w.lag1[i] * np.where(np.isnan(w.vmeas[i]), 1.0, 1.0 - self._beta)
            return w.acc2[i].copy(), lam, True
        return w.acc2[i].copy(), _ZERO3, False

    def _innov_var(self, qh: FloatArray, var: FloatArray) -> FloatArray:
        """Variance of ``fix − prediction`` for a fix of variance ``var`` (per axis).

        The calibrated ``q(h)`` is the mean squared difference between the
        fixes and the predictions: it already holds whatever part of the fixes'
        error does not cancel between fixes (all of it for white errors, almost
        none for RTK's slowly varying ones). A fix reported less accurate than
        the calibration's fixes adds the difference; the rounding of the
        positions (``fix_resolution_m``) sets the floor. Before calibration:
        ``P + R``.
        """
        r_cal = self._r_cal
        if r_cal is None:
            return qh + self._last_var + var
        pc = self._pc
        if pc is not None and (var is self._last_var or var.tolist() == self._last_var.tolist()):
            excess = pc[6]  # the same accuracy as the newest fix
        else:
            excess = np.maximum(var - r_cal, 0.0)
        return np.maximum(qh + excess, self._innov_floor)

    def _calibrate(self) -> FloatArray:
        """Per-axis ``q_pos, q_vel, q_acc`` (rows) from the binned residual sums."""
        prior = self._prior_q()
        self._r_cal = None
        if self._bins is None or self._await_fit:
            return prior
        cnt_all = self._bins[:, 0]
        used = cnt_all >= 1.0
        if np.count_nonzero(used) < 3:
            return prior
        # mean reported variance of the fixes behind the residuals
        self._r_cal = self._bins[:, 5:8].sum(axis=0) / cnt_all.sum()
        b = self._bins[used]
        cnt = b[:, 0]
        hb = b[:, 1] / cnt
        design = np.column_stack([np.ones(hb.size), hb**2, 0.25 * hb**4])
        q = np.empty((3, 3))
        for k in range(3):
            e2b = b[:, 2 + k] / cnt
            coef = prior[:, k]
            for _ in range(2):
                # sd of a bin mean of e² ∝ E[e²]/√count
                wrow = np.sqrt(cnt) / np.maximum(design @ coef, 1e-12)
                sol, _res = nnls(design * wrow[:, None], e2b * wrow)
                coef = sol
            q[:, k] = coef
        return q

    def _predict_raw(self, t_s: float) -> _Raw:
        """Memoised (pos, vel, var_pos, var_vel, h) at ``t_s`` from the newest anchor."""
        anc = self._anchor
        if anc is None:
            raise ValueError("PotentialFilter.predict: no fix yet")
        q = self._q_coeffs()
        memo = self._memo
        if memo is not None and memo[0] is anc and memo[1] == t_s and memo[2] is q:
            return memo[3]
        h = t_s - anc.t_s
        if not math.isfinite(h) or h < 0.0:
            raise ValueError(f"PotentialFilter.predict: t_s={t_s!r} is before the newest fix")
        pos, vel = _anchor_propagate(anc, h)
        pc = self._pc
        if pc is None or pc[0] is not anc or pc[1] is not q:
            # per anchor and calibration: the truth offset R − 2 r_w (q(h) less
            # the fix's white part, plus the part shared with the fixes; see
            # _white_var) and the manoeuvre term's a² and λ
            man = self._manoeuvre()
            lv = self._last_var
            r_cal = self._r_cal
            excess = _ZERO3 if r_cal is None else np.maximum(lv - r_cal, 0.0)
            pc = self._pc = (anc, q, lv - 2.0 * _white_var(q[0], lv), *man, excess)
        h2 = h * h
        hc = min(h, self.config.velocity_span_s)
        b = pc[4] * hc + 0.5 * hc * hc if pc[5] else 0.5 * hc * hc
        qh = q[0] + h2 * (q[1] + (0.25 * h2) * q[2]) + pc[3] * (b * b)
        var_pos = qh + pc[2]
        var_vel = q[1] + h2 * q[2]
        raw = (pos, vel, var_pos, var_vel, h, qh)
        self._memo = (anc, t_s, q, raw)
        return raw

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
        t = float(t_s)
        pos, vel, var_pos, var_vel, h, qh = self._predict_raw(t)
        return PotentialPrediction(
            t_s=t,
            pos_ned_m=pos.copy(),
            vel_ned_mps=vel.copy(),
            cov_ned_m2=np.diag(var_pos),
            vel_cov_ned_m2ps2=np.diag(var_vel),
            horizon_s=h,
            anchor_var_ned_m2=self._last_var.copy(),
            innov_cov_ned_m2=np.diag(self._innov_var(qh, self._last_var)),
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
        if not math.isfinite(t_s):
            return pos, var, "bad_time"
        px, py, pz = pos.tolist()
        if not (math.isfinite(px) and math.isfinite(py) and math.isfinite(pz)):
            return pos, var, "non_finite_position"
        vx, vy, vz = var.tolist()
        # comparisons with NaN are False: a NaN variance fails here too
        if not (0.0 < vx < math.inf and 0.0 < vy < math.inf and 0.0 < vz < math.inf):
            return pos, var, "bad_variance"
        return pos, var, ""

    def test_fix(self, t_s: float, pos_ned_m: ArrayLike, var_ned_m2: ArrayLike) -> FixTest:
        """χ² (3 dof) test of a fix against the predicted position and its ellipsoid.

        The ellipsoid is the innovation covariance ``S`` (the variance of
        ``fix − prediction`` calibrated from the filter's residuals, see the
        module docstring), not ``cov_ned_m2 + R``: with slowly varying fix
        errors (RTK, DGPS) the prediction shares most of the fix's error, and
        ``cov_ned_m2 + R`` would count it twice (χ² ≈ 0.2 on average on the
        simulator's RTK flight instead of 3).

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
            fewer than ``min_test_fixes`` fixes or its covariance is not
            calibrated (before the first fit, and after a restart until the
            restarted window is refitted).

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
        chi2 = self._chi2(t_s, pos, var)
        if chi2 is None:
            return FixTest(t_s, math.nan, self._threshold, True, False)
        return FixTest(t_s, chi2, self._threshold, chi2 <= self._threshold, True)

    def _chi2(self, t_s: float, pos: FloatArray, var: FloatArray) -> float | None:
        """``dᵀ S⁻¹ d`` at the fix, None while there is nothing to test against."""
        if (
            self._anchor is None
            or self._bins is None
            or self._await_fit
            or len(self._win) < self.config.min_test_fixes
        ):
            # no calibrated covariance yet: the test would only test the prior
            return None
        ppos, _v, _vp, _vv, _h, qh = self._predict_raw(t_s)
        d = pos - ppos
        # S is diagonal: dᵀ S⁻¹ d is a sum
        return float((d * d / self._innov_var(qh, var)).sum())

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
        t_s = float(t_s)
        pos, var, why = self._validate(t_s, pos_ned_m, var_ned_m2)
        thr = self._threshold
        vel = _NAN3
        if not why and vel_ned_mps is not None:
            v = np.asarray(vel_ned_mps, dtype=np.float64)
            if v.shape != (3,) or math.isinf(float(np.abs(v).max())):
                why = "bad_velocity"
            else:
                vel = v
        if not why and self._anchor is not None and t_s <= self._anchor.t_s:
            why = "time_not_increasing"
        if why:
            self._reject(why, t_s)
            return FixTest(t_s, float("nan"), thr, False, False, False, why)

        chi2_or_none = self._chi2(t_s, pos, var)
        if (
            chi2_or_none is not None
            and chi2_or_none > thr
            and not force
            and self._inconsistent_run == 0
            and self._refit_allowed()
        ):
            # The first inconsistent fix of a run: the model may be the one at
            # fault (a turn or an acceleration begins). Refit on the window and
            # test the fix again before rejecting it.
            if self.refit(force=True) is not None:
                self.inconsistency_refits += 1
                chi2_or_none = self._chi2(t_s, pos, var)
        tested = chi2_or_none is not None
        chi2 = chi2_or_none if chi2_or_none is not None else math.nan
        consistent = not tested or chi2 <= thr
        if not consistent and not force:
            self._inconsistent_run += 1
            if self._inconsistent_run <= self.config.max_consecutive_inconsistent:
                self._pending.append((t_s, pos, var, vel))
                self._reject("inconsistent", t_s)
                return FixTest(t_s, chi2, thr, False, True, False, "inconsistent")
            _log.warning(
                "potential: %d consecutive inconsistent fixes: restarting at t=%.3f s",
                self._inconsistent_run,
                t_s,
            )
            self.rejections["restart"] = self.rejections.get("restart", 0) + 1
            # The model, not the fixes, is taken to be wrong: restart the field
            # and the particle from the run of inconsistent fixes (they agree
            # with each other), keeping α, G and the covariance calibration
            # as the fit's warm start. The suspect model tests no fix until it
            # is refitted, which is due as soon as the restarted window spans
            # first_fit_span_s: a restart cannot lead to another restart
            # before a fit (no restart loop).
            pending = self._pending
            kept = (self._bins, self._q, self._last_fit_x)
            self._reset_state()
            self._bins, self._q, self._last_fit_x = kept
            self._q_dirty = True
            self._await_fit = True
            # until then the particle takes the least-lagging velocities: the
            # receiver's where it gives one, the parabola's slope elsewhere
            self._beta = max(self.config.velocity_weights)
            self._order = max(self.config.velocity_fit_orders)
            # and a field no stiffer than the configured one (a stiff field
            # fitted while parked would hold the restarted particle back; the
            # position update ties a weak one to the fixes)
            self._g = min(self._g, self.config.g0_ps2)
            for tp, pp, vp, vv in pending:
                self._accept(tp, pp, vp, vv)
        self._inconsistent_run = 0
        self._pending = []
        self._accept(t_s, pos, var, vel)
        if refit:
            self.refit()
        return FixTest(t_s, chi2, thr, consistent, tested, True, "")

    def _derived_velocity(
        self, t_s: float, var: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray, float]:
        """Least-squares velocities through the window's fixes of the last
        ``velocity_span_s`` (the newest, just appended, included): the slope of a
        line and the slope at ``t_s`` of a parabola (the line's where fewer than
        four fixes or a span shorter than ``_PARABOLA_MIN_SPAN`` of
        ``velocity_span_s``); the parabola's squared acceleration less its noise variance
        (``var`` the fixes' per-axis variance; 0 where that is negative) [m²/s⁴];
        the age of the line's slope, ``t_s`` − the span's mean time [s]."""
        w = self._win
        # first row within the span: moves forward only (rows never go back)
        j = max(w.span_i0, w.i0)
        t_lo = t_s - self.config.velocity_span_s - 1e-9
        while w.t[j] < t_lo:
            j += 1
        w.span_i0 = j
        tt = w.t[j : w.i1]
        pp = w.pos[j : w.i1]
        n = tt.size
        tc = tt - tt.sum() / n
        den = float(tc @ tc)
        if den <= 0.0:
            return _NAN3, _NAN3, _ZERO3, 0.0
        # Σ tc = 0: any offset of the positions cancels; the newest is nearest
        y = pp - pp[-1]
        lin = (tc @ y) / den
        lag = float(t_s - tt.sum() / n)
        if n < 4 or tt[-1] - tt[0] < _PARABOLA_MIN_SPAN * self.config.velocity_span_s:
            # a parabola through a short span (after a restart, a gap) is noise
            return lin, lin, _ZERO3, lag
        # parabola y = c0 + c1 x + c2 x², x = t − t_s: c1 is the velocity at t_s
        x = tt - t_s
        x2 = x * x
        s0, s1, s2 = float(n), float(x.sum()), float(x2.sum())
        s3, s4 = float(x2 @ x), float(x2 @ x2)
        # inverse of the symmetric normal matrix [[s0 s1 s2] [s1 s2 s3] [s2 s3 s4]]
        # by cofactors (rows 1 and 2 are needed: the slope and the curvature)
        c00 = s2 * s4 - s3 * s3
        c01 = s2 * s3 - s1 * s4
        c02 = s1 * s3 - s2 * s2
        det = s0 * c00 + s1 * c01 + s2 * c02
        if not det > 0.0:
            return lin, lin, _ZERO3, lag
        c11 = s0 * s4 - s2 * s2
        c12 = s1 * s2 - s0 * s3
        c22 = s0 * s2 - s1 * s1
        r0, r1, r2 = y.sum(axis=0), x @ y, x2 @ y
        vel = (c01 * r0 + c11 * r1 + c12 * r2) / det
        acc = 2.0 * (c02 * r0 + c12 * r1 + c22 * r2) / det
        acc2 = np.maximum(acc * acc - (4.0 * c22 / det) * var, 0.0)
        return lin, vel, acc2, lag

    def _accept(self, t_s: float, pos: FloatArray, var: FloatArray, vel: FloatArray) -> None:
        c = self.config
        anc = self._anchor
        all_known = self._all_known
        if anc is not None:
            ppos, pvel, vp, _vv, _h, _qh = self._predict_raw(t_s)
            if c.position_update:
                ppos = ppos + (vp / (vp + var)) * (pos - ppos)
            if not all_known:
                # axes whose velocity was still unknown: the particle starts here
                ppos = np.where(self._vel_known, ppos, pos)
        else:
            ppos, pvel = pos.copy(), np.zeros(3)
        w = self._win
        i = w.append(t_s, pos, 2.0 / var)
        if c.velocity_mode == "measured" or not all_known:
            der, der2, acc2, lag1 = self._derived_velocity(t_s, var)
            w.acc2[i] = acc2
            w.lag1[i] = lag1
            reset = _reset_velocity3(vel, der if self._order == 1 else der2, self._beta)
            w.vmeas[i] = vel
            w.vder[i] = der
            w.vder2[i] = der2
            r0, r1, r2 = reset.tolist()
            if math.isnan(r0) or math.isnan(r1) or math.isnan(r2):
                unset = np.isnan(reset)
                self._vel_known = self._vel_known | ~unset
                pvel = np.where(unset, pvel, reset)
            else:
                self._vel_known = np.ones(3, dtype=bool)
                pvel = reset
            all_known = all(self._vel_known.tolist())
            self._all_known = all_known
            if not all_known:
                pvel = np.where(self._vel_known, pvel, 0.0)  # placeholder until known
        else:
            w.vmeas[i] = _NAN3
            w.vder[i] = _NAN3
            w.vder2[i] = _NAN3
            w.acc2[i] = _ZERO3
            w.lag1[i] = 0.0
        w.pvel[i] = pvel
        w.known[i] = all_known
        self._last_var = var
        self._drop_old(t_s)
        a, b = self._sums(t_s)
        self._anchor = _make_anchor(t_s, ppos, pvel, self._alpha, self._g, a, b, all_known)

    def _drop_old(self, t_s: float) -> None:
        c = self.config
        w = self._win
        while w.i1 > w.i0 and (w.i1 - w.i0 > c.max_sources or t_s - w.t[w.i0] > c.window_s):
            w.i0 += 1

    def _sums(self, t0_s: float) -> tuple[FloatArray, FloatArray]:
        w = self._win
        sl = slice(w.i0, w.i1)
        # field_sums() on the window's rows (2p and 2p·pos kept per row)
        wt = np.exp(self._alpha * (w.t[sl] - t0_s))
        if self._alpha * (w.t[w.i0] - t0_s) < self._ln_floor:
            wt *= wt >= self.config.weight_floor
        # relative weights σ²_ref/σ²_i, σ_ref the newest source's (module docstring)
        ref = self._last_var
        return (wt @ w.wp[sl]) * ref, (wt @ w.wpx[sl]) * ref

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
        gain: FloatArray | None,
    ) -> None:
        """Add the fitted model's gap-prediction residuals over the window to the bins."""
        c = self.config
        apos, avel, aa, bb = replay_anchors(alpha, g, t, pos, p, vreset, p0, v0, gain)
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
        self, beta: float, order: int
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        # the replay starts at the oldest fix where the particle's velocity was known
        w = self._win
        known = w.known[w.i0 : w.i1]
        k0 = int(np.argmax(known)) if known.any() else 0
        i = w.i0 + k0
        sl = slice(i, w.i1)
        t = w.t[sl].copy()
        pos = w.pos[sl].copy()
        p = 0.5 * w.wp[sl]
        vreset = reset_velocity(w.vmeas[sl], (w.vder if order == 1 else w.vder2)[sl], beta)
        p0 = pos[0]
        v0 = w.pvel[i].copy() if w.known[i] else np.nan_to_num(vreset[0])
        return t, pos, p, vreset, p0, v0

    def _pos_gains(self, t: FloatArray, p: FloatArray) -> FloatArray | None:
        """Per-fix, per-axis gains ``P/(P + R)`` of the position update in a replay.

        ``P`` is the predicted variance one fix interval ahead of the previous
        fix (the covariance model of :meth:`predict` with the current
        coefficients), ``R = 1/p`` the fix's variance; row 0 is unused (0).
        """
        if not self.config.position_update:
            return None
        q = self._q_coeffs()
        var = 1.0 / p
        h2 = np.diff(t)[:, None] ** 2
        pp = (q[0] + var[:-1] - 2.0 * _white_var(q[0], var[:-1])) + h2 * (q[1] + (0.25 * h2) * q[2])
        gain = np.zeros_like(var)
        gain[1:] = pp / (pp + var[1:])
        return gain

    def refit(self, *, force: bool = False) -> tuple[float, float] | None:
        """Fit α and G on the window if a fit is due (or ``force``).

        Runs bounded, seeded, warm-started differential evolution on
        :func:`replay_cost` in ``(log10 α, log10 G)``; the particle then takes
        the replayed state at the newest fix.

        The first fit seeds ``2·de_popsize`` members: the current values, the
        best quarter of a coarse log grid and uniform draws. Later fits are
        warm-started with ``de_warm_popsize`` members: the last solution, the
        grid's best (so that a narrow valley elsewhere is still seeded) and
        draws around the last solution (normal, ``de_warm_spread_dex`` decades).

        Returns
        -------
        (alpha_ps, g_ps2) or None
            The new values, or None when no fit was due or possible.

        References
        ----------
        S0 (SEEDS.md §S0, self-learning).
        """
        c = self.config
        anc = self._anchor
        if len(self._win) < c.min_fit_fixes or anc is None:
            return None
        t_new = anc.t_s
        if not force and self._last_fit_t is not None:
            since = t_new - self._last_fit_t
            if since < c.refit_interval_s and not (
                since >= c.refit_min_interval_s and self._speed_changed(anc)
            ):
                return None
        w = self._win
        if not force and w.t[w.i1 - 1] - w.t[w.i0] < min(c.refit_interval_s, c.first_fit_span_s):
            return None
        t, pos, p, vreset, p0, v0 = self._window_arrays(self._beta, self._order)
        if t.size < c.min_fit_fixes:
            return None
        gain = self._pos_gains(t, p)
        lo = np.log10([c.alpha_bounds_ps[0], c.g_bounds_ps2[0]])
        hi = np.log10([c.alpha_bounds_ps[1], c.g_bounds_ps2[1]])
        x0 = np.clip(np.log10([self._alpha, self._g]), lo, hi)

        pairs = fit_pairs(t, c.fit_horizons_s, c.fit_start_every_s)

        def cost(x: FloatArray) -> FloatArray:
            xx = np.asarray(x, dtype=np.float64).reshape(2, -1)
            out = replay_cost(10.0 ** xx[0], 10.0 ** xx[1], t, pos, p, vreset, p0, v0, pairs, gain)
            return out if np.ndim(x) > 1 else out[0]

        rng = np.random.default_rng(c.seed + self.fit_count)
        init = self._initial_population(cost, x0, lo, hi, rng)
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
        self._await_fit = False
        self._q_dirty = True
        self._last_fit_x = np.asarray(res.x, dtype=np.float64).copy()
        alpha, g = (float(v) for v in 10.0 ** np.asarray(res.x))
        self.last_fit_cost_m2 = float(res.fun)
        self._alpha, self._g = alpha, g
        if c.velocity_mode == "measured" and (
            len(c.velocity_weights) > 1 or len(c.velocity_fit_orders) > 1
        ):
            # the weight of the measured velocity against the position-derived one
            # and the order of the latter: the candidate pair whose window
            # predictions fit best (same objective)
            best, best_bo, best_vr = math.inf, (self._beta, self._order), vreset
            for order in c.velocity_fit_orders:
                for beta in c.velocity_weights:
                    if (beta, order) == (self._beta, self._order):
                        vr = vreset
                    else:
                        vr = self._window_arrays(beta, order)[3]
                    cb = float(
                        replay_cost(
                            np.array([alpha]), np.array([g]), t, pos, p, vr, p0, v0, pairs, gain
                        )[0]
                    )
                    if cb < best:
                        best, best_bo, best_vr = cb, (beta, order), vr
            (self._beta, self._order), vreset = best_bo, best_vr
        if c.adopt_replay_state:
            # the fitted model's own trajectory: replayed state at the newest fix
            ppos, pvel = replay_state(alpha, g, t, pos, p, vreset, p0, v0, gain)
        else:
            # the carried particle continues; only the field changes
            ppos, pvel = anc.pos_ned_m, anc.vel_ned_mps
        w.pvel[w.i1 - 1] = pvel
        w.known[w.i1 - 1] = True
        a, b = self._sums(t_new)
        self._anchor = _make_anchor(t_new, ppos, pvel, alpha, g, a, b)
        self._last_fit_speed = float(np.linalg.norm(pvel))
        self._update_calibration(alpha, g, t, pos, p, vreset, p0, v0, gain)
        _log.debug("potential: fit %d alpha=%.4g 1/s G=%.4g 1/s2", self.fit_count, alpha, g)
        return alpha, g

    def _refit_allowed(self) -> bool:
        """True when ``refit_min_interval_s`` of fix time has passed since the last fit."""
        anc = self._anchor
        if anc is None or self._last_fit_t is None:
            return anc is not None
        return anc.t_s - self._last_fit_t >= self.config.refit_min_interval_s

    def _speed_changed(self, anc: _Anchor) -> bool:
        """True when the particle's speed left the band around its speed at the last fit."""
        v_fit = self._last_fit_speed
        if v_fit is None or not anc.vel_known:
            return False
        c = self.config
        v = math.sqrt(float(anc.vel_ned_mps @ anc.vel_ned_mps))
        return abs(v - v_fit) > c.refit_speed_change_mps + c.refit_speed_change_rel * v_fit

    def _initial_population(
        self,
        cost: Callable[[FloatArray], FloatArray],
        x0: FloatArray,
        lo: FloatArray,
        hi: FloatArray,
        rng: np.random.Generator,
    ) -> FloatArray:
        """Initial DE population in ``(log10 α, log10 G)`` (rows), warm start first."""
        c = self.config

        def grid_best(n_best: int) -> FloatArray:
            # the best of a coarse log grid (one vectorised replay): seeds a
            # narrow global valley even when the warm start sits in another basin
            ga_ = np.linspace(lo[0], hi[0], c.de_grid_points)
            gg_ = np.linspace(lo[1], hi[1], c.de_grid_points)
            grid = np.array(np.meshgrid(ga_, gg_)).reshape(2, -1)
            order = np.argsort(cost(grid), kind="stable")
            return np.asarray(grid[:, order[:n_best]].T)

        last = self._last_fit_x
        if last is not None and c.de_warm_popsize > 0:
            # warm: the last solution, the grid's best and draws around the last
            n_pop = c.de_warm_popsize
            x_last = np.clip(last, lo, hi)
            best = grid_best(max(1, n_pop // 4))
            around = x_last + rng.normal(0.0, c.de_warm_spread_dex, size=(n_pop - 1 - len(best), 2))
            return np.vstack([x_last, best, np.clip(around, lo, hi)])
        n_pop = 2 * c.de_popsize
        n_best = max(1, n_pop // 4)
        return np.vstack([x0, grid_best(n_best), rng.uniform(lo, hi, size=(n_pop - 1 - n_best, 2))])

    def outputs(self, t_s: float) -> list[NamedValue]:
        """The fitted α [1/s] and G [1/s²] as NAMED_VALUE_FLOAT ``CMP_PALPHA``, ``CMP_PG``."""
        return [NamedValue(t_s, NAME_ALPHA, self._alpha), NamedValue(t_s, NAME_G, self._g)]


# --------------------------------------------------------------------------- replay (fit)


@dataclass(frozen=True, slots=True)
class _Replay:
    """One replay of the window for ``P`` candidate (α, G) (fix index first).

    ``cost`` (P,) [m²]; ``pos``, ``vel`` (n, P, 3): the particle right after each
    fix (carried position, velocity after the reset); ``a``, ``b`` (n, P, 3): the
    field sums with the origin at each fix, that fix included.
    """

    cost: FloatArray
    pos: FloatArray
    vel: FloatArray
    a: FloatArray
    b: FloatArray


def _replay(
    alpha_ps: ArrayLike,
    g_ps2: ArrayLike,
    t_s: FloatArray,
    pos_m: FloatArray,
    p_pm2: FloatArray,
    vel_reset_mps: FloatArray,
    pos0_m: FloatArray,
    vel0_mps: FloatArray,
    pairs: tuple[IntArray, IntArray] | None = None,
    pos_gain: FloatArray | None = None,
) -> _Replay:
    """The replay behind :func:`replay_cost`, :func:`replay_state` and :func:`replay_anchors`.

    The field sums follow the recursion ``A_i = e^{−α(t_i − t_{i−1})} A_{i−1} + 2 p_i``
    (and likewise ``B``): every source of the window counts, none is floored
    (the filter's ``weight_floor`` drops contributions below 1e-12 of a
    source's weight: immaterial here). The transition matrices of all steps and
    candidates depend only on (α, G, A_i, Δt_i), so they come from one
    vectorised :func:`_transition_core` call; only the 2 × 2 recursion of the
    particle runs fix by fix.

    References
    ----------
    S0 (SEEDS.md §S0, self-learning).
    """
    al = np.asarray(alpha_ps, dtype=np.float64).reshape(1, -1, 1)  # (1, P, 1)
    g = np.asarray(g_ps2, dtype=np.float64).reshape(1, -1, 1)
    npop = al.shape[1]
    n = t_s.size
    wp = 2.0 * np.asarray(p_pm2, dtype=np.float64)  # (n, 3)
    wpx = wp * pos_m
    a = np.empty((n, npop, 3))
    b = np.empty((n, npop, 3))
    a[0] = wp[0]
    b[0] = wpx[0]
    dt = np.diff(t_s)
    decay = np.exp(-al[0] * dt[None, :]).T[:, :, None]  # (n-1, P, 1)
    for i in range(1, n):
        np.multiply(decay[i - 1], a[i - 1], out=a[i])
        a[i] += wp[i]
        np.multiply(decay[i - 1], b[i - 1], out=b[i])
        b[i] += wpx[i]
    # relative weights: the sums at fix i in units of that fix's own weight
    # (σ²_ref = σ²_i per axis), so that G·A does not scale with 1/σ²
    inv = 1.0 / np.asarray(p_pm2, dtype=np.float64)[:, None, :]  # (n, 1, 3)
    a *= inv
    b *= inv
    centre = b / a
    ppos_all = np.empty((n, npop, 3))
    pred_all = np.empty((n, npop, 3))  # carried, before the position update
    pvel_all = np.empty((n, npop, 3))
    ppos = np.broadcast_to(np.asarray(pos0_m, dtype=np.float64), (npop, 3)).copy()
    pvel = np.broadcast_to(np.asarray(vel0_mps, dtype=np.float64), (npop, 3)).copy()
    ppos_all[0] = ppos
    pred_all[0] = ppos
    pvel_all[0] = pvel
    if n > 1:
        ga = g * a[:-1]  # (n-1, P, 3): the field of fixes 0..i-1 drives the step i-1 -> i
        w1, w2, w1d, w2d = _transition_core(
            ga, np.broadcast_to(al, ga.shape), np.broadcast_to(dt[:, None, None], ga.shape)
        )
        keep = np.isnan(vel_reset_mps)  # (n, 3): keep the carried velocity
        reset = np.where(keep, 0.0, vel_reset_mps)
        for i in range(1, n):
            c = centre[i - 1]
            u0 = ppos - c
            ppos = c + w1[i - 1] * u0 + w2[i - 1] * pvel
            pred_all[i] = ppos
            if pos_gain is not None:
                ppos = ppos + pos_gain[i] * (pos_m[i] - ppos)
            ud = w1d[i - 1] * u0 + w2d[i - 1] * pvel
            pvel = np.where(keep[i], ud, reset[i])
            ppos_all[i] = ppos
            pvel_all[i] = pvel
    res = pred_all[1:] - pos_m[1:, None, :]
    cost = np.einsum("ipk,ipk->p", res, res)
    if pairs is not None and pairs[0].size:
        # gap predictions: from the particle at fix j, field frozen, to fix k
        jj, kk = pairs
        ga = g * a[jj]  # (m, P, 3)
        hh = np.broadcast_to((t_s[kk] - t_s[jj])[:, None, None], ga.shape)
        w1, w2, _w1d, _w2d = _transition_core(ga, np.broadcast_to(al, ga.shape), hh)
        cj = centre[jj]
        pred = cj + w1 * (ppos_all[jj] - cj) + w2 * pvel_all[jj]
        res = pred - pos_m[kk][:, None, :]
        cost = cost + np.einsum("ipk,ipk->p", res, res)
    return _Replay(cost, ppos_all, pvel_all, a, b)


def reset_velocity(vmeas_mps: FloatArray, vder_mps: FloatArray, beta: float) -> FloatArray:
    """Particle velocity taken at fixes: ``β v_meas + (1 − β) v_lsq`` per component.

    Where one of the two is NaN the other is taken; NaN where both are (the
    particle keeps its own velocity there).

    Parameters
    ----------
    vmeas_mps, vder_mps : ndarray, shape (3,) or (n, 3)
        Measured and least-squares (position-derived) velocities [m/s].
    beta : float
        Weight of the measured velocity, in [0, 1].

    Returns
    -------
    ndarray, same shape [m/s]

    References
    ----------
    S0 (SEEDS.md §S0): β = 1 is S0's ``k̇_n``, the fix's velocity.
    """
    both = beta * vmeas_mps + (1.0 - beta) * vder_mps
    return np.where(np.isnan(vder_mps), vmeas_mps, np.where(np.isnan(vmeas_mps), vder_mps, both))


def _reset_velocity3(vmeas: FloatArray, vder: FloatArray, beta: float) -> FloatArray:
    """:func:`reset_velocity` for one fix, in scalars (cheaper on a 3-vector)."""
    out = []
    for m, d in zip(vmeas.tolist(), vder.tolist(), strict=True):
        if math.isnan(d):
            out.append(m)
        elif math.isnan(m):
            out.append(d)
        else:
            out.append(beta * m + (1.0 - beta) * d)
    return np.array(out)


def fit_pairs(
    t_s: FloatArray, horizons_s: tuple[float, ...], start_every_s: float
) -> tuple[IntArray, IntArray]:
    """Fix index pairs ``(j, k)`` of the multi-step terms of the fit objective.

    Starts ``j`` every ``start_every_s`` (the first fix, then the first fix at
    least that much later, ...); for each horizon ``h`` the end ``k`` is the
    first fix at or after ``t_j + h`` (pairs past the last fix are dropped).

    Parameters
    ----------
    t_s : ndarray, shape (n,)
        Fix times, increasing [s].
    horizons_s : tuple of float
        Prediction horizons [s].
    start_every_s : float
        Spacing of the start fixes [s].

    Returns
    -------
    jj, kk : ndarray of int
    """
    if not horizons_s or t_s.size < 2:
        return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)
    grid = np.arange(t_s[0], t_s[-1], start_every_s)
    starts = np.unique(np.searchsorted(t_s, grid - 1e-9))
    starts = starts[starts < t_s.size - 1]
    h = np.asarray(horizons_s, dtype=np.float64)
    ends = np.searchsorted(t_s, t_s[starts][:, None] + h[None, :] - 1e-9)  # (S, H)
    jj = np.broadcast_to(starts[:, None], ends.shape).ravel()
    kk = ends.ravel()
    keep = kk < t_s.size
    return jj[keep], kk[keep]


def replay_cost(
    alpha_ps: FloatArray,
    g_ps2: FloatArray,
    t_s: FloatArray,
    pos_m: FloatArray,
    p_pm2: FloatArray,
    vel_reset_mps: FloatArray,
    pos0_m: FloatArray,
    vel0_mps: FloatArray,
    pairs: tuple[IntArray, IntArray] | None = None,
    pos_gain: FloatArray | None = None,
) -> FloatArray:
    """S0's self-learning objective ``Σ_i |r(t_i) − r_0i|²`` for many (α, G) at once.

    The particle starts at ``pos0_m``, ``vel0_mps`` at ``t_s[0]`` and is carried
    from fix to fix through the field of the fixes before it; at each fix its
    velocity components are replaced where ``vel_reset_mps`` is finite. With
    ``pairs`` (fix indices ``j < k``) the objective also sums the squared
    errors of the gap predictions ``r_j→k`` from the particle at fix ``j``
    through the frozen field of fixes ``0..j`` to ``t_k`` (see
    :func:`fit_pairs`).

    Parameters
    ----------
    alpha_ps, g_ps2 : ndarray, shape (P,)
        Candidate α [1/s] and G [1/s²].
    t_s : ndarray, shape (n,)
        Fix times, increasing [s].
    pos_m : ndarray, shape (n, 3)
        Fix positions (NED) [m].
    p_pm2 : ndarray, shape (n, 3)
        Fix weights ``1/σ²`` [1/m²]; at each fix the field uses them relative
        to that fix's own (``A_k`` dimensionless, see :func:`field_sums`).
    vel_reset_mps : ndarray, shape (n, 3)
        Velocity taken by the particle at each fix, NaN to keep its own [m/s].
    pos0_m, vel0_mps : ndarray, shape (3,)
        Particle state at ``t_s[0]``.
    pairs : (ndarray, ndarray) of int, optional
        Start and end fix indices of the gap predictions added to the sum.
    pos_gain : ndarray, shape (n, 3), optional
        Per-axis gain in [0, 1] of the position update at each fix,
        ``r ← r + K (r_0i − r)`` after the carried position is compared with
        the fix (None: the position is only carried, pure S0).

    Returns
    -------
    ndarray, shape (P,)
        Sum of squared position residuals [m²] (``inf`` where not finite).

    References
    ----------
    S0 (SEEDS.md §S0, self-learning: ``f(α, G) = Σ_i |r(t_i) − r_0i|² → min``).
    """
    with np.errstate(over="ignore", invalid="ignore"):
        cost = _replay(
            alpha_ps, g_ps2, t_s, pos_m, p_pm2, vel_reset_mps, pos0_m, vel0_mps, pairs, pos_gain
        ).cost
    return np.where(np.isfinite(cost), cost, np.inf)


def replay_state(
    alpha_ps: float,
    g_ps2: float,
    t_s: FloatArray,
    pos_m: FloatArray,
    p_pm2: FloatArray,
    vel_reset_mps: FloatArray,
    pos0_m: FloatArray,
    vel0_mps: FloatArray,
    pos_gain: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Particle state at the last fix after :func:`replay_cost`'s replay (one α, G).

    Returns
    -------
    pos_ned_m, vel_ned_mps : ndarray, shape (3,)

    References
    ----------
    S0 (SEEDS.md §S0).
    """
    r = _replay(
        alpha_ps, g_ps2, t_s, pos_m, p_pm2, vel_reset_mps, pos0_m, vel0_mps, pos_gain=pos_gain
    )
    return r.pos[-1, 0].copy(), r.vel[-1, 0].copy()


def replay_anchors(
    alpha_ps: float,
    g_ps2: float,
    t_s: FloatArray,
    pos_m: FloatArray,
    p_pm2: FloatArray,
    vel_reset_mps: FloatArray,
    pos0_m: FloatArray,
    vel0_mps: FloatArray,
    pos_gain: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The replay of :func:`replay_cost` (one α, G), keeping the state at every fix.

    Returns
    -------
    pos_ned_m, vel_ned_mps : ndarray, shape (n, 3)
        Particle position (carried) and velocity (after the reset) at each fix.
    a_rel, b_m : ndarray, shape (n, 3)
        Field sums at each fix with the time origin there (that fix included).

    References
    ----------
    S0 (SEEDS.md §S0).
    """
    r = _replay(
        alpha_ps, g_ps2, t_s, pos_m, p_pm2, vel_reset_mps, pos0_m, vel0_mps, pos_gain=pos_gain
    )
    return r.pos[:, 0].copy(), r.vel[:, 0].copy(), r.a[:, 0].copy(), r.b[:, 0].copy()

"""Self-learning of α and G: replay of the fix window and its evolutionary fit.

α and G minimise over the window Grzegorzewski's (2005) objective
``Σ_i |r(t_i) − r_0i|²``: the particle replayed through the window from the
oldest fix's position and the particle's velocity there, the sources added
one by one. Two deviations from the paper: the particle's position is
updated at each fix (``position_update``; with the position only carried,
the particle is tied to the fixes by the field alone, whose centre trails a
moving aircraft, and the fit's only way out, G → 0, lets it drift), and the
objective adds the squared errors of gap predictions from the particle at
fixes every ``fit_start_every_s``, field frozen, over ``fit_horizons_s``
(:func:`fit_pairs`): the one-step sum barely sees the field's pull, which
over a 5-20 s gap moves the prediction by metres.

The optimiser (:func:`fit_alpha_g`) is
:func:`scipy.optimize.differential_evolution` in ``(log10 α, log10 G)``:
bounded, seeded (``seed + fit count``), vectorised over the population (all
transition matrices of a replay in one call, the particle's 2 × 2 recursion
fix by fix). The first fit seeds its population with the best quarter of a
coarse log grid, later ones are warm-started (the last solution, the grid's
best, draws around the last). With the same objective :func:`choose_velocity`
picks the weight β of the receiver's velocity and the order of the
least-squares one (precise RTK positions make the slope better than a
receiver's velocity; DGPS-level positions the reverse).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numpy.typing import ArrayLike
from scipy.optimize import OptimizeResult, differential_evolution

from companion.nav.potential.bessel import transition_core
from companion.nav.potential.config import PotentialConfig
from companion.types import FloatArray

IntArray = npt.NDArray[np.intp]


# --------------------------------------------------------------------------- replay


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
    vectorised :func:`transition_core` call; only the 2 × 2 recursion of the
    particle runs fix by fix.

    References
    ----------
    Grzegorzewski (2005), self-learning.
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
        w1, w2, w1d, w2d = transition_core(
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
        w1, w2, _w1d, _w2d = transition_core(ga, np.broadcast_to(al, ga.shape), hh)
        cj = centre[jj]
        pred = cj + w1 * (ppos_all[jj] - cj) + w2 * pvel_all[jj]
        res = pred - pos_m[kk][:, None, :]
        cost = cost + np.einsum("ipk,ipk->p", res, res)
    return _Replay(cost, ppos_all, pvel_all, a, b)


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
    """The paper's self-learning objective ``Σ_i |r(t_i) − r_0i|²`` for many (α, G) at once.

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
        the fix (None: the position is only carried, as in the paper).

    Returns
    -------
    ndarray, shape (P,)
        Sum of squared position residuals [m²] (``inf`` where not finite).

    References
    ----------
    Grzegorzewski (2005), self-learning: ``f(α, G) = Σ_i |r(t_i) − r_0i|² → min``.
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
    Grzegorzewski (2005).
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
    Grzegorzewski (2005).
    """
    r = _replay(
        alpha_ps, g_ps2, t_s, pos_m, p_pm2, vel_reset_mps, pos0_m, vel0_mps, pos_gain=pos_gain
    )
    return r.pos[:, 0].copy(), r.vel[:, 0].copy(), r.a[:, 0].copy(), r.b[:, 0].copy()


# --------------------------------------------------------------------------- optimiser


def initial_population(
    config: PotentialConfig,
    cost: Callable[[FloatArray], FloatArray],
    x0: FloatArray,
    last_x: FloatArray | None,
    lo: FloatArray,
    hi: FloatArray,
    rng: np.random.Generator,
) -> FloatArray:
    """Initial DE population in ``(log10 α, log10 G)`` (rows), warm start first.

    The first fit (``last_x`` None, or ``de_warm_popsize`` 0) seeds
    ``2·de_popsize`` members: ``x0``, the best quarter of a coarse log grid and
    uniform draws. Later fits are warm-started with ``de_warm_popsize``
    members: the last solution ``last_x``, the grid's best (so that a narrow
    valley elsewhere is still seeded) and draws around the last solution
    (normal, ``de_warm_spread_dex`` decades).
    """
    c = config

    def grid_best(n_best: int) -> FloatArray:
        # the best of a coarse log grid (one vectorised replay): seeds a
        # narrow global valley even when the warm start sits in another basin
        ga_ = np.linspace(lo[0], hi[0], c.de_grid_points)
        gg_ = np.linspace(lo[1], hi[1], c.de_grid_points)
        grid = np.array(np.meshgrid(ga_, gg_)).reshape(2, -1)
        order = np.argsort(cost(grid), kind="stable")
        return np.asarray(grid[:, order[:n_best]].T)

    last = last_x
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


def fit_alpha_g(
    config: PotentialConfig,
    alpha_ps: float,
    g_ps2: float,
    last_x: FloatArray | None,
    fit_count: int,
    t: FloatArray,
    pos: FloatArray,
    p: FloatArray,
    vreset: FloatArray,
    p0: FloatArray,
    v0: FloatArray,
    pairs: tuple[IntArray, IntArray],
    gain: FloatArray | None,
) -> OptimizeResult:
    """Differential evolution of :func:`replay_cost` in ``(log10 α, log10 G)``.

    Parameters
    ----------
    config : PotentialConfig
        Bounds and optimiser settings.
    alpha_ps, g_ps2 : float
        Current α [1/s] and G [1/s²] (the first fit's starting member).
    last_x : ndarray, shape (2,), or None
        ``(log10 α, log10 G)`` of the last fit, the warm start.
    fit_count : int
        Fits so far: the seed is ``config.seed + fit_count``.
    t, pos, p, vreset, p0, v0, pairs, gain
        The window's replay inputs (:func:`replay_cost`).

    Returns
    -------
    scipy.optimize.OptimizeResult
        ``x`` the solution in ``(log10 α, log10 G)``, ``fun`` its cost [m²].

    References
    ----------
    Grzegorzewski (2005), self-learning.
    """
    c = config
    lo = np.log10([c.alpha_bounds_ps[0], c.g_bounds_ps2[0]])
    hi = np.log10([c.alpha_bounds_ps[1], c.g_bounds_ps2[1]])
    x0 = np.clip(np.log10([alpha_ps, g_ps2]), lo, hi)

    def cost(x: FloatArray) -> FloatArray:
        xx = np.asarray(x, dtype=np.float64).reshape(2, -1)
        out = replay_cost(10.0 ** xx[0], 10.0 ** xx[1], t, pos, p, vreset, p0, v0, pairs, gain)
        return out if np.ndim(x) > 1 else out[0]

    rng = np.random.default_rng(c.seed + fit_count)
    init = initial_population(c, cost, x0, last_x, lo, hi, rng)
    return differential_evolution(
        cost,
        bounds=list(zip(lo, hi, strict=True)),
        maxiter=c.de_maxiter,
        tol=c.de_tol,
        seed=c.seed + fit_count,
        polish=False,
        init=init,
        updating="deferred",
        vectorized=True,
    )


def choose_velocity(
    config: PotentialConfig,
    alpha_ps: float,
    g_ps2: float,
    beta: float,
    order: int,
    vreset: FloatArray,
    vreset_for: Callable[[float, int], FloatArray],
    t: FloatArray,
    pos: FloatArray,
    p: FloatArray,
    p0: FloatArray,
    v0: FloatArray,
    pairs: tuple[IntArray, IntArray],
    gain: FloatArray | None,
) -> tuple[float, int, FloatArray]:
    """The (β, order) candidate whose window replay fits best (the fit's objective).

    ``beta``, ``order`` and ``vreset`` are the pair in use and its reset
    velocities; ``vreset_for(beta, order)`` gives another pair's. Returns the
    best β, order and reset velocities (the pair in use on a tie or when no
    cost is finite).
    """
    c = config
    best, best_bo, best_vr = math.inf, (beta, order), vreset
    for order_c in c.velocity_fit_orders:
        for beta_c in c.velocity_weights:
            if (beta_c, order_c) == (beta, order):
                vr = vreset
            else:
                vr = vreset_for(beta_c, order_c)
            cb = float(
                replay_cost(
                    np.array([alpha_ps]), np.array([g_ps2]), t, pos, p, vr, p0, v0, pairs, gain
                )[0]
            )
            if cb < best:
                best, best_bo, best_vr = cb, (beta_c, order_c), vr
    return best_bo[0], best_bo[1], best_vr

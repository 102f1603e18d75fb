"""The position-potential filter: carry the particle, predict, test fixes, refit α and G.

:class:`PotentialFilter` carries the particle from fix to fix through the
field of the fixes it has accepted (:mod:`~companion.nav.potential.window`,
:mod:`~companion.nav.potential.anchor`), predicts with the field frozen and
the covariance of :mod:`~companion.nav.potential.calibration`, tests each new
fix against that prediction and refits α and G on the window
(:mod:`~companion.nav.potential.fit`).

At each fix the particle's carried position (its offset from the fix is
Grzegorzewski's (2005) ``Δk_n``) moves towards the fix by ``K = P/(P + R)``
per axis (``position_update``; P the predicted variance, R the fix's), and
its velocity is reset to the window's estimate there (``velocity_mode``).

The fix test is the paper's χ² consistency test, ``χ² = dᵀ S⁻¹ d`` with 3
degrees of freedom against ``chi2.ppf(1 − false_alarm_prob, 3)``, with ``S``
the calibrated innovation covariance plus the excess of the fix's variance
over the calibration's fixes'. An inconsistent fix is not made a source;
after ``max_consecutive_inconsistent`` of them in a row the filter restarts
from them (the model, not the fixes, is taken to be wrong) with the
least-lagging velocity (largest β and order), a field no stiffer than
``g0_ps2``, and declares itself uncalibrated: no fix is tested and the prior
covariance is used until the restarted window is refitted, which is due as
soon as it spans ``first_fit_span_s``. A restart therefore always leads to a
fit before the next test (no restart loop).

Refits follow :mod:`~companion.nav.potential.schedule`; after a fit the
particle takes the fitted model's replayed state at the newest fix
(``adopt_replay_state``).

Cost: the last prediction is memoised (the engine predicts at a fix's time,
then adds the fix, which tests it there).
"""

from __future__ import annotations

import logging
import math

import numpy as np
from numpy.typing import ArrayLike
from scipy import stats

from companion.nav.potential.anchor import Anchor, anchor_propagate, make_anchor
from companion.nav.potential.calibration import Calibration, position_gains, white_var
from companion.nav.potential.config import PotentialConfig
from companion.nav.potential.fit import choose_velocity, fit_alpha_g, fit_pairs, replay_state
from companion.nav.potential.results import FixTest, PotentialPrediction
from companion.nav.potential.schedule import RefitSchedule
from companion.nav.potential.window import NAN3, ZERO3, Window, reset_velocity3
from companion.types import FloatArray, NamedValue

# one logger for the whole package
_log = logging.getLogger(__package__)

NAME_ALPHA = "CMP_PALPHA"
NAME_G = "CMP_PG"

# position, velocity, position variance, velocity variance (per axis), horizon
# and the calibrated innovation variance q(h) (per axis)
_Raw = tuple[FloatArray, FloatArray, FloatArray, FloatArray, float, FloatArray]
# per (anchor, calibration) constants of a prediction (see _predict_raw)
_PerAnchor = tuple[Anchor, FloatArray, FloatArray, FloatArray, FloatArray, bool, FloatArray]


def _validate(
    t_s: float, pos_ned_m: ArrayLike, var_ned_m2: ArrayLike
) -> tuple[FloatArray, FloatArray, str]:
    """A fix's position and variance as arrays, and why it is malformed ("" if it is not)."""
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


class PotentialFilter:
    """Grzegorzewski's (2005) position-potential filter: carry, predict, self-learn α
    and G, test fixes.

    Pure: no clock, no I/O; time enters only as the fixes' ``t_s``.

    Parameters
    ----------
    config : PotentialConfig

    References
    ----------
    Grzegorzewski (2005).
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
        self._win = Window(2 * (self.config.max_sources + 1))
        self._anchor: Anchor | None = None
        self._cal = Calibration(self.config)
        # per (anchor, calibration): truth offset, manoeuvre a², λ, λ used, and
        # the newest fix's variance over the calibration's fixes'
        self._pc: _PerAnchor | None = None
        self._schedule = RefitSchedule(self.config)
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
        self._memo: tuple[Anchor, float, FloatArray, _Raw] | None = None

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

    @property
    def calibrated(self) -> bool:
        """True when the predicted covariance comes from the filter's own residuals.

        False before the first fit and, after a restart, until the restarted
        window is refitted: the calibration belonged to the model the restart
        declared wrong, so the prediction carries the prior covariance and
        no fix is tested against it (by the filter or, through this flag, by
        the caller).
        """
        return self._cal.bins is not None and not self._await_fit

    def _reject(self, reason: str, t_s: float) -> None:
        self.rejections[reason] = self.rejections.get(reason, 0) + 1
        _log.warning("potential: fix at t=%.3f s rejected: %s", t_s, reason)

    # ----------------------------------------------------------------- prediction

    def _q_coeffs(self) -> FloatArray:
        return self._cal.coeffs(self._await_fit)

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
        r_cal = self._cal.r_cal
        if r_cal is None:
            return qh + self._last_var + var
        pc = self._pc
        if pc is not None and (var is self._last_var or var.tolist() == self._last_var.tolist()):
            excess = pc[6]  # the same accuracy as the newest fix
        else:
            excess = np.maximum(var - r_cal, 0.0)
        return np.maximum(qh + excess, self._innov_floor)

    def _predict_raw(self, t_s: float) -> _Raw:
        """Memoised (pos, vel, var_pos, var_vel, h, q(h)) at ``t_s`` from the newest anchor."""
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
        pos, vel = anchor_propagate(anc, h)
        pc = self._pc
        if pc is None or pc[0] is not anc or pc[1] is not q:
            # per anchor and calibration: the truth offset R − 2 r_w (q(h) less
            # the fix's white part, plus the part shared with the fixes; see
            # white_var) and the manoeuvre term's a² and λ
            man = self._win.manoeuvre(self._order, self._beta)
            lv = self._last_var
            r_cal = self._cal.r_cal
            excess = ZERO3 if r_cal is None else np.maximum(lv - r_cal, 0.0)
            pc = self._pc = (anc, q, lv - 2.0 * white_var(q[0], lv), *man, excess)
        h2 = h * h
        # the acceleration is known over the span it was measured on, not beyond
        # (longer horizons are the calibration's q_acc h⁴/4)
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
        Grzegorzewski (2005); the covariance model is described in
        :mod:`~companion.nav.potential.calibration`.
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

    def test_fix(self, t_s: float, pos_ned_m: ArrayLike, var_ned_m2: ArrayLike) -> FixTest:
        """χ² (3 dof) test of a fix against the predicted position and its ellipsoid.

        The ellipsoid is the innovation covariance ``S`` (the variance of
        ``fix − prediction`` calibrated from the filter's residuals, see
        :mod:`~companion.nav.potential.calibration`), not ``cov_ned_m2 + R``:
        with slowly varying fix errors (RTK, DGPS) the prediction shares most
        of the fix's error, and ``cov_ned_m2 + R`` would count it twice.

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
        Grzegorzewski (2005), error detection.
        """
        pos, var, why = _validate(t_s, pos_ned_m, var_ned_m2)
        if why:
            raise ValueError(f"PotentialFilter.test_fix: {why}")
        t = float(t_s)
        chi2 = self._chi2(t, pos, var)
        if chi2 is None:
            return FixTest(t, math.nan, self._threshold, True, False)
        return FixTest(t, chi2, self._threshold, chi2 <= self._threshold, True)

    def _chi2(self, t_s: float, pos: FloatArray, var: FloatArray) -> float | None:
        """``dᵀ S⁻¹ d`` at the fix, None while there is nothing to test against."""
        if (
            self._anchor is None
            or self._cal.bins is None
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
        Grzegorzewski (2005).
        """
        t_s = float(t_s)
        pos, var, why = _validate(t_s, pos_ned_m, var_ned_m2)
        thr = self._threshold
        vel = NAN3
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
            and self._schedule.allowed(self._anchor)
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
            self._restart(t_s)
        self._inconsistent_run = 0
        self._pending = []
        self._accept(t_s, pos, var, vel)
        if refit:
            self.refit()
        return FixTest(t_s, chi2, thr, consistent, tested, True, "")

    def _restart(self, t_s: float) -> None:
        """Restart the field and the particle from the pending run of inconsistent fixes
        (they agree with each other), keeping α, G and the covariance calibration as
        the fit's warm start; the model is suspect until refitted (module docstring)."""
        _log.warning(
            "potential: %d consecutive inconsistent fixes: restarting at t=%.3f s",
            self._inconsistent_run,
            t_s,
        )
        self.rejections["restart"] = self.rejections.get("restart", 0) + 1
        pending = self._pending
        cal, last_x = self._cal.kept(), self._last_fit_x
        self._reset_state()
        self._cal, self._last_fit_x = cal, last_x
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

    def _accept(self, t_s: float, pos: FloatArray, var: FloatArray, vel: FloatArray) -> None:
        """Carry the particle to the fix, update its position and velocity, add the source."""
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
            der, der2, acc2, lag1 = w.derived_velocity(t_s, c.velocity_span_s, var)
            w.acc2[i] = acc2
            w.lag1[i] = lag1
            reset = reset_velocity3(vel, der if self._order == 1 else der2, self._beta)
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
            w.vmeas[i] = NAN3
            w.vder[i] = NAN3
            w.vder2[i] = NAN3
            w.acc2[i] = ZERO3
            w.lag1[i] = 0.0
        w.pvel[i] = pvel
        w.known[i] = all_known
        self._last_var = var
        w.drop_old(t_s, c.max_sources, c.window_s)
        a, b = self._sums(t_s)
        self._anchor = make_anchor(t_s, ppos, pvel, self._alpha, self._g, a, b, all_known)

    def _sums(self, t0_s: float) -> tuple[FloatArray, FloatArray]:
        """The field sums ``A``, ``B`` of the window at ``t0_s`` with the current α."""
        return self._win.sums(
            t0_s, self._alpha, self._last_var, self.config.weight_floor, self._ln_floor
        )

    # ----------------------------------------------------------------- self-learning

    def refit(self, *, force: bool = False) -> tuple[float, float] | None:
        """Fit α and G on the window if a fit is due (or ``force``).

        Runs bounded, seeded, warm-started differential evolution on
        :func:`~companion.nav.potential.fit.replay_cost` in
        ``(log10 α, log10 G)`` (:func:`~companion.nav.potential.fit.fit_alpha_g`);
        then picks the velocity weight and order with the same objective, and
        the particle takes the replayed state at the newest fix.

        Returns
        -------
        (alpha_ps, g_ps2) or None
            The new values, or None when no fit was due or possible.

        References
        ----------
        Grzegorzewski (2005), self-learning.
        """
        c = self.config
        anc = self._anchor
        if len(self._win) < c.min_fit_fixes or anc is None:
            return None
        t_new = anc.t_s
        w = self._win
        if not force and not self._schedule.due(anc, w.t[w.i1 - 1] - w.t[w.i0]):
            return None
        t, pos, p, vreset, p0, v0 = w.replay_inputs(self._beta, self._order)
        if t.size < c.min_fit_fixes:
            return None
        gain = position_gains(self._q_coeffs(), t, p) if c.position_update else None
        pairs = fit_pairs(t, c.fit_horizons_s, c.fit_start_every_s)
        res = fit_alpha_g(
            c, self._alpha, self._g, self._last_fit_x, self.fit_count,
            t, pos, p, vreset, p0, v0, pairs, gain,
        )  # fmt: skip
        self.fit_count += 1
        self._schedule.last_fit_t = t_new
        self._await_fit = False
        self._cal.dirty = True
        self._last_fit_x = np.asarray(res.x, dtype=np.float64).copy()
        alpha, g = (float(v) for v in 10.0 ** np.asarray(res.x))
        self.last_fit_cost_m2 = float(res.fun)
        self._alpha, self._g = alpha, g
        if c.velocity_mode == "measured" and (
            len(c.velocity_weights) > 1 or len(c.velocity_fit_orders) > 1
        ):
            self._beta, self._order, vreset = choose_velocity(
                c, alpha, g, self._beta, self._order, vreset,
                lambda beta, order: w.replay_inputs(beta, order)[3],
                t, pos, p, p0, v0, pairs, gain,
            )  # fmt: skip
        if c.adopt_replay_state:
            # the fitted model's own trajectory: replayed state at the newest fix
            ppos, pvel = replay_state(alpha, g, t, pos, p, vreset, p0, v0, gain)
        else:
            # the carried particle continues; only the field changes
            ppos, pvel = anc.pos_ned_m, anc.vel_ned_mps
        w.pvel[w.i1 - 1] = pvel
        w.known[w.i1 - 1] = True
        a, b = self._sums(t_new)
        self._anchor = make_anchor(t_new, ppos, pvel, alpha, g, a, b)
        self._schedule.last_fit_speed = float(np.linalg.norm(pvel))
        self._cal.add_residuals(alpha, g, t, pos, p, vreset, p0, v0, gain)
        _log.debug("potential: fit %d alpha=%.4g 1/s G=%.4g 1/s2", self.fit_count, alpha, g)
        return alpha, g

    def outputs(self, t_s: float) -> list[NamedValue]:
        """The fitted α [1/s] and G [1/s²] as NAMED_VALUE_FLOAT ``CMP_PALPHA``, ``CMP_PG``."""
        return [NamedValue(t_s, NAME_ALPHA, self._alpha), NamedValue(t_s, NAME_G, self._g)]

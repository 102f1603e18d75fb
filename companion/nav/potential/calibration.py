"""Covariance of the potential filter's predictions, calibrated on its own residuals.

The fixes' innovations (fix − prediction) are binned by horizon ``h`` and
fitted by ``q(h) = q_pos + q_vel h² + q_acc h⁴/4`` per axis, to which the
filter adds the known error of coasting through the current acceleration
``a``, ``(|a| (λh + h²/2))²`` (``a²`` from the window's parabola less its
noise variance, ``λ`` the age of the velocity used). ``q(h)`` is the variance
of ``fix − prediction``, the fix test's ``S`` (at least the rounding variance
of the fixes' positions, ``fix_resolution_m``). The error against the truth is
``P = q(h) + R − 2 r_w`` with ``r_w = min(R, q_pos)`` the fix's white part
(:func:`white_var`): the prediction is made of earlier fixes and shares their
slowly varying error (RTK and DGPS errors are correlated over tens of
seconds), which the innovations cannot see and ``P`` must carry (``≈ q + R``),
while a white fix error is in ``q`` but not in the prediction (``q − R``).

The residuals come from the fitted model's replay of the window after every
fit: from the particle's state at each fix, the frozen-field prediction to
every later fix in the window (horizons from one fix interval to the window's
span). The binned sums of older fits decay by ``calib_forgetting`` per fit,
and ``mean(e²)`` is regressed on ``[1, h², h⁴/4]`` by non-negative least
squares, each bin weighted by ``√count / model`` (two passes, the first with
the prior). Until the first fit the prior (``prior_vel_sigma_mps``,
``prior_acc_sigma_mps2``) is used.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import nnls

from companion.nav.potential.bessel import propagate_axis
from companion.nav.potential.config import PotentialConfig
from companion.nav.potential.fit import replay_anchors
from companion.types import FloatArray

_CALIB_EDGES_S = np.array(
    [0.0, 0.15, 0.3, 0.6, 1.0, 1.5, 2.0, 3.0, 4.5, 6.5, 9.0, 13.0, 20.0, 30.0, 1e9]
)
"""Horizon bins of the calibration [s]."""


def white_var(q0: FloatArray, var: FloatArray) -> FloatArray:
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


def prior_q(config: PotentialConfig) -> FloatArray:
    """The prior ``q_pos, q_vel, q_acc`` (rows) per axis (columns), before calibration."""
    c = config
    return np.vstack(
        [
            np.zeros(3),
            np.full(3, c.prior_vel_sigma_mps**2),
            np.full(3, c.prior_acc_sigma_mps2**2),
        ]
    )


def position_gains(q: FloatArray, t: FloatArray, p: FloatArray) -> FloatArray:
    """Per-fix, per-axis gains ``P/(P + R)`` of the position update in a replay.

    ``P`` is the predicted variance one fix interval ahead of the previous
    fix (the covariance model with the coefficients ``q``, rows ``q_pos,
    q_vel, q_acc``), ``R = 1/p`` the fix's variance; row 0 is unused (0).
    """
    var = 1.0 / p
    h2 = np.diff(t)[:, None] ** 2
    pp = (q[0] + var[:-1] - 2.0 * white_var(q[0], var[:-1])) + h2 * (q[1] + (0.25 * h2) * q[2])
    gain = np.zeros_like(var)
    gain[1:] = pp / (pp + var[1:])
    return gain


class Calibration:
    """The binned residual sums and the ``q(h)`` coefficients fitted to them.

    ``bins`` (one row per horizon bin): count, Σh, Σe² (3 axes), Σσ²_fix (3
    axes), None before the first fit's residuals; ``q`` (3, 3) the coefficients
    (rows ``q_pos, q_vel, q_acc``, columns the axes), refitted when ``dirty``;
    ``r_cal`` (3,) the mean fix variance behind the calibration, None while
    the prior is in use.
    """

    __slots__ = ("bins", "config", "dirty", "q", "r_cal")

    def __init__(self, config: PotentialConfig) -> None:
        self.config = config
        self.bins: FloatArray | None = None
        self.q: FloatArray | None = None
        self.dirty = True
        self.r_cal: FloatArray | None = None

    def kept(self) -> Calibration:
        """A copy that keeps the sums and coefficients, to be refitted at next use."""
        out = Calibration(self.config)
        out.bins, out.q = self.bins, self.q
        return out

    def coeffs(self, await_fit: bool) -> FloatArray:
        """The coefficients (the prior while ``await_fit``: the model is suspect)."""
        if self.dirty or self.q is None:
            self.q = self._fit(await_fit)
            self.dirty = False
        return self.q

    def _fit(self, await_fit: bool) -> FloatArray:
        """Per-axis ``q_pos, q_vel, q_acc`` (rows) from the binned residual sums."""
        prior = prior_q(self.config)
        self.r_cal = None
        if self.bins is None or await_fit:
            return prior
        cnt_all = self.bins[:, 0]
        used = cnt_all >= 1.0
        if np.count_nonzero(used) < 3:
            return prior
        # mean reported variance of the fixes behind the residuals
        self.r_cal = self.bins[:, 5:8].sum(axis=0) / cnt_all.sum()
        b = self.bins[used]
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

    def add_residuals(
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
        """Add the fitted model's gap-prediction residuals over the window to the bins.

        The arguments are the fit's (:func:`~companion.nav.potential.fit.replay_cost`).
        """
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
        self.bins = new if self.bins is None else c.calib_forgetting * self.bins + new
        self.dirty = True

"""The window of fixes acting as sources, and the particle's velocity at each fix.

The window keeps each fix's position and weight (its terms of the field sums
``A_k``, ``B_k``), the receiver's velocity, the least-squares velocities
through the last ``velocity_span_s`` of fixes (a line's slope, the velocity
at mid-span; a parabola's slope at the newest fix, not late but noisier),
the parabola's squared acceleration and the particle's velocity there.
At a fix the particle takes ``β v_meas + (1 − β) v_lsq``
(:func:`reset_velocity`); Grzegorzewski (2005) takes the fix's velocity
(β = 1), and the least-squares one also gives the components the receiver
does not (GPS_RAW_INT has no vertical velocity).
"""

from __future__ import annotations

import math

import numpy as np

from companion.types import FloatArray

NAN3 = np.full(3, np.nan)
NAN3.setflags(write=False)
ZERO3 = np.zeros(3)
ZERO3.setflags(write=False)
_PARABOLA_MIN_SPAN = 0.75
"""Fraction of velocity_span_s the fixes must span before a parabola is fitted
(its slope's noise grows as span^-1.5)."""


class Window:
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

    def derived_velocity(
        self, t_s: float, span_s: float, var: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray, float]:
        """Least-squares velocities through the fixes of the last ``span_s`` [s]
        (the newest, just appended, included): the slope of a line and the slope
        at ``t_s`` of a parabola (the line's where fewer than four fixes or a span
        shorter than ``_PARABOLA_MIN_SPAN`` of ``span_s``); the parabola's squared
        acceleration less its noise variance (``var`` the fixes' per-axis
        variance; 0 where that is negative) [m²/s⁴]; the age of the line's slope,
        ``t_s`` − the span's mean time [s]."""
        # first row within the span: moves forward only (rows never go back)
        j = max(self.span_i0, self.i0)
        t_lo = t_s - span_s - 1e-9
        while self.t[j] < t_lo:
            j += 1
        self.span_i0 = j
        tt = self.t[j : self.i1]
        pp = self.pos[j : self.i1]
        n = tt.size
        tc = tt - tt.sum() / n
        den = float(tc @ tc)
        if den <= 0.0:
            return NAN3, NAN3, ZERO3, 0.0
        # Σ tc = 0: any offset of the positions cancels; the newest is nearest
        y = pp - pp[-1]
        lin = (tc @ y) / den
        lag = float(t_s - tt.sum() / n)
        if n < 4 or tt[-1] - tt[0] < _PARABOLA_MIN_SPAN * span_s:
            # a parabola through a short span (after a restart, a gap) is noise
            return lin, lin, ZERO3, lag
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
            return lin, lin, ZERO3, lag
        c11 = s0 * s4 - s2 * s2
        c12 = s1 * s2 - s0 * s3
        c22 = s0 * s2 - s1 * s1
        r0, r1, r2 = y.sum(axis=0), x @ y, x2 @ y
        vel = (c01 * r0 + c11 * r1 + c12 * r2) / det
        acc = 2.0 * (c02 * r0 + c12 * r1 + c22 * r2) / det
        acc2 = np.maximum(acc * acc - (4.0 * c22 / det) * var, 0.0)
        return lin, vel, acc2, lag

    def manoeuvre(self, order: int, beta: float) -> tuple[FloatArray, FloatArray, bool]:
        """The manoeuvre term's ``a²`` [m²/s⁴] and ``λ`` [s] (per axis) at the newest fix.

        Coasting ``h`` through the current acceleration ``a`` with a velocity
        ``λ`` seconds old errs by ``|a| (λ h + h²/2)``; the prediction's
        variance gets its square. ``a²`` is the newest fix's parabola estimate
        less its noise variance; ``λ`` is the line's age where the line's slope
        is used (``order`` 1; weighted by ``1 − beta`` on axes the receiver
        measures), 0 for the parabola's slope. The third value says whether
        ``λ`` is used.
        """
        i = self.i1 - 1
        if i < self.i0:
            return ZERO3, ZERO3, False
        if order == 1:
            lam = self.lag1[i] * np.where(np.isnan(self.vmeas[i]), 1.0, 1.0 - beta)
            return self.acc2[i].copy(), lam, True
        return self.acc2[i].copy(), ZERO3, False

    def drop_old(self, t_s: float, max_sources: int, window_s: float) -> None:
        """Drop the oldest rows beyond ``max_sources`` or older than ``window_s`` at ``t_s``."""
        while self.i1 > self.i0 and (
            self.i1 - self.i0 > max_sources or t_s - self.t[self.i0] > window_s
        ):
            self.i0 += 1

    def sums(
        self, t0_s: float, alpha: float, ref: FloatArray, weight_floor: float, ln_floor: float
    ) -> tuple[FloatArray, FloatArray]:
        """:func:`~companion.nav.potential.bessel.field_sums` on the window's rows.

        ``ref`` is the newest source's variance (the weights are relative to it),
        ``ln_floor`` the log of ``weight_floor``.
        """
        sl = slice(self.i0, self.i1)
        # 2p and 2p·pos are kept per row
        wt = np.exp(alpha * (self.t[sl] - t0_s))
        if alpha * (self.t[self.i0] - t0_s) < ln_floor:
            wt *= wt >= weight_floor
        # relative weights σ²_ref/σ²_i, σ_ref the newest source's
        return (wt @ self.wp[sl]) * ref, (wt @ self.wpx[sl]) * ref

    def replay_inputs(
        self, beta: float, order: int
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        """The window as the fit replays it (:func:`~companion.nav.potential.fit.replay_cost`).

        Returns ``t`` (n,), ``pos`` (n, 3), ``p`` (n, 3) [1/m²], the reset
        velocities with weight ``beta`` and fit order ``order`` (n, 3), and the
        particle's position and velocity at the first row, the oldest fix where
        the particle's velocity was known.
        """
        known = self.known[self.i0 : self.i1]
        k0 = int(np.argmax(known)) if known.any() else 0
        i = self.i0 + k0
        sl = slice(i, self.i1)
        t = self.t[sl].copy()
        pos = self.pos[sl].copy()
        p = 0.5 * self.wp[sl]
        vreset = reset_velocity(self.vmeas[sl], (self.vder if order == 1 else self.vder2)[sl], beta)
        p0 = pos[0]
        v0 = self.pvel[i].copy() if self.known[i] else np.nan_to_num(vreset[0])
        return t, pos, p, vreset, p0, v0


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
    Grzegorzewski (2005): β = 1 is the paper's ``k̇_n``, the fix's velocity.
    """
    both = beta * vmeas_mps + (1.0 - beta) * vder_mps
    return np.where(np.isnan(vder_mps), vmeas_mps, np.where(np.isnan(vmeas_mps), vder_mps, both))


def reset_velocity3(vmeas: FloatArray, vder: FloatArray, beta: float) -> FloatArray:
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

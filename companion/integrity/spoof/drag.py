"""One receiver's horizontal velocity against the IMU's: a drag the IMU does not feel.

A spoofer that tracks the vehicle moves the reported position and velocity together,
smoothly: every fix is consistent with the last, and a navigator that fuses them follows.
What it cannot move is the IMU. :class:`DragTest` watches the difference

    z_k = v_gnss(t_k) - V(t_k)            (north, east; V: the IMU's velocity increments)

which, for an honest receiver, is the initial velocity plus what the IMU's errors
integrate to: a NED bias ``b_n`` (the autopilot's tilt error times g) and a body-frame
accelerometer bias ``b_b`` (``dV = -dW b_b``, :mod:`.inertial`), random walks at the
rates of the IMU grade, plus the IMU's white noise (its measured vibration) and the
receiver's velocity noise; and, where the fix is placed ``delta`` later than it was valid
(a lag not yet measured, or measured slightly wrong), ``-a(t) delta`` (``a``: the IMU's
acceleration), with ``delta = sigma_lag u``: ``sigma_lag`` is what is not known of the
placement, ``u`` a unit-variance constant. What the service itself changes of the
placement, ``delta_s``, is known: the separation from a reference anchored at ``t_a``
moves by ``a(t_a) (delta_s(t) - delta_s(t_a))``, which is taken out, as is its step
between consecutive fixes from the filter. A small Kalman filter on the state

    x = [d_N, d_E, b_n,N, b_n,E, b_b,x, b_b,y, b_b,z, u]

follows it, ``u`` a *consider* state (Schmidt-Kalman: never updated, its prior and its
correlations with the rest carried). A misplaced fix shows in a bank's entry and exit as
the bias along the body's z axis does (seen horizontally only through the tilt); with
``u`` considered the filter fits the bias there only by what the misplacement cannot
explain, and the test is widened by what the misplacement could explain.

Every ``anchor_interval_s`` while nothing is suspected the filter's state is kept as a
*reference*; references up to ``max_window_s`` old are carried forward open loop (no fix
after their anchor) and each fix is tested against every one:

    s = z - J x_a,   J = [I, -tau I, -(W(t) - W(t_a)), -sigma_lag a(t)],
    S = J P_a J^T + (q_vrw tau + (q_n + q_b) tau^3 / 3) I + R + R_slow(tau)
        + (sigma_att (R(t) - R(t_a)))^2 I,

``T = s^T S^-1 s`` against the chi-square (2 dof) quantile of ``false_alarm_prob``. A drag
of acceleration ``a`` that began after a reference's anchor shows as ``s = a tau``: the
reference as old as the drag sees it best, and the test needs no guess of its start
(solution separation against coasting references, Kim, Walter and Powell, on the
velocity; the IMU monitor of Tanil et al.). The white and slow parts of the receiver's
velocity noise and the IMU's vibration are measured in flight (the receiver's claimed
accuracy is never used: a spoofer controls it); the ratio of the statistic to its
chi-square mean, per window length, is measured while nothing is suspected and
scales ``S`` up (never down): the real autopilots' attitude and lag errors that the
model leaves out then widen the test rather than raise false alarms.

The smallest drag the test sees within a window ``tau`` is
``a_min(tau) = sqrt(threshold * S(tau)) / tau`` (:meth:`DragTest.detectable_mps2`).

Pure: no I/O, no clock.

References
----------
Tanil, Khanafseh, Joerger and Pervan, "An INS monitor to detect GNSS spoofers capable of
tracking vehicle position", IEEE Trans. AES 54(1), 2018. Kim, Walter and Powell,
"Standalone GPS-based flight inspection system" (solution separation). Groves,
Principles of GNSS, inertial and multisensor navigation, 2nd ed., sec. 14.4 (velocity
error of accelerometer biases and attitude errors).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from companion.integrity.spoof.config import WINDOW_EDGES_S, SpoofConfig
from companion.integrity.spoof.inertial import Increments
from companion.types import FloatArray


@dataclass(slots=True)
class Anchor:
    """The filter's state kept at ``t_s``: ``x`` (7,), ``p`` (7, 7), the IMU increments
    then ``inc``, the mean north-east acceleration then ``acc`` (2,), m/s^2, and what the
    caller gave with that fix (``payload``: the navigator's state, for an episode's
    reference)."""

    t_s: float
    x: FloatArray
    p: FloatArray
    inc: Increments
    acc: FloatArray
    payload: object = None
    placed_s: float = 0.0
    """The lag the service placed that fix with, s."""

    @property
    def w(self) -> FloatArray:
        return self.inc.w


@dataclass(frozen=True, slots=True)
class DragVerdict:
    """The test of one fix: the largest normalised statistic over the references
    (``stat`` / ``threshold`` > 1 fails), the window ``tau_s`` it came from, the mean
    extra acceleration over it ``acc_ne_mps2`` (2,), and the velocity separation
    ``sep_ne_mps`` (2,). ``tested`` is False when no reference existed."""

    t_s: float
    tested: bool
    stat: float
    threshold: float
    tau_s: float
    acc_ne_mps2: FloatArray
    sep_ne_mps: FloatArray
    anchor: Anchor | None = None
    """The reference of the largest statistic."""
    oldest: Anchor | None = None
    """The oldest reference (anchored before a drag that began within ``max_window_s``)."""
    step: bool = False
    """The separation appeared within the last fix intervals, all at once: a jump of the
    receiver's velocity (a fault, or a spoofer letting go: the IMU cannot tell which
    side of it is true), not a drag."""

    @property
    def failed(self) -> bool:
        return self.tested and self.stat > self.threshold


@dataclass(slots=True)
class _Filter:
    """The drag filter: state ``x`` (7,) and covariance ``p`` (7, 7) at ``t_s``, the IMU's
    ``w`` increment then, its integration epoch, and when it started."""

    x: FloatArray
    p: FloatArray
    t_s: float
    w: FloatArray
    epoch: int
    start_t_s: float


_I2 = np.eye(2)
N_STATE = 8
"""``[d_N, d_E, b_n,N, b_n,E, b_b,x, b_b,y, b_b,z, u]``; ``u`` is a consider state: its
gain is zero (Schmidt-Kalman), the Joseph update keeps the covariance right for that gain."""
U = 7
"""Index of ``u``: the fixes' misplacement in time is ``lag_sigma_s * u``."""
CALM_NIS = float(chi2.isf(1e-3, 2))
"""A fix whose innovation in the filter exceeds this (2 dof, 1e-3) pulls the filter: its
biases may be learning a disturbance (a failing IMU, a drag), and no reference is kept
for ``calm_s`` after it."""
LEARN_BELOW = 0.25
"""The calibration and the wander learn only from fixes whose statistic is below this
fraction of the threshold: a drag building up below the threshold stops teaching them
long before it is detected (what they learn is the honest receiver's spread)."""
STEP_FRACTION = 0.5
"""A failure is a step, not a drag, when the fix's change since the last fix (less what
the biases drift) is this fraction of the separation."""


CALIBRATION_STEP_CAP = 4.0
"""One fix adds at most this many times the current factor to the calibration's mean (a
chi-square (2 dof) value exceeds 4 times its mean with probability 3e-4)."""


class DragTest:
    """The drag test of one receiver (see the module docstring)."""

    def __init__(self, config: SpoofConfig) -> None:
        self.config = config
        n_classes = len(WINDOW_EDGES_S) + 1
        self.threshold = float(chi2.isf(config.false_alarm_prob / n_classes, 2))
        self.lag_sigma_s = config.lag_sigma_s
        """What is not known of the fixes' time placement, s (the caller's measurement of
        the lag, or the configured prior)."""
        self._cal_sum = np.zeros(n_classes)
        self._cal_n = np.zeros(n_classes)
        self._calib = np.full(n_classes, config.calibration_prior)
        self._q_n = 0.0
        self._q_wander = config.wander_prior_m2ps5
        """The apparent bias's random walk measured in flight (what the attitude of a real
        autopilot wanders by), (m/s^2)^2/s."""
        self.reset()

    def reset(self) -> None:
        """Forget the filter and every reference (a new IMU epoch, a reboot). The in-flight
        calibration is kept: it measures the installation, not the moment."""
        self.f: _Filter | None = None
        """The filter (None until the first fix)."""
        self.refs: list[Anchor] = []
        self._last_anchor_t = -math.inf
        self._cal_t: float | None = None
        self._acc = np.zeros(2)
        self._last_acc = np.zeros(2)
        self._upset_t = -math.inf
        self._r_white = self.config.gnss_vel_floor_mps**2
        self._r_n = 0
        self._last_z: FloatArray | None = None
        self._placed_s = 0.0
        self.frozen = False
        """References are kept, none added (an episode holds its evidence)."""

    # ------------------------------------------------------------------ filter

    def _q(self, vrw: float) -> tuple[float, float, float]:
        cfg = self.config
        q_n = max(cfg.tilt_rw_m2ps5, self._q_wander)
        return max(vrw, cfg.acc_vrw_floor_m2ps3), q_n, cfg.acc_bias_rw_m2ps5

    @property
    def running(self) -> bool:
        """The filter has started (since the last reset)."""
        return self.f is not None

    def _start(self, t_s: float, z: FloatArray, inc: Increments, placed_s: float) -> None:
        cfg = self.config
        x = np.concatenate([z, np.zeros(N_STATE - 2)])
        p = np.diag(
            [
                self._r_white,
                self._r_white,
                cfg.tilt_bias_sigma_mps2**2,
                cfg.tilt_bias_sigma_mps2**2,
                cfg.acc_bias_sigma_mps2**2,
                cfg.acc_bias_sigma_mps2**2,
                cfg.acc_bias_z_sigma_mps2**2,
                1.0,
            ]
        )
        self.f = _Filter(x, p, t_s, inc.w, inc.epoch, t_s)
        self.refs = []
        self._placed_s = placed_s
        self._last_anchor_t = -math.inf
        self._last_z = z

    def on_fix(
        self,
        t_s: float,
        vel_ne_mps: FloatArray,
        inc: Increments,
        acc_ne_mps2: FloatArray,
        vrw_m2ps3: float,
        hold: bool,
        payload: object = None,
        placed_s: float = 0.0,
    ) -> DragVerdict:
        """Test one fix's velocity, then take it into the filter.

        Parameters
        ----------
        t_s : the fix's time of validity, s.
        vel_ne_mps : (2,) its north and east velocity, m/s.
        inc : the IMU increments at ``t_s``.
        acc_ne_mps2 : (2,) the IMU's mean north-east acceleration over the
            ``accel_smoothing_s`` before ``t_s``, m/s^2.
        vrw_m2ps3 : the IMU's measured white noise PSD (:meth:`InertialIncrements.vrw_psd_m2ps3`).
        hold : something is suspected: no reference is anchored, nothing calibrated.
        payload : kept with the reference anchored at this fix, if one is.
        placed_s : the lag the service placed the fix with, s (its own change between
            fixes moves ``z`` by the acceleration times the change: taken out).
        """
        z = np.asarray(vel_ne_mps, dtype=float) - inc.vel[:2]
        none = DragVerdict(t_s, False, 0.0, self.threshold, 0.0, np.zeros(2), np.zeros(2))
        f = self.f
        if f is None or inc.epoch != f.epoch or t_s <= f.t_s:
            if f is None or inc.epoch != f.epoch:
                self._start(t_s, z, inc, placed_s)
            return none
        q_vrw, q_n, q_b = self._q(vrw_m2ps3)
        self._last_acc = self._acc
        self._acc = np.asarray(acc_ne_mps2, dtype=float)
        if placed_s != self._placed_s:  # the service's own change: z moves by a known step
            known = self._last_acc * (placed_s - self._placed_s)
            f.x[0:2] += known
            if self._last_z is not None:
                self._last_z = self._last_z + known
            self._placed_s = placed_s
        verdict = self._test(f, t_s, z, inc, q_vrw, q_n, q_b)
        if not hold and verdict.tested and verdict.stat < LEARN_BELOW * verdict.threshold:
            self._calibrate(verdict)
        self._predict(f, t_s, inc, q_vrw, q_n, q_b)
        self._update(f, z, hold or verdict.failed)
        if (
            not hold
            and not self.frozen
            and not verdict.failed
            and t_s - f.start_t_s >= self.config.settle_s
            and t_s - self._last_anchor_t >= self.config.anchor_interval_s
            and t_s - self._upset_t >= self.config.calm_s
        ):
            self._anchor(f, t_s, inc, payload)
        self._prune(t_s)
        return verdict

    def _predict(
        self, f: _Filter, t_s: float, inc: Increments, q_vrw: float, q_n: float, q_b: float
    ) -> None:
        dt = t_s - f.t_s
        phi = np.eye(N_STATE)
        phi[0:2, 2:4] = -dt * _I2
        dw = inc.w - f.w
        phi[0:2, 4:7] = -dw
        f.x = phi @ f.x
        q = np.zeros(N_STATE)
        q[0:2] = q_vrw * dt
        q[2:4] = q_n * dt
        q[4:7] = q_b * dt
        f.p = phi @ f.p @ phi.T + np.diag(q)
        f.t_s, f.w = t_s, inc.w

    def _drift(self, f: _Filter, t_s: float, inc: Increments) -> FloatArray:
        """What the filter expects ``z`` to change by from its last fix to ``t_s`` (2,): the
        biases' drift."""
        return -(t_s - f.t_s) * f.x[2:4] - (inc.w - f.w) @ f.x[4:7]

    def _update(self, f: _Filter, z: FloatArray, hold: bool) -> None:
        """Fuse ``z``; the receiver's white velocity noise measured from consecutive ones
        (their difference less what the filter predicts between them) unless ``hold``."""
        cfg = self.config
        if not hold and self._last_z is not None:
            e2 = float(np.mean((z - self._last_z) ** 2)) * 0.5
            self._r_n += 1
            w = max(1.0 / self._r_n, 0.01)
            self._r_white += w * (max(e2, cfg.gnss_vel_floor_mps**2) - self._r_white)
        self._last_z = z
        r = self._r_white
        h = np.zeros((2, N_STATE))
        h[:, 0:2] = _I2
        h[:, U] = -self.lag_sigma_s * self._acc  # a misplaced fix: its acceleration times it
        ph = f.p @ h.T
        s = h @ ph + r * _I2
        k = np.linalg.solve(s, ph.T).T  # (8, 2)
        k[U] = 0.0
        y = z - h @ f.x
        if float(y @ np.linalg.solve(s, y)) > CALM_NIS:
            self._upset_t = f.t_s  # the filter is being pulled: no reference for a while
        f.x = f.x + k @ y
        ikh = np.eye(N_STATE) - k @ h
        f.p = ikh @ f.p @ ikh.T + r * (k @ k.T)

    # ------------------------------------------------------------------ references

    def _anchor(self, f: _Filter, t_s: float, inc: Increments, payload: object) -> None:
        self.refs.append(
            Anchor(t_s, f.x.copy(), f.p.copy(), inc, self._acc.copy(), payload, self._placed_s)
        )
        self._last_anchor_t = t_s

    def _prune(self, t_s: float) -> None:
        if self.frozen:
            return
        horizon = t_s - self.config.max_window_s
        while self.refs and self.refs[0].t_s < horizon:
            self.refs.pop(0)

    def _separations(
        self, t_s: float, z: FloatArray, inc: Increments, q_vrw: float, q_n: float, q_b: float
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Per reference: tau (n,), the separation s (n, 2), its covariance S (n, 2, 2) and
        the statistic ``s^T S^-1 s`` (n,), before the calibration."""
        cfg = self.config
        refs = self.refs
        tau = np.array([t_s - r.t_s for r in refs])
        xa = np.array([r.x for r in refs])
        pa = np.array([r.p for r in refs])
        dw = inc.w[None, :, :] - np.array([r.w for r in refs])
        n = len(refs)
        j = np.zeros((n, 2, N_STATE))
        j[:, 0, 0] = j[:, 1, 1] = 1.0
        j[:, 0, 2] = j[:, 1, 3] = -tau
        j[:, :, 4:7] = -dw
        j[:, :, U] = -self.lag_sigma_s * self._acc
        sep = z[None, :] - np.einsum("nij,nj->ni", j, xa)
        if any(r.placed_s != self._placed_s for r in refs):  # the service's own changes
            acc_a = np.array([r.acc for r in refs])
            sep -= acc_a * (self._placed_s - np.array([r.placed_s for r in refs]))[:, None]
        slow = 2.0 * cfg.gnss_vel_slow_mps**2 * (1.0 - np.exp(-tau / cfg.gnss_vel_slow_tau_s))
        dturn = inc.turn - np.array([r.inc.turn for r in refs])
        att_time = (cfg.attitude_time_sigma_s * dturn) ** 2
        extra = q_vrw * tau + (q_n + q_b) * tau**3 / 3.0 + self._r_white + slow + att_time
        cov = j @ pa @ j.transpose(0, 2, 1) + extra[:, None, None] * _I2
        a, b, d = cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]
        det = a * d - b * b
        sx, sy = sep[:, 0], sep[:, 1]
        stat = (d * sx * sx - 2.0 * b * sx * sy + a * sy * sy) / det
        return tau, sep, cov, stat

    def _test(
        self,
        f: _Filter,
        t_s: float,
        z: FloatArray,
        inc: Increments,
        q_vrw: float,
        q_n: float,
        q_b: float,
    ) -> DragVerdict:
        live = [r for r in self.refs if r.t_s < t_s]
        if not live:
            return DragVerdict(t_s, False, 0.0, self.threshold, 0.0, np.zeros(2), np.zeros(2))
        refs, self.refs = self.refs, live
        tau, sep, cov, raw = self._separations(t_s, z, inc, q_vrw, q_n, q_b)
        self.refs = refs
        self._last_wander = (tau, sep, cov, q_n)
        self._last_wander_t = t_s
        cls = np.searchsorted(np.array(WINDOW_EDGES_S), tau, side="right")
        stat = raw / self._calib[cls]
        k = int(np.argmax(stat))
        self._last_stats = (t_s, cls, raw)
        # a step: most of the separation arrived since the last fix (the change of z less
        # what the biases drift), where a drag adds only its acceleration times a fix
        # interval
        step = False
        if self._last_z is not None:
            jump = z - self._last_z - self._drift(f, t_s, inc)
            step = float(np.hypot(*jump)) >= STEP_FRACTION * float(np.hypot(*sep[k]))
        return DragVerdict(
            t_s,
            True,
            float(stat[k]),
            self.threshold,
            float(tau[k]),
            sep[k] / tau[k],
            sep[k],
            live[k],
            live[0],
            step,
        )

    def _calibrate(self, verdict: DragVerdict) -> None:
        """Per window class, the mean of the statistic over its chi-square mean (2), with
        ``calibration_prior`` weighing ``calibration_prior_fixes`` and an exponential memory
        of ``calibration_tau_s``: the factor on ``S`` (at least 1, at most
        ``max_calibration``, never smaller for a longer window than for a shorter one)."""
        t_s, cls, raw = self._last_stats
        cfg = self.config
        dt = 0.0 if self._cal_t is None else max(t_s - self._cal_t, 0.0)
        self._cal_t = t_s
        keep = math.exp(-dt / cfg.calibration_tau_s)
        self._cal_sum *= keep
        self._cal_n *= keep
        cap = CALIBRATION_STEP_CAP * self._calib
        for c in set(cls.tolist()):
            # a value far above the current factor moves it only a little: a drag that
            # builds up below the threshold must not calibrate the test away
            self._cal_sum[c] += min(float(np.mean(raw[cls == c])) / 2.0, float(cap[c]))
            self._cal_n[c] += 1.0
        n0, c0 = cfg.calibration_prior_fixes, cfg.calibration_prior
        mean = (n0 * c0 + self._cal_sum) / (n0 + self._cal_n)
        self._calib = np.clip(np.maximum.accumulate(mean), 1.0, cfg.max_calibration)
        self._learn_wander(math.exp(-dt / cfg.wander_tau_s))

    def _learn_wander(self, keep: float) -> None:
        """The random walk of the apparent bias from the long windows (tau >= 10 s), where
        it dominates: per reference the separation's mean square per axis less the rest of
        its modelled variance, over tau^3 / 3 (a moment estimate), each fix's capped at
        ``CALIBRATION_STEP_CAP`` times the current value; a running mean from
        ``wander_prior_m2ps5`` with the memory ``wander_tau_s`` (after
        ``calibration_prior_fixes`` fixes)."""
        tau, sep, cov, q_n = self._last_wander
        long = tau >= WINDOW_EDGES_S[2]
        if not np.any(long):
            return
        t3 = tau[long] ** 3 / 3.0
        rest = 0.5 * (cov[long, 0, 0] + cov[long, 1, 1]) - q_n * t3
        ms = 0.5 * np.sum(sep[long] ** 2, axis=1)
        est = float(np.mean((ms - rest) / t3))  # unbiased: negative values count too
        cfg = self.config
        self._q_n += 1.0
        w = max(1.0 - keep, 1.0 / (cfg.calibration_prior_fixes + self._q_n))
        step = min(est, CALIBRATION_STEP_CAP * max(self._q_wander, cfg.tilt_rw_m2ps5))
        self._q_wander = max(self._q_wander + w * (step - self._q_wander), 0.0)

    def anchor_before_drag(self) -> Anchor | None:
        """At a detection, the youngest reference a drag has not touched (else the oldest).

        A drag of acceleration ``a`` that began ``tau_on`` ago separates a reference
        anchored ``tau`` ago by ``a min(tau, tau_on)`` along its direction. That line is
        fitted to the references' separations (weighted by their variances) for every
        ``tau_on`` among their ages; the best fit's ``tau_on`` is where the drag began, and
        the reference returned is the youngest at least one anchor interval older."""
        refs = [r for r in self.refs if r.t_s < self._last_wander_t]
        tau, sep, cov, _q = self._last_wander
        if not refs or len(refs) != len(tau):
            return refs[0] if refs else None
        k = int(np.argmax(np.sum(sep * sep, axis=1) / np.maximum(tau, 1e-9)))
        u = sep[k] / max(float(np.hypot(*sep[k])), 1e-12)
        along = sep @ u
        w = 1.0 / np.maximum(np.einsum("i,nij,j->n", u, cov, u), 1e-12)
        shape = np.minimum(tau[None, :], tau[:, None])  # row: candidate tau_on, col: reference
        a = (shape * w) @ along / np.maximum((shape * shape) @ w, 1e-12)
        resid = ((along[None, :] - a[:, None] * shape) ** 2) @ w
        tau_on = float(tau[int(np.argmin(resid))])
        older = [
            r for r, t in zip(refs, tau, strict=True)
            if t >= tau_on + self.config.anchor_interval_s
        ]  # fmt: skip
        return older[-1] if older else refs[0]

    # ------------------------------------------------------------------ bounds

    @property
    def wander_m2ps5(self) -> float:
        """The apparent bias's random walk in force (measured, at least the grade's)."""
        return max(self.config.tilt_rw_m2ps5, self._q_wander)

    @property
    def inflation(self) -> float:
        """The calibration's factor of the longest windows."""
        return float(self._calib[-1])

    @property
    def gnss_vel_var_m2ps2(self) -> float:
        """The receiver's velocity noise as measured (white and slow parts), m^2/s^2."""
        return self._r_white + 2.0 * self.config.gnss_vel_slow_mps**2

    def detectable_mps2(self, tau_s: float, vrw_m2ps3: float) -> float:
        """The smallest constant drag this test sees after ``tau_s`` against a reference as
        old as it, m/s^2 (with the newest reference's covariance; ``inf`` before one)."""
        if not self.refs or tau_s <= 0.0:
            return math.inf
        ref = self.refs[-1]
        q_vrw, q_n, q_b = self._q(vrw_m2ps3)
        cfg = self.config
        j = np.zeros((2, N_STATE))
        j[0, 0] = j[1, 1] = 1.0
        j[0, 2] = j[1, 3] = -tau_s
        cov = j @ ref.p @ j.T
        slow = 2.0 * cfg.gnss_vel_slow_mps**2 * (1.0 - math.exp(-tau_s / cfg.gnss_vel_slow_tau_s))
        var = float(np.max(np.linalg.eigvalsh(cov)))
        var += q_vrw * tau_s + (q_n + q_b) * tau_s**3 / 3.0 + self._r_white + slow
        var *= float(self._calib[int(np.searchsorted(np.array(WINDOW_EDGES_S), tau_s, "right"))])
        return math.sqrt(self.threshold * var) / tau_s

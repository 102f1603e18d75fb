"""An inertial coasting reference for solution separation: INS predictions free of recent fixes.

Solution separation (Kim, Walter and Powell) needs solutions that do not share the
fault under test. With one receiver the navigator is no such solution: it fuses
the receiver and follows a slow ramp. :class:`InertialCoast` supplies one: the
fault detector (:mod:`companion.integrity.fde.pairs`) separates each receiver
from every slot's prediction. It integrates the
IMU's specific force, rotated to NED by the autopilot's attitude, plus normal
gravity, as cumulative increments ``V(t) = int a dt`` and ``P(t) = int V dt``
with a short history, so that they can be read at a GNSS fix's (older) time of
validity. A few *anchor slots* are reset, staggered, from the navigator's
state (position, velocity, their covariances, optionally its accelerometer-bias
estimate) every ``life_s``; a slot's prediction at ``t``, ``tau = t - t_a``
after its anchor at ``t_a``, is

    p(t) = p0 + v0 tau + P(t) - P(t_a) - V(t_a) tau,   v(t) = v0 + V(t) - V(t_a),

which contains no fix later than ``t_a``. Its covariance grows from the anchor
covariance with the IMU grade, per NED axis (errors independent across axes):

    P_p(tau) = P_p0 + tau^2 P_v0 + tau^4 / 4 S_a + q tau^3 / 3
    P_v(tau) = P_v0 + tau^2 S_a + q tau

``S_a`` (3, 3) is the covariance of the effective NED acceleration error: the
accelerometer bias (turn-on plus instability, or the anchor's estimate
covariance when one is given) and the autopilot's attitude error times the
mean specific force over the slot's life, ``[f x] S_psi [f x]^T``. Both are
first-order Gauss-Markov processes with correlation times of minutes; over a
slot's life (a minute) they are taken as random constants, which bounds the
variance of their double integral from above (an exponential autocorrelation
never exceeds its value at lag 0). ``q`` is the accelerometer white noise
(velocity random walk) PSD. The anchor's position and velocity errors are taken
as independent (the navigator's state gives no cross covariance).

The frame is the engine's flat local NED frame (as :mod:`companion.nav.ins`:
Earth rate, transport rate and the tilt of the vertical neglected); gravity is
the frame origin's normal gravity with the free-air gradient applied along the
down axis (over a 250 m approach the gradient changes gravity by 8e-4 m/s^2,
more than a tactical accelerometer bias). Between attitude samples the attitude
is carried to the IMU time with the attitude sample's body rate (first order).

Pure: no I/O, no clock; time is the samples' ``t_s``.

References
----------
Kim, Walter and Powell, "Standalone GPS-based flight inspection system" (solution
separation between independent solutions). El-Mowafy (2005), RTK networks for
precision approach with an adaptive GPS/INS blend (tactical IMU grade).
"Tracking with the aircraft's kinematic and dynamic parameters" (the measured
specific force as the motion model). Titterton & Weston, Strapdown Inertial
Navigation Technology, 2nd ed., eq. 12.20-12.22 (the psi-angle error model:
dv error = [f x] psi - C dba). Groves, Principles of GNSS, inertial and
multisensor navigation, sec. 4.4 (IMU error model). ``docs/methods.md``.
"""

from __future__ import annotations

import bisect
import logging
import math
from collections import Counter
from dataclasses import dataclass

import numpy as np

from companion.nav import earth
from companion.nav.grades import ATTITUDE_ERROR_BY_GRADE, IMU_GRADES
from companion.nav.navigator import NavState
from companion.ranges import check_ranges, ranged
from companion.types import AttitudeSample, FloatArray, ImuSample

log = logging.getLogger(__name__)

_M_RATIO = earth.OMEGA_IE_RADPS**2 * earth.A_M**2 * earth.B_M / earth.GM_M3PS2
_SKEW = np.zeros((3, 9))
"""``(f @ _SKEW).reshape(3, 3)`` is the cross-product matrix ``[f x]`` of a (3,) vector."""
_SKEW[2, 1], _SKEW[1, 2] = -1.0, 1.0
_SKEW[2, 3], _SKEW[0, 5] = 1.0, -1.0
_SKEW[1, 6], _SKEW[0, 7] = -1.0, 1.0
_EYE3 = np.eye(3)
_FREE_AIR_PER_M = 2.0 / earth.A_M * (1.0 + earth.F + _M_RATIO)
"""Relative free-air gradient of normal gravity, 1/m (NIMA TR8350.2 eq. 4-3 at the
equator; the latitude term changes it by < 0.7 %)."""


@dataclass(frozen=True, slots=True)
class CoastState(NavState):
    """A coasting slot's prediction: a :class:`NavState` plus what the separation tests need.

    ``anchor_t_s``: time of the slot's anchor (a change means the slot re-anchored: its
    separation series must restart). ``acc_cov_ned_m2ps4`` (3, 3): covariance of the
    effective acceleration error (drift rate of the velocity error), m^2/s^4.
    ``vrw_psd_m2ps3``: accelerometer white-noise PSD, m^2/s^3 per axis.
    """

    anchor_t_s: float = math.nan
    acc_cov_ned_m2ps4: FloatArray | None = None
    vrw_psd_m2ps3: float = 0.0


_RESTAGGER = 0.95
"""An overdue slot waits until this fraction of the stagger has passed since the last
anchor (a fraction: in steady flight consecutive slots come due a stagger apart, give or
take the publication tick that anchors them)."""


@dataclass(frozen=True, slots=True)
class CoastConfig:
    """Settings of :class:`InertialCoast` (validated). Defaults: the tactical grade.

    The IMU-grade figures are the simulator's grade profiles
    (:data:`companion.nav.grades.IMU_GRADES`, ``ATTITUDE_ERROR_BY_GRADE``), which are
    also the blend's (:meth:`companion.nav.blend.BlendConfig.for_grade`); use
    :meth:`for_grade` rather than typing them.
    """

    slots: int = ranged(6, ge=1, le=16)
    """Number of staggered anchor slots. A fault that starts at ``t`` is seen by the slots
    anchored before ``t`` until they re-anchor; the youngest of them (at most
    ``life_s / slots`` old at ``t``, so the most accurate) lasts ``life_s (1 - 1/slots)``
    more: more slots give a younger, sharper reference that still outlives detection."""
    life_s: float = ranged(30.0, gt=0.0)
    """A slot is re-anchored this long after its last anchor; slots are staggered by
    ``life_s / slots``, so the oldest is always at least ``life_s (1 - 1/slots)`` old
    (25 s by default: older than the monitor's 10 s window). Beyond about 30 s a
    tactical-grade slot's vertical sigma exceeds 15 cm and it no longer sharpens the
    tests (``python bench/integrity.py`` measures detection for other lives)."""
    history_s: float = ranged(2.0, gt=0.0)
    """Length of the increment history: the oldest fix time a reference can be given at, s."""
    max_imu_gap_s: float = ranged(0.5, gt=0.0)
    """An IMU gap longer than this breaks the integration: every slot is dropped, s."""
    acc_bias_sigma_mps2: float = ranged(math.hypot(0.3e-3, 0.05e-3) * 9.80665, ge=0.0)
    """Accelerometer bias 1-sigma per axis when the anchor gives no estimate (turn-on and
    instability combined), m/s^2."""
    acc_vrw_mps_rts: float = ranged(0.03 / 60.0, ge=0.0)
    """Accelerometer white noise (velocity random walk), m/s/sqrt(s)."""
    att_err_sigma_rad: tuple[float, float, float] = ranged(
        (math.radians(0.01), math.radians(0.01), math.radians(0.02)), ge=0.0, length=3
    )
    """The autopilot's attitude error 1-sigma about roll, pitch, yaw axes, rad."""

    def __post_init__(self) -> None:
        check_ranges(self)
        if not isinstance(self.slots, int):
            raise ValueError(f"slots must be an integer, got {self.slots!r}")

    @classmethod
    def for_grade(cls, grade: str, **overrides: object) -> CoastConfig:
        """The figures of an IMU grade (``"tactical"``, ``"mems"``) from the grade profiles.

        Bias: turn-on and instability 1-sigma combined; white noise: the noise
        density; attitude: the autopilot's attitude error for that grade.
        """
        if grade not in IMU_GRADES or grade not in ATTITUDE_ERROR_BY_GRADE:
            raise ValueError(f"unknown IMU grade {grade!r}")
        g = IMU_GRADES[grade]
        att, _tau = ATTITUDE_ERROR_BY_GRADE[grade]
        params: dict[str, object] = {
            "acc_bias_sigma_mps2": math.hypot(g.acc_bias_sigma_mps2, g.acc_instability_mps2),
            "acc_vrw_mps_rts": g.acc_noise_density_mps2_rthz,
            "att_err_sigma_rad": tuple(float(a) for a in att),
        }
        params.update(overrides)
        return cls(**params)  # type: ignore[arg-type]


@dataclass(slots=True)
class _Slot:
    """One anchor: the navigator's state at ``t_s`` and the increments there."""

    t_s: float
    pos: FloatArray
    vel: FloatArray
    pos_cov: FloatArray
    vel_cov: FloatArray
    acc_cov_bias: FloatArray
    v_inc: FloatArray
    p_inc: FloatArray


class InertialCoast:
    """Free-inertial predictions from staggered anchors (see the module docstring).

    Parameters
    ----------
    config : CoastConfig
    gravity_ned_mps2 : (3,) normal gravity at the local frame's origin, m/s^2
        (``companion.nav.earth.gravity_ned_mps2``).

    ``stats`` counts rejected inputs and dropped slots by reason.
    """

    def __init__(self, config: CoastConfig, gravity_ned_mps2: FloatArray) -> None:
        g = np.asarray(gravity_ned_mps2, dtype=float)
        if g.shape != (3,) or not np.all(np.isfinite(g)):
            raise ValueError("gravity_ned_mps2 must be 3 finite numbers")
        self.config = config
        self._g = [float(c) for c in g]
        self._g_grad = _FREE_AIR_PER_M * float(np.linalg.norm(g))
        """Increase of down gravity per metre of descent, 1/s^2."""
        self._g_ref_d = 0.0
        """Down coordinate of the point where gravity is ``gravity_ned_mps2``, m."""
        self._att_var = np.array(config.att_err_sigma_rad) ** 2
        self._g_vec = g.copy()
        self._bias_cov = np.eye(3) * config.acc_bias_sigma_mps2**2
        self._q = config.acc_vrw_mps_rts**2
        self.stats: Counter[str] = Counter()
        self.reset()

    # ------------------------------------------------------------------ state

    def reset(self) -> None:
        """Forget the attitude, the increments and every slot (autopilot reboot)."""
        self._att: tuple[float, ...] | None = None
        self._att_t = 0.0
        self._att_rate = (0.0, 0.0, 0.0)
        self._bias = (0.0, 0.0, 0.0)
        self._last_t: float | None = None
        self._last_a = (0.0, 0.0, 0.0)
        self._v = [0.0, 0.0, 0.0]
        self._p = [0.0, 0.0, 0.0]
        self._h_t: list[float] = []
        self._h_v: list[tuple[float, float, float]] = []
        self._h_p: list[tuple[float, float, float]] = []
        self._pd_run = 0.0
        self._vd_run = 0.0
        self._slots: list[_Slot | None] = [None] * self.config.slots
        self._first_anchor_t: float | None = None
        self._last_anchor_t = -math.inf
        self._restack()

    def drop_slots(self, reason: str) -> None:
        """Drop every slot (their anchors came from a navigator the service has since
        changed: :mod:`companion.engine.self_change`); they re-anchor as they come due."""
        self._drop_slots(reason)

    def _drop_slots(self, reason: str) -> None:
        if any(s is not None for s in self._slots):
            self.stats[f"slots_dropped_{reason}"] += 1
            log.warning("inertial coast: every slot dropped (%s)", reason)
        self._slots = [None] * self.config.slots
        self._first_anchor_t = None
        self._last_anchor_t = -math.inf
        self._restack()

    # ------------------------------------------------------------------ inputs

    def on_attitude(self, sample: AttitudeSample, yaw_correction_rad: float = 0.0) -> None:
        """Take the autopilot's attitude (``yaw_correction_rad`` is subtracted from its yaw)."""
        r = sample.rate_b_radps.tolist()
        vals = (sample.t_s, sample.roll_rad, sample.pitch_rad, sample.yaw_rad, yaw_correction_rad)
        if len(r) != 3 or not math.isfinite(sum(vals) + sum(r)):
            self.stats["bad_attitude"] += 1
            log.warning("inertial coast: non-finite attitude at t=%s rejected", sample.t_s)
            return
        # body-to-NED matrix of the ZYX Euler angles (as companion.nav.rotations.euler_to_mat_nb),
        # in floats: this runs at the attitude rate
        cr, sr = math.cos(sample.roll_rad), math.sin(sample.roll_rad)
        cp, sp = math.cos(sample.pitch_rad), math.sin(sample.pitch_rad)
        yaw = sample.yaw_rad - yaw_correction_rad
        cy, sy = math.cos(yaw), math.sin(yaw)
        self._att = (
            cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr,
            sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr,
            -sp, cp * sr, cp * cr,
        )  # fmt: skip
        self._att_t = sample.t_s
        self._att_rate = (r[0], r[1], r[2])

    def on_imu(self, sample: ImuSample) -> None:
        """Integrate one IMU sample's specific force (trapezoid between samples)."""
        t = sample.t_s
        fx, fy, fz = sample.acc_b_mps2.tolist()
        if not (math.isfinite(t) and math.isfinite(fx + fy + fz)):
            self.stats["bad_imu"] += 1
            log.warning("inertial coast: non-finite IMU sample at t=%s rejected", t)
            return
        c = self._att
        if c is None:
            self.stats["imu_before_attitude"] += 1
            return
        last_t = self._last_t
        dt = 0.0 if last_t is None else t - last_t
        if last_t is not None and dt <= 0.0:
            self.stats["imu_time_not_increasing"] += 1
            return
        bx, by, bz = self._bias
        fx -= bx
        fy -= by
        fz -= bz
        # carry the attitude to the IMU time: f' = f + theta x f, theta = omega (t - t_att)
        h = t - self._att_t
        wx, wy, wz = self._att_rate
        tx, ty, tz = wx * h, wy * h, wz * h
        gx = fx + ty * fz - tz * fy
        gy = fy + tz * fx - tx * fz
        gz = fz + tx * fy - ty * fx
        g = self._g
        an = c[0] * gx + c[1] * gy + c[2] * gz + g[0]
        ae = c[3] * gx + c[4] * gy + c[5] * gz + g[1]
        ad = (
            c[6] * gx + c[7] * gy + c[8] * gz + g[2] + self._g_grad * (self._pd_run - self._g_ref_d)
        )
        if last_t is None or dt > self.config.max_imu_gap_s:
            if last_t is not None:
                self.stats["imu_gap"] += 1
                log.warning("inertial coast: IMU gap of %.3f s at t=%.3f s", dt, t)
                self._drop_slots("imu_gap")
                self._h_t.clear()
                self._h_v.clear()
                self._h_p.clear()
            self._last_t = t
            self._last_a = (an, ae, ad)
            self._h_t.append(t)
            self._h_v.append((self._v[0], self._v[1], self._v[2]))
            self._h_p.append((self._p[0], self._p[1], self._p[2]))
            return
        la = self._last_a
        hdt = 0.5 * dt
        v, p = self._v, self._p
        v0n, v0e, v0d = v
        v[0] = v0n + (an + la[0]) * hdt
        v[1] = v0e + (ae + la[1]) * hdt
        v[2] = v0d + (ad + la[2]) * hdt
        p[0] += (v0n + v[0]) * hdt
        p[1] += (v0e + v[1]) * hdt
        p[2] += (v0d + v[2]) * hdt
        vd_new = self._vd_run + (ad + la[2]) * hdt
        self._pd_run += (self._vd_run + vd_new) * hdt
        self._vd_run = vd_new
        self._last_t = t
        self._last_a = (an, ae, ad)
        ht = self._h_t
        ht.append(t)
        self._h_v.append((v[0], v[1], v[2]))
        self._h_p.append((p[0], p[1], p[2]))
        if t - ht[0] > 2.0 * self.config.history_s:
            self._trim()

    def _trim(self) -> None:
        ht = self._h_t
        k = bisect.bisect_left(ht, ht[-1] - self.config.history_s) - 1
        if k > 0:
            del ht[:k]
            del self._h_v[:k]
            del self._h_p[:k]

    # ------------------------------------------------------------------ increments

    def _increments(self, t_s: float) -> tuple[FloatArray, FloatArray] | None:
        """``V(t_s)``, ``P(t_s)`` (3,) from the history (interpolated; extrapolated with the
        last acceleration up to ``history_s`` past the newest sample), None outside it."""
        ht = self._h_t
        if not ht or self._last_t is None:
            return None
        last = ht[-1]
        # per axis in Python floats (the same operations, in the same order, as numpy's
        # elementwise ones would do on the 3-vectors, without a numpy call each)
        if t_s >= last:
            h = t_s - last
            if h > self.config.history_s:
                return None
            vi = [v + a * h for v, a in zip(self._v, self._last_a, strict=True)]
            pi = [
                p + v * h + 0.5 * a * h * h
                for p, v, a in zip(self._p, self._v, self._last_a, strict=True)
            ]
            return np.array(vi), np.array(pi)
        k = bisect.bisect_right(ht, t_s)
        if k == 0:
            return None
        t0, t1 = ht[k - 1], ht[k]
        w = (t_s - t0) / (t1 - t0)
        dt0 = t_s - t0
        vi = [v0 + (v1 - v0) * w for v0, v1 in zip(self._h_v[k - 1], self._h_v[k], strict=True)]
        # trapezoid inside the interval (linear V): P = P0 + (V0 + Vi) / 2 * (t - t0)
        pi = [
            p0 + 0.5 * (v0 + v) * dt0
            for p0, v0, v in zip(self._h_p[k - 1], self._h_v[k - 1], vi, strict=True)
        ]
        return np.array(vi), np.array(pi)

    # ------------------------------------------------------------------ anchors

    def _due_index(self, t_s: float) -> int | None:
        cfg = self.config
        stagger = cfg.life_s / cfg.slots
        best: int | None = None
        best_age = -math.inf
        for i, slot in enumerate(self._slots):
            if slot is None:
                first = self._first_anchor_t
                if first is None or t_s >= first + i * stagger:
                    return i
                continue
            age = t_s - slot.t_s
            if age >= cfg.life_s and age > best_age:
                best, best_age = i, age
        if best is not None and t_s - self._last_anchor_t < _RESTAGGER * stagger:
            # slots overdue together (anchoring was suspended through an outage or a
            # fault) are re-anchored a stagger apart, not all at the next few ticks:
            # otherwise they would age, expire and re-anchor together from then on
            return None
        return best

    def anchor_due(self, t_s: float) -> bool:
        """True when some slot wants a new anchor at ``t_s`` (and the IMU is running)."""
        if self._last_t is None:
            return False
        return self._due_index(t_s) is not None

    def anchor(
        self,
        state: NavState,
        acc_bias_b_mps2: FloatArray | None = None,
        acc_bias_cov_b_m2ps4: FloatArray | None = None,
    ) -> None:
        """Reset the due slot (if any) from the navigator's ``state``.

        Parameters
        ----------
        state : the navigator's state at (about) its newest time, local NED frame.
        acc_bias_b_mps2 : (3,) its accelerometer-bias estimate, m/s^2, subtracted from
            the specific force from now on (None: keep the last one given).
        acc_bias_cov_b_m2ps4 : (3, 3) the covariance of that estimate; None: the grade's
            bias variance (``acc_bias_sigma_mps2``).
        """
        t = state.t_s
        if not (
            math.isfinite(t)
            and np.all(np.isfinite(state.pos_ned_m))
            and np.all(np.isfinite(state.vel_ned_mps))
            and np.all(np.isfinite(state.pos_cov_ned_m2))
            and np.all(np.isfinite(state.vel_cov_ned_m2ps2))
        ):
            self.stats["bad_anchor"] += 1
            log.warning("inertial coast: non-finite anchor state at t=%s rejected", t)
            return
        i = self._due_index(t)
        if i is None:
            self.stats["anchor_not_due"] += 1
            return
        bias_cov = self._bias_cov
        if acc_bias_b_mps2 is not None:
            b = np.asarray(acc_bias_b_mps2, dtype=float)
            if b.shape != (3,) or not np.all(np.isfinite(b)):
                self.stats["bad_anchor"] += 1
                log.warning("inertial coast: bad accelerometer bias estimate rejected")
                return
            c_att = self._att
            if c_att is not None:  # the last acceleration as if read with the new estimate
                d0, d1, d2 = (float(b[i]) - self._bias[i] for i in range(3))
                la = self._last_a
                self._last_a = (
                    la[0] - (c_att[0] * d0 + c_att[1] * d1 + c_att[2] * d2),
                    la[1] - (c_att[3] * d0 + c_att[4] * d1 + c_att[5] * d2),
                    la[2] - (c_att[6] * d0 + c_att[7] * d1 + c_att[8] * d2),
                )
            self._bias = (float(b[0]), float(b[1]), float(b[2]))
            if acc_bias_cov_b_m2ps4 is not None:
                bc = np.asarray(acc_bias_cov_b_m2ps4, dtype=float)
                if bc.shape != (3, 3) or not np.all(np.isfinite(bc)):
                    self.stats["bad_anchor"] += 1
                    log.warning("inertial coast: bad bias covariance rejected")
                    return
                bias_cov = bc
        inc = self._increments(t)
        if inc is None:
            self.stats["anchor_outside_history"] += 1
            return
        if self._att is not None:
            c = np.array(self._att).reshape(3, 3)
            bias_cov = c @ bias_cov @ c.T  # body to NED at the anchor (turns: see docstring)
        pos = np.array(state.pos_ned_m, dtype=float)
        vel = np.array(state.vel_ned_mps, dtype=float)
        self._slots[i] = _Slot(
            t,
            pos,
            vel,
            np.array(state.pos_cov_ned_m2, dtype=float),
            np.array(state.vel_cov_ned_m2ps2, dtype=float),
            bias_cov,
            inc[0],
            inc[1],
        )
        if self._first_anchor_t is None:
            self._first_anchor_t = t
        self._last_anchor_t = t
        self._restack()
        # the running down position for the gravity gradient follows the newest anchor
        h = (self._last_t or t) - t
        self._vd_run = float(vel[2])
        self._pd_run = float(pos[2] + vel[2] * h)
        self.stats["anchors"] += 1

    # ------------------------------------------------------------------ outputs

    def slot_ages_s(self, t_s: float) -> list[float | None]:
        """Age of each slot at ``t_s`` (None: not anchored), s."""
        return [None if s is None else t_s - s.t_s for s in self._slots]

    def references(self, t_s: float) -> dict[str, CoastState]:
        """The anchored slots' predictions at ``t_s``, by name (``ins0``, ``ins1``, ...).

        Each is a :class:`CoastState`; a slot anchored at or after ``t_s`` or a time
        outside the increment history gives nothing. All slots are evaluated in one
        batched numpy pass (the per-call cost hardly depends on the number of slots).
        """
        names = self._names
        if not names:
            return {}
        inc = self._increments(t_s)
        if inc is None:
            self.stats["reference_outside_history"] += 1
            return {}
        v_t, p_t = inc
        tau = t_s - self._st_t  # (n,)
        tau_c = tau[:, None]
        dv = v_t - self._st_vinc
        pos = self._st_pos + self._st_vel * tau_c + (p_t - self._st_pinc - self._st_vinc * tau_c)
        vel = self._st_vel + dv
        # mean specific force over each slot's life, NED, and [f x] S_psi [f x]^T
        f = dv / np.where(tau_c > 0.0, tau_c, 1.0) - self._g_vec
        fx = (f @ _SKEW).reshape(-1, 3, 3)
        s_a = self._st_bcov + (fx * self._att_var) @ fx.transpose(0, 2, 1)
        tau2 = (tau * tau)[:, None, None]
        q = self._q
        pos_cov = (
            self._st_pcov + tau2 * self._st_vcov + (0.25 * tau2 * tau2) * s_a
            + (q / 3.0) * tau2 * tau[:, None, None] * _EYE3
        )  # fmt: skip
        vel_cov = self._st_vcov + tau2 * s_a + q * tau[:, None, None] * _EYE3
        t_anchor = self._st_t.tolist()
        return {
            name: CoastState(
                t_s, pos[k], vel[k], pos_cov[k], vel_cov[k], None, t_anchor[k], s_a[k], q
            )
            for k, name in enumerate(names)
            if tau[k] > 0.0
        }

    # ------------------------------------------------------------------ frames

    def shift_frame(self, rot_ned: FloatArray, offset_ned_m: FloatArray) -> None:
        """Re-express everything in a new local frame: ``p_new = rot_ned @ p_old + offset``.

        Anchors, their covariances, the increment history and the attitude are
        rotated; positions are also offset. The slots keep their ages.
        """
        rot = np.asarray(rot_ned, dtype=float)
        off = np.asarray(offset_ned_m, dtype=float)
        if rot.shape != (3, 3) or off.shape != (3,) or not np.all(np.isfinite(rot)):
            raise ValueError("rot_ned must be (3, 3) and offset_ned_m (3,), finite")
        for s in self._slots:
            if s is None:
                continue
            s.pos = rot @ s.pos + off
            s.vel = rot @ s.vel
            s.pos_cov = rot @ s.pos_cov @ rot.T
            s.vel_cov = rot @ s.vel_cov @ rot.T
            s.acc_cov_bias = rot @ s.acc_cov_bias @ rot.T
            s.v_inc = rot @ s.v_inc
            s.p_inc = rot @ s.p_inc
        if self._h_t:
            hv = np.array(self._h_v) @ rot.T
            hp = np.array(self._h_p) @ rot.T
            self._h_v = [tuple(r) for r in hv.tolist()]  # type: ignore[misc]
            self._h_p = [tuple(r) for r in hp.tolist()]  # type: ignore[misc]
        self._v = (rot @ np.array(self._v)).tolist()
        self._p = (rot @ np.array(self._p)).tolist()
        self._last_a = tuple((rot @ np.array(self._last_a)).tolist())  # type: ignore[assignment]
        if self._att is not None:
            self._att = tuple((rot @ np.array(self._att).reshape(3, 3)).ravel().tolist())
        self._pd_run += float(off[2])
        self._g_ref_d += float(off[2])
        self._restack()

    def _restack(self) -> None:
        """Stack the anchored slots' arrays for :meth:`references` (one numpy pass for all)."""
        live = [(i, s) for i, s in enumerate(self._slots) if s is not None]
        self._names = [f"ins{i}" for i, _ in live]
        slots = [s for _, s in live]
        self._st_t = np.array([s.t_s for s in slots])
        self._st_pos = np.array([s.pos for s in slots]).reshape(-1, 3)
        self._st_vel = np.array([s.vel for s in slots]).reshape(-1, 3)
        self._st_pcov = np.array([s.pos_cov for s in slots]).reshape(-1, 3, 3)
        self._st_vcov = np.array([s.vel_cov for s in slots]).reshape(-1, 3, 3)
        self._st_bcov = np.array([s.acc_cov_bias for s in slots]).reshape(-1, 3, 3)
        self._st_vinc = np.array([s.v_inc for s in slots]).reshape(-1, 3)
        self._st_pinc = np.array([s.p_inc for s in slots]).reshape(-1, 3)

"""Synthetic approaches with injected GNSS faults, to test and benchmark the monitor cheaply.

An approach is a straight 3 deg glide towards the runway threshold (the local
NED origin, at the field elevation) with a wandering velocity (first-order
Gauss-Markov per axis: turbulence and small corrections). One or two receivers
see it with the simulator's GNSS error model (per-axis first-order
Gauss-Markov with the mode's sigma and correlation time,
:data:`companion.sim.sensors.GNSS_MODE_SPECS`), plus an injected fault on
receiver 0 (step, ramp or dither, as the simulator's events).

The navigator is :class:`CvKalman`, a constant-velocity Kalman filter that
fuses every fix of every receiver (as the GNSS/INS blend does): it follows a
slow ramp, which is what solution separation is for (Kim, Walter and Powell).
Its process noise is derived from the truth's velocity wander
(``q = 2 sigma_v^2 / tau_v``), so its innovation statistics are honest. No IMU,
no 400 Hz loop: hours of approaches run in minutes, which is what the Monte
Carlo bench (``bench/integrity.py``) needs.

:mod:`companion.sim.integrity_runs` drives the monitor with a simulated flight's
samples instead.

References
----------
Kim, Walter and Powell, "Standalone GPS-based flight inspection system" (4 cm/s
ramp, 1 m dither); El-Mowafy (2005) (GNSS mode accuracies, via the simulator's
table); Bar-Shalom, Li, Kirubarajan (2001) sec. 6.2 (the constant-velocity
model). ``docs/methods.md`` (the integrity monitor).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from companion.integrity.coast import CoastState
from companion.integrity.monitor import IntegrityMonitor
from companion.nav.navigator import GnssMeasurement, GnssUpdate, NavState
from companion.ranges import check_ranges, ranged
from companion.sim.integrity_runs import is_alarm
from companion.sim.scenarios import Event
from companion.sim.sensors import GNSS_MODE_SPECS, gauss_markov_fast
from companion.types import (
    Alert,
    FixType,
    FloatArray,
    GnssFix,
    NavMode,
    NavSolution,
    Output,
)

FAULT_KINDS = ("step", "ramp", "dither")
USABLE_GNSS_MODES = tuple(mode for mode in GNSS_MODE_SPECS if mode != "none")


@dataclass(frozen=True, slots=True)
class Fault:
    """A fault on one receiver from ``t_start_s`` to the end of the run.

    step: constant ``vector_ned`` (m); ramp: ``vector_ned`` (m/s) times the time
    since the start; dither: ``amplitude_m`` sin(2 pi tau / ``period_s``) along
    ``vector_ned`` (normalised).
    """

    kind: str
    t_start_s: float
    vector_ned: tuple[float, float, float]
    amplitude_m: float = 0.0
    period_s: float = 20.0
    receiver_id: int = 0

    def __post_init__(self) -> None:
        if self.kind not in FAULT_KINDS:
            raise ValueError(f"fault kind must be one of {FAULT_KINDS}")
        if not math.isfinite(self.t_start_s):
            raise ValueError("t_start_s must be finite")
        if self.kind == "dither" and not (self.period_s > 0.0 and self.amplitude_m > 0.0):
            raise ValueError("a dither needs period_s > 0 and amplitude_m > 0")

    def offset_ned_m(self, t_s: FloatArray) -> FloatArray:
        """The fault's position offset at times ``t_s`` (n,), m, shape (n, 3)."""
        t = np.asarray(t_s, dtype=float)
        tau = t - self.t_start_s
        on = (tau >= 0.0).astype(float)[:, None]
        vec = np.asarray(self.vector_ned, dtype=float)[None, :]
        if self.kind == "step":
            return on * vec
        if self.kind == "ramp":
            return on * vec * np.maximum(tau, 0.0)[:, None]
        axis = vec / np.linalg.norm(vec)
        return on * self.amplitude_m * np.sin(2.0 * math.pi * tau / self.period_s)[:, None] * axis

    def as_event(self, t_end_s: float) -> Event:
        """The same fault as the simulator's event on ``[t_start_s, t_end_s)``
        (:mod:`companion.sim.scenarios`: step ``offset_ned_m``, ramp ``rate_ned_mps``,
        dither ``amplitude_m``, ``period_s``, ``axis_ned``)."""
        params: dict[str, object]
        if self.kind == "dither":
            params = {
                "amplitude_m": self.amplitude_m,
                "period_s": self.period_s,
                "axis_ned": self.vector_ned,
            }
        else:
            key = "offset_ned_m" if self.kind == "step" else "rate_ned_mps"
            params = {key: self.vector_ned}
        return Event(self.kind, self.t_start_s, t_end_s, self.receiver_id, params)

    def size_m(self, t_s: float) -> float:
        """Magnitude of the offset at ``t_s``, m (for a dither: its amplitude once started)."""
        if t_s < self.t_start_s:
            return 0.0
        if self.kind == "dither":
            return self.amplitude_m
        return float(np.linalg.norm(self.offset_ned_m(np.array([t_s]))[0]))


@dataclass(frozen=True, slots=True)
class ApproachSpec:
    """One synthetic approach."""

    duration_s: float = ranged(115.0, gt=0.0)
    speed_mps: float = ranged(70.0, gt=0.0)
    glide_deg: float = 3.0
    start_height_m: float = 440.0
    field_elevation_msl_m: float = 110.0
    gnss_mode: str = ranged("rtk_fixed", choices=USABLE_GNSS_MODES)
    rate_hz: float = ranged(10.0, gt=0.0)
    receivers: int = ranged(2, choices=(1, 2))
    vel_wander_h_mps: float = 1.0
    vel_wander_v_mps: float = 0.3
    vel_wander_tau_s: float = ranged(10.0, gt=0.0)
    fuse_all: bool = False
    """False: the navigator fuses the first receiver not excluded (the primary; the other is
    the independent solution); True: it fuses every receiver not excluded."""
    faults: tuple[Fault, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        check_ranges(self)


class CvKalman:
    """Constant-velocity Kalman filter on 3 independent axes, fusing position fixes.

    State per axis (position m, velocity m/s); white acceleration noise of
    spectral density ``q`` (m^2/s^3) per axis. ``on_gnss`` returns the
    position innovation record the monitor reads.

    References
    ----------
    Bar-Shalom, Li, Kirubarajan (2001) sec. 6.2.2 (continuous white-noise acceleration).
    """

    def __init__(self, q_m2ps3: FloatArray, gate_false_alarm_prob: float = 1e-4) -> None:
        self.q = np.asarray(q_m2ps3, dtype=float)
        self.gate = float(chi2.isf(gate_false_alarm_prob, 3))
        self.t_s: float | None = None
        self.x = np.zeros((3, 2))
        self.p = np.zeros((3, 2, 2))
        self.rejects = 0

    def init(self, t_s: float, pos: FloatArray, vel: FloatArray, var_pos: FloatArray) -> None:
        """Start from a position (with its variance) and a velocity (variance 1 m^2/s^2)."""
        self.t_s = t_s
        self.x[:, 0] = pos
        self.x[:, 1] = vel
        self.p[:] = 0.0
        self.p[:, 0, 0] = var_pos
        self.p[:, 1, 1] = 1.0

    def _predicted(self, t_s: float) -> tuple[FloatArray, FloatArray]:
        if self.t_s is None:
            raise ValueError("filter not initialised")
        dt = t_s - self.t_s
        x = self.x.copy()
        x[:, 0] += dt * x[:, 1]
        p = self.p.copy()
        p00 = p[:, 0, 0] + 2 * dt * p[:, 0, 1] + dt * dt * p[:, 1, 1] + self.q * dt**3 / 3.0
        p01 = p[:, 0, 1] + dt * p[:, 1, 1] + self.q * dt**2 / 2.0
        p11 = p[:, 1, 1] + self.q * dt
        p[:, 0, 0], p[:, 0, 1], p[:, 1, 0], p[:, 1, 1] = p00, p01, p01, p11
        return x, p

    def predict(self, t_s: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Position, velocity (3,) and their diagonal covariances (3, 3) at ``t_s``."""
        x, p = self._predicted(t_s)
        return x[:, 0].copy(), x[:, 1].copy(), np.diag(p[:, 0, 0]), np.diag(p[:, 1, 1])

    def on_gnss(self, meas: GnssMeasurement, *, gate: bool = True) -> GnssUpdate:
        """Gate and fuse one position fix."""
        x, p = self._predicted(meas.t_s)
        r = meas.pos_var_ned_m2
        innov = meas.pos_ned_m - x[:, 0]
        s = p[:, 0, 0] + r
        nis = float(np.sum(innov * innov / s))
        s_cov = np.diag(s)
        if gate and nis > self.gate:
            self.rejects += 1
            return GnssUpdate(meas.t_s, False, nis, 3, self.gate, innov, s_cov, "gate")
        self.rejects = 0
        k0 = p[:, 0, 0] / s
        k1 = p[:, 0, 1] / s
        x[:, 0] += k0 * innov
        x[:, 1] += k1 * innov
        p00 = (1 - k0) * p[:, 0, 0]
        p01 = (1 - k0) * p[:, 0, 1]
        p11 = p[:, 1, 1] - k1 * p[:, 0, 1]
        p[:, 0, 0], p[:, 0, 1], p[:, 1, 0], p[:, 1, 1] = p00, p01, p01, p11
        self.x, self.p, self.t_s = x, p, meas.t_s
        return GnssUpdate(meas.t_s, True, nis, 3, self.gate, innov, s_cov)


class SyntheticReference:
    """Inertial-coast-like references without an IMU: truth plus the coast's error model.

    ``slots`` anchors staggered over ``life_s`` (as :class:`InertialCoast`); at each
    anchor a position error, a velocity error and a constant acceleration error are
    drawn from the stated 1-sigmas (per axis, independent), and the slot's error at
    age ``tau`` is ``dp0 + dv0 tau + a tau^2 / 2``, with the covariance the coast
    reports (:class:`CoastState`). The anchors do not depend on the receivers (an
    ideal navigator): this exercises the monitor's drift-aware tests and attribution
    at the cost of the synthetic approaches.

    References
    ----------
    :mod:`companion.integrity.coast` (error model and covariance).
    """

    def __init__(
        self,
        rng: np.random.Generator,
        anchor_sigma_pos_m: float = 0.02,
        anchor_sigma_vel_mps: float = 0.005,
        acc_sigma_mps2: tuple[float, float, float] = (3e-4, 3e-4, 3e-4),
        slots: int = 6,
        life_s: float = 60.0,
    ) -> None:
        if slots < 1 or not life_s > 0.0:
            raise ValueError("slots must be >= 1 and life_s > 0")
        self.rng = rng
        self.sp = anchor_sigma_pos_m
        self.sv = anchor_sigma_vel_mps
        self.sa = np.asarray(acc_sigma_mps2, dtype=float)
        self.slots = slots
        self.life_s = life_s
        self._t0: float | None = None
        self._anchor: list[tuple[float, FloatArray, FloatArray, FloatArray] | None] = [None] * slots

    def at(
        self, t_s: float, pos_ned_m: FloatArray, vel_ned_mps: FloatArray, hold: bool = False
    ) -> dict[str, NavState]:
        """The slots' references at ``t_s`` given the truth there (re-anchoring due slots,
        unless ``hold``: the engine does not re-anchor while the monitor reports a fault)."""
        if self._t0 is None:
            self._t0 = t_s
        out: dict[str, NavState] = {}
        sp2, sv2 = self.sp**2, self.sv**2
        s_a = np.diag(self.sa**2)
        for i in range(self.slots):
            a = self._anchor[i]
            if not hold and (
                (a is None and t_s >= self._t0 + i * self.life_s / self.slots)
                or (a is not None and t_s - a[0] >= self.life_s)
            ):
                a = (
                    t_s,
                    self.rng.normal(0.0, self.sp, 3),
                    self.rng.normal(0.0, self.sv, 3),
                    self.rng.normal(0.0, 1.0, 3) * self.sa,
                )
                self._anchor[i] = a
            if a is None:
                continue
            tau = t_s - a[0]
            err_p = a[1] + a[2] * tau + 0.5 * a[3] * tau * tau
            err_v = a[2] + a[3] * tau
            pos_cov = np.eye(3) * (sp2 + tau * tau * sv2) + s_a * (0.25 * tau**4)
            vel_cov = np.eye(3) * sv2 + s_a * (tau * tau)
            out[f"ins{i}"] = CoastState(
                t_s, pos_ned_m + err_p, vel_ned_mps + err_v, pos_cov, vel_cov, None, a[0], s_a, 0.0
            )
        return out


@dataclass(frozen=True, slots=True)
class RunResult:
    """What one synthetic run gives the scorer.

    ``first_alert_s``: time of the monitor's first FAULT or INTEGRITY-lost alert at or
    after ``t_from_s`` (None: none); ``alerts``: all FAULT/INTEGRITY-lost alert times;
    ``baseline_first_s`` / ``baseline_alerts``: the same for a plain innovation chi-square
    monitor (an alert at each onset of NIS above ``chi2^-1(1 - P_fa, 3)``).
    """

    first_alert_s: float | None
    alerts: tuple[float, ...]
    baseline_first_s: float | None
    baseline_alerts: tuple[float, ...]
    hours: float
    monitor: IntegrityMonitor
    first_alert_text: str = ""
    """The text of the first alert counted in ``first_alert_s`` (which test fired)."""


def truth_and_fixes(
    spec: ApproachSpec, rng: np.random.Generator
) -> tuple[FloatArray, FloatArray, FloatArray, list[FloatArray], FloatArray]:
    """Times (n,), truth position (n, 3), truth velocity (n, 3), per-receiver fix positions
    (n, 3) each, and the per-axis fix variance (3,), for one approach."""
    n = int(round(spec.duration_s * spec.rate_hz)) + 1
    dt = 1.0 / spec.rate_hz
    t: FloatArray = np.arange(n, dtype=float) * dt
    gamma = math.radians(spec.glide_deg)
    v0 = np.array([spec.speed_mps * math.cos(gamma), 0.0, spec.speed_mps * math.sin(gamma)])
    wander = np.column_stack(
        (
            gauss_markov_fast(rng, n, dt, spec.vel_wander_h_mps, spec.vel_wander_tau_s, 2),
            gauss_markov_fast(rng, n, dt, spec.vel_wander_v_mps, spec.vel_wander_tau_s, 1),
        )
    )
    vel: FloatArray = v0[None, :] + wander
    start = np.array(
        [-spec.start_height_m / math.tan(gamma), 0.0, -spec.start_height_m], dtype=float
    )
    pos: FloatArray = start[None, :] + np.vstack(
        (np.zeros(3), np.cumsum(0.5 * (vel[1:] + vel[:-1]) * dt, 0))
    )
    mode = GNSS_MODE_SPECS[spec.gnss_mode]
    var: FloatArray = np.array([mode.sigma_h_m**2, mode.sigma_h_m**2, mode.sigma_v_m**2])
    fixes: list[FloatArray] = []
    for rid in range(spec.receivers):
        err = np.column_stack(
            (
                gauss_markov_fast(rng, n, dt, mode.sigma_h_m, mode.tau_s, 2),
                gauss_markov_fast(rng, n, dt, mode.sigma_v_m, mode.tau_s, 1),
            )
        )
        fix = pos + err
        for fault in spec.faults:
            if fault.receiver_id == rid:
                fix = fix + fault.offset_ned_m(t)
        fixes.append(fix)
    return t, pos, vel, fixes, var


def run_approach(
    spec: ApproachSpec,
    monitor: IntegrityMonitor,
    rng: np.random.Generator,
    t_from_s: float = 0.0,
    baseline_false_alarm_prob: float | None = None,
    t_offset_s: float = 0.0,
    reference: SyntheticReference | None = None,
) -> RunResult:
    """Fly one approach through :class:`CvKalman` and ``monitor`` (and the plain baseline).

    ``t_offset_s`` shifts every time (a sequence of approaches on one clock); the
    monitor is reset first. The engine's rule is followed: fixes of an excluded
    receiver are not offered to the navigator, but still go to the monitor. The
    baseline has its own navigator with the same fusion policy and no exclusions (what a
    system with only the innovation test would fly). ``reference``: inertial-like
    references given to the monitor with every fix.
    """
    cfg = monitor.config
    p_fa = cfg.false_alarm_prob if baseline_false_alarm_prob is None else baseline_false_alarm_prob
    base_th = float(chi2.isf(p_fa, 3))
    t, pos, vel, fixes, var = truth_and_fixes(spec, rng)
    t = t + t_offset_s
    mode = GNSS_MODE_SPECS[spec.gnss_mode]
    wander = np.array([spec.vel_wander_h_mps, spec.vel_wander_h_mps, spec.vel_wander_v_mps])
    q = 2.0 * wander**2 / spec.vel_wander_tau_s
    nav = CvKalman(q)
    nav.init(float(t[0]), fixes[0][0], vel[0], var)
    plain = CvKalman(q)  # the baseline's navigator: same fusion policy, never excludes
    plain.init(float(t[0]), fixes[0][0], vel[0], var)
    monitor.reset()
    alerts: list[float] = []
    texts: list[str] = []
    base_alerts: list[float] = []
    base_high = [False] * spec.receivers
    nan3 = np.full(3, np.nan)
    field_elev = spec.field_elevation_msl_m
    for k in range(1, t.size):
        tk = float(t[k])
        outputs: list[Output] = []
        fused_one = False
        refs = (
            None
            if reference is None
            else reference.at(tk, pos[k], vel[k], hold=monitor.fault_detected)
        )
        for rid in range(spec.receivers):
            p_fix = fixes[rid][k]
            meas = GnssMeasurement(tk, p_fix, var, nan3, nan3, mode.fix_type, rid)
            gfix = _fix(tk, rid, mode.fix_type)
            update: GnssUpdate | None = None
            if not monitor.exclude(rid) and (spec.fuse_all or not fused_one):
                fused_one = True
                update = nav.on_gnss(meas)
            if spec.fuse_all or rid == 0:
                high = plain.on_gnss(meas).nis > base_th
                if high and not base_high[rid]:
                    base_alerts.append(tk)
                base_high[rid] = high
            outputs += monitor.on_fix(gfix, meas, update, references=refs)
        p_nav, v_nav, p_cov, v_cov = nav.predict(tk)
        sol = NavSolution(
            t_s=tk,
            lat_rad=0.0,
            lon_rad=0.0,
            alt_msl_m=field_elev - float(p_nav[2]),
            vel_ned_mps=v_nav,
            pos_cov_ned_m2=p_cov,
            vel_cov_ned_m2ps2=v_cov,
            yaw_rad=None,
            mode=NavMode.NORMAL,
            fix_type=mode.fix_type,
            satellites=mode.satellites,
        )
        outputs += monitor.on_solution(sol)
        for out in outputs:
            if isinstance(out, Alert) and is_alarm(out):
                alerts.append(out.t_s)
                texts.append(out.text)
    t_from = t_from_s + t_offset_s
    i_first = next((i for i, a in enumerate(alerts) if a >= t_from), None)
    first = alerts[i_first] if i_first is not None else None
    first_text = texts[i_first] if i_first is not None else ""
    base_first = next((a for a in base_alerts if a >= t_from), None)
    hours = (float(t[-1]) - float(t[0])) / 3600.0
    return RunResult(
        first, tuple(alerts), base_first, tuple(base_alerts), hours, monitor, first_text
    )


def _fix(t_s: float, rid: int, fix_type: FixType) -> GnssFix:
    return GnssFix(
        t_s=t_s,
        t_rx_s=t_s,
        receiver_id=rid,
        fix_type=fix_type,
        lat_rad=0.0,
        lon_rad=0.0,
        alt_msl_m=0.0,
        alt_hae_m=None,
        vel_ne_mps=None,
        ground_speed_mps=0.0,
        course_rad=None,
        h_acc_m=None,
        v_acc_m=None,
        vel_acc_mps=None,
        hdop=None,
        vdop=None,
        satellites=None,
    )

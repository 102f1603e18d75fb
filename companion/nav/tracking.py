"""Tracking the aircraft from a ground station: azimuth, elevation, range and their rates.

The θ-θ channel of "Tracking with the aircraft's kinematic and dynamic parameters":
an acceleration-state filter updated with two observations (the paper's z1, z2):

    z1(k) = r(k) + v1(k)                  the reported position
    z2(k) = a(k) + C_nb b + v2(k)         the aircraft's acceleration from its own
                                          attitude and specific force, a = C_nb f_b + g

The paper writes both per angle channel (θ and θ̈). Here the state is the
station-relative position, velocity and acceleration in the station's NED frame,
where both observations are linear; the angles, their rates and their
accelerations are exact functions of (r, v, a) (:func:`spherical_rates`), so the
angular-acceleration observation carries the same information without the
linearisation of its velocity terms (2 β̇ ρ̇/ρ and the like) about the filter's
own rates. The acceleration is Singer's (mean-reverting, stationary 1σ σ_m) but
driven by a first-order Markov jerk instead of white noise: between two z2
samples a white-driven acceleration is a Brownian bridge, which leaves the
velocity wandering and keeps the channel well above a filter told the
acceleration; a smooth one lets z2 carry it (the channel's steady-state position
σ is then within 1.2× (1 Hz) and 1.05× (5 Hz) of that filter's, from 1.4×).
Two additions the real telemetry needs:

* ``b``: a body-frame bias of the acceleration observation (a tilt offset between
  ATTITUDE and the accelerometer, an accelerometer bias), a slow random walk;
  real autopilot logs show 0.2–0.9 m/s² of it, which would otherwise be taken
  for a manoeuvre;
* the observation noise of z2 is estimated from its own innovations (covariance
  matching, Mohamed and Schwarz 1999), floored at the sensor model: one IMU sample taken down a
  telemetry link carries vibration that depends on the airframe.

Baselines, in the same frame and machinery (filterpy's
:class:`~filterpy.kalman.KalmanFilter`), positions only: Singer's
manoeuvring-target model (Singer 1970: the acceleration a first-order Markov
process of time constant τ and variance σ_m², van Loan's discretisation) and a
constant-velocity filter (white acceleration).

Pure: no I/O, no clock (times are the samples' ``t_s``). Elevation near ±90°
(overhead) is a singularity of the angles, as for any az/el mount.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from filterpy.common import Q_continuous_white_noise, van_loan_discretization
from filterpy.kalman import KalmanFilter
from filterpy.kalman import predict as kf_predict

from companion.types import FloatArray

Model = Literal["dynamic", "singer", "cv"]
MODELS: tuple[Model, ...] = ("dynamic", "singer", "cv")
MIN_RANGE_M = 10.0
"""Below this the angles are meaningless: positions this close to the station are refused."""
GRAVITY_MPS2 = 9.80665
_I3 = np.eye(3)


@dataclass(frozen=True, slots=True)
class TrackerConfig:
    """Noise model of the tracking filters (SI units, 1σ).

    The dynamic channel and Singer's share the manoeuvre model (σ_m, τ: Singer's
    values for an evasive manoeuvre, not fitted); the dynamic channel's
    acceleration changes through a jerk of correlation time ``jerk_tau_s`` (an
    aircraft's roll response, not fitted) scaled to the same stationary σ_m, so
    that without z2 it predicts the same manoeuvre amplitude. The measurement
    noises are the telemetry's (defaults: an autopilot's estimate over a radio
    link, see ``bench/tracking.py``'s realistic profile), the same for every model.
    """

    pos_sigma_m: float = 0.7
    """White error of a reported position per axis, m (unless the report carries one)."""
    pos_gm_sigma_m: float = 1.5
    """Slowly wandering error of the reported positions per axis (first-order Markov), m."""
    pos_gm_tau_s: float = 30.0
    """Its correlation time, s."""
    singer_tau_s: float = 10.0
    """Singer and dynamic: manoeuvre time constant 1/α, s."""
    singer_sigma_mps2: float = 3.0
    """Singer and dynamic: standard deviation of the manoeuvre acceleration σ_m, m/s²."""
    cv_acc_psd: float = 3.0
    """Constant velocity: power spectral density of the white acceleration, m²/s³."""
    f_sigma_mps2: float = 0.5
    """Dynamic: noise of one accelerometer sample down the link (vibration), m/s²."""
    att_sigma_rad: float = math.radians(0.5)
    """Dynamic: noise of one ATTITUDE message, rad (with f: the floor of z2's noise)."""
    acc_sigma_start_mps2: float = 1.0
    """Dynamic: z2's noise assumed before its innovations tell, m/s²."""
    acc_sigma_max_mps2: float = 5.0
    """Dynamic: the estimated z2 noise is kept below this, m/s²."""
    acc_noise_memory: int = 50
    """Dynamic: samples over which the z2 noise is estimated (forgetting factor 1/N)."""
    bias_sigma_mps2: float = 0.5
    """Dynamic: prior 1σ of the body-frame bias of z2 per axis, m/s²."""
    bias_walk_psd: float = 1e-6
    """Dynamic: random walk of that bias, m²/s⁵ (a mounting tilt, an accelerometer
    bias: 0.03 m/s² over 1000 s)."""
    jerk_tau_s: float = 0.3
    """Dynamic: correlation time of the jerk, s (an aircraft's roll response); 0: no
    jerk state, Singer's white-driven acceleration."""

    @property
    def jerk_sigma_mps3(self) -> float:
        """Dynamic: 1σ of the jerk, m/s³, such that the acceleration's stationary 1σ is
        Singer's σ_m: σ_a² = σ_j² τ_a² τ_j / (τ_a + τ_j) for ȧ = -a/τ_a + j."""
        if self.jerk_tau_s <= 0.0:
            return 0.0
        tau_a, tau_j = self.singer_tau_s, self.jerk_tau_s
        return self.singer_sigma_mps2 * math.sqrt((tau_a + tau_j) / (tau_a * tau_a * tau_j))

    @property
    def acc_sigma_floor_mps2(self) -> float:
        """z2's noise from the sensor model alone: √(σ_f² + (g σ_att)²)."""
        return math.hypot(self.f_sigma_mps2, GRAVITY_MPS2 * self.att_sigma_rad)


@dataclass(frozen=True, slots=True)
class TrackEstimate:
    """The track at one time: angles (rad), range (m), their rates and 1σ."""

    t_s: float
    az_rad: float
    el_rad: float
    range_m: float
    az_rate_radps: float
    el_rate_radps: float
    range_rate_mps: float
    az_sigma_rad: float
    el_sigma_rad: float
    range_sigma_m: float
    since_position_s: float
    """Time since the last reported position, s (the prediction's length)."""
    pos_ned_m: FloatArray
    """The estimated position in the station's NED frame, m."""
    vel_ned_mps: FloatArray
    pos_cov_m2: FloatArray
    """Covariance of ``pos_ned_m``, m² (3×3)."""

    @property
    def pointing_sigma_rad(self) -> float:
        """1σ of the pointing error (the angle between estimated and true line of sight)."""
        return math.hypot(self.az_sigma_rad * math.cos(self.el_rad), self.el_sigma_rad)


def ned_to_spherical(pos_ned_m: FloatArray) -> tuple[float, float, float]:
    """Station-relative NED position to (azimuth from north, elevation up, range)."""
    n, e, d = float(pos_ned_m[0]), float(pos_ned_m[1]), float(pos_ned_m[2])
    rho = math.hypot(n, e)
    return math.atan2(e, n), math.atan2(-d, rho), math.sqrt(rho * rho + d * d)


def los_to_ned(az_rad: float, el_rad: float, range_m: float) -> FloatArray:
    """(azimuth, elevation, range) to a station-relative NED position, m."""
    ce = math.cos(el_rad)
    return range_m * np.array([ce * math.cos(az_rad), ce * math.sin(az_rad), -math.sin(el_rad)])


def spherical_jacobian(pos_ned_m: FloatArray) -> FloatArray:
    """∂(β, ε, D)/∂(N, E, D) at a station-relative position (rows: az, el, range)."""
    n, e, d = (float(x) for x in pos_ned_m)
    rho2 = max(n * n + e * e, 1e-9)
    rho = math.sqrt(rho2)
    dist2 = rho2 + d * d
    dist = math.sqrt(dist2)
    return np.array(
        [
            [-e / rho2, n / rho2, 0.0],
            [n * d / (rho * dist2), e * d / (rho * dist2), -rho / dist2],
            [n / dist, e / dist, d / dist],
        ]
    )


def spherical_rates(
    pos_ned_m: FloatArray, vel_ned_mps: FloatArray, acc_ned_mps2: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """First and second time derivatives of (β, ε, D) from Cartesian r, v, a (exact).

    β = atan2(E, N), ε = atan2(h, ρ) with h = -Down and ρ = √(N²+E²), D = |r|.
    """
    n, e, d = (float(x) for x in pos_ned_m)
    vn, ve, vd = (float(x) for x in vel_ned_mps)
    an, ae, ad = (float(x) for x in acc_ned_mps2)
    h, vh, ah = -d, -vd, -ad
    rho2 = max(n * n + e * e, 1e-9)
    rho = math.sqrt(rho2)
    dist2 = rho2 + h * h
    dist = math.sqrt(dist2)
    rho_d = (n * vn + e * ve) / rho
    rho_dd = (vn * vn + ve * ve + n * an + e * ae) / rho - rho_d * rho_d / rho
    az_d = (n * ve - e * vn) / rho2
    az_dd = (n * ae - e * an) / rho2 - 2.0 * az_d * (n * vn + e * ve) / rho2
    el_d = (rho * vh - h * rho_d) / dist2
    el_dd = (rho * ah - h * rho_dd) / dist2 - 2.0 * el_d * (rho * rho_d + h * vh) / dist2
    dist_d = (n * vn + e * ve + h * vh) / dist
    v2 = vn * vn + ve * ve + vh * vh
    dist_dd = (v2 + n * an + e * ae + h * ah) / dist - dist_d * dist_d / dist
    return np.array([az_d, el_d, dist_d]), np.array([az_dd, el_dd, dist_dd])


def los_velocity_ned(az_rad: float, el_rad: float, range_m: float, rates: FloatArray) -> FloatArray:
    """Cartesian velocity from (β, ε, D) and their rates: Ḋ e_r + D ε̇ e_ε + D β̇ cos ε e_β."""
    sb, cb = math.sin(az_rad), math.cos(az_rad)
    se, ce = math.sin(el_rad), math.cos(el_rad)
    e_r = np.array([ce * cb, ce * sb, -se])
    e_el = np.array([-se * cb, -se * sb, -ce])
    e_az = np.array([-sb, cb, 0.0])
    az_d, el_d, dist_d = (float(x) for x in rates)
    return dist_d * e_r + range_m * el_d * e_el + range_m * az_d * ce * e_az


def acceleration_ned(mat_nb: FloatArray, f_b_mps2: FloatArray, gravity_mps2: float) -> FloatArray:
    """The aircraft's acceleration in NED from attitude and specific force: C_nb f_b + g."""
    a = np.asarray(mat_nb, dtype=float) @ np.asarray(f_b_mps2, dtype=float)
    a[2] += gravity_mps2
    return a


@functools.lru_cache(maxsize=512)
def _singer_unit(dt: float, tau_s: float) -> tuple[FloatArray, FloatArray]:
    """Singer's transition and process noise for σ_m = 1 over ``dt`` (cached: one per rate).

    ȧ = -α a + w with E[w w] = 2α σ_m² (Singer 1970), discretised by van Loan's method.
    """
    alpha = 1.0 / tau_s
    a_c = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -alpha]])
    g = np.array([[0.0], [0.0], [math.sqrt(2.0 * alpha)]])
    f, q = van_loan_discretization(a_c, g, dt)
    q = 0.5 * (q + q.T)
    f.setflags(write=False)
    q.setflags(write=False)
    return f, q


_JERK_STEP_S = 0.5
"""Longest interval discretised at once: van Loan's block exponential of the stiff jerk
model (-1/τ_j against t⁵ growth) loses the positive definiteness of Q beyond a few
seconds; longer intervals are composed from halves."""


@functools.lru_cache(maxsize=512)
def _jerk_unit(dt: float, tau_a_s: float, tau_j_s: float) -> tuple[FloatArray, FloatArray]:
    """Transition and process noise of [r, v, a, j] for σ_j = 1 over ``dt`` (cached).

    ȧ = -a/τ_a + j, j̇ = -j/τ_j + w with E[w w] = 2 σ_j²/τ_j: Singer's mean-reverting
    acceleration driven by a smooth (first-order Markov) jerk instead of white noise.
    """
    if dt > _JERK_STEP_S:
        # two halves: F = F½ F½, Q = F½ Q½ F½ᵀ + Q½ (a sum of positive definite terms)
        f2, q2 = _jerk_unit(0.5 * dt, tau_a_s, tau_j_s)
        f = f2 @ f2
        q = f2 @ q2 @ f2.T + q2
        q = 0.5 * (q + q.T)
        f.setflags(write=False)
        q.setflags(write=False)
        return f, q
    a_c = np.array(
        [
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, -1.0 / tau_a_s, 1.0],
            [0.0, 0.0, 0.0, -1.0 / tau_j_s],
        ]
    )
    g = np.array([[0.0], [0.0], [0.0], [math.sqrt(2.0 / tau_j_s)]])
    f, q = van_loan_discretization(a_c, g, dt)
    q = 0.5 * (q + q.T)
    f.setflags(write=False)
    q.setflags(write=False)
    return f, q


@functools.lru_cache(maxsize=1024)
def _transition(model: Model, dt: float, cfg: TrackerConfig) -> tuple[FloatArray, FloatArray]:
    """(F, Q) over ``dt`` for the state [r, v, (a), (j), (b), e], 3 axes each (cached)."""
    if model == "cv":
        f1 = np.array([[1.0, dt], [0.0, 1.0]])
        q1 = Q_continuous_white_noise(2, dt, cfg.cv_acc_psd)
    elif model == "dynamic" and cfg.jerk_sigma_mps3 > 0.0:
        f1, q1 = _jerk_unit(dt, cfg.singer_tau_s, cfg.jerk_tau_s)
        q1 = q1 * cfg.jerk_sigma_mps3**2
    else:
        f1, q1 = _singer_unit(dt, cfg.singer_tau_s)
        q1 = q1 * cfg.singer_sigma_mps2**2
    n = 3 * f1.shape[0]
    dim = _dim(model, cfg)
    f = np.eye(dim)
    f[:n, :n] = np.kron(f1, _I3)
    q = np.zeros((dim, dim))
    q[:n, :n] = np.kron(q1, _I3)
    if model == "dynamic":
        q[n : n + 3, n : n + 3] = cfg.bias_walk_psd * dt * _I3
    # the reported positions' wandering error: e' = -e/τ + w
    phi = math.exp(-dt / cfg.pos_gm_tau_s)
    f[dim - 3 :, dim - 3 :] = phi * _I3
    q[dim - 3 :, dim - 3 :] = cfg.pos_gm_sigma_m**2 * (1.0 - phi * phi) * _I3
    for m in (f, q):
        m.setflags(write=False)
    return f, q


def _order(model: Model, cfg: TrackerConfig) -> int:
    """Kinematic states per axis: r, v (cv); r, v, a (singer); r, v, a, (j) (dynamic)."""
    if model == "cv":
        return 2
    return 4 if model == "dynamic" and cfg.jerk_sigma_mps3 > 0.0 else 3


def _dim(model: Model, cfg: TrackerConfig) -> int:
    """State size: the kinematic states, then b (dynamic), then e; 3 axes each."""
    return 3 * (_order(model, cfg) + (model == "dynamic") + 1)


class Tracker:
    """Azimuth, elevation and range of the aircraft from a station, by one model.

    Feed :meth:`position` with each reported position (station NED, m) and, for
    the ``dynamic`` model, :meth:`acceleration` with each acceleration from the
    aircraft's attitude and specific force (:func:`acceleration_ned`, and the
    attitude itself so that the bias is estimated in the body frame); the
    baselines ignore the latter. :meth:`estimate` predicts to any time.
    Samples older than the filter's time, non-finite or on the station are
    counted in ``rejected`` and dropped.

    ``nis_position`` / ``nis_acceleration``: sums of the normalised innovation
    squares (3 degrees of freedom each) over ``positions`` / ``accelerations``
    updates, the filter's own consistency check.
    """

    def __init__(self, model: Model = "dynamic", config: TrackerConfig | None = None) -> None:
        if model not in MODELS:
            raise ValueError(f"unknown tracking model {model!r} (known: {', '.join(MODELS)})")
        self.model: Model = model
        self.cfg = config or TrackerConfig()
        self._order = _order(model, self.cfg)
        self._dim = _dim(model, self.cfg)
        self._bias = 3 * self._order
        """Index of the bias b in the state (dynamic model)."""
        self.kf = KalmanFilter(dim_x=self._dim, dim_z=3)
        self.t_s: float | None = None
        self.t_position_s: float | None = None
        self.positions = 0
        self.accelerations = 0
        self.rejected = 0
        self.nis_position = 0.0
        self.nis_acceleration = 0.0
        self.acc_var_mps2 = np.full(
            3, max(self.cfg.acc_sigma_start_mps2, self.cfg.acc_sigma_floor_mps2) ** 2
        )
        """The estimated variance of z2 per NED axis, m²/s⁴."""

    @property
    def started(self) -> bool:
        return self.t_s is not None

    @property
    def bias_b_mps2(self) -> FloatArray:
        """The estimated body-frame bias of z2, m/s² (zeros for the baselines)."""
        if self.model != "dynamic" or self.t_s is None:
            return np.zeros(3)
        return np.asarray(self.kf.x[self._bias : self._bias + 3, 0], dtype=float).copy()

    def _fq(self, dt: float) -> tuple[FloatArray, FloatArray]:
        return _transition(self.model, round(dt, 6), self.cfg)

    def _advance(self, t_s: float) -> bool:
        if self.t_s is None or t_s < self.t_s:
            self.rejected += self.t_s is not None
            return False
        dt = t_s - self.t_s
        if dt > 0.0:
            f, q = self._fq(dt)
            self.kf.predict(F=f, Q=q)
            self.t_s = t_s
        return True

    def _start(self, t_s: float, pos_ned_m: FloatArray, r: FloatArray) -> None:
        x = np.zeros((self._dim, 1))
        x[0:3, 0] = pos_ned_m
        # rates unknown at the first fix: ~100 m/s, ~10 m/s², the jerk at its stationary 1σ
        jerk2 = self.cfg.jerk_sigma_mps3**2
        p = [np.diag(r), 100.0**2 * _I3, 10.0**2 * _I3, jerk2 * _I3][: self._order]
        if self.model == "dynamic":
            p.append(self.cfg.bias_sigma_mps2**2 * _I3)
        p.append(self.cfg.pos_gm_sigma_m**2 * _I3)
        self.kf.x = x
        self.kf.P = np.zeros((self._dim, self._dim))
        for i, blk in enumerate(p):
            self.kf.P[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = blk
        # r = z1 - e: the first position carries the wandering error too
        gm2 = self.cfg.pos_gm_sigma_m**2 * _I3
        self.kf.P[0:3, 0:3] += gm2
        self.kf.P[0:3, self._dim - 3 :] = -gm2
        self.kf.P[self._dim - 3 :, 0:3] = -gm2
        self.t_s = t_s

    def position(
        self, t_s: float, pos_ned_m: FloatArray, sigma_ned_m: FloatArray | None = None
    ) -> bool:
        """Update with a reported position (station-relative NED, m; optionally its 1σ per
        axis, m); False if rejected."""
        pos = np.asarray(pos_ned_m, dtype=float)
        if not np.all(np.isfinite(pos)) or float(np.linalg.norm(pos)) < MIN_RANGE_M:
            self.rejected += 1
            return False
        sig = np.full(3, self.cfg.pos_sigma_m)
        if sigma_ned_m is not None and np.all(np.isfinite(sigma_ned_m)):
            sig = np.maximum(np.asarray(sigma_ned_m, dtype=float), 0.1)
        r = np.diag(sig * sig)
        if self.t_s is None:
            self._start(t_s, pos, np.diag(r))
        elif not self._advance(t_s):
            return False
        else:
            h = np.zeros((3, self._dim))
            h[:, 0:3] = _I3
            h[:, self._dim - 3 :] = _I3  # z1 = r + e + v1
            self.kf.update(pos.reshape(3, 1), R=r, H=h)
            self.nis_position += (self.kf.y.T @ self.kf.SI @ self.kf.y).item()
        self.t_position_s = t_s
        self.positions += 1
        return True

    def acceleration(
        self, t_s: float, acc_ned_mps2: FloatArray, mat_nb: FloatArray | None = None
    ) -> bool:
        """Second observation: the aircraft's acceleration (station NED, m/s²), from the
        attitude ``mat_nb`` (body to NED) and the specific force (dynamic model only)."""
        if self.model != "dynamic" or self.t_s is None:
            return False
        acc = np.asarray(acc_ned_mps2, dtype=float)
        if not np.all(np.isfinite(acc)) or (mat_nb is not None and not np.all(np.isfinite(mat_nb))):
            self.rejected += 1
            return False
        if not self._advance(t_s):
            return False
        h = np.zeros((3, self._dim))
        h[:, 6:9] = _I3
        if mat_nb is not None:
            h[:, self._bias : self._bias + 3] = np.asarray(mat_nb, dtype=float)
        # z2's noise by covariance matching of the innovations (Mohamed and Schwarz
        # 1999, eq. 20-28):
        # E[ν νᵀ] = H P⁻ Hᵀ + R; the plain mean of the first N samples, then a fading
        # memory of N; from a cautious start, between the sensor model's floor and a cap
        nu = acc - (h @ self.kf.x)[:, 0]
        hph = np.diag(h @ self.kf.P @ h.T)
        lam = 1.0 / min(self.accelerations + 1, max(self.cfg.acc_noise_memory, 1))
        est = (1.0 - lam) * self.acc_var_mps2 + lam * (nu * nu - hph)
        self.acc_var_mps2 = np.clip(
            est, self.cfg.acc_sigma_floor_mps2**2, self.cfg.acc_sigma_max_mps2**2
        )
        self.kf.update(acc.reshape(3, 1), R=np.diag(self.acc_var_mps2), H=h)
        self.nis_acceleration += (self.kf.y.T @ self.kf.SI @ self.kf.y).item()
        self.accelerations += 1
        return True

    def estimate(self, t_s: float) -> TrackEstimate | None:
        """The track predicted to ``t_s`` (None before the first position)."""
        if self.t_s is None or self.t_position_s is None:
            return None
        t = max(t_s, self.t_s)
        x, p = self.kf.x, self.kf.P
        if t > self.t_s:
            f, q = self._fq(t - self.t_s)
            x, p = kf_predict(x, p, f, q)
        r = x[0:3, 0]
        v = x[3:6, 0]
        a = x[6:9, 0] if self._order >= 3 else np.zeros(3)
        az, el, dist = ned_to_spherical(r)
        first, _ = spherical_rates(r, v, a)
        pr = p[0:3, 0:3]
        jac = spherical_jacobian(r)
        var = np.maximum(np.diag(jac @ pr @ jac.T), 0.0)
        return TrackEstimate(
            t_s=t,
            az_rad=az,
            el_rad=el,
            range_m=dist,
            az_rate_radps=float(first[0]),
            el_rate_radps=float(first[1]),
            range_rate_mps=float(first[2]),
            az_sigma_rad=math.sqrt(var[0]),
            el_sigma_rad=math.sqrt(var[1]),
            range_sigma_m=math.sqrt(var[2]),
            since_position_s=t - self.t_position_s,
            pos_ned_m=r.copy(),
            vel_ned_mps=v.copy(),
            pos_cov_m2=pr.copy(),
        )


def pointing_error_rad(est: TrackEstimate, true_pos_ned_m: FloatArray) -> float:
    """Angle between the estimated and the true line of sight, rad."""
    u = los_to_ned(est.az_rad, est.el_rad, 1.0)
    v = np.asarray(true_pos_ned_m, dtype=float)
    c = (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])
    return float(math.atan2(math.sqrt(c[0] ** 2 + c[1] ** 2 + c[2] ** 2), float(u @ v)))

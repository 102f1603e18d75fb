"""Tracking the aircraft from a ground station: azimuth, elevation, range and their rates.

The θ-θ channel of "Tracking with the aircraft's kinematic and dynamic parameters":
each channel (azimuth β, elevation ε, range D) is a constant-acceleration filter
whose acceleration changes by white noise, updated with two observations (the
paper's z1, z2):

    z1(k) = θ(k) + v1(k)        the channel's value from the reported position
    z2(k) = θ̈(k) + v2(k)        its second derivative from the aircraft's own
                                attitude and specific force (load factors)

z2 is the aircraft's acceleration ``a_ned = C_nb f_b + g_ned`` taken into the
station's spherical coordinates with the exact kinematics of ``atan2`` and the
norm (:func:`spherical_rates`), the position and velocity terms from the
filter's own state. The acceleration observation keeps the track through a
manoeuvre (the state's acceleration is measured, not guessed) and carries the
prediction through a loss of the positions.

Baselines, per channel as the paper compares them: Singer's manoeuvring-target
model (Singer 1970; acceleration a first-order Markov process of time constant
τ and variance σ_m²) and a constant-velocity filter (white acceleration). The
standard machinery is filterpy's :class:`~filterpy.kalman.KalmanFilter`; the
Singer process noise is van Loan's discretisation (filterpy.common).

Angular process and observation noises are the linear ones divided by the
range estimate. Pure: no I/O, no clock (times are the samples' ``t_s``).
The frame is the station's local NED (:class:`companion.nav.frames.LocalFrame`);
elevation near ±90° (overhead) is a singularity of the angles, as for any
az/el mount.
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

from companion.nav.rotations import wrap_pi
from companion.types import FloatArray

Model = Literal["dynamic", "singer", "cv"]
MODELS: tuple[Model, ...] = ("dynamic", "singer", "cv")
CHANNELS = ("az", "el", "range")
MIN_RANGE_M = 10.0
"""Below this the angles are meaningless; the angular noises are scaled with it as a floor."""


@dataclass(frozen=True, slots=True)
class TrackerConfig:
    """Noise model of the tracking channels (SI units, 1σ)."""

    pos_sigma_m: float = 2.0
    """Reported position's error across and along the line of sight, m."""
    dyn_jerk_psd: float = 1.0
    """Dynamic channel: power spectral density of the acceleration's change, m²/s⁵."""
    dyn_acc_sigma_mps2: float = 0.3
    """Dynamic channel: error of the acceleration from attitude and specific force, m/s²."""
    singer_tau_s: float = 10.0
    """Singer: manoeuvre time constant 1/α, s."""
    singer_sigma_mps2: float = 3.0
    """Singer: standard deviation of the manoeuvre acceleration σ_m, m/s²."""
    cv_acc_psd: float = 4.0
    """Constant velocity: power spectral density of the white acceleration, m²/s³."""


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

    @property
    def pointing_sigma_rad(self) -> float:
        """1σ of the pointing error (the angle between estimated and true line of sight)."""
        return math.hypot(self.az_sigma_rad * math.cos(self.el_rad), self.el_sigma_rad)

    def pos_ned_m(self) -> FloatArray:
        """The estimated position in the station's NED frame, m."""
        return los_to_ned(self.az_rad, self.el_rad, self.range_m)


def ned_to_spherical(pos_ned_m: FloatArray) -> tuple[float, float, float]:
    """Station-relative NED position to (azimuth from north, elevation up, range)."""
    n, e, d = float(pos_ned_m[0]), float(pos_ned_m[1]), float(pos_ned_m[2])
    rho = math.hypot(n, e)
    return math.atan2(e, n), math.atan2(-d, rho), math.sqrt(rho * rho + d * d)


def los_to_ned(az_rad: float, el_rad: float, range_m: float) -> FloatArray:
    """(azimuth, elevation, range) to a station-relative NED position, m."""
    ce = math.cos(el_rad)
    return range_m * np.array([ce * math.cos(az_rad), ce * math.sin(az_rad), -math.sin(el_rad)])


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


class _Channel:
    """One channel (β, ε or D): a filterpy KalmanFilter with this model's F and Q."""

    def __init__(self, model: Model, cfg: TrackerConfig, angular: bool, wraps: bool) -> None:
        self.model = model
        self.cfg = cfg
        self.angular = angular
        self.wraps = wraps
        dim = 2 if model == "cv" else 3
        self.kf = KalmanFilter(dim_x=dim, dim_z=1)
        self.t_s: float | None = None

    def start(self, t_s: float, value: float, sigma: float, scale: float) -> None:
        dim = self.kf.dim_x
        self.kf.x = np.zeros((dim, 1))
        self.kf.x[0, 0] = value
        # rates unknown at the first fix: ~100 m/s and ~10 m/s² across the line of sight
        p = [sigma**2, (100.0 / scale) ** 2, (10.0 / scale) ** 2][:dim]
        self.kf.P = np.diag(p)
        self.t_s = t_s

    def _fq(self, dt: float, scale: float) -> tuple[FloatArray, FloatArray]:
        """Transition and process noise over ``dt`` (angular channels: linear / range)."""
        s2 = 1.0 / (scale * scale)
        cfg = self.cfg
        if self.model == "cv":
            f = np.array([[1.0, dt], [0.0, 1.0]])
            return f, Q_continuous_white_noise(2, dt, cfg.cv_acc_psd * s2)
        if self.model == "dynamic":
            f = np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
            return f, Q_continuous_white_noise(3, dt, cfg.dyn_jerk_psd * s2)
        f, q = _singer_unit(round(dt, 6), cfg.singer_tau_s)
        return f, q * (cfg.singer_sigma_mps2**2 * s2)

    def predicted(self, t_s: float, scale: float) -> tuple[FloatArray, FloatArray]:
        """(x, P) predicted to ``t_s`` without changing the filter."""
        assert self.t_s is not None
        dt = t_s - self.t_s
        if dt <= 0.0:
            return self.kf.x.copy(), self.kf.P.copy()
        f, q = self._fq(dt, scale)
        x, p = kf_predict(self.kf.x, self.kf.P, f, q)
        return x, p

    def advance(self, t_s: float, scale: float) -> None:
        assert self.t_s is not None
        dt = t_s - self.t_s
        if dt > 0.0:
            f, q = self._fq(dt, scale)
            self.kf.predict(F=f, Q=q)
            self.t_s = t_s

    def update(self, z: float, sigma: float, derivative: int) -> None:
        h = np.zeros((1, self.kf.dim_x))
        h[0, derivative] = 1.0
        if self.wraps and derivative == 0:
            z = float(self.kf.x[0, 0]) + wrap_pi(z - float(self.kf.x[0, 0]))
        self.kf.update(np.array([[z]]), R=np.array([[sigma * sigma]]), H=h)
        if self.wraps:
            self.kf.x[0, 0] = wrap_pi(float(self.kf.x[0, 0]))


class Tracker:
    """Azimuth, elevation and range of the aircraft from a station, by one model.

    Feed :meth:`position` with each reported position (station NED, m) and, for
    the ``dynamic`` model, :meth:`acceleration` with each acceleration from the
    aircraft's attitude and specific force (:func:`acceleration_ned`); the
    baselines ignore the latter. :meth:`estimate` predicts to any time.
    Samples older than the filter's time are counted in ``rejected`` and dropped.
    """

    def __init__(self, model: Model = "dynamic", config: TrackerConfig | None = None) -> None:
        if model not in MODELS:
            raise ValueError(f"unknown tracking model {model!r} (known: {', '.join(MODELS)})")
        self.model: Model = model
        self.cfg = config or TrackerConfig()
        self._ch = (
            _Channel(model, self.cfg, angular=True, wraps=True),
            _Channel(model, self.cfg, angular=True, wraps=False),
            _Channel(model, self.cfg, angular=False, wraps=False),
        )
        self.t_s: float | None = None
        self.t_position_s: float | None = None
        self.positions = 0
        self.accelerations = 0
        self.rejected = 0

    @property
    def started(self) -> bool:
        return self.t_s is not None

    def _range_scale(self) -> float:
        return max(float(self._ch[2].kf.x[0, 0]), MIN_RANGE_M)

    def _advance(self, t_s: float) -> bool:
        if self.t_s is None or t_s < self.t_s:
            self.rejected += self.t_s is not None
            return False
        scale = self._range_scale()
        for ch in self._ch:
            ch.advance(t_s, 1.0 if not ch.angular else scale)
        self.t_s = t_s
        return True

    def position(self, t_s: float, pos_ned_m: FloatArray) -> bool:
        """Update with a reported position (station-relative NED, m); False if rejected."""
        if not np.all(np.isfinite(pos_ned_m)):
            self.rejected += 1
            return False
        az, el, dist = ned_to_spherical(pos_ned_m)
        if dist < MIN_RANGE_M:
            self.rejected += 1
            return False
        sig = self.cfg.pos_sigma_m
        if self.t_s is None:
            for ch, v in zip(self._ch, (az, el, dist), strict=True):
                ch.start(t_s, v, sig / dist if ch.angular else sig, dist if ch.angular else 1.0)
            self.t_s = t_s
        elif not self._advance(t_s):
            return False
        else:
            for ch, v in zip(self._ch, (az, el, dist), strict=True):
                ch.update(v, sig / dist if ch.angular else sig, 0)
        self.t_position_s = t_s
        self.positions += 1
        return True

    def acceleration(self, t_s: float, acc_ned_mps2: FloatArray) -> bool:
        """Second observation: the aircraft's acceleration (station NED, m/s²)."""
        if self.model != "dynamic":
            return False
        if not np.all(np.isfinite(acc_ned_mps2)) or not self._advance(t_s):
            if self.t_s is not None and not np.all(np.isfinite(acc_ned_mps2)):
                self.rejected += 1
            return False
        az, el, dist = (float(ch.kf.x[0, 0]) for ch in self._ch)
        dist = max(dist, MIN_RANGE_M)
        rates = np.array([float(ch.kf.x[1, 0]) for ch in self._ch])
        vel = los_velocity_ned(az, el, dist, rates)
        _, second = spherical_rates(los_to_ned(az, el, dist), vel, np.asarray(acc_ned_mps2))
        sig = self.cfg.dyn_acc_sigma_mps2
        for ch, v in zip(self._ch, second, strict=True):
            ch.update(float(v), sig / dist if ch.angular else sig, 2)
        self.accelerations += 1
        return True

    def estimate(self, t_s: float) -> TrackEstimate | None:
        """The track predicted to ``t_s`` (None before the first position)."""
        if self.t_s is None or self.t_position_s is None:
            return None
        t = max(t_s, self.t_s)
        scale = self._range_scale()
        xs, ps = [], []
        for ch in self._ch:
            x, p = ch.predicted(t, scale if ch.angular else 1.0)
            xs.append(x)
            ps.append(p)
        return TrackEstimate(
            t_s=t,
            az_rad=wrap_pi(float(xs[0][0, 0])),
            el_rad=float(xs[1][0, 0]),
            range_m=float(xs[2][0, 0]),
            az_rate_radps=float(xs[0][1, 0]),
            el_rate_radps=float(xs[1][1, 0]),
            range_rate_mps=float(xs[2][1, 0]),
            az_sigma_rad=math.sqrt(max(float(ps[0][0, 0]), 0.0)),
            el_sigma_rad=math.sqrt(max(float(ps[1][0, 0]), 0.0)),
            range_sigma_m=math.sqrt(max(float(ps[2][0, 0]), 0.0)),
            since_position_s=t - self.t_position_s,
        )


def pointing_error_rad(est: TrackEstimate, true_pos_ned_m: FloatArray) -> float:
    """Angle between the estimated and the true line of sight, rad."""
    u = los_to_ned(est.az_rad, est.el_rad, 1.0)
    v = np.asarray(true_pos_ned_m, dtype=float)
    v = v / np.linalg.norm(v)
    return float(math.atan2(np.linalg.norm(np.cross(u, v)), float(np.dot(u, v))))

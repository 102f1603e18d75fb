"""A smooth, kinematically consistent flight path built from a phase script.

The path is described by six scalar *channels*, each a piecewise polynomial of
time (:class:`scipy.interpolate.PPoly`) made of holds and C3-smooth transitions
(the septic smoothstep ``S(u) = 35u^4 - 84u^5 + 70u^6 - 20u^7``, whose first
three derivatives vanish at both ends):

* ``speed``  horizontal ground speed ``V``, m/s
* ``trackrate`` rate of the ground-track angle ``psi_dot``, rad/s (the track
  angle ``psi`` is its exact antiderivative)
* ``vd``     down velocity, m/s (down position is its exact antiderivative)
* ``pitch``  pitch angle ``theta``, rad
* ``crab``   heading minus track on top of the wind crab, rad
* ``air``    airborne weight in [0, 1] (0 on the wheels: no bank)

Everything else follows analytically::

    vel_ned = [V cos psi, V sin psi, vd]
    acc_ned = [V' cos psi - V psi' sin psi, V' sin psi + V psi' cos psi, vd']
    yaw     = psi + crab + air * delta_wind        (fixed wing: heading into the wind)
    roll    = air * atan(V psi' / g0)               (coordinated turn)
    gyro_b  = ZYX Euler-rate kinematics of (roll, pitch, yaw)
    f_b     = C_bn (acc_ned - [0, 0, g(lat, h)])

Horizontal position is the time integral of the horizontal velocity, computed
with Gauss-Legendre quadrature on sub-intervals of at most 1 s between
breakpoints (exact to rounding for these analytic integrands). So position,
velocity, acceleration, attitude, angular rate and specific force all come from
one path and agree to numerical precision: integrating ``gyro_b`` and ``f_b``
reproduces the path.

Model (documented simplification): flat, non-rotating local NED frame anchored
at the airfield: the gyros measure the body rate relative to that frame (no
Earth rate), the accelerometers measure ``a - g`` with gravity along the frame's
down axis, magnitude WGS-84 normal gravity at the point's latitude and height
(:func:`gravity_down_mps2`).

References
----------
Groves, Principles of GNSS, inertial and multisensor navigation, eq. 2.58
(Euler-rate to body-rate kinematics); NIMA TR8350.2 eq. 4-1 (normal gravity).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import PPoly

from companion.nav import earth
from companion.nav.frames import LocalFrame
from companion.types import FloatArray

CHANNELS = ("speed", "trackrate", "vd", "pitch", "crab", "air")
"""The scripted scalar channels, in order."""

BANK_G_MPS2 = 9.80665
"""g used in the coordinated-bank definition roll = atan(V psi_dot / g), m/s^2."""

_SMOOTHSTEP_COEF = {4: 35.0, 5: -84.0, 6: 70.0, 7: -20.0}
_DEGREE = 7
_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(12)
_MAX_QUAD_STEP_S = 1.0


@dataclass(frozen=True, slots=True)
class Segment:
    """One scripted segment: every channel moves smoothly from its start to its end value.

    ``start``/``end`` map channel name to value (SI units, radians).
    """

    t0_s: float
    t1_s: float
    phase: str
    start: tuple[float, ...]
    end: tuple[float, ...]


@dataclass(frozen=True, slots=True)
class PathState:
    """The path and its derivatives at an array of times (all arrays, first axis = time)."""

    t_s: FloatArray
    pos_ned_m: FloatArray
    vel_ned_mps: FloatArray
    acc_ned_mps2: FloatArray
    euler_rad: FloatArray
    gyro_b_radps: FloatArray
    f_b_mps2: FloatArray
    mat_nb: FloatArray


class ScriptBuilder:
    """Builds a phase script segment by segment, tracking heading and height in closed form.

    Parameters
    ----------
    t0_s : float
        Time of the first segment, s (autopilot time since boot).
    pos0_ned_m : array_like, shape (3,)
        Start position in the local frame, m.
    track0_rad : float
        Initial ground-track angle, rad.
    **initial : float
        Initial channel values (missing channels start at 0).
    """

    def __init__(
        self, t0_s: float, pos0_ned_m: Sequence[float], track0_rad: float, **initial: float
    ) -> None:
        unknown = set(initial) - set(CHANNELS)
        if unknown:
            raise ValueError(f"unknown channel(s): {sorted(unknown)}")
        self.t_s = float(t0_s)
        self.t0_s = float(t0_s)
        self.pos0_ned_m = np.asarray(pos0_ned_m, dtype=float).copy()
        self.track0_rad = float(track0_rad)
        self.value = {c: float(initial.get(c, 0.0)) for c in CHANNELS}
        self.track_rad = float(track0_rad)
        self.down_m = float(self.pos0_ned_m[2])
        self.segments: list[Segment] = []

    def seg(self, duration_s: float, phase: str, **targets: float) -> ScriptBuilder:
        """Append a segment; each named channel moves to its target over the whole segment."""
        if not duration_s > 0.0 or not math.isfinite(duration_s):
            raise ValueError(f"segment duration must be positive, got {duration_s}")
        unknown = set(targets) - set(CHANNELS)
        if unknown:
            raise ValueError(f"unknown channel(s): {sorted(unknown)}")
        start = tuple(self.value[c] for c in CHANNELS)
        for c, v in targets.items():
            self.value[c] = float(v)
        end = tuple(self.value[c] for c in CHANNELS)
        t1 = self.t_s + duration_s
        self.segments.append(Segment(self.t_s, t1, phase, start, end))
        # Closed forms: the integral of a smoothstep transition is its mean times T.
        i_tr, i_vd = CHANNELS.index("trackrate"), CHANNELS.index("vd")
        self.track_rad += 0.5 * (start[i_tr] + end[i_tr]) * duration_s
        self.down_m += 0.5 * (start[i_vd] + end[i_vd]) * duration_s
        self.t_s = t1
        return self

    def turn(
        self, angle_rad: float, rate_radps: float, ramp_s: float, phase: str, **targets: float
    ) -> ScriptBuilder:
        """A turn by ``angle_rad`` at ``|rate_radps|``: ramp in, hold, ramp out (no-op if 0)."""
        if angle_rad == 0.0:
            return self
        rate = math.copysign(abs(rate_radps), angle_rad)
        hold = abs(angle_rad) / abs(rate) - ramp_s
        if hold < 0.0:
            # too small an angle for the ramps: lower the rate, no hold
            rate = angle_rad / ramp_s
            hold = 0.0
        self.seg(ramp_s, phase, trackrate=rate, **targets)
        if hold > 0.0:
            self.seg(hold, phase)
        return self.seg(ramp_s, phase, trackrate=0.0)

    @property
    def height_m(self) -> float:
        """Current height above the frame origin, m."""
        return -self.down_m

    def build(self, frame: LocalFrame, wind_ned_mps: Sequence[float], fixed_wing: bool) -> Path:
        """Freeze the script into a :class:`Path`."""
        if not self.segments:
            raise ValueError("empty script")
        return Path(
            tuple(self.segments),
            frame,
            self.pos0_ned_m,
            self.track0_rad,
            np.asarray(wind_ned_mps, dtype=float),
            fixed_wing,
        )


def _channel_ppoly(segments: Sequence[Segment], index: int) -> PPoly:
    """Piecewise septic-smoothstep polynomial of one channel, C3 everywhere."""
    x = np.array([s.t0_s for s in segments] + [segments[-1].t1_s])
    c = np.zeros((_DEGREE + 1, len(segments)))
    for j, s in enumerate(segments):
        v0, v1 = s.start[index], s.end[index]
        c[_DEGREE, j] = v0
        dv = v1 - v0
        if dv != 0.0:
            dur = s.t1_s - s.t0_s
            for p, k in _SMOOTHSTEP_COEF.items():
                c[_DEGREE - p, j] = k * dv / dur**p
    return PPoly(c, x, extrapolate=True)


def gravity_down_mps2(frame: LocalFrame, pos_ned_m: FloatArray) -> FloatArray:
    """Normal gravity magnitude along the local frame's down axis, m/s^2, shape (N,).

    Latitude from the north offset on the anchor's meridian radius, height from
    the down offset. This is the simulator's gravity model (see module docstring).

    Parameters
    ----------
    frame : LocalFrame
        The anchor.
    pos_ned_m : ndarray, shape (N, 3) or (3,)
        Positions in the local frame, m.

    References
    ----------
    NIMA TR8350.2 eq. 4-1, 4-3 (via :func:`companion.nav.earth.gravity_mps2`).
    """
    p = np.atleast_2d(np.asarray(pos_ned_m, dtype=float))
    m_m, _ = earth.radii_of_curvature_m(frame.lat0_rad)
    lat = frame.lat0_rad + p[:, 0] / (m_m + frame.alt0_m)
    alt = frame.alt0_m - p[:, 2]
    s2 = np.sin(lat) ** 2
    k = (earth.B_M * earth.GAMMA_P_MPS2) / (earth.A_M * earth.GAMMA_E_MPS2) - 1.0
    m_ratio = earth.OMEGA_IE_RADPS**2 * earth.A_M**2 * earth.B_M / earth.GM_M3PS2
    g0 = earth.GAMMA_E_MPS2 * (1.0 + k * s2) / np.sqrt(1.0 - earth.E2 * s2)
    return np.asarray(
        g0
        * (
            1.0
            - 2.0 / earth.A_M * (1.0 + earth.F + m_ratio - 2.0 * earth.F * s2) * alt
            + 3.0 / earth.A_M**2 * alt**2
        ),
        dtype=float,
    )


def euler_to_mat_nb_batch(euler_rad: FloatArray) -> FloatArray:
    """Body-to-NED matrices from ZYX Euler angles (N, 3) -> (N, 3, 3)."""
    r, p, y = euler_rad[:, 0], euler_rad[:, 1], euler_rad[:, 2]
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    m = np.empty((len(r), 3, 3))
    m[:, 0, 0] = cp * cy
    m[:, 0, 1] = sr * sp * cy - cr * sy
    m[:, 0, 2] = cr * sp * cy + sr * sy
    m[:, 1, 0] = cp * sy
    m[:, 1, 1] = sr * sp * sy + cr * cy
    m[:, 1, 2] = cr * sp * sy - sr * cy
    m[:, 2, 0] = -sp
    m[:, 2, 1] = sr * cp
    m[:, 2, 2] = cr * cp
    return m


class Path:
    """The analytic path of one flight (see the module docstring for the model).

    Evaluate it at any time in ``[t_start_s, t_end_s]`` with :meth:`evaluate`.
    """

    def __init__(
        self,
        segments: tuple[Segment, ...],
        frame: LocalFrame,
        pos0_ned_m: FloatArray,
        track0_rad: float,
        wind_ned_mps: FloatArray,
        fixed_wing: bool,
    ) -> None:
        self.segments = segments
        self.frame = frame
        self.pos0_ned_m = np.asarray(pos0_ned_m, dtype=float)
        self.wind_ned_mps = np.asarray(wind_ned_mps, dtype=float)
        self.fixed_wing = fixed_wing
        self.t_start_s = segments[0].t0_s
        self.t_end_s = segments[-1].t1_s
        pp = {c: _channel_ppoly(segments, i) for i, c in enumerate(CHANNELS)}
        self._pp = pp
        self._d = {c: pp[c].derivative() for c in CHANNELS}
        self._speed_dd = pp["speed"].derivative(2)
        self._trackrate_d = self._d["trackrate"]
        self._track = pp["trackrate"].antiderivative()
        self._track0 = float(track0_rad)
        self._down = pp["vd"].antiderivative()
        self._vd_d = self._d["vd"]
        self._breaks = np.array([s.t0_s for s in segments] + [self.t_end_s])
        # quadrature knots: breakpoints subdivided to at most _MAX_QUAD_STEP_S
        knots: list[float] = []
        for a, b in zip(self._breaks[:-1], self._breaks[1:], strict=True):
            n = max(1, math.ceil((b - a) / _MAX_QUAD_STEP_S))
            knots.extend(np.linspace(a, b, n + 1)[:-1].tolist())
        knots.append(float(self._breaks[-1]))
        self._knots = np.array(knots)
        inc = self._quad_ne(self._knots[:-1], self._knots[1:])
        self._cum_ne = np.vstack([np.zeros((1, 2)), np.cumsum(inc, axis=0)])

    # ------------------------------------------------------------------ channels
    def track_rad(self, t_s: FloatArray) -> FloatArray:
        """Ground-track angle, rad (unwrapped)."""
        return np.asarray(self._track0 + self._track(t_s), dtype=float)

    def phase_at(self, t_s: FloatArray) -> np.ndarray:
        """Phase name of each time (array of str)."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        idx = np.clip(np.searchsorted(self._breaks, t, side="right") - 1, 0, len(self.segments) - 1)
        names = np.array([s.phase for s in self.segments], dtype=object)
        return np.asarray(names[idx].astype(str))

    def channel(self, name: str, t_s: FloatArray, nu: int = 0) -> FloatArray:
        """A raw channel value (or its derivative of order ``nu``) at times ``t_s``."""
        pp = self._pp[name] if nu == 0 else self._pp[name].derivative(nu)
        return np.asarray(pp(t_s), dtype=float)

    def _vel_ne(self, t_s: FloatArray) -> FloatArray:
        v = self._pp["speed"](t_s)
        psi = self.track_rad(t_s)
        return np.stack([v * np.cos(psi), v * np.sin(psi)], axis=-1)

    def _quad_ne(self, a: FloatArray, b: FloatArray) -> FloatArray:
        """Integral of the horizontal velocity from a to b (same sub-interval), shape (N, 2)."""
        half = 0.5 * (b - a)
        mid = 0.5 * (b + a)
        tt = mid[:, None] + half[:, None] * _GL_NODES[None, :]
        vel = self._vel_ne(tt)  # (N, nodes, 2)
        return np.asarray(np.einsum("nki,k->ni", vel, _GL_WEIGHTS) * half[:, None])

    def pos_ned_m(self, t_s: FloatArray) -> FloatArray:
        """Position in the local frame at times ``t_s`` (N,), m, shape (N, 3)."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        k = np.clip(np.searchsorted(self._knots, t, side="right") - 1, 0, len(self._knots) - 2)
        ne = self._cum_ne[k] + self._quad_ne(self._knots[k], t)
        d = self._down(t)
        return np.column_stack([ne[:, 0], ne[:, 1], d]) + self.pos0_ned_m[None, :]

    # ------------------------------------------------------------------ full state
    def evaluate(self, t_s: FloatArray, with_position: bool = True) -> PathState:
        """Path state at times ``t_s`` (N,): position, velocity, attitude, rates, specific force.

        Raises
        ------
        ValueError
            If a time lies outside the scripted span.
        """
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        if t.size and (t.min() < self.t_start_s - 1e-9 or t.max() > self.t_end_s + 1e-9):
            raise ValueError(
                f"time outside the path [{self.t_start_s}, {self.t_end_s}] s: "
                f"[{t.min()}, {t.max()}]"
            )
        pp, d = self._pp, self._d
        v, v_d = pp["speed"](t), d["speed"](t)
        psi = self.track_rad(t)
        psi_d = pp["trackrate"](t)
        psi_dd = self._trackrate_d(t)
        vd, vd_d = pp["vd"](t), self._vd_d(t)
        theta, theta_d = pp["pitch"](t), d["pitch"](t)
        crab, crab_d = pp["crab"](t), d["crab"](t)
        air, air_d = pp["air"](t), d["air"](t)
        cpsi, spsi = np.cos(psi), np.sin(psi)
        vel = np.column_stack([v * cpsi, v * spsi, vd])
        acc = np.column_stack([v_d * cpsi - v * psi_d * spsi, v_d * spsi + v * psi_d * cpsi, vd_d])
        # heading: track + scripted crab (+ the wind crab in the air for a fixed wing)
        yaw = psi + crab
        yaw_d = psi_d + crab_d
        if self.fixed_wing and np.any(self.wind_ned_mps[:2] != 0.0):
            van = vel[:, 0] - self.wind_ned_mps[0]
            vae = vel[:, 1] - self.wind_ned_mps[1]
            h2 = van**2 + vae**2
            ok = (air > 0.0) & (h2 > 1e-6)
            delta = np.zeros_like(t)
            delta_d = np.zeros_like(t)
            psi_air = np.arctan2(vae[ok], van[ok])
            delta[ok] = np.angle(np.exp(1j * (psi_air - psi[ok])))
            psi_air_d = (van[ok] * acc[ok, 1] - vae[ok] * acc[ok, 0]) / h2[ok]
            delta_d[ok] = psi_air_d - psi_d[ok]
            yaw = yaw + air * delta
            yaw_d = yaw_d + air_d * delta + air * delta_d
        # coordinated bank on the ground-track rate, only when airborne
        x = v * psi_d / BANK_G_MPS2
        x_d = (v_d * psi_d + v * psi_dd) / BANK_G_MPS2
        roll = air * np.arctan(x)
        roll_d = air_d * np.arctan(x) + air * x_d / (1.0 + x**2)
        yaw = (yaw + np.pi) % (2.0 * np.pi) - np.pi
        euler = np.column_stack([roll, theta, yaw])
        sr, cr = np.sin(roll), np.cos(roll)
        st, ct = np.sin(theta), np.cos(theta)
        gyro = np.column_stack(
            [
                roll_d - yaw_d * st,
                theta_d * cr + yaw_d * sr * ct,
                -theta_d * sr + yaw_d * cr * ct,
            ]
        )
        mat_nb = euler_to_mat_nb_batch(euler)
        pos = self.pos_ned_m(t) if with_position else np.full((len(t), 3), np.nan)
        g = gravity_down_mps2(self.frame, pos if with_position else self.pos_ned_m(t))
        f_n = acc.copy()
        f_n[:, 2] -= g
        f_b = np.einsum("nji,nj->ni", mat_nb, f_n)
        return PathState(t, pos, vel, acc, euler, gyro, f_b, mat_nb)

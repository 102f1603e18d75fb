"""Sensor error models: IMU grades, Gauss-Markov processes, GNSS modes and events, attitude.

Every random draw comes from a ``numpy.random.Generator`` the caller seeds.

* IMU: measured = truth + turn-on bias + first-order Gauss-Markov bias
  instability + white noise (per-sample sigma = noise density * sqrt(rate)).
* GNSS: position error per axis = sigma(mode) * z, z a unit-variance
  Gauss-Markov process whose correlation time follows the mode; velocity noise
  white. Per-axis 1-sigma figures are what the receiver reports as h_acc/v_acc.
* Attitude: the autopilot's estimate = truth + small Gauss-Markov error + an
  optional constant heading error (the fast-alignment error of Markelov et al.).

References
----------
El-Mowafy (2005), RTK networks for precision approach with an adaptive GPS/INS
blend (tactical gyro drift 1-10 deg/h; RTK fixed 1.6-2.2 cm 2-D / 2.8-3.4 cm
height, float 26-32 / 53-54 cm, > 3.5-4 m without corrections). Markelov et al.,
"INS course correction from satellite navigation before take-off" (heading error
~1 deg). Groves, Principles of GNSS, inertial and multisensor
navigation, sec. 4.4 (IMU error model), eq. 3.65 (Gauss-Markov discretisation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from companion.nav.grades import ImuGrade
from companion.sim.attacks import jamming_lost
from companion.sim.scenarios import Event, Scenario
from companion.types import FixType, FloatArray

_DEG = math.pi / 180.0


@dataclass(frozen=True, slots=True)
class GnssModeSpec:
    """Accuracy and reporting figures of one GNSS mode (per-axis 1-sigma)."""

    fix_type: FixType
    sigma_h_m: float
    sigma_v_m: float
    tau_s: float
    satellites: int
    hdop: float
    vdop: float
    vel_noise_scale: float


GNSS_MODE_SPECS: dict[str, GnssModeSpec] = {
    "rtk_fixed": GnssModeSpec(FixType.RTK_FIXED, 0.015, 0.03, 30.0, 20, 0.7, 1.1, 1.0),
    "rtk_float": GnssModeSpec(FixType.RTK_FLOAT, 0.2, 0.5, 60.0, 18, 0.8, 1.2, 1.0),
    "dgps": GnssModeSpec(FixType.DGPS, 0.5, 1.0, 120.0, 14, 0.9, 1.4, 1.0),
    "3d": GnssModeSpec(FixType.FIX_3D, 2.5, 4.0, 300.0, 10, 1.2, 1.9, 2.0),
    "none": GnssModeSpec(FixType.NO_FIX, 0.0, 0.0, 300.0, 3, 99.99, 99.99, 0.0),
}
"""Per-axis sigmas: RTK fixed 2.1 cm 2-D RMS / 3 cm V, float 0.28 / 0.5 m, 3D 3.5 / 4 m
(El-Mowafy (2005))."""

ATTITUDE_RATE_NOISE_RADPS = 0.001
AUTOPILOT_POS_SIGMA_M = (0.3, 0.3, 0.5)
AUTOPILOT_POS_TAU_S = 30.0


def gauss_markov(
    rng: np.random.Generator, t_s: FloatArray, sigma: float, tau_s: float | FloatArray, dim: int = 1
) -> FloatArray:
    """First-order Gauss-Markov process sampled at times ``t_s``, stationary from the start.

    ``x_k = phi_k x_{k-1} + sigma sqrt(1 - phi_k^2) w_k``, ``phi_k = exp(-dt_k / tau_k)``:
    exact discretisation for any (also uneven) spacing and a time-varying tau.

    Parameters
    ----------
    rng : numpy.random.Generator
    t_s : ndarray, shape (N,)
        Increasing sample times, s.
    sigma : float
        Stationary standard deviation.
    tau_s : float or ndarray, shape (N,)
        Correlation time(s), s.
    dim : int
        Number of independent components.

    Returns
    -------
    ndarray, shape (N, dim)

    References
    ----------
    Groves, Principles of GNSS, inertial and multisensor navigation, eq. 3.65 (Markov
    process, discrete form).
    """
    t = np.asarray(t_s, dtype=float)
    n = len(t)
    out = np.zeros((n, dim))
    if n == 0 or sigma == 0.0:
        return out
    tau = np.broadcast_to(np.asarray(tau_s, dtype=float), (n,))
    dt = np.diff(t, prepend=t[0])
    phi = np.exp(-dt / tau)
    drive = np.sqrt(np.maximum(1.0 - phi**2, 0.0))
    w = rng.standard_normal((n, dim))
    x = w[0].copy()
    out[0] = x
    for k in range(1, n):  # a first-order recursion; n is fix/IMU count
        x = phi[k] * x + drive[k] * w[k]
        out[k] = x
    return sigma * out


def gauss_markov_fast(
    rng: np.random.Generator, n: int, dt_s: float, sigma: float, tau_s: float, dim: int
) -> FloatArray:
    """Gauss-Markov process on an even grid (vectorised with scipy.signal.lfilter), (n, dim)."""
    from scipy.signal import lfilter

    if n == 0 or sigma == 0.0:
        return np.zeros((n, dim))
    phi = math.exp(-dt_s / tau_s)
    w = rng.standard_normal((n, dim))
    w[1:] *= math.sqrt(1.0 - phi**2)
    x = lfilter([1.0], [1.0, -phi], w, axis=0)
    return np.asarray(sigma * x, dtype=float)


@dataclass(frozen=True, slots=True)
class ImuErrors:
    """IMU errors on the IMU time grid: ``total = bias + white`` per sensor, shapes (N, 3)."""

    gyro_bias_b_radps: FloatArray
    acc_bias_b_mps2: FloatArray
    gyro_white_b_radps: FloatArray
    acc_white_b_mps2: FloatArray


def imu_errors(
    rng: np.random.Generator, grade: ImuGrade, n: int, rate_hz: float, enabled: bool = True
) -> ImuErrors:
    """Draw IMU errors for ``n`` samples at ``rate_hz`` (all zero when not enabled).

    References
    ----------
    Groves, sec. 4.4.1-4.4.3 (biases, random walk); El-Mowafy (2005) (grades);
    :mod:`companion.nav.grades` (the grade table).
    """
    if not enabled:
        z = np.zeros((n, 3))
        return ImuErrors(z, z.copy(), z.copy(), z.copy())
    dt = 1.0 / rate_hz
    gb = rng.normal(0.0, grade.gyro_bias_sigma_radps, 3)[None, :] + gauss_markov_fast(
        rng, n, dt, grade.gyro_instability_radps, grade.gyro_tau_s, 3
    )
    ab = rng.normal(0.0, grade.acc_bias_sigma_mps2, 3)[None, :] + gauss_markov_fast(
        rng, n, dt, grade.acc_instability_mps2, grade.acc_tau_s, 3
    )
    sq = math.sqrt(rate_hz)
    gw = rng.standard_normal((n, 3)) * grade.gyro_noise_density_radps_rthz * sq
    aw = rng.standard_normal((n, 3)) * grade.acc_noise_density_mps2_rthz * sq
    return ImuErrors(gb, ab, gw, aw)


# --------------------------------------------------------------------------- GNSS schedule


@dataclass(frozen=True, slots=True)
class GnssState:
    """What the receiver does at one fix time."""

    mode: str
    """Quality mode: a key of GNSS_MODE_SPECS."""
    present: bool
    """False in an outage: no message at all."""
    stale: bool
    """True when the receiver repeats its last fix."""
    label: str
    """Truth label: the mode, or 'outage' / 'stale'."""


def gnss_state(sc: Scenario, receiver_id: int, t_s: float) -> GnssState:
    """Mode and presence of a receiver at time ``t_s`` under the scenario's events."""
    mode = sc.gnss_mode
    present, stale = True, False
    for ev in sc.events:
        if ev.receiver_id != receiver_id:
            continue
        if ev.kind == "rtk_outage" and mode.startswith("rtk"):
            mode = _rtk_outage_mode(ev, mode, t_s)
        elif ev.kind == "jamming" and jamming_lost(ev, t_s):
            mode = "none"
        elif ev.active(t_s):
            if ev.kind == "downgrade":
                mode = str(ev.params["mode"])
            elif ev.kind == "outage":
                present = False
            elif ev.kind == "stale":
                stale = True
    label = "outage" if not present else "stale" if stale else mode
    return GnssState(mode, present, stale, label)


def _rtk_outage_mode(ev: Event, mode: str, t_s: float) -> str:
    extrap = float(ev.params.get("extrap_s", 3.0))
    float_s = float(ev.params.get("float_s", 5.0))
    refix = float(ev.params.get("refix_s", 8.0))
    fallback = str(ev.params.get("fallback", "3d"))
    if ev.t_start_s <= t_s < ev.t_end_s:
        tau = t_s - ev.t_start_s
        if tau < extrap:
            return mode
        if tau < extrap + float_s:
            return "rtk_float"
        return fallback
    if ev.t_end_s <= t_s < ev.t_end_s + refix:
        return "rtk_float"
    return mode


def fault_offset_ned_m(sc: Scenario, receiver_id: int, t_s: float) -> FloatArray:
    """Sum of the step/ramp/dither offsets active on a receiver at ``t_s``, m, shape (3,).

    The attacks' offsets (drags, meaconing) are :func:`companion.sim.attacks.on_receiver`'s.

    References
    ----------
    Kim, Walter and Powell, "Standalone GPS-based flight inspection system" (slow
    ramps, e.g. 4 cm/s; dithering, e.g. a 1 m sinusoid).
    """
    off = np.zeros(3)
    for ev in sc.events:
        if ev.receiver_id != receiver_id or not ev.active(t_s):
            continue
        tau = t_s - ev.t_start_s
        if ev.kind == "step":
            off += np.asarray(ev.params.get("offset_ned_m", (0.0, 0.0, 0.0)), dtype=float)
        elif ev.kind == "ramp":
            off += np.asarray(ev.params.get("rate_ned_mps", (0.04, 0.0, 0.0)), dtype=float) * tau
        elif ev.kind == "dither":
            axis = np.asarray(ev.params.get("axis_ned", (0.0, 0.0, 1.0)), dtype=float)
            axis = axis / np.linalg.norm(axis)
            amp = float(ev.params.get("amplitude_m", 1.0))
            period = float(ev.params.get("period_s", 20.0))
            off += amp * math.sin(2.0 * math.pi * tau / period) * axis
    return off

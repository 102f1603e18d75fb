"""An autopilot as imperfect as a real one: every trait on its own switch, a profile per vehicle.

:class:`Realism` holds the switches. Each field's default turns its trait off, and
``Scenario.realism`` is None by default, so a scenario without it flies exactly as
before (same bytes). :func:`realistic` gives the scenario overrides of a vehicle's
``realistic`` profile (``copter``, ``copter_radio``, ``plane``, ``px4``), whose
magnitudes come from the real logs that ``bench/realism.py`` measures:

1. ATTITUDE (and GLOBAL_POSITION_INT) are estimates: a constant trim tilt in a random
   direction plus slowly varying (Gauss-Markov) roll/pitch/yaw errors, and a lag.
2. IMU errors per unit: turn-on accelerometer bias, scale factor, misalignment, gyro
   bias and rate random walk, a temperature drift as the board warms up, white noise,
   and vibration: harmonics of the rotor or engine speed plus broadband noise, passed
   through the autopilot's second-order low-pass filter and then point-sampled at the
   stream rate (so that it aliases). Extra IMU units (SCALED_IMU2/3) draw their own errors.
3. Streams as links deliver them: sample-time jitter, bursts, repeated and
   out-of-order messages, dropouts of every stream at once, an autopilot reboot.
4. GNSS: no-fix periods (fix type 0/1) with garbage coordinates, gaps, 2D/3D flapping,
   a slowly varying velocity bias, reported accuracies off by a slowly varying factor,
   satellites and HDOP varying (the latency is ``Scenario.gnss_latency_s``).
5. A barometer (SCALED_PRESSURE): noise, weather drift, a ground-effect step, dropouts.

References
----------
ArduPilot documentation, "Measuring vibration" (VIBE levels below 30 m/s^2 are
acceptable; aliasing of vibration by sampling) and the INS_ACCEL_FILTER /
INS_GYRO_FILTER parameters (default 20 Hz low-pass). Groves, Principles of GNSS,
inertial and multisensor navigation, sec. 4.4 (scale factor, misalignment, bias
random walk, temperature). The magnitudes of each profile: ``bench/realism.py``
against the real logs (docs/simulator.md).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from companion.types import FloatArray

_DEG = math.pi / 180.0


@dataclass(frozen=True, slots=True)
class Realism:
    """The switches (all off by default). Per-axis 1-sigma unless the name says otherwise."""

    # 1. the autopilot's estimates
    attitude_trim_deg: float = 0.0
    """Constant tilt offset of ATTITUDE, in a random direction, deg."""
    attitude_tilt_sigma_deg: float = 0.0
    """Gauss-Markov roll and pitch error, deg."""
    attitude_yaw_sigma_deg: float = 0.0
    attitude_tau_s: float = 120.0
    attitude_lag_s: float = 0.0
    """ATTITUDE shows the state this long ago, s."""
    autopilot_pos_sigma_m: float = 0.0
    """Extra Gauss-Markov error of GLOBAL_POSITION_INT per axis, m."""
    autopilot_pos_tau_s: float = 60.0
    autopilot_lag_s: float = 0.0
    # 2. the IMU
    acc_bias_mps2: float = 0.0
    """Turn-on accelerometer bias, uniform in +-this per axis, m/s^2."""
    acc_scale_sigma: float = 0.0
    """Accelerometer scale-factor error (fraction)."""
    misalign_sigma_rad: float = 0.0
    gyro_bias_radps: float = 0.0
    """Turn-on gyro bias, rad/s."""
    gyro_rw_radps_rts: float = 0.0
    """Gyro bias random walk, rad/s per sqrt(s)."""
    temp_rise_c: float = 0.0
    """Board warm-up after boot, deg C (exponential, ``temp_tau_s``)."""
    temp_tau_s: float = 600.0
    acc_temp_mps2_per_c: float = 0.0
    gyro_temp_radps_per_c: float = 0.0
    acc_noise_mps2: float = 0.0
    """White accelerometer noise per sample, m/s^2."""
    gyro_noise_radps: float = 0.0
    vibration_mps2: float = 0.0
    """Harmonic vibration amplitude per axis before the autopilot's filter, m/s^2 (in flight)."""
    vibration_broadband_mps2: float = 0.0
    """Broadband vibration per axis after the filter, m/s^2 (in flight)."""
    vibration_gyro_ratio_radps_per_mps2: float = 0.0
    vibration_hz: float = 0.0
    """Fundamental (rotor or engine) frequency at mid throttle, Hz; harmonics 1 and 2."""
    vibration_wander: float = 0.03
    """Slow wander of the rotor or engine speed (fraction, 37 s period)."""
    vibration_ground_fraction: float = 0.3
    """Vibration on the ground with the motor running, as a fraction of in flight."""
    filter_hz: float = 20.0
    """The autopilot's accelerometer/gyro low-pass (second order), Hz."""
    extra_imus: int = 0
    """0..2 further IMU units (SCALED_IMU2, SCALED_IMU3) with their own errors."""
    # 3. the link
    stamp_jitter_s: float = 0.0
    """Sample-time jitter of the IMU stream (Gaussian), s."""
    burst_per_h: float = 0.0
    burst_s: float = 0.5
    """Messages held and delivered together at the end of a window this long, s."""
    duplicate_fraction: float = 0.0
    reorder_fraction: float = 0.0
    dropout_per_h: float = 0.0
    """Dropouts of every stream at once, per hour (at least one if > 0)."""
    dropout_min_s: float = 5.0
    dropout_max_s: float = 30.0
    reboot_at_fraction: float | None = None
    """Autopilot reboot at this fraction of the flight: 3 s of silence, then the boot
    clock restarts from zero."""
    # 4. GNSS
    gnss_nofix_start_s: float = 0.0
    """No fix (fix type 1) for this long from the start of the record, s."""
    gnss_nofix_per_h: float = 0.0
    gnss_nofix_s: float = 5.0
    gnss_garbage: bool = False
    """No-fix reports carry non-zero garbage coordinates (km off) instead of zeros."""
    gnss_gap_per_h: float = 0.0
    gnss_gap_min_s: float = 2.0
    gnss_gap_max_s: float = 7.0
    gnss_flap_per_h: float = 0.0
    """2D/3D flapping windows per hour (30 s each: the fix alternates 2D and 3D)."""
    gnss_vel_bias_mps: float = 0.0
    """Gauss-Markov velocity bias per axis, m/s (tau ``gnss_vel_bias_tau_s``)."""
    gnss_vel_bias_tau_s: float = 20.0
    gnss_acc_log_sigma: float = 0.0
    """Reported h_acc/v_acc = the mode's sigma * exp(slowly varying N(0, this))."""
    gnss_sats_sigma: float = 0.0
    gnss_hdop_sigma: float = 0.0
    # 5. barometer
    baro_rate_hz: float = 0.0
    """SCALED_PRESSURE rate, Hz (0: no barometer stream)."""
    baro_noise_hpa: float = 0.0
    baro_drift_hpa_per_h: float = 0.0
    """Weather drift, hPa/h, in a random sign."""
    baro_ground_effect_hpa: float = 0.0
    """Pressure step while within 2 m of the ground with the motors running, hPa."""
    baro_dropout_per_h: float = 0.0
    baro_dropout_s: float = 3.0

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or v is None:
                continue
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                raise ValueError(f"realism {f.name} must be a finite number >= 0, got {v!r}")
        if self.extra_imus not in (0, 1, 2):
            raise ValueError("realism extra_imus must be 0, 1 or 2")
        if self.reboot_at_fraction is not None and not 0.05 <= self.reboot_at_fraction <= 0.95:
            raise ValueError("realism reboot_at_fraction must be in [0.05, 0.95]")
        if self.dropout_max_s < self.dropout_min_s or self.gnss_gap_max_s < self.gnss_gap_min_s:
            raise ValueError("realism: a window's max must not be below its min")
        if self.filter_hz <= 0 or self.attitude_tau_s <= 0 or self.temp_tau_s <= 0:
            raise ValueError("realism filter_hz, attitude_tau_s, temp_tau_s must be > 0")

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return dataclasses.asdict(self)


# --------------------------------------------------------------------------- profiles

_ARDU_COPTER = Realism(
    attitude_trim_deg=1.4, attitude_tilt_sigma_deg=0.25, attitude_yaw_sigma_deg=3.0,
    attitude_tau_s=120.0, attitude_lag_s=0.05, autopilot_pos_sigma_m=2.0,
    autopilot_lag_s=0.1,
    acc_bias_mps2=0.1, acc_scale_sigma=0.005, misalign_sigma_rad=2e-3,
    gyro_bias_radps=0.1 * _DEG, gyro_rw_radps_rts=3e-5, temp_rise_c=15.0,
    acc_temp_mps2_per_c=0.004, gyro_temp_radps_per_c=0.0001,
    acc_noise_mps2=0.1, gyro_noise_radps=0.003,
    vibration_mps2=34.0, vibration_broadband_mps2=1.0,
    vibration_gyro_ratio_radps_per_mps2=0.02, vibration_hz=140.0, extra_imus=1,
    dropout_per_h=4.0, dropout_min_s=5.0, dropout_max_s=30.0,
    gnss_nofix_start_s=8.0, gnss_garbage=True, gnss_gap_per_h=20.0,
    gnss_vel_bias_mps=0.05, gnss_acc_log_sigma=0.5, gnss_sats_sigma=0.7,
    gnss_hdop_sigma=0.08,
)  # fmt: skip
"""ArduCopter of the 3.3 era on a companion's serial port (50 Hz IMU)."""

_PROFILES: dict[str, tuple[Realism, dict[str, Any]]] = {
    "copter": (
        _ARDU_COPTER,
        {
            "imu_message": "RAW_IMU",
            "imu_rate_hz": 50.0,
            "attitude_rate_hz": 10.0,
            "gnss_rate_hz": 5.0,
            "gnss_latency_s": 0.2,
            "gnss_mode": "3d",
            "gnss_vel_noise_mps": 0.02,
        },
    ),
    "copter_radio": (
        dataclasses.replace(
            _ARDU_COPTER,
            stamp_jitter_s=0.25,
            burst_per_h=250.0,
            burst_s=1.5,
            reboot_at_fraction=0.4,
            gnss_nofix_start_s=2.0,
            gnss_garbage=False,
            dropout_per_h=30.0,
            baro_rate_hz=1.3,
            baro_noise_hpa=0.025,
            baro_drift_hpa_per_h=1.0,
            baro_ground_effect_hpa=0.1,
            baro_dropout_per_h=4.0,
        ),
        {
            "imu_message": "RAW_IMU",
            "imu_rate_hz": 1.3,
            "attitude_rate_hz": 1.0,
            "gnss_rate_hz": 1.3,
            "gnss_latency_s": 0.2,
            "gnss_mode": "3d",
            "gnss_vel_noise_mps": 0.02,
        },
    ),  # fmt: skip
    "plane": (
        dataclasses.replace(
            _ARDU_COPTER,
            attitude_trim_deg=1.3,
            acc_noise_mps2=0.15,
            vibration_mps2=25.0,
            vibration_hz=90.0,
            vibration_broadband_mps2=1.2,
            stamp_jitter_s=0.0015,
            gnss_nofix_start_s=0.4,
            gnss_garbage=False,
            gnss_gap_per_h=4.0,
            gnss_gap_min_s=0.5,
            gnss_gap_max_s=0.9,
            dropout_per_h=0.0,
        ),
        {
            "imu_message": "RAW_IMU",
            "imu_rate_hz": 10.0,
            "attitude_rate_hz": 10.0,
            "gnss_rate_hz": 5.0,
            "gnss_latency_s": 0.2,
            "gnss_mode": "3d",
            "gnss_vel_noise_mps": 0.02,
        },
    ),  # fmt: skip
    "px4": (
        Realism(
            attitude_trim_deg=0.07,
            attitude_tilt_sigma_deg=0.03,
            attitude_yaw_sigma_deg=1.0,
            attitude_lag_s=0.01,
            autopilot_pos_sigma_m=1.0,
            acc_bias_mps2=0.005,
            acc_scale_sigma=0.002,
            misalign_sigma_rad=1e-3,
            gyro_bias_radps=0.09 * _DEG,
            gyro_rw_radps_rts=5e-5,
            temp_rise_c=10.0,
            acc_temp_mps2_per_c=0.0005,
            acc_noise_mps2=0.015,
            gyro_noise_radps=0.002,
            vibration_mps2=5.0,
            vibration_broadband_mps2=0.1,
            vibration_gyro_ratio_radps_per_mps2=0.15,
            vibration_hz=140.0,
            filter_hz=30.0,
            gnss_vel_bias_mps=0.05,
            dropout_per_h=60.0,
            dropout_min_s=0.07,
            dropout_max_s=0.14,
            gnss_acc_log_sigma=0.2,
            gnss_sats_sigma=0.0,
            gnss_hdop_sigma=0.0,
        ),
        {
            "flavour_px4": True,
            "imu_message": "HIGHRES_IMU",
            "imu_rate_hz": 250.0,
            "attitude_rate_hz": 50.0,
            "gnss_rate_hz": 5.0,
            "gnss_latency_s": 0.12,
            "gnss_mode": "3d",
            "gnss_vel_noise_mps": 0.02,
        },
    ),  # fmt: skip
}
VEHICLES = tuple(_PROFILES)


def realistic(vehicle: str) -> dict[str, Any]:
    """Scenario overrides of a vehicle's realistic profile (``realism`` and stream rates).

    Raises
    ------
    ValueError
        Unknown vehicle.
    """
    from companion.types import AutopilotFlavour

    if vehicle not in _PROFILES:
        raise ValueError(f"unknown vehicle {vehicle!r} (known: {', '.join(VEHICLES)})")
    rl, over = _PROFILES[vehicle]
    out = dict(over)
    px4 = out.pop("flavour_px4", False)
    out["flavour"] = AutopilotFlavour.PX4 if px4 else AutopilotFlavour.ARDUPILOT
    out["realism"] = rl
    return out


# --------------------------------------------------------------------------- windows


def windows(
    rng: np.random.Generator, t0: float, t1: float, per_h: float, lo_s: float, hi_s: float
) -> list[tuple[float, float]]:
    """Non-overlapping windows: a Poisson count (at least one if per_h > 0), uniform lengths."""
    if per_h <= 0 or t1 - t0 < 3 * hi_s:
        return []
    n = max(1, int(rng.poisson(per_h * (t1 - t0) / 3600.0)))
    out: list[tuple[float, float]] = []
    for _ in range(20 * n):
        if len(out) == n:
            break
        length = float(rng.uniform(lo_s, hi_s))
        a = float(rng.uniform(t0 + 0.1 * (t1 - t0), t1 - length - 1.0))
        if all(a > b + 5.0 or a + length + 5.0 < s for s, b in out):
            out.append((a, a + length))
    return sorted(out)


# --------------------------------------------------------------------------- IMU


@dataclass(frozen=True, slots=True)
class ImuRealismErrors:
    """One unit's realistic errors on its time grid: measured = M f + acc_err (likewise gyro)."""

    acc_matrix: FloatArray
    """(I + scale + misalignment), shape (3, 3)."""
    gyro_matrix: FloatArray
    acc_err_b_mps2: FloatArray
    """Bias, temperature, vibration and noise, (N, 3)."""
    gyro_err_b_radps: FloatArray
    vibration_b_mps2: FloatArray
    """The vibration part of acc_err (as delivered: filtered, point-sampled), (N, 3)."""


def butter2_response(f_hz: FloatArray, fc_hz: float) -> tuple[FloatArray, FloatArray]:
    """Gain and phase of a second-order Butterworth low-pass at frequencies f."""
    x = np.asarray(f_hz, dtype=float) / fc_hz
    gain = 1.0 / np.sqrt(1.0 + x**4)
    phase = -np.arctan2(math.sqrt(2.0) * x, 1.0 - x**2)
    return gain, phase


def imu_realism(
    rng: np.random.Generator,
    rl: Realism,
    t_s: FloatArray,
    t_boot0_s: float,
    vib_level: FloatArray,
) -> ImuRealismErrors:
    """Draw one IMU unit's realistic errors at sample times ``t_s``.

    ``vib_level`` (N,) is 0 with the motor off, ``vibration_ground_fraction`` on the
    ground with it running, 1 in flight; the rotor speed follows it (0.8..1.0 of
    ``vibration_hz``) plus a slow wander.
    """
    n = len(t_s)
    eye = np.eye(3)
    acc_m = eye + np.diag(rng.normal(0.0, rl.acc_scale_sigma, 3))
    mis = rng.normal(0.0, rl.misalign_sigma_rad, 3)
    skew = np.array([[0.0, -mis[2], mis[1]], [mis[2], 0.0, -mis[0]], [-mis[1], mis[0], 0.0]])
    acc_m = acc_m + skew
    gyro_m = eye + np.diag(rng.normal(0.0, rl.acc_scale_sigma, 3)) + skew
    acc_err = np.broadcast_to(rng.uniform(-rl.acc_bias_mps2, rl.acc_bias_mps2, 3), (n, 3)).copy()
    gyro_err = np.broadcast_to(rng.normal(0.0, rl.gyro_bias_radps, 3), (n, 3)).copy()
    dt = np.diff(t_s, prepend=t_s[0] if n else 0.0)
    gyro_err += np.cumsum(
        rng.standard_normal((n, 3)) * rl.gyro_rw_radps_rts * np.sqrt(dt)[:, None], 0
    )
    temp = rl.temp_rise_c * (1.0 - np.exp(-(t_s - t_boot0_s + 60.0) / rl.temp_tau_s))
    da, dg = rng.standard_normal(3), rng.standard_normal(3)
    acc_err += temp[:, None] * rl.acc_temp_mps2_per_c * da / max(float(np.linalg.norm(da)), 1e-9)
    gyro_err += temp[:, None] * rl.gyro_temp_radps_per_c * dg / max(float(np.linalg.norm(dg)), 1e-9)
    acc_err += rng.standard_normal((n, 3)) * rl.acc_noise_mps2
    gyro_err += rng.standard_normal((n, 3)) * rl.gyro_noise_radps
    vib = np.zeros((n, 3))
    if (rl.vibration_mps2 > 0 or rl.vibration_broadband_mps2 > 0) and n > 1:
        # rotor speed: follows the vibration level, wanders slowly
        wander = 1.0 + rl.vibration_wander * np.sin(
            2 * np.pi * t_s / 37.0 + rng.uniform(0, 2 * np.pi)
        )
        f1 = rl.vibration_hz * (0.8 + 0.2 * np.clip(vib_level, 0.0, 1.0)) * wander
        cyc = np.concatenate([[0.0], np.cumsum(0.5 * (f1[1:] + f1[:-1]) * np.diff(t_s))])
        for h in (1, 2):
            gain, ph = butter2_response(h * f1, rl.filter_hz)
            amp = rl.vibration_mps2 / h * gain * vib_level
            phase0 = rng.uniform(0, 2 * np.pi, 3)
            vib += amp[:, None] * np.sin(
                2 * np.pi * h * cyc[:, None] + phase0[None, :] + ph[:, None]
            )
        vib += rng.standard_normal((n, 3)) * rl.vibration_broadband_mps2 * vib_level[:, None]
    acc_err += vib
    gyro_err += vib[:, ::-1] * rl.vibration_gyro_ratio_radps_per_mps2
    return ImuRealismErrors(acc_m, gyro_m, acc_err, gyro_err, vib)

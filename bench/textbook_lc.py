"""A textbook real-time loosely coupled GNSS/INS filter (bench baseline, not the service).

Groves, "Principles of GNSS, Inertial, and Multisensor Integrated Navigation Systems"
(2nd ed., 2013): ECEF-frame strapdown mechanisation (section 5.3, eqs. 5.73-5.85, 5.36,
5.38; gravity 2.142/2.133), 15-state closed-loop error-state Kalman filter (attitude,
velocity, position errors in ECEF, accelerometer and gyro biases in body axes; transition
14.50 to first order, system noise 14.82, propagation 3.46), GNSS position and velocity
measurements with the IMU-to-antenna lever arm (14.102-14.116), closed-loop correction
(14.7-14.9). Configured as rtklibexplorer's GNSS_IMU (BSD-3-Clause, T. Everett, 2025)
configures it for the walk_0827 recording (its ``walk_config.py``): its inflated
process noise, initial uncertainties, ZUPT/ZARU at rest, yaw aligned once from the GNSS
track, float solutions de-weighted. Written independently from the book's equations;
that code was read to learn the configuration, not copied. Forward only: no smoothing and
no retroactive "velocity matching" (that rewrites the outage's output after the fact).

Conventions (Groves): an error is estimate minus truth; the attitude error ``psi`` is
``C_est = (I + [psi x]) C_true``; the bias states are the residual biases of the
corrected IMU output (``corrected = true + b``), so a correction adds them to the
estimated bias.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

OMEGA_IE_RPS = 7.292115e-5
R0_M = 6378137.0
E_ECC = 0.0818191908425
MU_M3PS2 = 3.986004418e14
J2 = 1.082627e-3
G0_MPS2 = 9.80665
UG_MPS2 = G0_MPS2 * 1e-6
_OMEGA_IE = np.array([[0.0, -OMEGA_IE_RPS, 0.0], [OMEGA_IE_RPS, 0.0, 0.0], [0.0, 0.0, 0.0]])


def skew(a: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def gravity_ecef(r_e_m: np.ndarray) -> np.ndarray:
    """Acceleration due to gravity (gravitation + centrifugal), ECEF, m/s^2 (2.142, 2.133)."""
    mag = float(np.linalg.norm(r_e_m))
    z = 5.0 * (r_e_m[2] / mag) ** 2
    gamma = (
        -MU_M3PS2
        / mag**3
        * (
            r_e_m
            + 1.5
            * J2
            * (R0_M / mag) ** 2
            * np.array([(1 - z) * r_e_m[0], (1 - z) * r_e_m[1], (3 - z) * r_e_m[2]])
        )
    )
    gamma[0:2] += OMEGA_IE_RPS**2 * r_e_m[0:2]
    return gamma


def c_e_n(lat_rad: float, lon_rad: float) -> np.ndarray:
    """ECEF-to-NED rotation (2.150)."""
    sl, cl = math.sin(lat_rad), math.cos(lat_rad)
    so, co = math.sin(lon_rad), math.cos(lon_rad)
    return np.array([[-sl * co, -sl * so, cl], [-so, co, 0.0], [-cl * co, -cl * so, -sl]])


def llh_to_ecef(lat_rad: float, lon_rad: float, h_m: float) -> np.ndarray:
    """Geodetic to ECEF position (2.112)."""
    re = R0_M / math.sqrt(1 - (E_ECC * math.sin(lat_rad)) ** 2)
    return np.array(
        [
            (re + h_m) * math.cos(lat_rad) * math.cos(lon_rad),
            (re + h_m) * math.cos(lat_rad) * math.sin(lon_rad),
            ((1 - E_ECC**2) * re + h_m) * math.sin(lat_rad),
        ]
    )


def ecef_to_llh(r_e_m: np.ndarray) -> tuple[float, float, float]:
    """ECEF to geodetic latitude, longitude (rad) and height (m), by fixed-point
    iteration on the latitude (converges to < 1e-12 rad in a few steps near the surface)."""
    x, y, z = (float(v) for v in r_e_m)
    lon = math.atan2(y, x)
    p = math.hypot(x, y)
    lat = math.atan2(z, p * (1 - E_ECC**2))
    h = 0.0
    for _ in range(6):
        re = R0_M / math.sqrt(1 - (E_ECC * math.sin(lat)) ** 2)
        h = p / math.cos(lat) - re
        lat = math.atan2(z, p * (1 - E_ECC**2 * re / (re + h)))
    return lat, lon, h


def rodrigues(alpha: np.ndarray) -> np.ndarray:
    """Rotation matrix of a small rotation vector (5.73)."""
    mag = float(np.linalg.norm(alpha))
    a = skew(alpha)
    if mag < 1e-8:
        return np.eye(3) + a
    return np.eye(3) + math.sin(mag) / mag * a + (1 - math.cos(mag)) / mag**2 * (a @ a)


@dataclass
class LcSettings:
    """Tuning, as rtklibexplorer's walk_config.py sets it (units in the names)."""

    imu_rate_cfg_hz: float = 100.0
    """The rate its noise conversion assumes (the recording runs at ~150 Hz)."""
    gyro_noise_dps_rthz: float = 0.0038
    accel_noise_ug_rthz: float = 70.0
    accel_bias_ug_rthz: float = 7.0
    gyro_bias_dps2_rthz: float = 3.8e-5
    noise_factors: tuple[float, float, float, float] = (4.0, 4.0, 4.0, 4.0)
    """Attitude, velocity, accelerometer-bias, gyro-bias process noise multipliers."""
    att_unc_deg: tuple[float, float, float] = (10.0, 10.0, 100.0)
    vel_unc_mps: tuple[float, float, float] = (0.05, 0.05, 0.1)  # N, E, D
    pos_unc_m: tuple[float, float, float] = (0.05, 0.05, 0.1)  # N, E, D
    accel_bias_unc_mps2: float = 0.2
    gyro_bias_unc_dps: float = 0.2
    lever_arm_b_m: tuple[float, float, float] = (0.0, 0.05, 0.0)
    """Antenna relative to the IMU, body FRD, m: as its code applies the configuration
    (IMU offset minus antenna offset, added to the IMU's position). Its configuration says
    the IMU sits 5 cm right of the antenna, which would be (0, -0.05, 0); the filter's
    closures on the walk move by several metres between the two (see bench/walk_0827.py)."""
    lever_arm_in_h: bool = False
    """Couple the lever arm into the attitude and gyro-bias columns of H (14.115). Off as
    in rtklibexplorer's code: with a 5 cm arm guessed, not measured, and 1 cm RTK
    sigmas the coupling would make yaw look observable at rest."""
    float_gain: float = 2.0
    pos_sd_floor_m: tuple[float, float] = (0.0, 0.0)
    """Floors on the receiver's reported position 1-sigma (horizontal, vertical), m: none
    in the textbook configuration (a bench knob to swap in the service's floors)."""
    vel_sd_floor_mps: float = 0.0
    vertical_velocity: bool = True
    """Use the receiver's vertical velocity. The textbook does; the service's input on the
    walk (GPS_RAW_INT: ground speed and course) has none (a bench knob to swap that in)."""
    zupt_samples: int = 50
    zupt_accel_mps2: float = 0.25
    zupt_gyro_dps: float = 0.25
    zupt_vel_sd_mps: float = 0.01
    zaru_sd_dps: float = 0.01
    yaw_align_min_speed_mps: float = 1.0
    zupt: bool = True
    yaw_align: bool = True

    def process_noise_psd(self) -> np.ndarray:
        """Diagonal continuous-time system noise (per state, units^2/s) as its
        configuration computes it: (density x sqrt(rate) x factor)^2, i.e. the book's
        spectral density (14.82) inflated by rate x factor^2."""
        root_hz = math.sqrt(self.imu_rate_cfg_hz)
        f = self.noise_factors
        att = (math.radians(self.gyro_noise_dps_rthz) * root_hz * f[0]) ** 2
        vel = (self.accel_noise_ug_rthz * UG_MPS2 * root_hz * f[1]) ** 2
        ba = (self.accel_bias_ug_rthz * UG_MPS2 * root_hz * f[2]) ** 2
        bg = (math.radians(self.gyro_bias_dps2_rthz) * root_hz * f[3]) ** 2
        return np.array([att] * 3 + [vel] * 3 + [0.0] * 3 + [ba] * 3 + [bg] * 3)


@dataclass
class LcFilter:
    """State: IMU position/velocity (ECEF), body-to-ECEF attitude, biases, covariance."""

    r_e_m: np.ndarray
    v_e_mps: np.ndarray
    c_b_e: np.ndarray
    settings: LcSettings = field(default_factory=LcSettings)
    bias_acc_mps2: np.ndarray = field(default_factory=lambda: np.zeros(3))
    bias_gyro_rps: np.ndarray = field(default_factory=lambda: np.zeros(3))
    p: np.ndarray = field(default_factory=lambda: np.zeros((15, 15)))
    yaw_aligned: bool = False
    zupts: int = 0

    def __post_init__(self) -> None:
        self._qc = self.settings.process_noise_psd()
        self._lever = np.array(self.settings.lever_arm_b_m, dtype=float)
        self._w_b = np.zeros(3)  # the last bias-corrected angular rate (lever-arm velocity)
        self._still = 0
        self._gyro_sum = np.zeros(3)

    @classmethod
    def start(
        cls,
        lat_rad: float,
        lon_rad: float,
        h_m: float,
        vel_ned_mps: np.ndarray,
        c_b_n: np.ndarray,
        settings: LcSettings | None = None,
    ) -> LcFilter:
        """Initialised from a fix and an attitude guess, with the configured uncertainties."""
        s = settings or LcSettings()
        cen = c_e_n(lat_rad, lon_rad)
        f = cls(
            r_e_m=llh_to_ecef(lat_rad, lon_rad, h_m),
            v_e_mps=cen.T @ np.asarray(vel_ned_mps, dtype=float),
            c_b_e=cen.T @ c_b_n,
            settings=s,
        )
        p = np.zeros((15, 15))
        p[0:3, 0:3] = cen.T @ np.diag(np.radians(s.att_unc_deg) ** 2) @ cen
        p[3:6, 3:6] = cen.T @ np.diag(np.square(s.vel_unc_mps)) @ cen
        p[6:9, 6:9] = cen.T @ np.diag(np.square(s.pos_unc_m)) @ cen
        p[9:12, 9:12] = np.eye(3) * s.accel_bias_unc_mps2**2
        p[12:15, 12:15] = np.eye(3) * math.radians(s.gyro_bias_unc_dps) ** 2
        f.p = p
        return f

    # -- strapdown and covariance --------------------------------------------------------
    def propagate(self, dt_s: float, f_meas_b: np.ndarray, w_meas_b: np.ndarray) -> None:
        """One IMU interval: mechanisation (5.73-5.85, 5.36, 5.38) with the bias-corrected
        measurements, then the covariance (14.50 first order, 14.82, 3.46); ZUPT/ZARU when
        the IMU has been still for ``zupt_samples`` samples."""
        f_b = f_meas_b - self.bias_acc_mps2
        w_b = w_meas_b - self.bias_gyro_rps
        self._w_b = w_b
        gamma = gravity_ecef(self.r_e_m)
        c_old = self.c_b_e
        a_ie = OMEGA_IE_RPS * dt_s
        c_earth = np.array(
            [
                [math.cos(a_ie), math.sin(a_ie), 0.0],
                [-math.sin(a_ie), math.cos(a_ie), 0.0],
                [0, 0, 1],
            ]
        )
        alpha = w_b * dt_s
        mag = float(np.linalg.norm(alpha))
        a = skew(alpha)
        self.c_b_e = c_earth @ c_old @ rodrigues(alpha)
        if mag > 1e-8:
            c_avg = c_old @ (
                np.eye(3)
                + (1 - math.cos(mag)) / mag**2 * a
                + (1 - math.sin(mag) / mag) / mag**2 * (a @ a)
            )
        else:
            c_avg = c_old.copy()
        c_avg -= 0.5 * skew(np.array([0.0, 0.0, a_ie])) @ c_old
        f_e = c_avg @ f_b
        v_old = self.v_e_mps
        self.v_e_mps = v_old + dt_s * (f_e + gamma - 2.0 * _OMEGA_IE @ v_old)
        self.r_e_m = self.r_e_m + 0.5 * dt_s * (self.v_e_mps + v_old)
        # covariance
        c = self.c_b_e
        r_mag = float(np.linalg.norm(self.r_e_m))
        lat = math.asin(self.r_e_m[2] / r_mag)  # geocentric is enough for r_eS
        r_es = (
            R0_M
            / math.sqrt(1 - (E_ECC * math.sin(lat)) ** 2)
            * math.sqrt(math.cos(lat) ** 2 + (1 - E_ECC**2) ** 2 * math.sin(lat) ** 2)
        )
        phi = np.eye(15)
        phi[0:3, 0:3] -= _OMEGA_IE * dt_s
        phi[0:3, 12:15] = c * dt_s
        phi[3:6, 0:3] = -dt_s * skew(c @ f_b)
        phi[3:6, 3:6] -= 2.0 * _OMEGA_IE * dt_s
        phi[3:6, 6:9] = -dt_s * 2.0 * np.outer(gamma, self.r_e_m) / (r_es * r_mag)
        phi[3:6, 9:12] = c * dt_s
        phi[6:9, 3:6] = np.eye(3) * dt_s
        q = np.diag(self._qc * dt_s)
        self.p = phi @ (self.p + 0.5 * q) @ phi.T + 0.5 * q
        self.p = 0.5 * (self.p + self.p.T)
        if self.settings.zupt:
            self._zupt_check(f_b, w_b)

    # -- measurements --------------------------------------------------------------------
    def _correct(self, x: np.ndarray, kh: np.ndarray, k: np.ndarray, r: np.ndarray) -> None:
        i_kh = np.eye(15) - kh
        self.p = i_kh @ self.p @ i_kh.T + k @ r @ k.T  # Joseph form
        self.p = 0.5 * (self.p + self.p.T)
        self.c_b_e = (np.eye(3) - skew(x[0:3])) @ self.c_b_e  # 14.7
        u, _, vt = np.linalg.svd(self.c_b_e)
        self.c_b_e = u @ vt
        self.v_e_mps = self.v_e_mps - x[3:6]
        self.r_e_m = self.r_e_m - x[6:9]
        self.bias_acc_mps2 = self.bias_acc_mps2 + x[9:12]
        self.bias_gyro_rps = self.bias_gyro_rps + x[12:15]

    def _update(self, z: np.ndarray, h: np.ndarray, r: np.ndarray) -> np.ndarray:
        s = h @ self.p @ h.T + r
        k = self.p @ h.T @ np.linalg.inv(s)
        x = k @ z
        nis = float(z @ np.linalg.solve(s, z))
        self._correct(x, k @ h, k, r)
        return np.array([nis])

    def antenna(self) -> tuple[np.ndarray, np.ndarray]:
        """Antenna position and velocity, ECEF (lever arm, 14.102 / 14.111)."""
        cl = self.c_b_e @ self._lever
        w_b = self._w_b
        r = self.r_e_m + cl
        v = self.v_e_mps + self.c_b_e @ np.cross(w_b, self._lever) - _OMEGA_IE @ cl
        return r, v

    def update_gnss(
        self,
        lat_rad: float,
        lon_rad: float,
        h_m: float,
        vel_ned_mps: np.ndarray,
        pos_sd_ned_m: np.ndarray,
        vel_sd_ned_mps: np.ndarray,
    ) -> float:
        """Antenna position and velocity measurement (14.102, 14.115, 14.116); the NIS."""
        cen = c_e_n(lat_rad, lon_rad)
        r_meas = llh_to_ecef(lat_rad, lon_rad, h_m)
        v_meas = cen.T @ np.asarray(vel_ned_mps, dtype=float)
        r_ant, v_ant = self.antenna()
        cl = self.c_b_e @ self._lever
        w_b = self._w_b
        h = np.zeros((6, 15))
        h[0:3, 6:9] = -np.eye(3)
        h[3:6, 3:6] = -np.eye(3)
        if self.settings.lever_arm_in_h:  # the book's full 14.115; rtklibexplorer omits it
            h[0:3, 0:3] = skew(cl)
            h[3:6, 0:3] = skew(self.c_b_e @ np.cross(w_b, self._lever) - _OMEGA_IE @ cl)
            h[3:6, 12:15] = self.c_b_e @ skew(self._lever)
        s = self.settings
        floor_p = np.array([s.pos_sd_floor_m[0], s.pos_sd_floor_m[0], s.pos_sd_floor_m[1]])
        sd_p = np.maximum(np.asarray(pos_sd_ned_m, dtype=float), floor_p)
        sd_v = np.maximum(np.asarray(vel_sd_ned_mps, dtype=float), s.vel_sd_floor_mps)
        r = np.zeros((6, 6))
        r[0:3, 0:3] = cen.T @ np.diag(np.square(sd_p)) @ cen
        r[3:6, 3:6] = cen.T @ np.diag(np.square(sd_v)) @ cen
        z = np.concatenate([r_meas - r_ant, v_meas - v_ant])
        if not s.vertical_velocity:  # the velocity rows in NED, the down one dropped
            t = np.eye(6)
            t[3:6, 3:6] = cen
            z, h, r = t @ z, t @ h, t @ r @ t.T
            keep = [0, 1, 2, 3, 4]
            z, h, r = z[keep], h[keep], r[np.ix_(keep, keep)]
        return float(self._update(z, h, r)[0])

    def _zupt_check(self, f_b: np.ndarray, w_b: np.ndarray) -> None:
        s = self.settings
        g = float(np.linalg.norm(gravity_ecef(self.r_e_m)))
        still = abs(float(np.linalg.norm(f_b)) - g) < s.zupt_accel_mps2 and float(
            np.linalg.norm(w_b)
        ) < math.radians(s.zupt_gyro_dps)
        if not still:
            self._still = 0
            return
        self._still += 1
        self._gyro_sum = w_b.copy() if self._still == 1 else self._gyro_sum + w_b
        if self._still == s.zupt_samples:
            self.zupt(self._gyro_sum / s.zupt_samples)
            self._still = 0

    def zupt(self, mean_gyro_b_rps: np.ndarray) -> None:
        """Zero velocity and zero angular rate (w.r.t. the Earth) at rest (Groves ch. 15,
        zero updates), in the sign convention of the GNSS update (rtklibexplorer's code
        also ties the velocity row to the accelerometer bias and subtracts the bias
        correction; not followed). Its thresholds (0.25 deg/s on the corrected rate's norm
        for 50 samples in a row) fire on the walk only in the rest after it (from 117 s):
        before its biases are estimated the resting gyro reads ~0.23 deg/s plus noise."""
        s = self.settings
        h = np.zeros((6, 15))
        h[0:3, 3:6] = -np.eye(3)
        h[3:6, 12:15] = -np.eye(3)
        r = np.diag([s.zupt_vel_sd_mps**2] * 3 + [math.radians(s.zaru_sd_dps) ** 2] * 3)
        w_ie_b = self.c_b_e.T @ np.array([0.0, 0.0, OMEGA_IE_RPS])
        z = np.concatenate([-self.v_e_mps, w_ie_b - mean_gyro_b_rps])
        self._update(z, h, r)
        self.zupts += 1

    def align_yaw(self, vel_ned_mps: np.ndarray, lat_rad: float, lon_rad: float) -> float:
        """Yaw set to the GNSS course (the body's x axis along the track), the attitude
        covariance rotated with it; the correction, rad."""
        cen = c_e_n(lat_rad, lon_rad)
        c_b_n = cen @ self.c_b_e
        yaw = math.atan2(c_b_n[1, 0], c_b_n[0, 0])
        course = math.atan2(vel_ned_mps[1], vel_ned_mps[0])
        d = math.atan2(math.sin(course - yaw), math.cos(course - yaw))
        rz = np.array(
            [[math.cos(d), -math.sin(d), 0.0], [math.sin(d), math.cos(d), 0.0], [0, 0, 1]]
        )
        r_e = cen.T @ rz @ cen
        self.c_b_e = r_e @ self.c_b_e
        self.p[0:3, :] = r_e @ self.p[0:3, :]
        self.p[:, 0:3] = self.p[:, 0:3] @ r_e.T
        self.yaw_aligned = True
        return d

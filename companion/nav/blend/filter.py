"""The blend's navigator: the error-state Kalman filter that ties the mechanisation, the
error model, the snapshot history, the GNSS measurement model and the adaptive noise
together (the method: :mod:`companion.nav.blend`)."""

from __future__ import annotations

import dataclasses
import logging
import math
from collections import deque

import numpy as np

from companion.nav import ins
from companion.nav.blend.accel_noise import AccelNoise
from companion.nav.blend.adaptive import AdaptiveNoise
from companion.nav.blend.alignment import Alignment, CoarseAligner
from companion.nav.blend.config import BlendConfig
from companion.nav.blend.diagnostics import BlendDiagnostics
from companion.nav.blend.error_model import (
    IGB,
    N_STATE,
    ErrorModel,
    carry_pos_vel,
    open_segment_cov,
)
from companion.nav.blend.gyro_carry import GyroCarry
from companion.nav.blend.history import (
    History,
    carry_correction,
    inject_snapshot,
    snapshot_of,
    state_at,
)
from companion.nav.blend.measurement import GnssModel
from companion.nav.blend.rate_drift import RateDrift
from companion.nav.blend.receiver import GNSS_ERR_TAU_S, ReceiverError
from companion.nav.blend.rest import at_rest
from companion.nav.blend.unaided import UnaidedDeparture, heading_sensitivity
from companion.nav.blend.velocity_error import VelocityErrorMeter
from companion.nav.frames import LocalFrame, rotation_between_frames
from companion.nav.imu_check import ImuNoiseCheck, ImuNoiseVerdict
from companion.nav.kalman import chi2_gate, joseph_update_diag_r, predict_covariance
from companion.nav.navigator import GnssMeasurement, GnssUpdate, NavState
from companion.nav.rotations import (
    Quat,
    euler_to_quat_values,
    mat_to_quat,
    quat_from_rotvec,
    quat_mul,
    quat_normalise,
    quat_to_mat,
    quat_to_yaw,
    rotate_by_rotvec,
    wrap_pi,
)
from companion.types import AttitudeSample, FixType, FloatArray, ImuSample

log = logging.getLogger(__name__)

_DEG = math.pi / 180.0


class BlendNavigator:
    """Adaptive GNSS/INS blend (implements :class:`companion.nav.navigator.Navigator`).

    ``frame`` is the engine's local frame, used for the gravity model; it is
    updated by :meth:`shift_frame`. Positions are of the IMU reference point.
    """

    def __init__(self, config: BlendConfig | None = None, frame: LocalFrame | None = None) -> None:
        self.config = config or BlendConfig()
        self._frame = frame or LocalFrame(45.0 * _DEG, 0.0, 0.0)
        if frame is None:
            log.warning("no local frame given: gravity evaluated at 45 deg latitude, 0 m")
        cfg = self.config
        self._strapdown = cfg.mode == "strapdown"
        self._gm = cfg.gnss_error_model == "gauss_markov"
        self._gates = {m: chi2_gate(cfg.gate_false_alarm_prob, m) for m in range(1, 7)}
        self._rx_gate = chi2_gate(1e-6, 3)
        self._accel_psd0 = cfg.accel_vrw_mps_rts**2
        self._max_imu_gap_s = cfg.max_imu_gap_s
        self._cov_interval_s = cfg.cov_interval_s
        self._model = ErrorModel(cfg)
        self._gnss = GnssModel(cfg)
        self._adaptive = AdaptiveNoise(cfg, has_lever=self._gnss.has_lever, gauss_markov=self._gm)
        self._rx = ReceiverError(cfg.gnss_err_tau_s)
        self._aligner = CoarseAligner(
            cfg.align_static_s,
            cfg.align_static_acc_std_mps2,
            cfg.align_static_gyro_std_radps,
            cfg.align_window_s,
            cfg.align_yaw_sigma_max_rad,
            cfg.align_tilt_sigma_rad,
        )
        self._own_model: ErrorModel | None = None
        self._own_attitude = False
        self._gyro_meter = (
            ImuNoiseCheck(cfg.gyro_arw_rad_rts, cfg.accel_vrw_mps_rts)
            if cfg.gyro_noise_measured
            else None
        )
        """The gyro's measured white noise (kept across restarts: it is the IMU's)."""
        self._accel_noise = (
            AccelNoise(cfg.gyro_arw_rad_rts, cfg.accel_vrw_mps_rts)
            if cfg.accel_noise_measured
            else None
        )
        """The accelerometer's measured white noise (kept across restarts: it is the IMU's)."""
        self._gyro_psd_measured: float | None = None
        """Gyro PSD measured above the configured one (rad^2/s), None while it is not."""
        self._vel_error = (
            VelocityErrorMeter(cfg.gnss_white_fraction if self._gm else 1.0)
            if cfg.vel_error_measured
            else None
        )
        """The receiver's velocity error beyond its report, measured by its positions (kept
        across restarts: it is the receiver's)."""
        self.rate_drift = RateDrift(cfg.rate_drift_window_s)
        """How far the autopilot's attitude strays from its body rates (kept across
        restarts: it is the autopilot's)."""
        self._rate_drift_yaw_corr = math.nan
        self.gyro_carry = GyroCarry()
        """The IMU's gyro integrated between attitude samples (:mod:`.gyro_carry`)."""
        self.imu_drift = RateDrift(cfg.rate_drift_window_s)
        """As :attr:`rate_drift`, the attitude against the IMU's gyro between samples:
        the correction the unaided departure carries when the IMU covers the attitude."""
        self._imu_covers = False
        """The IMU's gyro carried the attitude's last step (:meth:`GyroCarry.take`)."""
        self._departure_on_imu = False
        """The gap's departure is carried by the IMU's gyro (else by the attitude's rates)."""
        self._held_w0_n: FloatArray | None = None
        """The rotation (nav frame, rad/s) when the rates began carrying the attitude."""
        self._held_peak_sq = 0.0
        """Largest squared change of that rotation since, (rad/s)^2."""
        self._unaided_origin: tuple[float, list[float], list[float]] = (0.0, [0.0] * 3, [0.0] * 3)
        """IMU time, position and velocity (NED) where the unaided heading began."""
        self.reset()

    # ------------------------------------------------------------------ protocol

    @property
    def initialised(self) -> bool:
        """True once a state exists (after the first accepted fix with an attitude)."""
        return self._init

    def reset(self) -> None:
        """Forget everything (the configuration and frame are kept), except, when the blend
        ran on its own alignment, its attitude and gyro bias: the aligner carries them on
        (no autopilot attitude would level it again while moving)."""
        seed = self._own_alignment() if getattr(self, "_init", False) else None
        self._aligner.reset()
        if seed is not None:
            self._aligner.seed(seed)
        self._strapdown = self.config.mode == "strapdown"
        self._own_attitude = False
        self.attitude_held = False
        """The autopilot's attitude is not taken: its body rates carry ours
        (:meth:`hold_attitude`)."""
        self._held_rates: list[tuple[float, list[float]]] = []
        """While held: the autopilot's two latest body rates ``(t_s, rad/s)``, integrated
        instead of the IMU's gyros."""
        self._bg_before_hold: list[float] | None = None
        self._last_rates_b: list[float] | None = None
        """The autopilot's latest body rates, rad/s (the rotation a hold starts in)."""
        self.attitude_unaided_flag = False
        """A GNSS gap the autopilot shares: its attitude is modelled as unaided
        (:meth:`attitude_unaided`)."""
        self.tilt_unaided_flag = False
        """... and its tilt too (:meth:`attitude_unaided`)."""
        self._unaided_on = False
        """The unaided model is in force (attitude-aided mode, the attitude taken)."""
        self._bg_before_unaided: list[float] | None = None
        self.departure = UnaidedDeparture()
        """Through an unaided gap: how far the autopilot's heading departs from its
        rates."""
        self._model = ErrorModel(self.config)
        self._model.set_gyro_psd(self._gyro_psd_measured)
        self._mech = ins.Mechanisation(ins.LocalGravity(self._frame.lat0_rad, self._frame.alt0_m))
        self._init = False
        self._pre_imu: deque[tuple[float, list[float], list[float]]]
        self._pre_imu = deque()
        self._p = np.zeros((N_STATE, N_STATE))
        self._rx.reset()
        if self._vel_error is not None:
            self._vel_error.restart_chain()
        self._hist: History = deque()
        self._att_q: Quat | None = None
        self._att_t_s = math.nan
        self._att_corr: Quat = (1.0, 0.0, 0.0, 0.0)
        self._last_fuse_t_s = math.nan
        self._fixes_moved_a = [0.0, 0.0, 0.0]
        self._fixes_moved_b = [0.0, 0.0, 0.0]
        self.generation = getattr(self, "generation", 0) + 1
        """Changes whenever the state restarts or changes frame (an inertial-only prediction
        kept from before is then meaningless)."""
        self._height_bias_var_m2 = 0.0
        """Variance of the common offset of the heights fused since the last fix (published
        on top of the filter's own down-position variance; see :meth:`on_height`)."""
        self._adaptive.reset()
        self.diag = BlendDiagnostics(accel_psd_ned=np.full(3, self._accel_psd0))
        self._model.reset(self.diag.accel_psd_ned)
        self._note_gyro_psd()

    def adopt_imu_noise(self, other: BlendNavigator) -> None:
        """Take over the IMU noise ``other`` measured (its accelerometer's and gyro's, on
        the same IMU), when both were configured with the same densities: a navigator
        built afresh (after a silence) need not measure the IMU again."""
        cfg, ocfg = self.config, other.config
        if (cfg.accel_vrw_mps_rts, cfg.gyro_arw_rad_rts) != (
            ocfg.accel_vrw_mps_rts,
            ocfg.gyro_arw_rad_rts,
        ):
            return
        if self._accel_noise is not None and other._accel_noise is not None:
            self._accel_noise = other._accel_noise
            if self._accel_noise.psd_m2ps3 != self._accel_psd0:
                self._follow_accel_noise(self._accel_noise.psd_m2ps3)
        if self._gyro_meter is not None and other._gyro_meter is not None:
            self._gyro_meter = other._gyro_meter
            if other._gyro_psd_measured != self._gyro_psd_measured:
                self._gyro_psd_measured = other._gyro_psd_measured
                self._model.set_gyro_psd(self._gyro_psd_measured)
                self._note_gyro_psd()

    def on_imu(self, sample: ImuSample) -> None:
        """Advance the nominal state with one IMU sample; propagate P every ``cov_interval_s``."""
        acc_t = sample.acc_b_mps2.tolist()
        gyro_t = sample.gyro_b_radps.tolist()
        if len(acc_t) != 3 or len(gyro_t) != 3:
            self._reject("imu_bad_shape")
            return
        if not math.isfinite(sum(acc_t) + sum(gyro_t)):  # NaN or inf makes the sum non-finite
            self._reject("imu_not_finite")
            return
        meter = self._gyro_meter
        if meter is not None and (self._strapdown or self._att_q is None):
            verdict = meter.on_imu(sample)
            if verdict is not None:
                self._follow_gyro_noise(verdict)
        accel_noise = self._accel_noise
        if accel_noise is not None and accel_noise.on_imu(sample):
            self._follow_accel_noise(accel_noise.psd_m2ps3)
        self.gyro_carry.on_imu(sample.t_s, gyro_t)
        if self._held_rates:
            gyro_t = held_rate_at(self._held_rates, sample.t_s)
        mech = self._mech
        if not self._init:
            if self._pre_imu and sample.t_s <= self._pre_imu[-1][0]:
                if sample.t_s > self._pre_imu[-1][0] - self.config.max_imu_gap_s:
                    self._reject("imu_time_not_increasing")
                    return
                self._reject("imu_clock_restarted")  # a new clock: start the buffer again
                self._pre_imu.clear()
            self._pre_imu.append((sample.t_s, acc_t, gyro_t))
            while self._pre_imu[0][0] < sample.t_s - self.config.history_s:
                self._pre_imu.popleft()
            mech.set_raw(acc_t, gyro_t)
            mech.t_s = sample.t_s
            if self._att_q is None:
                self._aligner.on_imu(sample.t_s, acc_t, gyro_t)
            return
        dt = sample.t_s - mech.t_s
        if dt <= 0.0:
            self._reject("imu_time_not_increasing")
            return
        if dt > self._max_imu_gap_s:
            self._reject("imu_gap")
        mech.step(sample.t_s, acc_t, gyro_t)
        if mech.seg_dt_s >= self._cov_interval_s:
            self._close_segment()

    def reset_heading(self, yaw_sigma_rad: float) -> None:
        """A taxi heading correction (Markelov et al.) was applied to the attitude input:
        restart the heading from the corrected autopilot yaw, 1-sigma ``yaw_sigma_rad``.

        Attitude-aided: the filter's own yaw correction estimated part of the error the
        taxi correction has now removed from the input; kept, it would correct twice.
        Strapdown: the mechanisation's yaw is set to the corrected autopilot yaw.
        Either way the yaw error's covariance restarts at ``yaw_sigma_rad``, uncorrelated.
        """
        if not (math.isfinite(yaw_sigma_rad) and yaw_sigma_rad > 0.0):
            raise ValueError("yaw_sigma_rad must be finite and > 0")
        if not self._init or self._att_q is None:
            return
        mech = self._mech
        if self._strapdown:
            target_yaw = quat_to_yaw(*self._att_q)
            yaw = quat_to_yaw(*mech.q_nb)
            turn = wrap_pi(target_yaw - yaw)
        else:
            w, x, y, z = self._att_corr
            sign = 1.0 if w >= 0.0 else -1.0
            # the correction's rotation about down (small-angle rotation vector)
            turn = -2.0 * sign * z
            self._att_corr = quat_normalise(
                quat_mul(quat_from_rotvec(0.0, 0.0, turn), self._att_corr)
            )
        mech.q_nb = rotate_by_rotvec(mech.q_nb, 0.0, 0.0, turn)
        k = ins.IA + 2
        p = self._p
        p[k, :] = 0.0
        p[:, k] = 0.0
        p[k, k] = yaw_sigma_rad**2
        for snap in self._hist:
            snap.q_nb = rotate_by_rotvec(snap.q_nb, 0.0, 0.0, turn)
        log.info("heading restarted from the taxi correction: turned %.3f deg", math.degrees(turn))

    def hold_attitude(self, hold: bool) -> None:
        """``hold``: stop taking the autopilot's attitude and integrate its body rates
        instead (ATTITUDE's rates: its gyros less its own bias estimate). An autopilot that
        fuses what we publish corrects its attitude with it: taken back, errors would feed
        on themselves; its rates carry only its slowly moving gyro bias estimate. The
        attitude error is then modelled as a strapdown's, from its error at that moment,
        the rates' bias variance how far the autopilot's attitude strayed from them before
        (:attr:`rate_drift`) plus ``gyro_instability_radps`` squared. ``False``: take the
        autopilot's attitude again, its error restarting from ``att_err_sigma_rad``.
        Nothing changes in strapdown mode or on the blend's own alignment, which never
        take the autopilot's attitude.

        The IMU's own gyros are not used for this: ArduPilot sends them in whole mrad/s,
        truncated toward zero (RAW_IMU, SCALED_IMU), a bias of 0.5 mrad/s that changes sign
        with the rate: carried on them, SITL's attitude drifted by about a degree in 30 s.
        """
        if hold is self.attitude_held:
            return
        self.attitude_held = hold
        if self.config.mode == "strapdown" or self._own_attitude:
            return
        if hold:
            self._leave_unaided()
        self._strapdown = hold
        self._model.set_strapdown(hold)
        self._held_w0_n = None  # a hold starts its rotation's record afresh
        self._held_peak_sq = 0.0
        if not self._init:
            return
        p = self._p
        mech = self._mech
        if hold:
            # the autopilot's body rates (its gyros less its own bias estimate) carry the
            # attitude: not its attitude, which its fusion of our output corrects
            self._bg_before_hold = list(mech.bg)
            mech.bg = [0.0, 0.0, 0.0]
            p[12:15, :] = 0.0
            p[:, 12:15] = 0.0
            var = self.rate_drift.bias_variance() or [0.0, 0.0, 0.0]
            floor = self.config.gyro_instability_radps**2
            p[12:15, 12:15] = np.diag([v + floor for v in var])
            # the rotation under way when the rates take over leaves an attitude error
            # along it (held_rates_lag_s)
            w = self._last_rates_b
            lag_s = self.config.held_rates_lag_s
            if not abs(mech.t_s - self._att_t_s) <= self._max_imu_gap_s:
                w = None  # no recent attitude: its rotation now is unknown
            if w is not None and lag_s > 0.0:
                w_n = quat_to_mat(mech.q_nb) @ np.array(w)
                p[6:9, 6:9] += lag_s**2 * np.outer(w_n, w_n)
                self._held_w0_n = w_n
            log.info(
                "autopilot attitude held out: its body rates carry ours (their bias 1-sigma "
                "%s deg/s; started turning at %s deg/s)",
                [round(math.degrees(math.sqrt(v + floor)), 4) for v in var],
                None if w is None else round(math.degrees(math.sqrt(sum(c * c for c in w))), 1),
            )
        else:
            self._held_rates = []
            if self._bg_before_hold is not None:
                mech.bg = self._bg_before_hold
                self._bg_before_hold = None
            p[6:9, :] = 0.0
            p[:, 6:9] = 0.0
            p[6:9, 6:9] = np.diag(np.square(self.config.att_err_sigma_rad))
            p[12:15, :] = 0.0
            p[:, 12:15] = 0.0
            p[12:15, 12:15] = np.eye(3) * self.config.gyro_bias_sigma_radps**2
            log.info("autopilot attitude taken again")

    def _held_rotation_changed(self, rates_b: list[float]) -> None:
        """While the rates carry the attitude: the carry lags the rotation by
        ``held_rates_lag_s``, so its error is that lag times the change of the rotation
        since the hold began (nav frame), present while the rotation differs (a turn
        entered in the gap) and turning the velocity meanwhile. Its largest square so far,
        along the change, is counted as attitude-error variance as it grows (the hold's
        start counts the rotation then)."""
        lag_s = self.config.held_rates_lag_s
        if not self._init or lag_s <= 0.0:
            return
        w_n = quat_to_mat(self._mech.q_nb) @ np.array(rates_b)
        d = w_n[2] - (self._held_w0_n[2] if self._held_w0_n is not None else 0.0)
        sq = d * d
        if sq > self._held_peak_sq:
            self._p[8, 8] += lag_s**2 * (sq - self._held_peak_sq)
            self._held_peak_sq = sq

    def attitude_unaided(self, unaided: bool, *, tilt: bool = False) -> None:
        """``unaided``: a GNSS gap the autopilot shares (its GNSS is ours). Its attitude,
        still taken, is no longer aided by GNSS: its heading error is modelled without the
        Gauss-Markov pull back (:meth:`ErrorModel.set_unaided`), turned by the bias of its
        body rates (the gyro-bias states restart at the variance :attr:`rate_drift`
        bounds, plus ``gyro_instability_radps`` squared, as when the rates carry the
        attitude) and widened by how far its heading departs from those rates
        (:mod:`.unaided`). ``tilt``: its tilt too (no pull back, turned by the same bias):
        the autopilot has lost all its aiding (:meth:`ErrorModel.set_unaided`).
        ``False``: the aided model again; the attitude error's
        covariance is kept for the fixes to shrink. Only in attitude-aided mode with the
        autopilot's attitude taken (not held, not strapdown, not the blend's own)."""
        self.attitude_unaided_flag = unaided
        self.tilt_unaided_flag = unaided and tilt
        self._follow_unaided()

    def _follow_unaided(self) -> None:
        want = (
            self.attitude_unaided_flag
            and self._init
            and not self._strapdown
            and not self._own_attitude
            and not self.attitude_held
        )
        if want and not self._unaided_on:
            self._enter_unaided()
        elif not want:
            self._leave_unaided()
        if self._unaided_on:
            self._model.set_unaided(True, tilt=self.tilt_unaided_flag)

    def _enter_unaided(self) -> None:
        self._unaided_on = True
        self._model.set_unaided(True)
        mech = self._mech
        self._bg_before_unaided = list(mech.bg)
        p = self._p
        p[12:15, :] = 0.0
        p[:, 12:15] = 0.0
        var = self.rate_drift.bias_variance() or [0.0, 0.0, 0.0]
        floor = self.config.gyro_instability_radps**2
        p[12:15, 12:15] = np.diag([v + floor for v in var])
        imu_rate = self.imu_drift.mean_rate()
        self._departure_on_imu = self._imu_covers and imu_rate is not None
        self.departure.start(imu_rate if self._departure_on_imu else self.rate_drift.mean_rate())
        self._unaided_origin = (mech.t_s, list(mech.pos), list(mech.vel))
        log.info(
            "GNSS gap: the autopilot's heading modelled unaided (its rates' bias 1-sigma %s deg/s)",
            [round(math.degrees(math.sqrt(v + floor)), 4) for v in var],
        )

    def _grow_heading(self, var_rad2: float) -> None:
        """A heading-error variance ``var_rad2`` the gap's departure adds, as an error
        present since the gap's start (:func:`.unaided.heading_sensitivity`): on the
        heading, and on the velocity and position it has turned since."""
        if var_rad2 <= 0.0:
            return
        t0, pos0, vel0 = self._unaided_origin
        mech = self._mech
        dt = mech.t_s - t0
        dv = (mech.vel[0] - vel0[0], mech.vel[1] - vel0[1])
        dq = (mech.pos[0] - pos0[0] - vel0[0] * dt, mech.pos[1] - pos0[1] - vel0[1] * dt)
        g = np.zeros(self._p.shape[0])
        g[[ins.IP, ins.IP + 1, ins.IV, ins.IV + 1]] = heading_sensitivity(dv, dq)
        g[ins.IA + 2] = 1.0
        self._p += var_rad2 * np.outer(g, g)

    def _leave_unaided(self) -> None:
        if not self._unaided_on:
            return
        self._unaided_on = False
        self._model.set_unaided(False)
        if self._bg_before_unaided is not None:
            self._mech.bg = self._bg_before_unaided
            self._bg_before_unaided = None
        p = self._p
        p[12:15, :] = 0.0
        p[:, 12:15] = 0.0
        p[12:15, 12:15] = np.eye(3) * self.config.gyro_bias_sigma_radps**2

    def on_attitude(self, sample: AttitudeSample, yaw_correction_rad: float) -> None:
        """Take the autopilot's attitude (yaw less ``yaw_correction_rad``).

        Attitude-aided mode: it replaces the attitude (after the filter's own
        estimated correction), carried by the gyro to the newest IMU time, and is compared
        with its body rates (:attr:`rate_drift`); while held (:meth:`hold_attitude`) only
        its body rates are kept. Strapdown mode: used only to initialise.
        """
        roll, pitch, yaw = sample.roll_rad, sample.pitch_rad, sample.yaw_rad
        isfinite = math.isfinite
        if not (
            isfinite(roll) and isfinite(pitch) and isfinite(yaw) and isfinite(yaw_correction_rad)
        ):
            self._reject("attitude_not_finite")
            return
        self._att_q = euler_to_quat_values(roll, pitch, yaw - yaw_correction_rad)
        self._att_t_s = sample.t_s
        rates = sample.rate_b_radps.tolist()
        dq_imu = self.gyro_carry.take(sample.t_s)
        self._imu_covers = dq_imu is not None
        if self._unaided_on and self._departure_on_imu:
            # its heading's departure from its rates: a correction of unknown quality
            self._grow_heading(self.departure.on_increment(sample.t_s, self._att_q, dq_imu))
        if not self.attitude_held:
            if yaw_correction_rad != self._rate_drift_yaw_corr:
                self._rate_drift_yaw_corr = yaw_correction_rad
                self.rate_drift.restart()
                self.imu_drift.restart()
            self.imu_drift.on_increment(sample.t_s, self._att_q, dq_imu)
        if len(rates) == 3 and math.isfinite(sum(rates)):
            self._last_rates_b = rates
            if self._unaided_on and not self._departure_on_imu:
                self._grow_heading(self.departure.on_sample(sample.t_s, self._att_q, rates))
            if not self.attitude_held:
                self.rate_drift.on_sample(sample.t_s, self._att_q, rates)
            elif self._strapdown and not self._own_attitude:
                held = self._held_rates
                if held and sample.t_s <= held[-1][0]:
                    held.clear()  # out of order, or a new clock: start again
                held.append((sample.t_s, rates))
                if len(held) > 2:
                    del held[0]
                self._held_rotation_changed(rates)
        if self._init and not self._strapdown:
            mech = self._mech
            q_used = quat_mul(self._att_corr, self._att_q)
            mech.q_nb = mech.carry_attitude(q_used, mech.t_s - sample.t_s)

    def on_gnss(self, meas: GnssMeasurement, *, gate: bool = True) -> GnssUpdate:
        """Gate and fuse one fix at its own time; carry the correction to the newest IMU time."""
        cfg = self.config
        z_pos = meas.pos_ned_m.tolist()
        if not (all(map(math.isfinite, z_pos)) and math.isfinite(meas.t_s)):
            return self._refuse(meas, "position_not_finite")
        r_pos_rep, r_vel_rep = self._gnss.reported_variances(meas)
        if self._vel_error is not None:
            self._measured_velocity_error(meas, r_pos_rep, r_vel_rep)
        if not self._init:
            vel = meas.vel_ned_mps.tolist()
            self._aligner.on_fix(meas.t_s, vel[0], vel[1])
            return self._initialise(meas, r_pos_rep, r_vel_rep)
        mech = self._mech
        if meas.t_s > mech.t_s + cfg.cov_interval_s:
            return self._refuse(meas, "fix_ahead_of_imu")
        if self._hist and meas.t_s < self._hist[0].t_s - cfg.cov_interval_s:
            return self._refuse(meas, "fix_older_than_history")
        if math.isfinite(self._last_fuse_t_s) and meas.t_s <= self._last_fuse_t_s - 1e-9:
            return self._refuse(meas, "fix_out_of_order")

        # per-fix vectors of 3 to 6 components are Python floats here (a numpy call costs
        # more than the arithmetic); the same operations as the array forms, so the same values
        scale = self._adaptive.r_scale(self.diag)
        r_pos_scaled = [r * k for r, k in zip(r_pos_rep, scale, strict=True)]
        self._follow_receiver_error(meas.fix_type, r_pos_scaled)
        idx, pos_m, vel_m, q_m = state_at(self._hist, mech, meas.t_s, self._cov_interval_s)
        snap = self._hist[idx]
        p_m = snap.p_mat
        dt_p = meas.t_s - snap.t_s
        if dt_p > 0.0:
            # the snapshot's covariance is up to cov_interval_s older than the fix: carry it
            # (negligible in steady flight, not while the velocity is uncertain: after the
            # first fix, where GPS_RAW_INT gives no vertical velocity, and after an outage)
            p_m = carry_pos_vel(p_m, dt_p, self.diag.accel_psd_ned)
        axes, y, h_mat, r_rep = self._gnss.innovation(
            meas,
            z_pos,
            pos_m,
            vel_m,
            q_m,
            r_pos_rep,
            r_vel_rep,
            mech.last_gyro_b_radps,
            mech.bg,
            self._rx.bias_ned_m,
        )
        if self._gm:  # the white part of the position noise; the rest is in states 15:18
            r_rep[:3] = self._gnss.white_part(r_pos_rep)
        # the adaptive scale is on the position components (the velocity components' is 1)
        r_diag = [r_rep[0] * scale[0], r_rep[1] * scale[1], r_rep[2] * scale[2], *r_rep[3:]]
        dof = len(y)
        threshold = self._gates[dof]
        y_arr = np.array(y)
        try:
            corr = joseph_update_diag_r(p_m, y_arr, h_mat, np.array(r_diag))
        except ValueError:
            return self._refuse(meas, "innovation_cov_not_pd")
        innov_pos = -y_arr[:3]
        nis = corr.nis
        s_pos = corr.innov_cov[:3, :3]
        self.diag.last_nis = nis
        self.diag.last_dof = dof
        if gate and nis > threshold:
            self.diag.gated += 1
            log.debug("fix %.3f gated: NIS %.1f > %.1f", meas.t_s, nis, threshold)
            return GnssUpdate(meas.t_s, False, nis, dof, threshold, innov_pos, s_pos, "gate")

        d = corr.dx.tolist()
        if cfg.adaptive and self._adaptive.update(
            y, axes, h_mat, r_rep, p_m, corr, d, meas.t_s, self._last_fuse_t_s, self.diag
        ):
            self._model.set_accel_psd(self.diag.accel_psd_ned)
        r_used = [*r_pos_scaled, math.nan, math.nan, math.nan]
        for k, axis in enumerate(axes):
            r_used[3 + axis] = r_diag[3 + k]
        self.diag.r_used = np.array(r_used)
        # the correction is for the fix time; injected at the snapshot, its position part
        # moves with its velocity part over the time between them (a 2 m/s correction
        # 0.05 s away would otherwise plant 0.1 m of position error)
        lag = snap.t_s - meas.t_s
        d[0] += lag * d[3]
        d[1] += lag * d[4]
        d[2] += lag * d[5]
        self._apply(idx, d, corr.p_post)
        self._last_fuse_t_s = meas.t_s
        self._height_bias_var_m2 = 0.0
        self.diag.fused += 1
        if self._gm:
            self._receiver_error_check()
        return GnssUpdate(meas.t_s, True, nis, dof, threshold, innov_pos, s_pos)

    def on_height(
        self, t_s: float, pos_d_m: float, white_var_m2: float, offset_var_m2: float
    ) -> bool:
        """Fuse an independent height (the calibrated barometer) as the down position at
        ``t_s`` (m, local NED); False when refused (counted in ``diag.rejected``).

        The height's error is white noise (``white_var_m2``) plus the calibration's offset
        (``offset_var_m2``), common to every height until the next calibration. Each height
        is fused with both as its noise (the filter leans on them no more than that), and
        the offset is also *considered* (Schmidt): every height carries the same offset
        ``b``, which repeated updates would average away, so the published down-position
        variance adds ``offset_var_m2`` until the next fix (an upper bound: the estimate is
        off by at most ``b`` more than the filter's own error). Fused with its white noise
        alone, the tighter height pulled the horizontal solution through the attitude and
        bias states on a recorded flight (bench/realdata.py, loiter_rtl's gap: 16.1 m to
        17.8 m of closure). The differences of the heights carry the vertical velocity
        through a GNSS gap.
        """
        if not self._init:
            return False
        if not all(map(math.isfinite, (t_s, pos_d_m, white_var_m2, offset_var_m2))):
            self._reject("height_not_finite")
            return False
        if white_var_m2 <= 0.0 or offset_var_m2 < 0.0:
            self._reject("height_variance")
            return False
        cfg = self.config
        mech = self._mech
        if t_s > mech.t_s + cfg.cov_interval_s or (self._hist and t_s < self._hist[0].t_s):
            self._reject("height_outside_history")
            return False
        idx, pos_m, _, _ = state_at(self._hist, mech, t_s, self._cov_interval_s)
        snap = self._hist[idx]
        p_m = snap.p_mat
        dt_p = t_s - snap.t_s
        if dt_p > 0.0:
            p_m = carry_pos_vel(p_m, dt_p, self.diag.accel_psd_ned)
        h_mat = np.zeros((1, N_STATE))
        h_mat[0, ins.IP + 2] = 1.0
        y = np.array([pos_m[2] - pos_d_m])
        try:
            corr = joseph_update_diag_r(p_m, y, h_mat, np.array([white_var_m2 + offset_var_m2]))
        except ValueError:
            self._reject("height_cov_not_pd")
            return False
        if corr.nis > self._gates[1]:
            self._reject("height_gate")
            return False
        d = corr.dx.tolist()
        lag = snap.t_s - t_s
        d[0] += lag * d[3]
        d[1] += lag * d[4]
        d[2] += lag * d[5]
        self._apply(idx, d, corr.p_post)
        self._height_bias_var_m2 = offset_var_m2
        self.diag.heights_fused += 1
        return True

    def predict(self, t_s: float) -> NavState | None:
        """The state carried from the newest IMU time to ``t_s`` (constant velocity), unchanged."""
        if not self._init:
            return None
        mech = self._mech
        dt = max(0.0, t_s - mech.t_s)
        # covariance at the newest IMU time: the last propagated P plus the open segment
        dt_p = max(0.0, t_s - self._hist[-1].t_s)
        cov = open_segment_cov(self._p[0:6, 0:6].tolist(), self.diag.accel_psd_ned.tolist(), dt_p)
        w, x, y, z = mech.q_nb
        yaw = quat_to_yaw(w, x, y, z)
        vn, ve, vd = mech.vel
        pn, pe, pd = mech.pos
        if dt > 0.0:
            # carry the heading with the latest body rate (turns at 10 deg/s move it
            # 0.2 deg in one 50 Hz IMU period): the down row of mat_nb times the rate
            g = mech.last_gyro_b_radps
            bg = mech.bg
            yaw_rate = (
                2 * (x * z - w * y) * (g[0] - bg[0])
                + 2 * (y * z + w * x) * (g[1] - bg[1])
                + (1 - 2 * (x * x + y * y)) * (g[2] - bg[2])
            )
            yaw = wrap_pi(yaw + yaw_rate * dt)
        # one array each for the vectors and the covariances (views of them in the state)
        pos_vel = np.array((pn + vn * dt, pe + ve * dt, pd + vd * dt, vn, ve, vd))
        cov_pv = np.array(cov).reshape(2, 3, 3)
        if self._height_bias_var_m2 > 0.0:  # the heights' common offset (on_height)
            cov_pv[0, 2, 2] += self._height_bias_var_m2
        return NavState(t_s, pos_vel[0:3], pos_vel[3:6], cov_pv[0], cov_pv[1], yaw)

    def shift_frame(self, old: LocalFrame, new: LocalFrame) -> None:
        """Re-express the state in ``new`` (position through geodetic, vectors rotated)."""
        self._frame = new
        self._mech.set_gravity(ins.LocalGravity(new.lat0_rad, new.alt0_m))
        if self._vel_error is not None:
            self._vel_error.restart_chain()  # its positions were in the old frame
        if not self._init:
            return
        if self._mech.seg_dt_s > 0.0:
            self._close_segment()
        rot = rotation_between_frames(old, new)
        mech = self._mech
        lat, lon, alt = old.ned_to_lla(np.array(mech.pos))
        mech.pos = [float(c) for c in new.lla_to_ned(lat, lon, alt)]
        mech.vel = [float(c) for c in rot @ np.array(mech.vel)]
        q_rot = mat_to_quat(rot)
        mech.q_nb = quat_normalise(quat_mul(q_rot, mech.q_nb))
        t = np.eye(N_STATE)
        self._rx.rotate(rot)
        for k in (ins.IP, ins.IV, ins.IA, IGB):
            t[k : k + 3, k : k + 3] = rot
        self._p = t @ self._p @ t.T
        self._att_corr = quat_normalise(quat_mul(q_rot, self._att_corr))
        self._hist = deque([snapshot_of(mech, self._p)])
        self._last_fuse_t_s = math.nan
        self.generation += 1

    def rebase(self, state: NavState) -> bool:
        """Restart the position and velocity from ``state`` (an independent reference at
        about the newest IMU time), keeping the attitude and the IMU's biases: what the
        blend took from a receiver found lying is undone. Their covariance becomes
        ``state``'s, uncorrelated with the rest. False (nothing done) before a state
        exists or with a non-finite ``state``."""
        arrays = (state.pos_ned_m, state.vel_ned_mps, state.pos_cov_ned_m2, state.vel_cov_ned_m2ps2)
        if not self._init or not all(np.all(np.isfinite(a)) for a in arrays):
            return False
        if self._mech.seg_dt_s > 0.0:
            self._close_segment()
        mech = self._mech
        dt = mech.t_s - state.t_s
        mech.pos = [float(c) for c in state.pos_ned_m + state.vel_ned_mps * dt]
        mech.vel = [float(c) for c in state.vel_ned_mps]
        p = self._p
        for k in (ins.IP, ins.IV):
            p[k : k + 3, :] = 0.0
            p[:, k : k + 3] = 0.0
        p[ins.IP : ins.IP + 3, ins.IP : ins.IP + 3] = state.pos_cov_ned_m2 + dt * dt * (
            state.vel_cov_ned_m2ps2
        )
        p[ins.IV : ins.IV + 3, ins.IV : ins.IV + 3] = state.vel_cov_ned_m2ps2
        self._hist = deque([snapshot_of(mech, self._p)])
        self._last_fuse_t_s = math.nan
        self.generation += 1
        return True

    # ------------------------------------------------------------------ diagnostics

    @property
    def r_estimate(self) -> FloatArray:
        """Measurement variances of the last update (pos N, E, D, vel N, E, D), (6,)."""
        return self.diag.r_used.copy()

    @property
    def q_estimate_accel_psd(self) -> FloatArray:
        """Accelerometer white-noise PSD in use per NED axis, m^2/s^3, (3,)."""
        return self.diag.accel_psd_ned.copy()

    @property
    def covariance(self) -> FloatArray:
        """Error-state covariance at the last covariance epoch, (18, 18)."""
        return self._p.copy()

    @property
    def biases(self) -> tuple[FloatArray, FloatArray]:
        """Accelerometer (m/s^2) and gyro (rad/s) bias estimates, body axes, (3,) each."""
        return np.array(self._mech.ba), np.array(self._mech.bg)

    @property
    def attitude_q_nb(self) -> FloatArray:
        """Body-to-NED quaternion (w, x, y, z) in use, (4,)."""
        return np.array(self._mech.q_nb)

    def fix_corrections(self) -> tuple[FloatArray, FloatArray]:
        """What the fused fixes have done to the position since the last restart, as the
        coefficients (a, b) of the shift a + b t they make at a time t after them (each
        correction's position part, and its velocity part carried from its time), (3,) m
        and m/s. Between two instants the change of the coefficients, evaluated at the
        later, is what the fixes in between moved the position by: the position less
        that is the inertial prediction from the earlier state alone."""
        return np.array(self._fixes_moved_a), np.array(self._fixes_moved_b)

    @property
    def imu_t_s(self) -> float:
        """Time of the newest IMU sample integrated, s."""
        return self._mech.t_s

    # ------------------------------------------------------------------ internals

    def _reject(self, reason: str) -> None:
        rej = self.diag.rejected
        rej[reason] = rej.get(reason, 0) + 1
        if rej[reason] in (1, 10, 100, 1000) or rej[reason] % 10000 == 0:
            log.warning("blend rejected input (%s), %d so far", reason, rej[reason])

    def _refuse(self, meas: GnssMeasurement, reason: str) -> GnssUpdate:
        self._reject(reason)
        nan3 = np.full(3, np.nan)
        return GnssUpdate(
            meas.t_s, False, math.nan, 0, math.nan, nan3, np.full((3, 3), np.nan), reason
        )

    def _close_segment(self) -> None:
        """Propagate P over the accumulated segment and push a snapshot."""
        mech = self._mech
        dt, f_ned = mech.take_segment_values()
        snap = self._hist[-1]
        phi, qd = self._model.transition(dt, f_ned, mech.q_nb)
        snap.phi, snap.qd = phi, qd
        if self._gm:
            self._rx.decay(dt)
        self._p = predict_covariance(self._p, phi, qd)
        self._hist.append(snapshot_of(mech, self._p))
        horizon = mech.t_s - self.config.history_s
        while len(self._hist) > 2 and self._hist[1].t_s <= horizon:
            self._hist.popleft()

    def _follow_receiver_error(self, fix_type: FixType, var: list[float]) -> None:
        """Keep the receiver-error states in step with the fix (variance ``var``, 3 floats);
        on a restart, decorrelate them from the rest of the state in P and the history."""
        if not self._gm:
            return
        change = self._rx.follow(fix_type, var)
        if change == "restart":
            var_block = np.diag(var)
            for p in [self._p] + [snap.p_mat for snap in self._hist]:
                p[IGB : IGB + 3, :] = 0.0
                p[:, IGB : IGB + 3] = 0.0
                p[IGB : IGB + 3, IGB : IGB + 3] = var_block
            self._model.restart_receiver_error(self._rx.var_ned_m2, self._rx.tau_s)
        elif change == "variance":
            self._model.set_receiver_variance(self._rx.var_ned_m2)

    def _receiver_error_check(self) -> None:
        """Return the position to the receiver when the receiver-error estimate is beyond
        what its own model allows (chi-square of the estimate against the stationary
        variance, 3 dof, false-alarm probability 1e-6).

        The stationary variance comes from the receiver's reported accuracy; an estimate far
        outside it means the disagreement it holds came from the rest of the state (a
        velocity bias or an IMU error integrated between fixes), not from a receiver that
        says it is at the centimetre. The estimate is moved into the position (the sum the
        fixes constrain is unchanged) and the receiver-error states restart.
        """
        b = self._rx.bias_ned_m
        var = self._rx.var_ned_m2.tolist()
        if min(var) <= 0.0:
            return
        stat = b[0] * b[0] / var[0] + b[1] * b[1] / var[1] + b[2] * b[2] / var[2]
        if stat <= self._rx_gate:
            return
        mech = self._mech
        mech.pos = [mech.pos[i] + b[i] for i in range(3)]
        for snap in self._hist:
            p = snap.pos
            snap.pos = (p[0] + b[0], p[1] + b[1], p[2] + b[2])
        for i in range(3):
            self._fixes_moved_a[i] += b[i]
        self._rx.bias_ned_m = [0.0, 0.0, 0.0]
        var_block = np.diag(var)
        for p_mat in [self._p] + [snap.p_mat for snap in self._hist]:
            p_mat[IGB : IGB + 3, :] = 0.0
            p_mat[:, IGB : IGB + 3] = 0.0
            p_mat[IGB : IGB + 3, IGB : IGB + 3] = var_block
        self.diag.receiver_error_returned += 1
        log.info(
            "receiver-error estimate %.2f %.2f %.2f m is %.0f chi2 for its model: position "
            "returned to the receiver",
            *b,
            stat,
        )

    def _apply(self, idx: int, d: list[float], p_post: FloatArray) -> None:
        """Carry a correction ``d`` (floats) made at snapshot ``idx`` to the newest IMU time
        through the buffered transitions, correcting the snapshots on the way and the
        nominal state."""
        hist = self._hist
        mech = self._mech
        hist[idx].p_mat = p_post
        inject_snapshot(hist[idx], d)
        p = p_post
        dt_open = mech.seg_dt_s
        if idx < len(hist) - 1 or dt_open > 0.0:
            dx, p = carry_correction(hist, idx, np.array(d), p)
            if dt_open > 0.0:  # the open segment (shorter than cov_interval_s)
                dx = self._model.carry_open_segment(dx, mech.seg_fn_sum, dt_open, mech.q_nb)
            d = dx.tolist()
        self._p = p
        mech.inject_values(d)
        # what the fixes moved the state by, as a function of time: -d_p - d_v (t - t_m)
        t_m = mech.t_s
        a, b = self._fixes_moved_a, self._fixes_moved_b
        for i in range(3):
            a[i] += -d[i] + d[3 + i] * t_m
            b[i] -= d[3 + i]
        if not self._strapdown:
            self._att_corr = rotate_by_rotvec(self._att_corr, d[6], d[7], d[8])
        if self._gm:
            self._rx.inject(d[IGB : IGB + 3])

    def _follow_gyro_noise(self, verdict: ImuNoiseVerdict) -> None:
        """One window of the gyro's measured noise: above the configured density beyond
        chance (the check's threshold), the measured PSD drives the attitude error;
        otherwise the configured one."""
        q0 = self.config.gyro_arw_rad_rts**2
        ratio = verdict.gyro_ratio
        psd = q0 * ratio if ratio > verdict.threshold else None
        if psd == self._gyro_psd_measured:
            return
        if psd is None or self._gyro_psd_measured is None:
            log.info(
                "gyro noise %s the configured density (%.1fx)",
                "above" if psd is not None else "back within",
                math.sqrt(ratio),
            )
        self._gyro_psd_measured = psd
        self._model.set_gyro_psd(psd)
        self._note_gyro_psd()

    def _measured_velocity_error(
        self, meas: GnssMeasurement, r_pos: list[float], r_vel: list[float]
    ) -> None:
        """Add to the horizontal velocity variances ``r_vel`` (in place) what the receiver's
        own positions show its velocity errs beyond them (:mod:`.velocity_error`)."""
        meter = self._vel_error
        if meter is None:
            return
        vel = meas.vel_ned_mps
        pos = meas.pos_ned_m
        tau = self.config.gnss_err_tau_s or GNSS_ERR_TAU_S.get(meas.fix_type, 300.0)
        ex_n, ex_e = meter.on_fix(
            meas.receiver_id,
            meas.t_s,
            (float(pos[0]), float(pos[1])),
            (float(vel[0]), float(vel[1])),
            (r_pos[0], r_pos[1]),
            (r_vel[0], r_vel[1]),
            tau,
            meas.fix_type,
        )
        r_vel[0] += ex_n
        r_vel[1] += ex_e

    def _follow_accel_noise(self, psd: float) -> None:
        """The accelerometer PSD measured in use changed (:mod:`.accel_noise`): it drives
        the velocity error from now on, as the floor of its adaptive estimate."""
        q0 = self.config.accel_vrw_mps_rts**2
        if (psd > q0) != (self._accel_psd0 > q0):
            log.info(
                "accelerometer noise %s the configured density (%.1fx)",
                "above" if psd > q0 else "back within",
                math.sqrt(psd / q0),
            )
        self._accel_psd0 = psd
        self._adaptive.set_base_psd(psd)
        bounded = self._adaptive.bounded_psd(self.diag.accel_psd_ned.tolist())
        self.diag.accel_psd_ned = np.array(bounded)
        self._model.set_accel_psd(self.diag.accel_psd_ned)

    def _note_gyro_psd(self) -> None:
        """The gyro PSD in use, in the diagnostics (strapdown only)."""
        if self._strapdown:
            psd = self._gyro_psd_measured
            self.diag.gyro_psd = self.config.gyro_arw_rad_rts**2 if psd is None else psd

    def _use_own_attitude(self) -> None:
        """Run strapdown on the blend's own alignment (no autopilot attitude to aid it)."""
        self._own_attitude = True
        if not self._strapdown:
            self._strapdown = True
            if self._own_model is None:
                self._own_model = ErrorModel(dataclasses.replace(self.config, mode="strapdown"))
            self._own_model.reset(self.diag.accel_psd_ned)
            self._own_model.set_gyro_psd(self._gyro_psd_measured)
            self._model = self._own_model
            self._note_gyro_psd()

    def _own_alignment(self) -> Alignment | None:
        """The blend's attitude as an alignment to restart from (own-alignment runs only)."""
        if not self._own_attitude:
            return None
        mech = self._mech
        p = self._p
        tilt = math.sqrt(max(p[6, 6], p[7, 7], 0.0))
        bg_sig = math.sqrt(max(p[12, 12], p[13, 13], p[14, 14], 0.0))
        yaw_sig = math.sqrt(max(p[8, 8], 0.0))
        if yaw_sig > self.config.align_yaw_sigma_max_rad:
            return None
        bg = mech.bg
        return Alignment(mech.t_s, mech.q_nb, (bg[0], bg[1], bg[2]), tilt, yaw_sig, bg_sig)

    def _initialise(
        self, meas: GnssMeasurement, r_pos_l: list[float], r_vel_l: list[float]
    ) -> GnssUpdate:
        """Start from the first fix and the latest attitude, at the newest IMU time."""
        cfg = self.config
        r_pos, r_vel = np.array(r_pos_l), np.array(r_vel_l)
        if not self._pre_imu:
            return self._refuse(meas, "no_imu_yet")
        align: Alignment | None = None
        if self._att_q is None:
            # no autopilot attitude: the blend's own, levelled at rest, yaw from GNSS velocity
            align = self._aligner.alignment()
            if align is None:
                return self._refuse(
                    meas, "aligning" if self._aligner.levelled else "not_levelled_yet"
                )
        pre = self._pre_imu
        if not pre:
            return self._refuse(meas, "no_imu_yet")
        if meas.t_s < pre[0][0]:
            return self._refuse(meas, "fix_older_than_history")
        mech = self._mech
        # start at the fix time from the IMU reading just before it, then replay the
        # buffered IMU samples up to the newest
        t0 = min(meas.t_s, pre[-1][0])
        before = [x for x in pre if x[0] <= t0]
        mech.set_raw(before[-1][1], before[-1][2])
        if align is not None:
            mech.bg = list(align.gyro_bias_b_radps)
            if align.rest_specific_force_b_mps2 is not None:
                # at rest |f| = g + the bias along the vertical (the observable component)
                f_b = align.rest_specific_force_b_mps2
                f_norm = math.sqrt(sum(c * c for c in f_b))
                b_v = f_norm - mech.gravity.down_mps2(meas.pos_ned_m[0], meas.pos_ned_m[2])
                mech.ba = [b_v * c / f_norm for c in f_b]
            q0 = mech.carry_attitude(align.q_nb, t0 - align.t_s)
            self._use_own_attitude()
        else:
            q0 = mech.carry_attitude(self._att_q, t0 - self._att_t_s)  # type: ignore[arg-type]
        mat_nb = quat_to_mat(q0)
        vel = np.asarray(meas.vel_ned_mps, dtype=float)
        vel_ok = np.isfinite(vel)
        vel0 = np.where(vel_ok, vel, 0.0)
        var_v = np.where(vel_ok, r_vel, cfg.init_vel_sigma_mps**2)
        meter = self._vel_error
        if meter is not None and vel_ok[0] and vel_ok[1]:
            speed = math.hypot(vel[0], vel[1])
            lim_a, lim_g = cfg.align_static_acc_std_mps2, cfg.align_static_gyro_std_radps
            if at_rest(pre, speed, lim_a, lim_g):  # standing: the velocity is its error
                ex_n, ex_e = meter.seed_at_rest(
                    meas.receiver_id, (float(vel[0]), float(vel[1])), (r_vel_l[0], r_vel_l[1])
                )
                var_v[0] += ex_n
                var_v[1] += ex_e
        pos0 = meas.pos_ned_m - mat_nb @ self._gnss.lever_b_m + vel0 * (t0 - meas.t_s)
        mech.initialise(t0, pos0, vel0, q0)
        p = np.zeros((N_STATE, N_STATE))
        p[0:3, 0:3] = np.diag(r_pos)
        self._rx.fix_type = None  # the first fix starts the receiver-error model afresh
        if self._gm:
            # the first fix carries the receiver error b: position error = b + w,
            # receiver-error state error = -b (the estimate starts at 0)
            self._p = p
            self._hist.clear()
            self._follow_receiver_error(meas.fix_type, r_pos_l)
            var = self._rx.var_ned_m2
            p[0:3, 0:3] = np.diag(var + np.array(self._gnss.white_part(r_pos_l)))
            p[0:3, IGB : IGB + 3] = -np.diag(var)
            p[IGB : IGB + 3, 0:3] = -np.diag(var)
        p[3:6, 3:6] = np.diag(var_v)
        att_sig = np.array(cfg.init_att_sigma_rad if self._strapdown else cfg.att_err_sigma_rad)
        bg_var = cfg.gyro_bias_sigma_radps**2
        if align is not None:
            att_sig = np.array([align.tilt_sigma_rad, align.tilt_sigma_rad, align.yaw_sigma_rad])
            bg_var = align.gyro_bias_sigma_radps**2
        p[6:9, 6:9] = np.diag(att_sig**2)
        p[9:12, 9:12] = np.eye(3) * cfg.accel_bias_sigma_mps2**2
        p[12:15, 12:15] = np.eye(3) * bg_var
        self._p = p
        self._att_corr = (1.0, 0.0, 0.0, 0.0)
        self._hist.clear()
        self._hist.append(snapshot_of(mech, p))
        self._init = True
        self._last_fuse_t_s = meas.t_s
        for t_s, acc, gyro in pre:
            if t_s > t0:
                mech.step(t_s, acc, gyro)
                if mech.seg_dt_s >= cfg.cov_interval_s:
                    self._close_segment()
        pre.clear()
        log.info(
            "blend initialised at t=%.3f s (%s)",
            meas.t_s,
            "own alignment" if align is not None else cfg.mode,
        )
        gate3 = self._gates[3]
        return GnssUpdate(meas.t_s, True, 0.0, 3, gate3, np.zeros(3), np.diag(r_pos), "init")


def held_rate_at(rates: list[tuple[float, list[float]]], t_s: float) -> list[float]:
    """The body rate (rad/s) at ``t_s`` from the autopilot's latest one or two
    ``(t_s, rates)``: linear between or beyond them, no further beyond the newest than
    they are apart (a rate sampled at 25 Hz and held until the next would carry the
    attitude late by half a sample interval, and through a roll into a turn keep it late
    by that rotation for the whole turn)."""
    t_b, w_b = rates[-1]
    if len(rates) < 2:
        return w_b
    t_a, w_a = rates[0]
    span = t_b - t_a
    if span <= 0.0:
        return w_b
    k = min(t_s - t_b, span) / span
    return [w_b[i] + (w_b[i] - w_a[i]) * k for i in range(3)]

"""The configuration as MAVLink parameters: the table of names, and the parameter server.

Every key of the configuration that a number can carry is a parameter of component
191 under a name of at most 16 characters: the block's prefix and an abbreviation
of the key (:data:`PREFIXES`, :data:`TABLE`), one parameter per item of a
fixed-length list (``BLD_LEVER_X``). The table is written out, never derived, so a
name stays what it is when keys are added; a parameter's index is its place in the
table. docs/params.md lists it (:func:`markdown_table` writes that list).

Types (:mod:`companion.mavlink.params` carries them on the wire): numbers REAL32,
integers INT32, booleans UINT8 (0 or 1); a key with a fixed set of words (``navigator
= "blend"``) is an INT32 index into its words, pinned in :data:`CHOICES`; an optional
key whose range excludes 0 reads 0 when unset and is unset by 0. Keys no number can
carry cleanly are not parameters (:data:`NOT_EXPOSED` says why, key by key).

A value set is validated exactly as the TOML file's (:func:`companion.config.merge_config`:
the same coercion, ranges and checks between keys); a refused one leaves everything
as it was. What a change does, per key (:data:`LIVE_KEYS`): applied to the running
service at once (the component that reads the key states it can), or kept and
applied when the service restarts. The values set are what the service persists
(``params.json`` beside ``link.state_file``) and loads over the TOML configuration
at start (:func:`load_overrides`).

:class:`ParamServer` answers the protocol's requests (already decoded and addressed
to us) with the messages to send: PARAM_VALUE, and a one-line STATUSTEXT ``CMP PARAM
<NAME> <why>`` when a value is refused, unknown, or waits for a restart.
"""

from __future__ import annotations

import dataclasses
import enum
import logging
import math
import re
import types
import typing
from dataclasses import dataclass
from typing import Any

from companion.config import Config, ConfigError, merge_config
from companion.engine import LIVE_KEYS as ENGINE_LIVE_KEYS
from companion.mavlink.encode import LIVE_KEYS as ENCODER_LIVE_KEYS
from companion.mavlink.params import (
    INT32_MAX,
    INT32_MIN,
    MAV_PARAM_TYPE_INT32,
    MAV_PARAM_TYPE_REAL32,
    MAV_PARAM_TYPE_UINT8,
    PARAM_ID_MAX_CHARS,
    ParamCodec,
    ParamList,
    ParamRead,
    ParamRequest,
    ParamSet,
    is_integral,
    printable_name,
    real32,
)
from companion.ranges import field_range
from companion.types import Severity

log = logging.getLogger(__name__)

PREFIXES: dict[str, str] = {
    "link": "LNK",
    "recorder": "REC",
    "streams": "SR",
    "engine": "ENG",
    "outage": "OUT",
    "heading": "HDG",
    "blend": "BLD",
    "integrity": "INT",
    "integrity.phase": "PHS",
    "spoof": "SPF",
    "potential": "POT",
    "coast": "CST",
    "baro": "BAR",
    "imu_innovations": "IMU",
    "decoder": "DEC",
    "encoder": "ENC",
    "raw": "RAW",
}
"""Configuration block -> the prefix of its parameters' names."""

TABLE: tuple[tuple[str, str], ...] = (
    # [link]
    ("LNK_BAUD", "link.baud"),
    ("LNK_HB_RATE", "link.heartbeat_rate_hz"),
    ("LNK_RECONNECT", "link.reconnect_s"),
    ("LNK_NOHB_WARN", "link.no_autopilot_warn_s"),
    ("LNK_NOHB_REPEAT", "link.no_autopilot_repeat_s"),
    # [recorder]
    ("REC_FILE_MB", "recorder.max_file_mb"),
    ("REC_TOTAL_MB", "recorder.max_total_mb"),
    ("REC_AGE_DAYS", "recorder.max_age_days"),
    ("REC_FLUSH", "recorder.flush_interval_s"),
    # [streams]
    ("SR_GPS_RAW_INT", "streams.gps_raw_int_hz"),
    ("SR_GPS2_RAW", "streams.gps2_raw_hz"),
    ("SR_GPS_RTK", "streams.gps_rtk_hz"),
    ("SR_RAW_IMU", "streams.raw_imu_hz"),
    ("SR_SCALED_IMU2", "streams.scaled_imu2_hz"),
    ("SR_HIGHRES_IMU", "streams.highres_imu_hz"),
    ("SR_ATTITUDE", "streams.attitude_hz"),
    ("SR_ATTITUDE_QUAT", "streams.attitude_quaternion_hz"),
    ("SR_EXT_SYS_STATE", "streams.extended_sys_state_hz"),
    ("SR_VFR_HUD", "streams.vfr_hud_hz"),
    ("SR_GLOBAL_POS", "streams.global_position_int_hz"),
    # [engine]
    ("ENG_PUB_RATE", "engine.publish_rate_hz"),
    ("ENG_STATUS_RATE", "engine.status_rate_hz"),
    ("ENG_REANCHOR", "engine.reanchor_distance_m"),
    ("ENG_NAVIGATOR", "engine.navigator"),
    ("ENG_IMU_TIMEOUT", "engine.imu_timeout_s"),
    ("ENG_PRIMARY_RX", "engine.primary_receiver"),
    ("ENG_POT_BRIDGE", "engine.potential_bridge"),
    ("ENG_POT_COMBINE", "engine.potential_combine"),
    ("ENG_INERTIAL_REF", "engine.inertial_reference"),
    ("ENG_POT_FIX_TEST", "engine.potential_fix_test"),
    ("ENG_SILENCE", "engine.silence_timeout_s"),
    ("ENG_NOGNSS", "engine.no_gnss_alert_s"),
    ("ENG_NOGNSS_REP", "engine.no_gnss_repeat_s"),
    # [outage]
    ("OUT_GNSS_TIMEOUT", "outage.gnss_timeout_s"),
    ("OUT_MIN_FIX_TYPE", "outage.min_fix_type"),
    ("OUT_MAX_BRIDGE", "outage.max_bridge_s"),
    ("OUT_REACQ_FIXES", "outage.reacquire_fixes"),
    ("OUT_REACQ_MAXREJ", "outage.reacquire_max_rejects"),
    ("OUT_STALE_SPEED", "outage.stale_min_speed_mps"),
    ("OUT_STALE_REPEAT", "outage.stale_repeats"),
    ("OUT_STALE_MOTION", "outage.stale_motion_ratio"),
    ("OUT_STALE_WINDOW", "outage.stale_window_s"),
    ("OUT_ACC_JUMP", "outage.accuracy_jump_ratio"),
    ("OUT_RTK_MAX_AGE", "outage.rtk_max_age_s"),
    ("OUT_DOWNGR_MEM", "outage.downgrade_memory_s"),
    # [heading]
    ("HDG_MIN_SPEED", "heading.min_speed_mps"),
    ("HDG_MAX_SPEED", "heading.max_speed_mps"),
    ("HDG_MAX_TURN", "heading.max_turn_rate_dps"),
    ("HDG_SETTLE", "heading.settle_time_s"),
    ("HDG_RECEIVER", "heading.receiver_id"),
    ("HDG_MIN_FIX", "heading.min_fix_type"),
    ("HDG_MAX_VEL_ACC", "heading.max_vel_acc_mps"),
    ("HDG_DEF_VEL_ACC", "heading.default_vel_acc_mps"),
    ("HDG_VEL_ACC_FLR", "heading.vel_acc_floor_mps"),
    ("HDG_INS_YAW_NSE", "heading.ins_yaw_noise_deg"),
    ("HDG_TRACK_SRC", "heading.track_source"),
    ("HDG_POS_BASELINE", "heading.pos_baseline_s"),
    ("HDG_POS_SIGMA", "heading.pos_diff_sigma_m"),
    ("HDG_POS_MIN_FIX", "heading.pos_min_fix_type"),
    ("HDG_GROUND_CRAB", "heading.ground_crab_deg"),
    ("HDG_EPS_LIMIT", "heading.eps_limit_deg"),
    ("HDG_CONFIDENCE", "heading.confidence"),
    ("HDG_MIN_CYCLES", "heading.min_cycles"),
    ("HDG_POS_MIN_CYC", "heading.pos_min_cycles"),
    ("HDG_MAX_CYCLES", "heading.max_cycles"),
    ("HDG_SPREAD_LIM", "heading.mean_spread_limit_deg"),
    ("HDG_SPREAD_CYC", "heading.spread_start_cycle"),
    ("HDG_POS_SPRD_CYC", "heading.pos_spread_start_cycle"),
    ("HDG_NORM_ALPHA", "heading.normality_alpha"),
    ("HDG_DISP_ALPHA", "heading.dispersion_alpha"),
    ("HDG_STAT_ALPHA", "heading.stationarity_alpha"),
    ("HDG_MAX_DRIFT", "heading.max_drift_deg"),
    ("HDG_MIN_LEG_CYC", "heading.min_leg_cycles"),
    ("HDG_MIN_LEGS", "heading.min_legs"),
    ("HDG_PARK_CHECK", "heading.require_park_check"),
    ("HDG_PARK_SPEED", "heading.park_speed_mps"),
    ("HDG_PARK_TIME", "heading.park_time_s"),
    ("HDG_PARK_WINDOW", "heading.park_window_s"),
    ("HDG_PARK_SMOOTH", "heading.park_smooth_s"),
    ("HDG_PARK_BIAS", "heading.park_max_bias_mps"),
    ("HDG_PARK_ALPHA", "heading.park_alpha"),
    ("HDG_AUTO_APPLY", "heading.auto_apply"),
    ("HDG_PUB_PERIOD", "heading.publish_period_s"),
    ("HDG_ATT_BUFFER", "heading.attitude_buffer_s"),
    ("HDG_MAX_ATT_GAP", "heading.max_attitude_gap_s"),
    ("HDG_MAX_EXTRAP", "heading.max_extrapolation_s"),
    ("HDG_GND_MAX_HGT", "heading.ground_max_height_m"),
    ("HDG_GND_MAX_CLMB", "heading.ground_max_climb_mps"),
    ("HDG_PARK_SUSPECT", "heading.park_suspect_bias_mps"),
    ("HDG_SUSPECT_LEGS", "heading.suspect_min_legs"),
    # [blend]
    ("BLD_MODE", "blend.mode"),
    ("BLD_ADAPTIVE", "blend.adaptive"),
    ("BLD_ADAPT_WINDOW", "blend.adaptive_window"),
    ("BLD_ADAPT_MIN_EP", "blend.adaptive_min_epochs"),
    ("BLD_LEVER_X", "blend.lever_arm_b_m[0]"),
    ("BLD_LEVER_Y", "blend.lever_arm_b_m[1]"),
    ("BLD_LEVER_Z", "blend.lever_arm_b_m[2]"),
    ("BLD_ACC_VRW", "blend.accel_vrw_mps_rts"),
    ("BLD_GYR_ARW", "blend.gyro_arw_rad_rts"),
    ("BLD_ACC_BIAS", "blend.accel_bias_sigma_mps2"),
    ("BLD_ACC_BIAS_TAU", "blend.accel_bias_tau_s"),
    ("BLD_GYR_BIAS", "blend.gyro_bias_sigma_radps"),
    ("BLD_GYR_BIAS_TAU", "blend.gyro_bias_tau_s"),
    ("BLD_ATT_ERR_N", "blend.att_err_sigma_rad[0]"),
    ("BLD_ATT_ERR_E", "blend.att_err_sigma_rad[1]"),
    ("BLD_ATT_ERR_D", "blend.att_err_sigma_rad[2]"),
    ("BLD_ATT_ERR_TAU", "blend.att_err_tau_s"),
    ("BLD_INIT_ATT_N", "blend.init_att_sigma_rad[0]"),
    ("BLD_INIT_ATT_E", "blend.init_att_sigma_rad[1]"),
    ("BLD_INIT_ATT_D", "blend.init_att_sigma_rad[2]"),
    ("BLD_INIT_VEL", "blend.init_vel_sigma_mps"),
    ("BLD_ALN_STATIC", "blend.align_static_s"),
    ("BLD_ALN_ACC_STD", "blend.align_static_acc_std_mps2"),
    ("BLD_ALN_GYR_STD", "blend.align_static_gyro_std_radps"),
    ("BLD_ALN_WINDOW", "blend.align_window_s"),
    ("BLD_ALN_YAW_MAX", "blend.align_yaw_sigma_max_rad"),
    ("BLD_ALN_TILT", "blend.align_tilt_sigma_rad"),
    ("BLD_GATE_PFA", "blend.gate_false_alarm_prob"),
    ("BLD_GNSS_MODEL", "blend.gnss_error_model"),
    ("BLD_GNSS_WHITE", "blend.gnss_white_fraction"),
    ("BLD_GNSS_TAU", "blend.gnss_err_tau_s"),
    ("BLD_POS_FLR_H", "blend.pos_std_floor_m[0]"),
    ("BLD_POS_FLR_V", "blend.pos_std_floor_m[1]"),
    ("BLD_VEL_FLR", "blend.vel_std_floor_mps"),
    ("BLD_VEL_FALLBACK", "blend.vel_std_fallback_mps"),
    ("BLD_R_SCALE_MIN", "blend.r_scale_bounds[0]"),
    ("BLD_R_SCALE_MAX", "blend.r_scale_bounds[1]"),
    ("BLD_Q_SCALE_MIN", "blend.q_scale_bounds[0]"),
    ("BLD_Q_SCALE_MAX", "blend.q_scale_bounds[1]"),
    ("BLD_COV_INTERVAL", "blend.cov_interval_s"),
    ("BLD_COV_DISCR", "blend.cov_discretisation"),
    ("BLD_HISTORY", "blend.history_s"),
    ("BLD_MAX_IMU_GAP", "blend.max_imu_gap_s"),
    # [integrity]
    ("INT_PFA", "integrity.false_alarm_prob"),
    ("INT_SLOPE_PFA", "integrity.slope_false_alarm_prob"),
    ("INT_RESID_PFA", "integrity.residual_false_alarm_prob"),
    ("INT_RISK_H", "integrity.integrity_risk_horizontal"),
    ("INT_RISK_V", "integrity.integrity_risk_vertical"),
    ("INT_SEP_WINDOW", "integrity.separation_window_s"),
    ("INT_MIN_WIN_PTS", "integrity.min_window_points"),
    ("INT_PAIR_MAX_DT", "integrity.pair_max_dt_s"),
    ("INT_RECOVERY", "integrity.recovery_s"),
    ("INT_APPROACH_CAT", "integrity.approach_category"),
    ("INT_REPORT_RATE", "integrity.report_rate_hz"),
    ("INT_CAT_DWELL", "integrity.category_upgrade_dwell_s"),
    ("INT_ATTRIB_PROB", "integrity.attribution_error_prob"),
    ("INT_DEF_VEL_VAR", "integrity.default_vel_var_m2ps2"),
    ("INT_REF_MAX_AGE", "integrity.reference_max_age_s"),
    ("INT_RESTORE_DWL", "integrity.integrity_restore_dwell_s"),
    # [integrity.phase]
    ("PHS_GROUND_HGT", "integrity.phase.ground_height_m"),
    ("PHS_LANDING_HGT", "integrity.phase.landing_height_m"),
    ("PHS_TERMINAL_HGT", "integrity.phase.terminal_height_m"),
    ("PHS_VERT_SPEED", "integrity.phase.vertical_speed_mps"),
    ("PHS_TAXI_MAX_SPD", "integrity.phase.taxi_max_speed_mps"),
    ("PHS_STATIONARY", "integrity.phase.stationary_speed_mps"),
    ("PHS_DWELL", "integrity.phase.dwell_s"),
    # [potential]
    ("POT_WINDOW", "potential.window_s"),
    ("POT_MAX_SOURCES", "potential.max_sources"),
    ("POT_WEIGHT_FLOOR", "potential.weight_floor"),
    ("POT_ALPHA0", "potential.alpha0_ps"),
    ("POT_G0", "potential.g0_ps2"),
    ("POT_ALPHA_MIN", "potential.alpha_bounds_ps[0]"),
    ("POT_ALPHA_MAX", "potential.alpha_bounds_ps[1]"),
    ("POT_G_MIN", "potential.g_bounds_ps2[0]"),
    ("POT_G_MAX", "potential.g_bounds_ps2[1]"),
    ("POT_REFIT_INT", "potential.refit_interval_s"),
    ("POT_MIN_FIT_FIX", "potential.min_fit_fixes"),
    ("POT_FIRST_SPAN", "potential.first_fit_span_s"),
    ("POT_REFIT_DSPD", "potential.refit_speed_change_mps"),
    ("POT_REFIT_DREL", "potential.refit_speed_change_rel"),
    ("POT_REFIT_MIN_DT", "potential.refit_min_interval_s"),
    ("POT_DE_MAXITER", "potential.de_maxiter"),
    ("POT_DE_POPSIZE", "potential.de_popsize"),
    ("POT_DE_TOL", "potential.de_tol"),
    ("POT_DE_GRID", "potential.de_grid_points"),
    ("POT_DE_WARM_POP", "potential.de_warm_popsize"),
    ("POT_FIT_START_DT", "potential.fit_start_every_s"),
    ("POT_DE_WARM_SPRD", "potential.de_warm_spread_dex"),
    ("POT_ADOPT_REPLAY", "potential.adopt_replay_state"),
    ("POT_POS_UPDATE", "potential.position_update"),
    ("POT_PFA", "potential.false_alarm_prob"),
    ("POT_FIX_RES_N", "potential.fix_resolution_m[0]"),
    ("POT_FIX_RES_E", "potential.fix_resolution_m[1]"),
    ("POT_FIX_RES_D", "potential.fix_resolution_m[2]"),
    ("POT_MIN_TEST_FIX", "potential.min_test_fixes"),
    ("POT_MAX_INCONS", "potential.max_consecutive_inconsistent"),
    ("POT_VEL_MODE", "potential.velocity_mode"),
    ("POT_VEL_SPAN", "potential.velocity_span_s"),
    ("POT_PRIOR_VEL", "potential.prior_vel_sigma_mps"),
    ("POT_PRIOR_ACC", "potential.prior_acc_sigma_mps2"),
    ("POT_CAL_MIN_RES", "potential.calib_min_residuals"),
    ("POT_CAL_FORGET", "potential.calib_forgetting"),
    ("POT_SEED", "potential.seed"),
    # [coast]
    ("CST_SLOTS", "coast.slots"),
    ("CST_LIFE", "coast.life_s"),
    ("CST_HISTORY", "coast.history_s"),
    ("CST_MAX_IMU_GAP", "coast.max_imu_gap_s"),
    ("CST_ACC_BIAS", "coast.acc_bias_sigma_mps2"),
    ("CST_ACC_VRW", "coast.acc_vrw_mps_rts"),
    ("CST_ATT_ERR_R", "coast.att_err_sigma_rad[0]"),
    ("CST_ATT_ERR_P", "coast.att_err_sigma_rad[1]"),
    ("CST_ATT_ERR_Y", "coast.att_err_sigma_rad[2]"),
    # [decoder]
    ("DEC_SYSID", "decoder.system_id"),
    ("DEC_MAX_SPEED", "decoder.max_speed_mps"),
    ("DEC_MAX_ACCURACY", "decoder.max_accuracy_m"),
    ("DEC_ALT_MIN", "decoder.alt_min_m"),
    ("DEC_ALT_MAX", "decoder.alt_max_m"),
    ("DEC_MAX_ACC", "decoder.max_acc_mps2"),
    ("DEC_MAX_GYRO", "decoder.max_gyro_radps"),
    ("DEC_REBOOT_JUMP", "decoder.reboot_backjump_s"),
    ("DEC_GNSS_DELAY", "decoder.gnss_delay_s"),
    ("DEC_SYSTIME_WAIT", "decoder.system_time_wait_s"),
    # [encoder]
    ("ENC_OUTPUT", "encoder.output"),
    ("ENC_GPS_ID", "encoder.gps_id"),
    ("ENC_MIN_HACC", "encoder.min_h_acc_m"),
    ("ENC_MIN_VACC", "encoder.min_v_acc_m"),
    ("ENC_MIN_VEL_ACC", "encoder.min_vel_acc_mps"),
    ("ENC_UERE", "encoder.uere_m"),
    ("ENC_GPS_YAW", "encoder.gps_input_yaw"),
    ("ENC_STXT_INTVL", "encoder.statustext_min_interval_s"),
    # added later, at the end so that earlier indices do not move
    ("ENG_IMU_MIN_RATE", "engine.min_imu_rate_hz"),
    ("ENG_IMU_HOLD", "engine.imu_rate_hold_s"),
    ("OUT_RESET_REJ", "outage.reset_after_rejection_s"),
    ("OUT_RESET_NREJ", "outage.reset_after_rejected_fixes"),
    ("OUT_RESET_ALERT", "outage.reset_alert_interval_s"),
    ("OUT_MIN_SATS", "outage.min_satellites"),
    ("OUT_MAX_HDOP", "outage.max_hdop"),
    ("OUT_CONTRA_SIG", "outage.contradiction_sigmas"),
    ("OUT_TIMEOUT_NFIX", "outage.timeout_fix_intervals"),
    ("ENC_GPS_ID_AUTO", "encoder.gps_id_from_autopilot"),
    ("ENG_PUB_ON_FIX", "engine.publish_on_fix"),
    ("ENG_PUB_MIN_INT", "engine.min_publish_interval_s"),
    ("ENG_BARO_BLEND", "engine.baro_in_blend"),
    ("INT_BARO_REF", "integrity.baro_reference"),
    ("INT_BARO_WIN", "integrity.baro_window_s"),
    ("INT_BARO_MIN_H", "integrity.baro_min_height_m"),
    ("ENG_IMU_CHECK", "engine.imu_grade_check"),
    ("HDG_GND_MAX_PTCH", "heading.ground_max_pitch_deg"),
    ("HDG_GND_RELEASE", "heading.ground_release_s"),
    ("HDG_GND_REL_HGT", "heading.ground_release_height_m"),
    # [baro]
    ("BAR_NOISE_FLOOR", "baro.noise_floor_m"),
    ("BAR_OFFSET_RW", "baro.offset_rw_m2ps"),
    ("BAR_DRIFT_RW", "baro.drift_rw_m2ps3"),
    ("BAR_DRIFT_INIT", "baro.initial_drift_sigma_mps"),
    ("BAR_CAL_INTERVAL", "baro.calib_interval_s"),
    ("BAR_GNSS_CORR", "baro.gnss_corr_s"),
    ("BAR_RESUME", "baro.resume_restart_s"),
    ("BAR_CAL_MIN", "baro.calib_min_s"),
    ("BAR_MEMORY", "baro.memory_s"),
    ("BAR_MAX_VACC", "baro.max_vertical_accel_mps2"),
    ("BAR_JUMP_SIGMAS", "baro.jump_sigmas"),
    ("BAR_MAX_JUMPS", "baro.max_consecutive_jumps"),
    ("BAR_TIMEOUT", "baro.timeout_s"),
    ("BAR_HISTORY", "baro.history_s"),
    # [imu_innovations]
    ("IMU_INN_WINDOW", "imu_innovations.window_s"),
    ("IMU_INN_MIN_FIX", "imu_innovations.min_fixes"),
    ("IMU_INN_RATIO", "imu_innovations.min_ratio"),
    ("IMU_INN_NEEDED", "imu_innovations.windows_needed"),
    ("IMU_INN_SPAN", "imu_innovations.windows_span"),
    ("IMU_INN_PFA", "imu_innovations.false_alarm_prob"),
    # [raw]
    ("RAW_BAUD", "raw.baud"),
    ("RAW_CONFIGURE", "raw.configure_receiver"),
    ("RAW_PORT", "raw.receiver_port"),
    ("RAW_RX_ID", "raw.receiver_id"),
    ("RAW_BANDS", "raw.bands"),
    ("RAW_PHASE_SIGMA", "raw.phase_sigma_m"),
    ("RAW_DRIFT_SIGMA", "raw.drift_sigma_mps"),
    ("RAW_MIN_SATS", "raw.min_satellites"),
    ("RAW_MAX_SPAN", "raw.max_span_s"),
    ("RAW_MAX_GAP", "raw.max_gap_s"),
    ("RAW_TIME_TOL", "raw.time_tolerance_s"),
    ("RAW_SILENCE", "raw.silence_s"),
    ("RAW_RECOVERY", "raw.recovery_s"),
    ("RAW_STATUS_RATE", "raw.status_rate_hz"),
    # [blend], added later
    ("BLD_GYR_MEASURED", "blend.gyro_noise_measured"),
    ("BLD_GYR_INSTAB", "blend.gyro_instability_radps"),
    ("BLD_RATE_DRIFT", "blend.rate_drift_window_s"),
    ("ENG_GAP_ATT", "engine.gap_attitude"),
    ("ENG_GAP_FEED_ACC", "engine.gap_feed_max_h_acc_m"),
    ("DEC_LAG_MEASURE", "decoder.gnss_delay_measure"),
    ("ENG_SIL_NINT", "engine.silence_intervals"),
    ("ENG_SIL_MAX", "engine.silence_timeout_max_s"),
    ("OUT_SLOW_ENTER", "outage.slow_enter_s"),
    ("OUT_SLOW_LEAVE", "outage.slow_leave_s"),
    ("OUT_SLOW_MAXINT", "outage.slow_max_interval_s"),
    ("OUT_GNSS_TMO_MAX", "outage.gnss_timeout_max_s"),
    ("BLD_ACC_MEASURED", "blend.accel_noise_measured"),
    ("BLD_VEL_ERR_MEAS", "blend.vel_error_measured"),
    ("ENG_GAP_FEED_ROT", "engine.gap_feed_no_airspeed_max_h_acc_m"),
    ("ENG_VERT_PRIOR", "engine.vertical_prior"),
    ("BLD_HELD_LAG", "blend.held_rates_lag_s"),
    ("ENC_AGP_LEAD", "encoder.px4_agp_lead_s"),
    # [spoof]
    ("SPF_ENABLE", "spoof.enabled"),
    ("SPF_PFA", "spoof.false_alarm_prob"),
    ("SPF_ANCHOR_INT", "spoof.anchor_interval_s"),
    ("SPF_MAX_WINDOW", "spoof.max_window_s"),
    ("SPF_SETTLE", "spoof.settle_s"),
    ("SPF_CAL_TAU", "spoof.calibration_tau_s"),
    ("SPF_CAL_PRIOR", "spoof.calibration_prior"),
    ("SPF_CAL_PRIOR_N", "spoof.calibration_prior_fixes"),
    ("SPF_CAL_MAX", "spoof.max_calibration"),
    ("SPF_VEL_FLOOR", "spoof.gnss_vel_floor_mps"),
    ("SPF_VEL_SLOW", "spoof.gnss_vel_slow_mps"),
    ("SPF_VEL_SLOW_TAU", "spoof.gnss_vel_slow_tau_s"),
    ("SPF_ACC_BIAS", "spoof.acc_bias_sigma_mps2"),
    ("SPF_ACC_BIAS_Z", "spoof.acc_bias_z_sigma_mps2"),
    ("SPF_TILT_BIAS", "spoof.tilt_bias_sigma_mps2"),
    ("SPF_ACC_BIAS_RW", "spoof.acc_bias_rw_m2ps5"),
    ("SPF_TILT_RW", "spoof.tilt_rw_m2ps5"),
    ("SPF_WANDER", "spoof.wander_prior_m2ps5"),
    ("SPF_WANDER_TAU", "spoof.wander_tau_s"),
    ("SPF_LAG_SIGMA", "spoof.lag_sigma_s"),
    ("SPF_ATT_TIME", "spoof.attitude_time_sigma_s"),
    ("SPF_ACC_SMOOTH", "spoof.accel_smoothing_s"),
    ("SPF_VRW_FLOOR", "spoof.acc_vrw_floor_m2ps3"),
    ("SPF_PERSIST_N", "spoof.persist_fixes"),
    ("SPF_PERSIST", "spoof.persist_s"),
    ("SPF_READMIT", "spoof.readmit_s"),
    ("SPF_READMIT_PFA", "spoof.readmit_false_alarm_prob"),
    ("SPF_CALM", "spoof.calm_s"),
    ("SPF_LAG_FLOOR", "spoof.lag_sigma_floor_s"),
    ("SPF_VERIFY_A", "spoof.verified_accel_mps2"),
    ("SPF_VERIFY_T", "spoof.verified_window_s"),
)
"""(parameter name, configuration key) in index order; ``key[i]`` is item ``i`` of a
fixed-length list. New parameters go at the end of their block."""

CHOICES: dict[str, tuple[str, ...]] = {
    "engine.navigator": ("blend", "singer", "passthrough"),
    "heading.track_source": ("auto", "velocity", "position"),
    "blend.mode": ("attitude_aided", "strapdown"),
    "blend.gnss_error_model": ("gauss_markov", "white"),
    "blend.cov_discretisation": ("second_order", "van_loan"),
    "potential.velocity_mode": ("measured", "carried"),
    "encoder.output": ("auto", "gps_input", "global_position_sensor"),
    "raw.receiver_port": ("UART1", "UART2", "USB", "SPI", "I2C"),
    "raw.bands": ("all", "l1"),
    "engine.gap_attitude": ("auto", "autopilot", "rates"),
}
"""Keys holding one of a fixed set of words: the parameter is the word's index here
(pinned: a new word is appended)."""

_SIGNING_WHY = "signing is set on the companion computer, never over the links it protects"

NOT_EXPOSED: dict[str, str] = {
    "link.master": "a link URL (text)",
    "link.gcs": "a link URL (text)",
    "link.state_file": "a file path (text); not to be changed over the air",
    "link.record_dir": "a folder path (text); not to be changed over the air",
    "decoder.own_component": "our own component id: the address of this very protocol",
    "encoder.dialect": "a pymavlink module name (text)",
    "encoder.statustext_interval_overrides": "a list of (alert code, interval) pairs",
    "integrity.phase.field_elevation_msl_m": (
        "optional, and every number (0 m too) is an elevation: no number means unset"
    ),
    "potential.velocity_weights": "a list of any length",
    "potential.velocity_fit_orders": "a list of any length",
    "potential.fit_horizons_s": "a list of any length",
    "signing.autopilot.mode": _SIGNING_WHY,
    "signing.autopilot.key_file": _SIGNING_WHY,
    "signing.autopilot.passphrase": _SIGNING_WHY,
    "signing.autopilot.link_id": _SIGNING_WHY,
    "signing.gcs.mode": _SIGNING_WHY,
    "signing.gcs.key_file": _SIGNING_WHY,
    "signing.gcs.passphrase": _SIGNING_WHY,
    "signing.gcs.link_id": _SIGNING_WHY,
    "raw.device": "a device path (text)",
    "raw.file": "a file path (text); a recording for tests",
}
"""Configuration keys that are not parameters, and why: set them in the TOML file."""

LIVE_KEYS: dict[str, frozenset[str]] = {
    **ENGINE_LIVE_KEYS,
    "encoder": ENCODER_LIVE_KEYS,
    "streams": frozenset(f.name for f in dataclasses.fields(Config().streams)),
    "link": frozenset({"heartbeat_rate_hz"}),
}
"""Keys a running service takes at once, by block. The engine's and the encoder's own
declarations, and the pipeline's: new stream rates are requested from the autopilot at
once, the heartbeat follows its new rate. Every other parameter takes effect when the
service restarts."""

LIST_BURST = 10
"""PARAM_VALUEs sent at once while answering a list request ..."""
LIST_PERIOD_S = 0.1
"""... and the period of the bursts (100 parameters/s: about 4 kB/s on the link, so that
an autopilot routing them to a radio link does not drop them)."""

_PATH = re.compile(r"^([a-z_.]+)\.([a-z0-9_]+)(?:\[(\d)\])?$")


@dataclass(frozen=True, slots=True)
class Param:
    """One parameter: its name, the configuration key it carries, its type."""

    index: int
    name: str
    block: str
    """The configuration block (``integrity.phase`` for a sub-block)."""
    key: str
    item: int | None
    """The item of a fixed-length list, else None."""
    kind: str
    """``float``, ``int``, ``bool`` or ``choice``."""
    choices: tuple[Any, ...] = ()
    """``choice``: the words in index order; an integer enumeration: its members."""
    optional: bool = False
    """Unset (None) is allowed: it reads 0 and 0 sets it."""
    live: bool = False
    """Applied to the running service at once (else at the next start)."""

    @property
    def path(self) -> str:
        """The configuration key as written in this table (``blend.lever_arm_b_m[0]``)."""
        return f"{self.block}.{self.key}" + ("" if self.item is None else f"[{self.item}]")

    @property
    def param_type(self) -> int:
        """MAV_PARAM_TYPE on the wire."""
        if self.kind == "float":
            return MAV_PARAM_TYPE_REAL32
        if self.kind == "bool":
            return MAV_PARAM_TYPE_UINT8
        return MAV_PARAM_TYPE_INT32


class ParamError(ValueError):
    """A value a parameter cannot take; the message is the reason, one line."""


def _block_of(config: Config, block: str) -> Any:
    obj: Any = config
    for part in block.split("."):
        obj = getattr(obj, part)
    return obj


def _build(index: int, name: str, path: str) -> Param:
    m = _PATH.match(path)
    if m is None:
        raise ValueError(f"{name}: bad configuration key {path!r}")
    block, key, item = m.group(1), m.group(2), m.group(3)
    default = _block_of(Config(), block)
    hints = typing.get_type_hints(type(default))
    hint = hints[key]
    optional = False
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        arms = [a for a in typing.get_args(hint) if a is not type(None)]
        optional = len(arms) == 1 and len(typing.get_args(hint)) == 2
        hint = arms[0]
    if item is not None:
        hint = typing.get_args(hint)[int(item)]
    choices: tuple[Any, ...] = ()
    if f"{block}.{key}" in CHOICES:
        kind, choices = "choice", CHOICES[f"{block}.{key}"]
    elif hint is bool:
        kind = "bool"
    elif hint is float:
        kind = "float"
    elif hint is int:
        kind = "int"
    elif isinstance(hint, type) and issubclass(hint, enum.IntEnum):
        kind, choices = "int", tuple(hint)
    else:
        raise ValueError(f"{name}: {path} ({hint}) cannot be a parameter")
    return Param(
        index=index,
        name=name,
        block=block,
        key=key,
        item=None if item is None else int(item),
        kind=kind,
        choices=choices,
        optional=optional,
        live=key in LIVE_KEYS.get(block, frozenset()),
    )


PARAMS: tuple[Param, ...] = tuple(_build(i, name, path) for i, (name, path) in enumerate(TABLE))
"""Every parameter, in index order."""
BY_NAME: dict[str, Param] = {p.name: p for p in PARAMS}


# --------------------------------------------------------------------------- values


def get_value(config: Config, p: Param) -> Any:
    """The configuration's value of ``p`` (the item, for a list's item)."""
    value = getattr(_block_of(config, p.block), p.key)
    return value if p.item is None else value[p.item]


def wire_of(p: Param, value: Any) -> float | int | bool:
    """The number ``p`` carries for the configuration value ``value``."""
    if value is None:
        return 0
    if p.kind == "choice":
        return p.choices.index(value)
    if p.kind == "bool":
        return bool(value)
    if p.kind == "int":
        return int(value)
    return float(value)


def value_of(p: Param, number: float) -> Any:
    """The configuration value the number ``number`` (from the wire) sets ``p`` to.

    Raises
    ------
    ParamError
        ``number`` is no value of the parameter's type (NaN; not an integer; a
        boolean other than 0 or 1; an index past the words).
    """
    if math.isnan(number):
        raise ParamError("must be a number")
    if p.optional and number == 0.0:
        return None
    if p.kind == "float":
        return real32(number)
    if not is_integral(number):
        raise ParamError("must be an integer")
    n = int(number)
    if p.kind == "bool":
        if n not in (0, 1):
            raise ParamError("must be 0 or 1")
        return bool(n)
    if p.kind == "choice":
        if not 0 <= n < len(p.choices):
            raise ParamError(f"must be 0..{len(p.choices) - 1}")
        return p.choices[n]
    if not INT32_MIN <= n <= INT32_MAX:
        raise ParamError("out of the INT32 range")
    return n


def with_value(config: Config, p: Param, value: Any) -> Config:
    """``config`` with ``p`` set to ``value``, validated as the TOML file's values are.

    Raises
    ------
    ConfigError
        The configuration refuses the value (range, type, a check between keys).
    """
    if p.item is not None:
        items = list(getattr(_block_of(config, p.block), p.key))
        items[p.item] = value
        value = items
    if isinstance(value, enum.Enum):
        value = value.value
    table: dict[str, Any] = {p.key: value}
    for part in reversed(p.block.split(".")[1:]):
        table = {part: table}
    return merge_config(config, {p.block.split(".")[0]: table})


def _same(p: Param, a: Any, b: Any) -> bool:
    """Equal as the wire carries them (a REAL32 cannot tell 0.1 from 0.1 + 1e-12)."""
    if p.kind == "float" and a is not None and b is not None:
        return real32(a) == real32(b)
    return bool(a == b)


def reason(p: Param, error: ConfigError) -> str:
    """The configuration's refusal in the parameters' words: ``must be in (0, 50]``, with
    the keys of the block spelled as their parameters' names."""
    text = re.sub(r"^\[[^\]]*\]\s*", "", str(error))
    text = re.sub(r",? got .*$", "", text)
    names = {q.key: q.name for q in PARAMS if q.block == p.block and q.item is None}
    names[p.key] = p.name
    text = re.sub(r"\b[a-z][a-z0-9_]*\b", lambda m: names.get(m.group(0), m.group(0)), text)
    text = text.removeprefix(p.name).lstrip(" :")
    return text


# --------------------------------------------------------------------------- persistence


def load_overrides(config: Config, saved: Any) -> tuple[Config, dict[str, Any], list[str]]:
    """``config`` with the values saved by :class:`ParamServer` (the content of
    ``params.json``: ``{"version": 1, "params": {NAME: value}}``) applied in the order
    they were set, each validated as a PARAM_SET is.

    Returns the configuration, the values applied (to be kept persisted) and one line
    per value dropped (unknown name, a value the configuration now refuses).
    """
    problems: list[str] = []
    applied: dict[str, Any] = {}
    params = saved.get("params") if isinstance(saved, dict) else None
    if not isinstance(params, dict):
        return config, applied, ["no 'params' table"]
    for name, value in params.items():
        p = BY_NAME.get(name)
        if p is None:
            problems.append(f"{name}: no such parameter")
            continue
        if p.kind == "choice" and value not in p.choices:
            problems.append(f"{name}: {value!r} is not one of {list(p.choices)}")
            continue
        if p.kind != "choice" and not (value is None or isinstance(value, bool | int | float)):
            problems.append(f"{name}: {value!r} is not a number")
            continue
        try:
            config = with_value(config, p, value)
        except ConfigError as exc:
            problems.append(f"{name}: {reason(p, exc)}")
            continue
        applied[name] = get_value(config, p)
    return config, applied, problems


def saved_form(overrides: dict[str, Any]) -> dict[str, Any]:
    """What :class:`ParamServer`'s values set look like in ``params.json``."""
    return {
        "version": 1,
        "params": {k: (v.value if isinstance(v, enum.Enum) else v) for k, v in overrides.items()},
    }


# --------------------------------------------------------------------------- the server


@dataclass(slots=True)
class Answer:
    """What a request gives: messages to send, the running configuration to adopt (a
    live parameter set), and the rejection reason to count (None: accepted)."""

    messages: list[Any]
    config: Config | None = None
    rejection: str | None = None


class ParamServer:
    """The parameter protocol of component 191 (see the module docstring).

    ``config`` is the configuration the parameters read: the running one plus the
    values set that wait for a restart. ``overrides`` holds every value set over
    MAVLink, in the order set (what the driver persists); ``changes`` counts its
    changes (the driver saves when it moves).
    """

    def __init__(self, config: Config, dialect: str) -> None:
        self.config = config
        self.overrides: dict[str, Any] = {}
        self.changes = 0
        self._codec = ParamCodec(dialect)
        self._list_next: int | None = None
        self._list_due_s = math.inf

    # ------------------------------------------------------------------ requests

    def handle(self, request: ParamRequest, running: Config, t_rx_s: float) -> Answer:
        """The answer to one request addressed to us; ``running`` is the configuration the
        service runs with, ``t_rx_s`` the driver's clock (paces a list)."""
        if isinstance(request, ParamList):
            self._list_next = 0
            self._list_due_s = t_rx_s
            return Answer(self.on_timer(t_rx_s))
        if isinstance(request, ParamRead):
            if request.index >= 0:
                p = PARAMS[request.index] if request.index < len(PARAMS) else None
            else:
                p = BY_NAME.get(request.name)
            if p is None:
                return Answer([], rejection="unknown_param")
            return Answer([self._value(p)])
        if isinstance(request, ParamSet):
            return self._set(request, running)
        return Answer([], rejection="unhandled_type")

    def next_due_s(self) -> float:
        """When :meth:`on_timer` next has PARAM_VALUEs to send (inf: nothing pending)."""
        return self._list_due_s

    def on_timer(self, t_rx_s: float) -> list[Any]:
        """The next burst of a list being answered, when due."""
        start = self._list_next
        if start is None or t_rx_s < self._list_due_s:
            return []
        stop = min(start + LIST_BURST, len(PARAMS))
        if stop >= len(PARAMS):
            self._list_next, self._list_due_s = None, math.inf
        else:
            self._list_next, self._list_due_s = stop, t_rx_s + LIST_PERIOD_S
        return [self._value(p) for p in PARAMS[start:stop]]

    # ------------------------------------------------------------------ internals

    def _value(self, p: Param) -> Any:
        number = wire_of(p, get_value(self.config, p))
        return self._codec.param_value(p.name, number, p.param_type, len(PARAMS), p.index)

    def _text(self, severity: Severity, p_name: str, why: str) -> Any:
        return self._codec.statustext(int(severity), f"CMP PARAM {p_name} {why}")

    def _refuse(self, p: Param, number: float, why: str) -> Answer:
        log.warning("PARAM_SET %s = %r refused: %s", p.name, number, why)
        return Answer(
            [self._value(p), self._text(Severity.WARNING, p.name, why)],
            rejection="param_refused",
        )

    def _set(self, request: ParamSet, running: Config) -> Answer:
        p = BY_NAME.get(request.name)
        if p is None:
            name = printable_name(request.name)
            log.warning("PARAM_SET of unknown parameter %s", name)
            return Answer(
                [self._text(Severity.WARNING, name, "unknown")], rejection="unknown_param"
            )
        try:
            value = value_of(p, request.value)
        except ParamError as exc:
            return self._refuse(p, request.value, str(exc))
        if _same(p, value, get_value(self.config, p)):
            return Answer([self._value(p)])  # nothing changes (a ground station writing all)
        try:
            stored = with_value(self.config, p, value)
        except ConfigError as exc:
            return self._refuse(p, request.value, reason(p, exc))
        self.config = stored
        self.overrides.pop(p.name, None)
        self.overrides[p.name] = get_value(stored, p)
        self.changes += 1
        log.info("parameter %s set to %r (%s)", p.name, value, p.path)
        answer = Answer([self._value(p)])
        if p.live:
            try:
                answer.config = with_value(running, p, value)
                return answer
            except ConfigError as exc:  # another value waiting for the restart decides
                log.info("%s: not applicable before the restart (%s)", p.name, exc)
        if not _same(p, value, get_value(running, p)):
            answer.messages.append(self._text(Severity.NOTICE, p.name, "applies after restart"))
        return answer


# --------------------------------------------------------------------------- documentation


def _values_doc(p: Param, default: Any) -> str:
    block = _block_of(default, p.block)
    field = next(f for f in dataclasses.fields(block) if f.name == p.key)
    if p.kind == "choice":
        return ", ".join(f"{i} {c}" for i, c in enumerate(p.choices))
    if p.kind == "bool":
        return "0 false, 1 true"
    parts = []
    if p.choices:  # an integer enumeration
        parts.append(", ".join(f"{int(c)} {c.name}" for c in p.choices))
    rng = field_range(field)
    if rng is not None and rng.choices is not None:
        parts.append(", ".join(str(c) for c in rng.choices))
    elif rng is not None and rng.describe() not in ("finite", "a number"):
        parts.append(rng.describe())
    if p.optional:
        parts.append("0 unset")
    return "; ".join(parts)


def markdown_table() -> str:
    """The table of docs/params.md: every parameter, its key, type, values and default
    (the built-in one, before any TOML file) and when a change takes effect."""
    default = Config()
    type_names = {
        MAV_PARAM_TYPE_REAL32: "REAL32",
        MAV_PARAM_TYPE_INT32: "INT32",
        MAV_PARAM_TYPE_UINT8: "UINT8",
    }
    lines = [
        "| index | name | configuration key | type | values | default | applies |",
        "|---|---|---|---|---|---|---|",
    ]
    for p in PARAMS:
        number = wire_of(p, get_value(default, p))
        shown = f"{real32(number):g}" if p.kind == "float" else str(int(number))
        lines.append(
            f"| {p.index} | `{p.name}` | `{p.path}` | {type_names[p.param_type]} | "
            f"{_values_doc(p, default)} | {shown} | {'live' if p.live else 'restart'} |"
        )
    return "\n".join(lines) + "\n"


def _check_table() -> None:
    """The table's own rules (import fails on a broken table; the tests say more)."""
    names = [name for name, _ in TABLE]
    if len(set(names)) != len(names):
        raise ValueError("duplicate parameter names")
    for name in names:
        if len(name) > PARAM_ID_MAX_CHARS or not re.fullmatch(r"[A-Z][A-Z0-9_]*", name):
            raise ValueError(f"bad parameter name {name!r}")
        if name.split("_", 1)[0] not in PREFIXES.values():
            raise ValueError(f"{name}: not a block prefix")


_check_table()

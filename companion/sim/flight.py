"""simulate(): a scenario and a seed in, a complete simulated flight out.

The result (:class:`SimFlight`) holds the truth on a dense grid (the IMU's
sample times), the exact path for any other time (:meth:`Truth.at`), the typed
samples in the order the service would receive them, and the MAVLink messages
(with their receive times) the .tlog is written from. Same scenario and seed,
same everything.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from companion.nav.frames import LocalFrame
from companion.nav.grades import ATTITUDE_ERROR_BY_GRADE, IMU_GRADES
from companion.sim import autopilot as ap
from companion.sim import realism as rz
from companion.sim.attacks import (
    MAV_JAMMING,
    MAV_SPOOFING,
    ReceiverAttacks,
    flags,
    on_receiver,
)
from companion.sim.scenarios import Event, Scenario, build_script
from companion.sim.sensors import (
    ATTITUDE_RATE_NOISE_RADPS,
    AUTOPILOT_POS_SIGMA_M,
    AUTOPILOT_POS_TAU_S,
    GNSS_MODE_SPECS,
    ImuErrors,
    gauss_markov,
    gauss_markov_fast,
    gnss_state,
    imu_errors,
)
from companion.sim.trajectory import Path, PathState
from companion.types import FixType, FloatArray, LandedState, Sample

logger = logging.getLogger(__name__)

TRANSPORT_LATENCY_S = 0.002
"""Autopilot-to-companion transport delay, s (plus up to 1 ms seeded jitter)."""
GNSS2_EXTRA_LATENCY_S = 0.01
RTK_BASE_NED_M = np.array([-400.0, 250.0, 0.0])
"""The RTK base station in the local frame, m (GPS_RTK baselines are from it)."""


@dataclass(frozen=True, slots=True)
class TruthPoint:
    """The true state at one time (angles in rad, yaw wrapped to [-pi, pi))."""

    t_s: float
    pos_ned_m: FloatArray
    vel_ned_mps: FloatArray
    acc_ned_mps2: FloatArray
    euler_rad: FloatArray
    gyro_b_radps: FloatArray
    f_b_mps2: FloatArray
    lat_rad: float
    lon_rad: float
    alt_msl_m: float
    phase: str
    gnss_mode: str


@dataclass(frozen=True, slots=True)
class Truth:
    """The truth on the dense grid (the IMU sample times); arrays have first axis N.

    ``gyro_b_radps`` and ``f_b_mps2`` are the exact (error-free, unquantised)
    angular rate and specific force. ``gnss_mode`` is receiver 0's state label:
    'rtk_fixed', 'rtk_float', 'dgps', '3d', 'none', 'outage' or 'stale'.
    """

    t_s: FloatArray
    pos_ned_m: FloatArray
    vel_ned_mps: FloatArray
    acc_ned_mps2: FloatArray
    euler_rad: FloatArray
    gyro_b_radps: FloatArray
    f_b_mps2: FloatArray
    lat_rad: FloatArray
    lon_rad: FloatArray
    alt_msl_m: FloatArray
    phase: np.ndarray
    gnss_mode: np.ndarray
    path: Path
    scenario: Scenario

    def sample(self, t_s: FloatArray) -> PathState:
        """The exact path state at arbitrary times (N,) inside the flight."""
        return self.path.evaluate(np.atleast_1d(np.asarray(t_s, dtype=float)))

    def at(self, t_s: float) -> TruthPoint:
        """The exact true state at one time (evaluated on the path, not interpolated).

        Raises
        ------
        ValueError
            If ``t_s`` is outside the flight.
        """
        if not (self.t_s[0] - 1e-9 <= t_s <= self.t_s[-1] + 1e-9):
            raise ValueError(f"t_s={t_s} outside the flight [{self.t_s[0]}, {self.t_s[-1]}]")
        st = self.path.evaluate(np.array([t_s]))
        lat, lon, alt = self.path.frame.ned_to_lla(st.pos_ned_m[0])
        return TruthPoint(
            float(t_s),
            st.pos_ned_m[0],
            st.vel_ned_mps[0],
            st.acc_ned_mps2[0],
            st.euler_rad[0],
            st.gyro_b_radps[0],
            st.f_b_mps2[0],
            lat,
            lon,
            alt,
            str(self.path.phase_at(np.array([t_s]))[0]),
            gnss_state(self.scenario, 0, t_s).label,
        )


@dataclass(frozen=True, slots=True)
class GnssTruthErrors:
    """Per receiver: fix times, the modes, the random position error and fault offsets (NED)."""

    receiver_id: int
    t_fix_s: FloatArray
    label: np.ndarray
    pos_err_ned_m: FloatArray
    fault_ned_m: FloatArray
    """Step/ramp/dither offsets plus the attacks' (drag, meaconing) position offsets."""
    vel_err_ned_mps: FloatArray
    attacks: ReceiverAttacks | None = None
    """Drags, meaconing, jamming (:mod:`companion.sim.attacks`): None when none."""


@dataclass(frozen=True, slots=True)
class SimErrors:
    """The errors the simulator injected (for tests of estimators against their truth)."""

    imu: ImuErrors
    attitude_err_rad: FloatArray
    """ATTITUDE minus truth (roll, pitch, yaw) at the attitude times, incl. heading error."""
    attitude_t_s: FloatArray
    gnss: tuple[GnssTruthErrors, ...]
    realism: RealismTruth | None = None
    """What the realistic autopilot added (None when ``Scenario.realism`` is None)."""


@dataclass(frozen=True, slots=True)
class RealismTruth:
    """The realistic traits' draws: IMU units, attitude error, windows and the reboot."""

    imu_units: tuple[rz.ImuRealismErrors, ...]
    """Main unit first, then SCALED_IMU2/3 (errors on the main IMU time grid)."""
    dropouts: tuple[tuple[float, float], ...]
    """Every stream silent, (t_start_s, t_end_s) on the first boot's clock."""
    gnss_gaps: tuple[tuple[float, float], ...]
    gnss_nofix: tuple[tuple[float, float], ...]
    bursts: tuple[tuple[float, float], ...]
    reboot_t_s: float | None
    """First-boot time of the reboot; later messages carry boot time t_s - reboot_t_s."""
    baro_bias_hpa: FloatArray
    """SCALED_PRESSURE minus the ISA pressure of the true altitude (no noise), at baro times."""
    baro_t_s: FloatArray


@dataclass(frozen=True, slots=True)
class SimFlight:
    """A simulated flight: truth, typed samples and MAVLink messages."""

    scenario: Scenario
    """As asked; with realism, ``events`` and ``truth.scenario`` add the drawn windows."""
    seed: int
    frame: LocalFrame
    truth: Truth
    events: tuple[Event, ...]
    samples: list[Sample]
    messages: list[tuple[float, object]]
    """(t_rx_s UNIX-epoch seconds, pymavlink message), in receive order."""
    errors: SimErrors
    phases: tuple[tuple[str, float, float], ...]
    """(phase, t_start_s, t_end_s) runs of the script, clipped to the flight."""


def _grid(t0: float, t1: float, rate_hz: float, unit: float, offset_s: float = 0.0) -> FloatArray:
    """Times t0 + offset + k / rate inside [t0, t1], rounded to the message's stamp unit."""
    n = int(math.floor((t1 - t0 - offset_s) * rate_hz + 1e-9)) + 1
    t = t0 + offset_s + np.arange(max(n, 0)) / rate_hz
    t = np.rint(t * unit) / unit
    return t[(t >= t0 - 1e-12) & (t <= t1 + 1e-12)]


def _rx_times(emit_s: FloatArray, epoch0_s: float, rng: np.random.Generator) -> FloatArray:
    """Receive times (UNIX s, whole microseconds), non-decreasing in emission order."""
    t = epoch0_s + emit_s + TRANSPORT_LATENCY_S + rng.uniform(0.0, 1e-3, len(emit_s))
    t = np.maximum.accumulate(t)
    return np.asarray(np.rint(t * 1e6) / 1e6, dtype=float)


def _make_path(sc: Scenario) -> tuple[Path, float]:
    b = build_script(sc)
    natural = b.t_s - sc.t_boot0_s
    duration = natural if sc.duration_s is None else sc.duration_s
    if duration > natural + 1e-9:
        b.seg(duration - natural, b.segments[-1].phase)
    return b.build(sc.frame, sc.wind_ned_mps, sc.profile == "fixed_wing"), duration


def simulate(scenario: Scenario, seed: int) -> SimFlight:
    """Simulate a flight.

    Parameters
    ----------
    scenario : Scenario
        What to fly (see :func:`companion.sim.make_scenario`).
    seed : int
        Seed of every random draw (``numpy.random.SeedSequence``).

    Returns
    -------
    SimFlight

    Raises
    ------
    ValueError
        Bad seed or a scenario that cannot be flown.
    """
    if not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    sc = scenario
    ss = np.random.SeedSequence(int(seed))
    rng_imu, rng_att, rng_g0, rng_g1, rng_ap, rng_rx = (
        np.random.default_rng(s) for s in ss.spawn(6)
    )
    path, duration = _make_path(sc)
    frame = sc.frame
    t0, t1 = sc.t_boot0_s, sc.t_boot0_s + duration
    rl = sc.realism
    plan: _RealismPlan | None = None
    if rl is not None:  # drawn from further children: the six above stay as they were
        plan = _plan_realism(sc, rl, ss, t0, t1)
        sc = plan.scenario
    noise = sc.noise
    fixed_wing = sc.profile == "fixed_wing"
    ardupilot = sc.flavour.value == "ardupilot"

    # ---------------------------------------------------------------- truth on the IMU grid
    unit = 1e3 if sc.imu_message == "SCALED_IMU2" else 1e6
    t_imu = _grid(t0, t1, sc.imu_rate_hz, unit)
    if plan is not None and plan.rl.stamp_jitter_s > 0:
        t_imu = np.rint(
            (t_imu + plan.rng_link.normal(0, plan.rl.stamp_jitter_s, len(t_imu))) * unit
        )
        t_imu = np.unique(np.clip(t_imu / unit, t0, t1))
    st = path.evaluate(t_imu)
    lat, lon, alt = _lla(frame, st.pos_ned_m)
    phase = path.phase_at(t_imu)
    labels = np.array([gnss_state(sc, 0, float(t)).label for t in t_imu])
    truth = Truth(
        t_imu, st.pos_ned_m, st.vel_ned_mps, st.acc_ned_mps2, st.euler_rad, st.gyro_b_radps,
        st.f_b_mps2, lat, lon, alt, phase, labels, path, sc,
    )  # fmt: skip

    # ---------------------------------------------------------------- IMU
    grade = IMU_GRADES[sc.imu_grade]
    ierr = imu_errors(rng_imu, grade, len(t_imu), sc.imu_rate_hz, enabled=noise)
    gyro_m = st.gyro_b_radps + ierr.gyro_bias_b_radps + ierr.gyro_white_b_radps
    acc_m = st.f_b_mps2 + ierr.acc_bias_b_mps2 + ierr.acc_white_b_mps2
    units_rz: list[rz.ImuRealismErrors] = []
    if plan is not None:
        vib = _vibration_level(phase, plan.rl, fixed_wing)
        e = rz.imu_realism(plan.rng_imu, plan.rl, t_imu, t0, vib)
        units_rz.append(e)
        gyro_m = st.gyro_b_radps @ e.gyro_matrix.T + ierr.gyro_bias_b_radps
        gyro_m = gyro_m + ierr.gyro_white_b_radps + e.gyro_err_b_radps
        acc_m = st.f_b_mps2 @ e.acc_matrix.T + ierr.acc_bias_b_mps2 + ierr.acc_white_b_mps2
        acc_m = acc_m + e.acc_err_b_mps2
    streams = [ap.imu_stream(sc.imu_message, t_imu, acc_m, gyro_m, st.mat_nb, alt)]
    if plan is not None:
        extra = [m for m in ("SCALED_IMU2", "SCALED_IMU3") if m != sc.imu_message]
        for name in extra[: plan.rl.extra_imus]:
            g = imu_errors(plan.rng_imu, grade, len(t_imu), sc.imu_rate_hz, enabled=noise)
            e = rz.imu_realism(plan.rng_imu, plan.rl, t_imu, t0, vib)
            units_rz.append(e)
            g_x = st.gyro_b_radps @ e.gyro_matrix.T + g.gyro_bias_b_radps + g.gyro_white_b_radps
            a_x = st.f_b_mps2 @ e.acc_matrix.T + g.acc_bias_b_mps2 + g.acc_white_b_mps2
            streams.append(
                ap.imu_stream(
                    name, t_imu, a_x + e.acc_err_b_mps2, g_x + e.gyro_err_b_radps, st.mat_nb, alt
                )
            )

    # ---------------------------------------------------------------- attitude
    t_att = _grid(t0, t1, sc.attitude_rate_hz, 1e3, offset_s=0.004)
    lag = plan.rl.attitude_lag_s if plan is not None else 0.0
    sa = path.evaluate(np.maximum(t_att - lag, t0) if lag else t_att)
    att_err = np.zeros((len(t_att), 3))
    rate_err = np.zeros((len(t_att), 3))
    if noise:
        att_sigma_rad, att_tau_s = ATTITUDE_ERROR_BY_GRADE[sc.imu_grade]
        for k in range(3):
            att_err[:, k] = gauss_markov_fast(
                rng_att, len(t_att), 1.0 / sc.attitude_rate_hz, att_sigma_rad[k],
                att_tau_s, 1,
            )[:, 0]  # fmt: skip
        rate_err = rng_att.standard_normal((len(t_att), 3)) * ATTITUDE_RATE_NOISE_RADPS
    att_err[:, 2] += math.radians(sc.heading_error_deg)
    att_rz = np.zeros((len(t_att), 3))
    if plan is not None:
        att_rz = _attitude_realism(plan, len(t_att), sc.attitude_rate_hz)
        att_err += att_rz
    euler_ap = sa.euler_rad + att_err
    euler_ap[:, 2] = (euler_ap[:, 2] + np.pi) % (2 * np.pi) - np.pi
    streams.append(ap.attitude_stream(not ardupilot, t_att, euler_ap, sa.gyro_b_radps + rate_err))

    # ---------------------------------------------------------------- GNSS
    gnss_truth = []
    receivers = (0, 1) if sc.second_receiver else (0,)
    for rid, rng in zip(receivers, (rng_g0, rng_g1), strict=False):
        stream_list, gt = _gnss_streams(sc, path, frame, rid, rng, t0, t1, ardupilot, plan)
        streams.extend(stream_list)
        gnss_truth.append(gt)

    if sc.gnss_integrity_relay:  # 1 Hz, the receiver's own flags (companion.sim.attacks)
        t_gi = _grid(t0, t1, 1.0, 1e3, offset_s=0.19)
        jam, spoof = flags(sc, 0, t_gi - sc.gnss_latency_s)
        streams.append(ap.gnss_integrity_stream(
            t_gi, [MAV_JAMMING[bool(x)] for x in jam], [MAV_SPOOFING[bool(x)] for x in spoof]
        ))  # fmt: skip

    # ---------------------------------------------------------------- housekeeping
    t_hb = _grid(t0, t1, 1.0, 1e3)  # the first message of the record
    armed = [p != "parked" for p in path.phase_at(t_hb)] if len(t_hb) else []
    streams.append(ap.heartbeat_stream(t_hb, ardupilot, fixed_wing, armed))
    streams.append(ap.system_time_stream(_grid(t0, t1, 1.0, 1e3), sc.epoch0_s))
    t_vfr = _grid(t0, t1, 4.0, 1e3, offset_s=0.11)
    sv = path.evaluate(t_vfr)
    _, _, alt_v = _lla(frame, sv.pos_ned_m)
    air_v = np.linalg.norm(sv.vel_ned_mps - np.asarray(sc.wind_ned_mps)[None, :], axis=1)
    ph_v = path.phase_at(t_vfr)
    streams.append(
        ap.vfr_hud_stream(
            t_vfr, air_v, np.hypot(sv.vel_ned_mps[:, 0], sv.vel_ned_mps[:, 1]),
            sv.euler_rad[:, 2], alt_v, -sv.vel_ned_mps[:, 2],
            [ap.THROTTLE_BY_PHASE.get(p, 0) for p in ph_v],
        )
    )  # fmt: skip
    t_ess = _grid(t0, t1, 2.0, 1e3, offset_s=0.17)
    streams.append(
        ap.ext_sys_state_stream(
            t_ess,
            [ap.LANDED_BY_PHASE.get(p, LandedState.UNDEFINED) for p in path.phase_at(t_ess)],
        )
    )
    t_gp = _grid(t0, t1, 10.0, 1e3, offset_s=0.007)
    lag_gp = plan.rl.autopilot_lag_s if plan is not None else 0.0
    sg = path.evaluate(np.maximum(t_gp - lag_gp, t0) if lag_gp else t_gp)
    pos_ap = sg.pos_ned_m.copy()
    if plan is not None and plan.rl.autopilot_pos_sigma_m > 0:
        pos_ap += gauss_markov_fast(
            plan.rng_att, len(t_gp), 0.1, plan.rl.autopilot_pos_sigma_m,
            plan.rl.autopilot_pos_tau_s, 3,
        )  # fmt: skip
    if noise:
        for k in range(3):
            pos_ap[:, k] += gauss_markov_fast(
                rng_ap, len(t_gp), 0.1, AUTOPILOT_POS_SIGMA_M[k], AUTOPILOT_POS_TAU_S, 1
            )[:, 0]
    la, lo, al = _lla(frame, pos_ap)
    yaw_gp = sg.euler_rad[:, 2] + math.radians(sc.heading_error_deg)
    if plan is not None and len(t_att):
        yaw_gp = yaw_gp + np.interp(t_gp, t_att, att_rz[:, 2])
    streams.append(ap.global_position_stream(t_gp, la, lo, al, sc.alt0_m, sg.vel_ned_mps, yaw_gp))
    baro_bias, t_baro = np.zeros(0), np.zeros(0)
    if plan is not None and plan.rl.baro_rate_hz > 0:
        t_baro = _grid(t0, t1, plan.rl.baro_rate_hz, 1e3, offset_s=0.013)
        t_baro = t_baro[~_inside(t_baro, plan.baro_dropouts)]
        p_hpa, baro_bias = _baro(plan, path, frame, t_baro, t0, fixed_wing)
        streams.append(
            ap.baro_stream(t_baro, p_hpa, 25.0 + 10.0 * (t_baro - t0) / max(t1 - t0, 1.0))
        )

    # ---------------------------------------------------------------- merge in receive order
    emit = np.concatenate([s.emit_s for s in streams])
    sid = np.concatenate([np.full(len(s.emit_s), j) for j, s in enumerate(streams)])
    idx = np.concatenate([np.arange(len(s.emit_s)) for s in streams])
    order = np.lexsort((idx, sid, emit))
    t_rx = _rx_times(emit[order], sc.epoch0_s, rng_rx)
    makers = [s.make for s in streams]
    if plan is None:
        messages: list[tuple[float, object]] = []
        samples: list[Sample] = []
        last_known: float | None = None
        for t_r, j, i in zip(t_rx.tolist(), sid[order].tolist(), idx[order].tolist(), strict=True):
            msg, smp, t_est = makers[j](i, t_r, last_known)
            messages.append((t_r, msg))
            if smp is not None:
                samples.append(smp)
            if t_est is not None and (last_known is None or t_est > last_known):
                last_known = t_est
    else:
        messages, samples = _deliver(plan, makers, emit[order], sid[order], idx[order], t_rx)

    phases = _phase_runs(path, t0, t1)
    logger.info(
        "simulated %s seed %d: %.0f s, %d messages, %d samples",
        sc.name, seed, duration, len(messages), len(samples),
    )  # fmt: skip
    return SimFlight(
        scenario, int(seed), frame, truth, sc.events, samples, messages,
        SimErrors(
            ierr, att_err, t_att, tuple(gnss_truth),
            None if plan is None else RealismTruth(
                tuple(units_rz), tuple(plan.dropouts), tuple(plan.gnss_gaps),
                tuple(plan.gnss_nofix), tuple(plan.bursts), plan.reboot_t_s, baro_bias, t_baro,
            ),
        ),
        phases,
    )  # fmt: skip


def _lla(frame: LocalFrame, pos_ned_m: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Vectorised local NED -> (lat_rad, lon_rad, alt_m) with the frame's geodesy (pymap3d)."""
    import pymap3d

    lat, lon, alt = pymap3d.ned2geodetic(
        pos_ned_m[:, 0], pos_ned_m[:, 1], pos_ned_m[:, 2],
        frame.lat0_rad, frame.lon0_rad, frame.alt0_m, deg=False,
    )  # fmt: skip
    return np.asarray(lat, float), np.asarray(lon, float), np.asarray(alt, float)


def _phase_runs(path: Path, t0: float, t1: float) -> tuple[tuple[str, float, float], ...]:
    runs: list[tuple[str, float, float]] = []
    for s in path.segments:
        a, b = max(s.t0_s, t0), min(s.t1_s, t1)
        if b <= a:
            continue
        if runs and runs[-1][0] == s.phase:
            runs[-1] = (s.phase, runs[-1][1], b)
        else:
            runs.append((s.phase, a, b))
    return tuple(runs)


def _gnss_streams(
    sc: Scenario,
    path: Path,
    frame: LocalFrame,
    rid: int,
    rng: np.random.Generator,
    t0: float,
    t1: float,
    ardupilot: bool,
    plan: _RealismPlan | None = None,
) -> tuple[list[ap.Stream], GnssTruthErrors]:
    """Receiver ``rid``: mode schedule, errors, events -> GPS_RAW_INT/GPS2_RAW and GPS_RTK."""
    from companion.sim.sensors import fault_offset_ned_m

    latency = sc.gnss_latency_s + (GNSS2_EXTRA_LATENCY_S if rid else 0.0)
    t_fix = _grid(t0, t1 - latency, sc.gnss_rate_hz, 1e3, offset_s=0.05)
    states = [gnss_state(sc, rid, float(t)) for t in t_fix]
    specs = [GNSS_MODE_SPECS[s.mode] for s in states]
    tau = np.array([sp.tau_s for sp in specs])
    unit_err = gauss_markov(rng, t_fix, 1.0, tau, 3)
    sig = np.array([[sp.sigma_h_m, sp.sigma_h_m, sp.sigma_v_m] for sp in specs]).reshape(-1, 3)
    pos_err = unit_err * sig
    vsig = np.array([sc.gnss_vel_noise_mps * sp.vel_noise_scale for sp in specs])
    vel_err = rng.standard_normal((len(t_fix), 3)) * vsig[:, None]
    if not sc.noise:
        pos_err[:] = 0.0
        vel_err[:] = 0.0
    fault = np.array([fault_offset_ned_m(sc, rid, float(t)) for t in t_fix]).reshape(-1, 3)
    sg = path.evaluate(t_fix)
    atk = on_receiver(sc, rid, t_fix, path)  # None without attacks: nothing changes
    if atk is not None:
        fault = fault + atk.pos_off_ned_m
        pos_err *= atk.acc_factor[:, None]
        vel_err *= atk.acc_factor[:, None]
    pos_rep = sg.pos_ned_m + pos_err + fault
    gx = _gnss_realism(plan, t_fix, specs) if plan is not None else None
    if gx is not None:
        vel_err = vel_err + gx.vel_bias_ned_mps
        pos_rep = pos_rep + gx.garbage_ned_m
    vel_rep = sg.vel_ned_mps + vel_err + (0.0 if atk is None else atk.vel_off_ned_mps)
    lat, lon, alt = _lla(frame, pos_rep)
    reports: list[ap.GnssReport] = []
    rtk_i: list[int] = []
    last: ap.GnssReport | None = None
    for k, (s, sp) in enumerate(zip(states, specs, strict=True)):
        if not s.present:
            continue
        if s.stale and last is not None:
            rep = dataclasses.replace(last, t_fix_s=float(t_fix[k]))
        else:
            rep = ap.GnssReport(
                float(t_fix[k]), sp.fix_type, float(lat[k]), float(lon[k]), float(alt[k]),
                float(alt[k]) + sc.geoid_undulation_m, vel_rep[k, :2].copy(), sp.sigma_h_m,
                sp.sigma_v_m, float(vsig[k]), sp.hdop, sp.vdop, sp.satellites,
            )  # fmt: skip
            if atk is not None:
                rep = atk.report(rep, k)
            if gx is not None:
                rep = gx.report(rep, k)
            last = rep
        reports.append(rep)
        on_second = abs((t_fix[k] - t0 - 0.05) - round(t_fix[k] - t0 - 0.05)) < 1e-6
        if s.mode.startswith("rtk") and on_second:
            rtk_i.append(k)
    streams = [ap.gnss_stream(rid, ardupilot, sc.epoch0_s, reports, latency)]
    if rtk_i:
        ri = np.array(rtk_i)
        streams.append(
            ap.rtk_stream(
                rid, sc.epoch0_s, t_fix[ri], pos_rep[ri] - RTK_BASE_NED_M[None, :],
                np.array([specs[i].sigma_h_m for i in rtk_i]),
                [specs[i].satellites for i in rtk_i],
                [specs[i].fix_type == FixType.RTK_FIXED for i in rtk_i], latency,
                None if atk is None else -atk.delay_s[ri],
            )
        )  # fmt: skip
    label = np.array([s.label for s in states])
    return streams, GnssTruthErrors(rid, t_fix, label, pos_err, fault, vel_err, atk)


# --------------------------------------------------------------------------- realism

_GROUND_PHASES = frozenset(("taxi", "lineup", "takeoff_roll", "landing_roll"))
REBOOT_SILENCE_S = 3.0
"""An autopilot reboot: no message for this long, then the boot clock restarts from 0."""


@dataclass(slots=True)
class _RealismPlan:
    """The realistic traits' random generators and windows for one flight."""

    rl: rz.Realism
    scenario: Scenario
    rng_imu: np.random.Generator
    rng_att: np.random.Generator
    rng_gnss: np.random.Generator
    rng_link: np.random.Generator
    rng_baro: np.random.Generator
    dropouts: list[tuple[float, float]]
    gnss_gaps: list[tuple[float, float]]
    gnss_nofix: list[tuple[float, float]]
    flaps: list[tuple[float, float]]
    bursts: list[tuple[float, float]]
    baro_dropouts: list[tuple[float, float]]
    reboot_t_s: float | None


def _plan_realism(
    sc: Scenario, rl: rz.Realism, ss: np.random.SeedSequence, t0: float, t1: float
) -> _RealismPlan:
    """Draw the windows and add them to the scenario as GNSS events (so the truth labels them)."""
    rng_w, rng_imu, rng_att, rng_gnss, rng_link, rng_baro = (
        np.random.default_rng(s) for s in ss.spawn(6)
    )
    w = rz.windows
    dropouts = w(rng_w, t0, t1, rl.dropout_per_h, rl.dropout_min_s, rl.dropout_max_s)
    reboot = None
    if rl.reboot_at_fraction is not None:
        reboot = round(t0 + rl.reboot_at_fraction * (t1 - t0), 3)
        dropouts = sorted(
            [d for d in dropouts if d[1] < reboot - 1.0 or d[0] > reboot + REBOOT_SILENCE_S + 1.0]
            + [(reboot, reboot + REBOOT_SILENCE_S)]
        )
    gaps = w(rng_w, t0, t1, rl.gnss_gap_per_h, rl.gnss_gap_min_s, rl.gnss_gap_max_s)
    nofix = w(rng_w, t0, t1, rl.gnss_nofix_per_h, rl.gnss_nofix_s, rl.gnss_nofix_s)
    if rl.gnss_nofix_start_s > 0:
        nofix = [(t0 - 1.0, t0 + rl.gnss_nofix_start_s), *nofix]
    flaps = w(rng_w, t0, t1, rl.gnss_flap_per_h, 30.0, 30.0)
    bursts = w(rng_w, t0, t1, rl.burst_per_h, rl.burst_s, rl.burst_s)
    baro_do = w(rng_w, t0, t1, rl.baro_dropout_per_h, rl.baro_dropout_s, rl.baro_dropout_s)
    events = list(sc.events)
    lat = sc.gnss_latency_s  # a dropout loses the fixes whose messages it would carry
    for rid in (0, 1) if sc.second_receiver else (0,):
        events += [Event("outage", a - lat, b - lat, rid) for a, b in dropouts]
        events += [Event("outage", a, b, rid) for a, b in gaps]
        events += [Event("downgrade", a, b, rid, {"mode": "none"}) for a, b in nofix]
    sc2 = dataclasses.replace(sc, events=tuple(events))
    return _RealismPlan(
        rl, sc2, rng_imu, rng_att, rng_gnss, rng_link, rng_baro, dropouts, gaps, nofix,
        flaps, bursts, baro_do, reboot,
    )  # fmt: skip


def _inside(t: FloatArray, wins: list[tuple[float, float]]) -> np.ndarray:
    m = np.zeros(len(t), bool)
    for a, b in wins:
        m |= (t >= a) & (t < b)
    return m


def _vibration_level(phase: np.ndarray, rl: rz.Realism, fixed_wing: bool) -> FloatArray:
    """0 parked (motor off), the ground fraction while rolling, 1 in flight."""
    lev = np.ones(len(phase))
    lev[np.isin(phase, list(_GROUND_PHASES))] = rl.vibration_ground_fraction
    lev[phase == "parked"] = 0.0
    return lev


def _attitude_realism(plan: _RealismPlan, n: int, rate_hz: float) -> FloatArray:
    """Trim tilt in a random direction + Gauss-Markov roll, pitch, yaw errors, rad (n, 3)."""
    rl, rng = plan.rl, plan.rng_att
    out = np.zeros((n, 3))
    d = rng.uniform(0.0, 2.0 * math.pi)
    trim = math.radians(rl.attitude_trim_deg)
    out[:, 0] += trim * math.cos(d)
    out[:, 1] += trim * math.sin(d)
    dt = 1.0 / rate_hz
    tilt = math.radians(rl.attitude_tilt_sigma_deg)
    out[:, :2] += gauss_markov_fast(rng, n, dt, tilt, rl.attitude_tau_s, 2)
    out[:, 2] += gauss_markov_fast(
        rng, n, dt, math.radians(rl.attitude_yaw_sigma_deg), rl.attitude_tau_s, 1
    )[:, 0]
    return out


@dataclass(slots=True)
class _GnssRealism:
    vel_bias_ned_mps: FloatArray
    garbage_ned_m: FloatArray
    garbage: np.ndarray
    acc_factor: FloatArray
    d_sats: FloatArray
    d_hdop: FloatArray
    flap_2d: np.ndarray

    def report(self, rep: ap.GnssReport, k: int) -> ap.GnssReport:
        if rep.fix_type < FixType.FIX_2D:
            return dataclasses.replace(rep, keep_coords=bool(self.garbage[k]))
        f = float(self.acc_factor[k])
        return dataclasses.replace(
            rep,
            fix_type=FixType.FIX_2D if self.flap_2d[k] else rep.fix_type,
            h_acc_m=rep.h_acc_m * f,
            v_acc_m=rep.v_acc_m * f,
            satellites=max(4, rep.satellites + round(float(self.d_sats[k]))),
            hdop=max(0.5, rep.hdop + float(self.d_hdop[k])),
        )


GARBAGE_SIGMA_M = 3000.0
"""Garbage coordinates during no-fix: a slowly wandering offset of this size per axis, m."""
GARBAGE_VERTICAL_FRACTION = 0.03
"""...and 3 % of that vertically (~90 m): log171's garbage passes a decoder's
altitude check."""


def _gnss_realism(plan: _RealismPlan, t_fix: FloatArray, specs: list[Any]) -> _GnssRealism:
    rl, rng = plan.rl, plan.rng_gnss
    n = len(t_fix)
    vb = gauss_markov(rng, t_fix, rl.gnss_vel_bias_mps, rl.gnss_vel_bias_tau_s, 3)
    vb[:, 2] = 0.0
    nofix = np.array([sp.fix_type < FixType.FIX_2D for sp in specs], bool).reshape(n)
    garbage = nofix & rl.gnss_garbage
    gar = gauss_markov(rng, t_fix, GARBAGE_SIGMA_M, 60.0, 3) * garbage[:, None]
    gar[:, 2] *= GARBAGE_VERTICAL_FRACTION
    fac = np.exp(gauss_markov(rng, t_fix, rl.gnss_acc_log_sigma, 120.0, 1)[:, 0])
    ds = gauss_markov(rng, t_fix, rl.gnss_sats_sigma, 60.0, 1)[:, 0]
    dh = gauss_markov(rng, t_fix, rl.gnss_hdop_sigma, 60.0, 1)[:, 0]
    flap = np.zeros(n, bool)
    for a, b in plan.flaps:
        inside = (t_fix >= a) & (t_fix < b)
        flap |= inside & (np.floor((t_fix - a) / 2.0) % 2 == 0)
    return _GnssRealism(vb, gar, garbage, fac, ds, dh, flap)


def _baro(
    plan: _RealismPlan, path: Path, frame: LocalFrame, t: FloatArray, t0: float, fixed_wing: bool
) -> tuple[FloatArray, FloatArray]:
    """SCALED_PRESSURE, hPa, and its error without the noise (drift + ground effect)."""
    rl, rng = plan.rl, plan.rng_baro
    st = path.evaluate(t)
    _, _, alt = _lla(frame, st.pos_ned_m)
    p_isa = 1013.25 * (1.0 - 2.25577e-5 * alt) ** 5.25588
    sign = 1.0 if rng.uniform() < 0.5 else -1.0
    bias = sign * rl.baro_drift_hpa_per_h * (t - t0) / 3600.0
    running = _vibration_level(path.phase_at(t), rl, fixed_wing) > 0
    near = (alt - frame.alt0_m) < 2.0
    bias = bias + rl.baro_ground_effect_hpa * (running & near)
    return p_isa + bias + rng.standard_normal(len(t)) * rl.baro_noise_hpa, bias


def _shift_boot(msg: Any, off_s: float) -> None:
    """Rebase a message's boot-clock fields by -off_s (UNIX-epoch stamps are left alone)."""
    if hasattr(msg, "time_boot_ms"):
        msg.time_boot_ms = max(0, msg.time_boot_ms - round(off_s * 1e3))
    if hasattr(msg, "time_usec") and msg.time_usec < 1e15:
        msg.time_usec = max(0, msg.time_usec - round(off_s * 1e6))
    if hasattr(msg, "time_last_baseline_ms"):
        msg.time_last_baseline_ms = max(0, msg.time_last_baseline_ms - round(off_s * 1e3))


def _deliver(
    plan: _RealismPlan,
    makers: list[Any],
    emit: FloatArray,
    sid: np.ndarray,
    idx: np.ndarray,
    t_rx: FloatArray,
) -> tuple[list[tuple[float, object]], list[Sample]]:
    """The link: dropouts, bursts, out-of-order and repeated messages, the reboot."""
    rl, rng = plan.rl, plan.rng_link
    epoch0 = plan.scenario.epoch0_s
    keep = ~_inside(emit, plan.dropouts)
    emit, sid, idx, t_rx = emit[keep], sid[keep], idx[keep], t_rx[keep].copy()
    for a, b in plan.bursts:
        m = (emit >= a) & (emit < b)
        t_rx[m] = np.maximum(t_rx[m], np.rint((epoch0 + b + TRANSPORT_LATENCY_S) * 1e6) / 1e6)
    t_rx = np.maximum.accumulate(t_rx)
    n = len(emit)
    perm = np.arange(n)
    if rl.reorder_fraction > 0 and n > 2:
        for sw in np.flatnonzero(rng.uniform(size=n - 1) < rl.reorder_fraction):
            perm[sw], perm[sw + 1] = perm[sw + 1], perm[sw]
    dup = rng.uniform(size=n) < rl.duplicate_fraction if rl.duplicate_fraction > 0 else None
    messages: list[tuple[float, object]] = []
    samples: list[Sample] = []
    last_known: float | None = None
    rebooted = False
    reboot = plan.reboot_t_s
    for k in range(n):
        q = int(perm[k])
        j, i, t_r = int(sid[q]), int(idx[q]), float(t_rx[k])
        off = 0.0
        if reboot is not None and emit[q] >= reboot:
            off = reboot
            if not rebooted:
                rebooted, last_known = True, 0.0
        for _ in range(2 if dup is not None and dup[k] else 1):
            t_this = t_r
            msg, smp, t_est = makers[j](i, t_this, last_known)
            if off:
                _shift_boot(msg, off)
                if t_est is not None:
                    t_est -= off
                    if smp is not None:
                        smp = dataclasses.replace(smp, t_s=smp.t_s - off)  # type: ignore[type-var]
            messages.append((t_this, msg))
            if smp is not None:
                samples.append(smp)
            if t_est is not None and (last_known is None or t_est > last_known):
                last_known = t_est
    return messages, samples

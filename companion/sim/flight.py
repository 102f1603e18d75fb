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

import numpy as np

from companion.nav.frames import LocalFrame
from companion.nav.grades import ATTITUDE_ERROR_BY_GRADE, IMU_GRADES
from companion.sim import autopilot as ap
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
    vel_err_ned_mps: FloatArray


@dataclass(frozen=True, slots=True)
class SimErrors:
    """The errors the simulator injected (for tests of estimators against their truth)."""

    imu: ImuErrors
    attitude_err_rad: FloatArray
    """ATTITUDE minus truth (roll, pitch, yaw) at the attitude times, incl. heading error."""
    attitude_t_s: FloatArray
    gnss: tuple[GnssTruthErrors, ...]


@dataclass(frozen=True, slots=True)
class SimFlight:
    """A simulated flight: truth, typed samples and MAVLink messages."""

    scenario: Scenario
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
    noise = sc.noise
    fixed_wing = sc.profile == "fixed_wing"
    ardupilot = sc.flavour.value == "ardupilot"

    # ---------------------------------------------------------------- truth on the IMU grid
    unit = 1e3 if sc.imu_message == "SCALED_IMU2" else 1e6
    t_imu = _grid(t0, t1, sc.imu_rate_hz, unit)
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
    streams = [ap.imu_stream(sc.imu_message, t_imu, acc_m, gyro_m, st.mat_nb, alt)]

    # ---------------------------------------------------------------- attitude
    t_att = _grid(t0, t1, sc.attitude_rate_hz, 1e3, offset_s=0.004)
    sa = path.evaluate(t_att)
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
    euler_ap = sa.euler_rad + att_err
    euler_ap[:, 2] = (euler_ap[:, 2] + np.pi) % (2 * np.pi) - np.pi
    streams.append(ap.attitude_stream(not ardupilot, t_att, euler_ap, sa.gyro_b_radps + rate_err))

    # ---------------------------------------------------------------- GNSS
    gnss_truth = []
    receivers = (0, 1) if sc.second_receiver else (0,)
    for rid, rng in zip(receivers, (rng_g0, rng_g1), strict=False):
        stream_list, gt = _gnss_streams(sc, path, frame, rid, rng, t0, t1, ardupilot)
        streams.extend(stream_list)
        gnss_truth.append(gt)

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
    sg = path.evaluate(t_gp)
    pos_ap = sg.pos_ned_m.copy()
    if noise:
        for k in range(3):
            pos_ap[:, k] += gauss_markov_fast(
                rng_ap, len(t_gp), 0.1, AUTOPILOT_POS_SIGMA_M[k], AUTOPILOT_POS_TAU_S, 1
            )[:, 0]
    la, lo, al = _lla(frame, pos_ap)
    yaw_gp = sg.euler_rad[:, 2] + math.radians(sc.heading_error_deg)
    streams.append(ap.global_position_stream(t_gp, la, lo, al, sc.alt0_m, sg.vel_ned_mps, yaw_gp))

    # ---------------------------------------------------------------- merge in receive order
    emit = np.concatenate([s.emit_s for s in streams])
    sid = np.concatenate([np.full(len(s.emit_s), j) for j, s in enumerate(streams)])
    idx = np.concatenate([np.arange(len(s.emit_s)) for s in streams])
    order = np.lexsort((idx, sid, emit))
    t_rx = _rx_times(emit[order], sc.epoch0_s, rng_rx)
    messages: list[tuple[float, object]] = []
    samples: list[Sample] = []
    last_known: float | None = None
    makers = [s.make for s in streams]
    for t_r, j, i in zip(t_rx.tolist(), sid[order].tolist(), idx[order].tolist(), strict=True):
        msg, smp, t_est = makers[j](i, t_r, last_known)
        messages.append((t_r, msg))
        if smp is not None:
            samples.append(smp)
        if t_est is not None and (last_known is None or t_est > last_known):
            last_known = t_est

    phases = _phase_runs(path, t0, t1)
    logger.info(
        "simulated %s seed %d: %.0f s, %d messages, %d samples",
        sc.name, seed, duration, len(messages), len(samples),
    )  # fmt: skip
    return SimFlight(
        sc, int(seed), frame, truth, sc.events, samples, messages,
        SimErrors(ierr, att_err, t_att, tuple(gnss_truth)), phases,
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
    pos_rep = sg.pos_ned_m + pos_err + fault
    vel_rep = sg.vel_ned_mps + vel_err
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
            )
        )  # fmt: skip
    label = np.array([s.label for s in states])
    return streams, GnssTruthErrors(rid, t_fix, label, pos_err, fault, vel_err)

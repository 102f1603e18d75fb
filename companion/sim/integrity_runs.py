"""A simulated flight's typed samples through the integrity monitor, without the engine.

:func:`run_samples` gives the monitor the GNSS pass-through navigator's
solutions; :func:`run_samples_ins` the GNSS/INS blend's, with the coasting
inertial references (:class:`companion.integrity.coast.InertialCoast`) at every
fix. Both follow the engine's receiver policy (the navigator fuses the primary:
the lowest-numbered receiver not excluded and heard within the last second;
every fix goes to the monitor), for the tests and ``bench/integrity.py``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from companion.integrity.coast import CoastConfig, InertialCoast
from companion.integrity.monitor import IntegrityMonitor
from companion.nav import earth
from companion.nav.baro import BaroHeight
from companion.nav.blend import BlendConfig, BlendNavigator
from companion.nav.frames import LocalFrame
from companion.nav.gnss import gnss_measurement
from companion.nav.navigator import GnssMeasurement, GnssUpdate, Navigator, NavState
from companion.nav.passthrough import PassthroughConfig, PassthroughNavigator
from companion.types import (
    Alert,
    AlertCode,
    AttitudeSample,
    BaroSample,
    FixType,
    GnssFix,
    ImuSample,
    LandedState,
    LandedStateSample,
    NavMode,
    NavSolution,
    Sample,
)


def is_alarm(alert: Alert) -> bool:
    """A FAULT alert, or an INTEGRITY alert that announces a loss (not a restoration)."""
    if alert.code is AlertCode.FAULT:
        return True
    return alert.code is AlertCode.INTEGRITY and alert.text.startswith("lost")


def _offer(
    nav: Navigator, monitor: IntegrityMonitor, meas: GnssMeasurement, last_t: dict[int, float]
) -> GnssUpdate | None:
    """The engine's receiver policy: the fix goes to the navigator only from the primary,
    the lowest-numbered receiver not excluded and heard within the last second."""
    rid = meas.receiver_id
    last_t[rid] = meas.t_s
    primary = min(
        (r for r in last_t if not monitor.exclude(r) and meas.t_s - last_t[r] < 1.0),
        default=None,
    )
    return nav.on_gnss(meas, gate=nav.initialised) if rid == primary else None


def _solution(state: NavState, frame: LocalFrame, fix: GnssFix) -> NavSolution:
    """The navigator's state published as the engine would in normal mode."""
    lat, lon, alt = frame.ned_to_lla(state.pos_ned_m)
    return NavSolution(
        t_s=state.t_s,
        lat_rad=lat,
        lon_rad=lon,
        alt_msl_m=alt,
        vel_ned_mps=state.vel_ned_mps,
        pos_cov_ned_m2=state.pos_cov_ned_m2,
        vel_cov_ned_m2ps2=state.vel_cov_ned_m2ps2,
        yaw_rad=None,
        mode=NavMode.NORMAL,
        fix_type=fix.fix_type,
        satellites=fix.satellites or 0,
    )


@dataclass(frozen=True, slots=True)
class SampleRunResult:
    """Alarms of :func:`run_samples`: (t_s, code, text) of every FAULT / INTEGRITY-lost alert,
    every alert, and the monitor after the run."""

    alarms: tuple[tuple[float, str, str], ...]
    alerts: tuple[Alert, ...]
    monitor: IntegrityMonitor


def run_samples(
    samples: Sequence[Sample], monitor: IntegrityMonitor, publish_rate_hz: float = 10.0
) -> SampleRunResult:
    """Drive the monitor with a simulated flight's typed samples, without the engine.

    The navigator is the GNSS pass-through (:class:`PassthroughNavigator`) fed with the
    first receiver not excluded (the primary); every fix goes to the monitor; a
    solution is published at ``publish_rate_hz`` on the fix clock with the autopilot's
    landed state as the phase hint. This is the monitor's own path through a flight,
    for tests and the bench; the engine wires the same calls.
    """
    nav = PassthroughNavigator(PassthroughConfig())
    frame: LocalFrame | None = None
    landed: LandedState | None = None
    alerts: list[Alert] = []
    tick = -1
    last_t: dict[int, float] = {}
    monitor.reset()
    for sample in samples:
        if isinstance(sample, LandedStateSample):
            landed = sample.landed_state
            continue
        if not isinstance(sample, GnssFix) or int(sample.fix_type) < int(FixType.FIX_3D):
            continue
        if frame is None:
            frame = LocalFrame(sample.lat_rad, sample.lon_rad, sample.alt_msl_m)
        meas = gnss_measurement(sample, frame)
        update = _offer(nav, monitor, meas, last_t)
        outs = monitor.on_fix(sample, meas, update)
        k = math.floor(sample.t_s * publish_rate_hz + 1e-6)
        if k > tick and nav.initialised:
            tick = k
            state = nav.predict(sample.t_s)
            if state is not None:
                outs += monitor.on_solution(_solution(state, frame, sample), landed)
        alerts += [o for o in outs if isinstance(o, Alert)]
    alarms = tuple((a.t_s, a.code.value, a.text) for a in alerts if is_alarm(a))
    return SampleRunResult(alarms, tuple(alerts), monitor)


@dataclass(frozen=True, slots=True)
class InsRunResult:
    """Alarms of :func:`run_samples_ins` (as :class:`SampleRunResult`), the exclusions seen
    (receiver id -> first time it was excluded), and the monitor and coast after the run."""

    alarms: tuple[tuple[float, str, str], ...]
    alerts: tuple[Alert, ...]
    excluded_first_s: dict[int, float]
    monitor: IntegrityMonitor
    coast: InertialCoast


def run_samples_ins(
    samples: Sequence[Sample],
    monitor: IntegrityMonitor,
    blend_config: BlendConfig,
    coast_config: CoastConfig,
    publish_rate_hz: float = 10.0,
    use_bias_estimate: bool = True,
    use_coast: bool = True,
    use_baro: bool = False,
) -> InsRunResult:
    """Drive the GNSS/INS blend, the inertial coast and the monitor with a flight's samples.

    The engine's rules, without the engine: the blend fuses the first receiver not
    excluded (the primary); every fix goes to the monitor with the coast's references
    at the fix time; a slot is re-anchored from the blend's state at its newest IMU
    time (and its accelerometer-bias estimate and covariance when
    ``use_bias_estimate``) when due, but not while the monitor reports a fault; a
    solution is published at ``publish_rate_hz`` on the fix clock. ``use_coast``
    False gives the same run without references (the baseline). ``use_baro``: the
    flight's barometer samples (:class:`BaroSample`) calibrated against the fused fixes
    while no fault is reported and given to the monitor at every fix, as the engine does.
    """
    frame: LocalFrame | None = None
    nav: BlendNavigator | None = None
    coast: InertialCoast | None = None
    pending: list[Sample] = []
    landed: LandedState | None = None
    alerts: list[Alert] = []
    excluded: dict[int, float] = {}
    tick = -1
    last_t: dict[int, float] = {}
    baro = BaroHeight(stats=monitor.stats)
    monitor.reset()
    for sample in samples:
        if isinstance(sample, LandedStateSample):
            landed = sample.landed_state
            continue
        if isinstance(sample, BaroSample):
            if use_baro:
                baro.on_sample(sample)
            continue
        if frame is None:
            if isinstance(sample, GnssFix) and int(sample.fix_type) >= int(FixType.FIX_3D):
                frame = LocalFrame(sample.lat_rad, sample.lon_rad, sample.alt_msl_m)
                nav = BlendNavigator(blend_config, frame)
                coast = InertialCoast(
                    coast_config, earth.gravity_ned_mps2(frame.lat0_rad, frame.alt0_m)
                )
                for old in pending:  # the last history_s of IMU and attitude
                    _feed_ins(old, nav, coast)
            elif isinstance(sample, ImuSample | AttitudeSample):
                pending.append(sample)
                while pending[0].t_s < sample.t_s - blend_config.history_s:
                    pending.pop(0)
                continue
            else:
                continue
        if nav is None or coast is None or frame is None:
            continue
        if isinstance(sample, ImuSample | AttitudeSample):
            _feed_ins(sample, nav, coast)
            if (
                isinstance(sample, ImuSample)
                and nav.initialised
                and not monitor.fault_detected
                and coast.anchor_due(nav.imu_t_s)
            ):
                state = nav.predict(nav.imu_t_s)
                if state is not None:
                    if use_bias_estimate:
                        cov = nav.covariance
                        coast.anchor(state, nav.biases[0], cov[9:12, 9:12])
                    else:
                        coast.anchor(state)
            continue
        if not isinstance(sample, GnssFix) or int(sample.fix_type) < int(FixType.FIX_3D):
            continue
        meas = gnss_measurement(sample, frame)
        update = _offer(nav, monitor, meas, last_t)
        refs = coast.references(sample.t_s) if use_coast else None
        ref_baro = None
        if use_baro and landed is not LandedState.ON_GROUND:
            ref_baro = baro.reference(sample.t_s, monitor.config.pair_max_dt_s)
        outs = monitor.on_fix(sample, meas, update, references=refs, baro=ref_baro)
        if use_baro and update is not None and update.fused and not monitor.fault_detected:
            baro.calibrate(sample.t_s, sample.alt_msl_m, float(meas.pos_var_ned_m2[2]))
        for r in list(last_t):
            if monitor.exclude(r) and r not in excluded:
                excluded[r] = sample.t_s
        k = math.floor(sample.t_s * publish_rate_hz + 1e-6)
        if k > tick and nav.initialised:
            tick = k
            state = nav.predict(max(sample.t_s, nav.imu_t_s))
            if state is not None:
                outs += monitor.on_solution(_solution(state, frame, sample), landed)
        alerts += [o for o in outs if isinstance(o, Alert)]
    if coast is None:
        coast = InertialCoast(coast_config, earth.gravity_ned_mps2(0.0, 0.0))
    alarms = tuple((a.t_s, a.code.value, a.text) for a in alerts if is_alarm(a))
    return InsRunResult(alarms, tuple(alerts), excluded, monitor, coast)


def _feed_ins(sample: Sample, nav: BlendNavigator, coast: InertialCoast) -> None:
    if isinstance(sample, ImuSample):
        nav.on_imu(sample)
        coast.on_imu(sample)
    elif isinstance(sample, AttitudeSample):
        nav.on_attitude(sample, 0.0)
        coast.on_attitude(sample)

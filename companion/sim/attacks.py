"""A receiver that lies or cannot hear: spoofing drags, meaconing and jamming as GNSS events.

Three event kinds (:class:`~companion.sim.scenarios.Event`), each on one receiver and on
the autopilot clock, active for ``t_start_s <= t < t_end_s``:

``drag``
    A spoofer that tracks the vehicle drags the receiver off: with ``tau = t - t_start_s``
    the reported position moves off the truth by ``d(tau)`` along ``direction_ned`` and the
    reported velocity by ``s(tau) = min(a tau, v_max)`` (``accel_mps2``, ``max_speed_mps``),
    ``d`` the integral of ``s``: position and velocity lie together, as a spoofer makes
    them. At ``t_end_s`` the spoofer lets go: the true signals win again and the offset
    drops to zero at the next fix (a window past the flight's end never lets go).
``meaconing``
    A delayed replay of the true signal: the receiver reports the position and velocity
    of ``t - delay``, ``delay = delay_s + delay_rate * tau``, and its clock solution is
    late by the same delay (what the autopilot stamps from the receiver's time shows it:
    :func:`on_receiver`). At ``t_end_s`` it reacquires the true signals.
``jamming``
    The signals drown: over ``degrade_s`` the satellites drop to ``min_satellites`` and the
    DOPs, the reported accuracies and the errors themselves grow to ``acc_factor`` times
    (geometrically: C/N0 falling); then no fix (fix type 1) until ``t_end_s``; then
    ``recover_s`` of recovery back to the nominal figures (after the window).

``flagged`` (bool): the receiver's own detector sees it (u-blox NAV-STATUS
``spoofDetState``, MON-RF ``jammingState``): spoofing flagged over a drag's or
meaconing's window (default off: a spoofer that tracks the vehicle passes most
receivers' checks), jamming from half-way through the degradation to ``t_end_s``
(default on). What the autopilot relays of these flags: GNSS_INTEGRITY
(:func:`companion.sim.autopilot.gnss_integrity_stream`, ``Scenario.gnss_integrity_relay``).

None of it draws a random number: a flight with an attack is the flight without it,
seed for seed, plus the attack (the tests rely on it). The autopilot's ATTITUDE,
IMU and GLOBAL_POSITION_INT are not affected: the spoofer reaches only the receiver.

References
----------
Tanil, Khanafseh, Joerger and Pervan (2018), "An INS monitor to detect GNSS spoofers
capable of tracking vehicle position" (the spoofer that tracks the vehicle; constant
acceleration drags). u-blox M8/F9 interface descriptions (NAV-STATUS spoofDetState,
MON-RF jammingState). MAVLink development.xml GNSS_INTEGRITY (GPS_JAMMING_STATE,
GPS_SPOOFING_STATE). ArduPilot libraries/AP_GPS/AP_GPS.cpp ``time_epoch_usec`` (the
GPS_RAW_INT stamp is the receiver's time) and libraries/AP_RTC/AP_RTC.cpp (the
SYSTEM_TIME clock never steps back).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from companion.types import FixType, FloatArray

if TYPE_CHECKING:
    from companion.sim.autopilot import GnssReport
    from companion.sim.scenarios import Event, Scenario
    from companion.sim.trajectory import Path

ATTACK_KINDS = ("drag", "meaconing", "jamming")
DEFAULTS: dict[str, dict[str, Any]] = {
    "drag": {"accel_mps2": 0.5, "max_speed_mps": 5.0, "direction_ned": (1.0, 0.0, 0.0),
             "flagged": False},
    "meaconing": {"delay_s": 1.0, "delay_rate": 0.0, "flagged": False},
    "jamming": {"degrade_s": 20.0, "recover_s": 10.0, "acc_factor": 8.0, "min_satellites": 5,
                "flagged": True},
}  # fmt: skip
"""Each kind's parameters and their defaults (an event's ``params`` override them)."""

MAV_JAMMING = {False: 1, True: 3}
"""Receiver flag -> GPS_JAMMING_STATE (1 NOT_JAMMED, 3 DETECTED)."""
MAV_SPOOFING = {False: 1, True: 3}
"""Receiver flag -> GPS_SPOOFING_STATE (1 NOT_SPOOFED, 3 DETECTED)."""


def param(ev: Event, key: str) -> Any:
    """An attack event's parameter, or its default."""
    return ev.params.get(key, DEFAULTS[ev.kind][key])


def check_params(kind: str, window_s: float, params: Mapping[str, Any]) -> None:
    """Raise ValueError (one line) on an attack event's unknown or out-of-range parameter."""
    unknown = set(params) - set(DEFAULTS[kind])
    if unknown:
        raise ValueError(f"{kind} event: unknown params {', '.join(sorted(unknown))}")
    p = {**DEFAULTS[kind], **params}

    def num(key: str, lo: float, hi: float, lo_open: bool = False) -> float:
        v = p[key]
        ok = isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
        if not ok or not (v > lo if lo_open else v >= lo) or v > hi:
            bracket = "(" if lo_open else "["
            raise ValueError(f"{kind} event: {key} must be in {bracket}{lo}, {hi}], got {v!r}")
        return float(v)

    if not isinstance(p["flagged"], bool):
        raise ValueError(f"{kind} event: flagged must be true or false")
    if kind == "drag":
        num("accel_mps2", 0.0, 50.0, lo_open=True)
        num("max_speed_mps", 0.0, 300.0, lo_open=True)
        d = p["direction_ned"]
        finite = isinstance(d, Sequence) and len(d) == 3
        finite = finite and all(isinstance(x, int | float) and math.isfinite(x) for x in d)
        if not (finite and math.hypot(*d) > 0.0):
            raise ValueError(
                f"drag event: direction_ned must be 3 finite numbers, not all 0: {d!r}"
            )
    elif kind == "meaconing":
        num("delay_s", 0.0, 600.0)
        num("delay_rate", 0.0, 0.99)
    else:
        num("degrade_s", 0.0, window_s)
        num("recover_s", 0.0, 3600.0)
        num("acc_factor", 1.0, 1000.0)
        n = p["min_satellites"]
        if not isinstance(n, int) or isinstance(n, bool) or not 4 <= n <= 30:
            raise ValueError(
                f"jamming event: min_satellites must be an integer in [4, 30], got {n!r}"
            )


# --------------------------------------------------------------------------- the three kinds


def drag_offsets(ev: Event, t_s: FloatArray) -> tuple[FloatArray, FloatArray]:
    """A drag's (position m, velocity m/s) offsets NED at times ``t_s`` (N,), each (N, 3).

    ``s(tau) = min(a tau, v_max)``; ``d(tau) = a tau^2 / 2`` up to ``tau_a = v_max / a``,
    then ``a tau_a^2 / 2 + v_max (tau - tau_a)``: d is the integral of s.
    """
    a, v_max = float(param(ev, "accel_mps2")), float(param(ev, "max_speed_mps"))
    u = np.asarray(param(ev, "direction_ned"), dtype=float)
    u = u / np.linalg.norm(u)
    t = np.asarray(t_s, dtype=float)
    on = (t >= ev.t_start_s) & (t < ev.t_end_s)
    tau = np.where(on, t - ev.t_start_s, 0.0)
    tau_a = v_max / a
    speed = np.minimum(a * tau, v_max)
    dist = np.where(tau <= tau_a, 0.5 * a * tau**2, 0.5 * v_max * tau_a + v_max * (tau - tau_a))
    return dist[:, None] * u[None, :], speed[:, None] * u[None, :]


def meaconing_delay_s(ev: Event, t_s: FloatArray) -> FloatArray:
    """The replay's delay at times ``t_s`` (0 outside the window), s."""
    t = np.asarray(t_s, dtype=float)
    on = (t >= ev.t_start_s) & (t < ev.t_end_s)
    d0, rate = float(param(ev, "delay_s")), float(param(ev, "delay_rate"))
    return np.where(on, d0 + rate * (t - ev.t_start_s), 0.0)


def jamming_lost(ev: Event, t_s: float) -> bool:
    """True while a jamming event has taken the fix (after its degradation, in its window)."""
    return ev.t_start_s + float(param(ev, "degrade_s")) <= t_s < ev.t_end_s


def jamming_progress(ev: Event, t_s: FloatArray) -> FloatArray:
    """0 (nominal) .. 1 (fully degraded): rising over ``degrade_s``, 1 while the fix is lost,
    falling over ``recover_s`` after the window."""
    t = np.asarray(t_s, dtype=float)
    deg, rec = float(param(ev, "degrade_s")), float(param(ev, "recover_s"))
    rise = np.clip((t - ev.t_start_s) / deg, 0.0, 1.0) if deg > 0 else np.ones_like(t)
    fall = np.clip(1.0 - (t - ev.t_end_s) / rec, 0.0, 1.0) if rec > 0 else np.zeros_like(t)
    return np.where(t < ev.t_start_s, 0.0, np.where(t < ev.t_end_s, rise, fall))


def flags(sc: Scenario, receiver_id: int, t_s: FloatArray) -> tuple[np.ndarray, np.ndarray]:
    """The receiver's own (jamming, spoofing) detector flags at times ``t_s``, bool (N,) each."""
    t = np.asarray(t_s, dtype=float)
    jam = np.zeros(len(t), bool)
    spoof = np.zeros(len(t), bool)
    for ev in sc.events:
        if ev.receiver_id != receiver_id or ev.kind not in ATTACK_KINDS or not param(ev, "flagged"):
            continue
        if ev.kind == "jamming":
            half = ev.t_start_s + 0.5 * float(param(ev, "degrade_s"))
            jam |= (t >= half) & (t < ev.t_end_s)
        else:
            spoof |= (t >= ev.t_start_s) & (t < ev.t_end_s)
    return jam, spoof


# --------------------------------------------------------------------------- one receiver


@dataclass(frozen=True, slots=True)
class ReceiverAttacks:
    """What the attacks do to one receiver's fixes (arrays over its fix times, N).

    ``pos_off_ned_m``/``vel_off_ned_mps``: reported minus true (drags; meaconing's
    ``truth(t - delay) - truth(t)``), before the receiver's own noise; ``delay_s``: the
    meaconing delay (the receiver's clock is late by it); ``acc_factor``: jamming's growth
    of DOPs, accuracies and errors; ``sat_drop``: 0..1 of the way from the mode's satellite
    count to ``min_satellites``; ``min_satellites``: per fix."""

    pos_off_ned_m: FloatArray
    vel_off_ned_mps: FloatArray
    delay_s: FloatArray
    acc_factor: FloatArray
    sat_drop: FloatArray
    min_satellites: np.ndarray

    def report(self, rep: GnssReport, k: int) -> GnssReport:
        """Fix ``k``'s report as the attacked receiver gives it (accuracies, DOPs, satellites,
        its clock)."""
        f, drop = float(self.acc_factor[k]), float(self.sat_drop[k])
        sats = rep.satellites
        if drop > 0.0 and sats > self.min_satellites[k]:
            sats = round(sats - (sats - int(self.min_satellites[k])) * drop)
        if rep.fix_type < FixType.FIX_2D:
            return dataclasses.replace(rep, clock_offset_s=-float(self.delay_s[k]))
        return dataclasses.replace(
            rep,
            h_acc_m=rep.h_acc_m * f,
            v_acc_m=rep.v_acc_m * f,
            vel_acc_mps=rep.vel_acc_mps * f,
            hdop=rep.hdop * f,
            vdop=rep.vdop * f,
            satellites=sats,
            clock_offset_s=-float(self.delay_s[k]),
        )


def on_receiver(
    sc: Scenario, receiver_id: int, t_fix_s: FloatArray, path: Path
) -> ReceiverAttacks | None:
    """The attacks on a receiver at its fix times; None when it has none (nothing changes).

    Meaconing evaluates the path at ``t - delay`` (not before the path's start).
    """
    events = [e for e in sc.events if e.receiver_id == receiver_id and e.kind in ATTACK_KINDS]
    if not events:
        return None
    t = np.asarray(t_fix_s, dtype=float)
    n = len(t)
    pos = np.zeros((n, 3))
    vel = np.zeros((n, 3))
    delay = np.zeros(n)
    progress = np.zeros(n)
    factor = np.ones(n)
    min_sats = np.full(n, 4, dtype=int)
    for ev in events:
        if ev.kind == "drag":
            p, v = drag_offsets(ev, t)
            pos += p
            vel += v
        elif ev.kind == "meaconing":
            delay += meaconing_delay_s(ev, t)
        else:
            prog = jamming_progress(ev, t)
            factor *= float(param(ev, "acc_factor")) ** prog
            progress = np.maximum(progress, prog)
            min_sats = np.where(prog > 0, int(param(ev, "min_satellites")), min_sats)
    if np.any(delay > 0.0):
        late = delay > 0.0
        now = path.evaluate(t[late])
        then = path.evaluate(np.maximum(t[late] - delay[late], path.t_start_s))
        pos[late] += then.pos_ned_m - now.pos_ned_m
        vel[late] += then.vel_ned_mps - now.vel_ned_mps
    return ReceiverAttacks(pos, vel, delay, factor, progress, min_sats)


def event_drag(
    t_start_s: float,
    duration_s: float,
    accel_mps2: float,
    direction_ned: Sequence[float],
    max_speed_mps: float = 5.0,
    receiver_id: int = 0,
    flagged: bool = False,
) -> Event:
    """A drag event (the spoofer lets go at ``t_start_s + duration_s``)."""
    from companion.sim.scenarios import Event

    params = {
        "accel_mps2": float(accel_mps2),
        "max_speed_mps": float(max_speed_mps),
        "direction_ned": tuple(float(x) for x in direction_ned),
        "flagged": flagged,
    }
    return Event("drag", t_start_s, t_start_s + duration_s, receiver_id, params)


def horizontal_direction(rng: np.random.Generator) -> tuple[float, float, float]:
    """A horizontal unit direction NED with a uniform azimuth (one draw from ``rng``)."""
    az = float(rng.uniform(0.0, 2.0 * math.pi))
    return (math.cos(az), math.sin(az), 0.0)

"""What the console knows, from the messages it hears: a pure model, no terminal, no socket.

:class:`ConsoleModel` takes every MAVLink message heard on the link with its
receive time (``take``) and keeps: the age of the last message from the service
(component 191) and from the autopilot (component 1); the published solution,
fix and accuracies; the navigation mode derived from them; the protection levels
against the approach categories' alert limits; the outage timer; the heading
correction; the alert history with autopilot time; the last minutes of accuracy
and protection levels and of the track; the service's parameters and the
answers to commands; and, with a ground station's position, the tracking
channel of "Tracking with the aircraft's kinematic and dynamic parameters"
(:mod:`companion.nav.tracking`) fed by the positions and by the autopilot's
ATTITUDE and SCALED_IMU/HIGHRES_IMU. :meth:`ConsoleModel.snapshot` is what the
widgets draw and ``--json`` prints; :meth:`ConsoleModel.render` is the text
screen of ``--once``.
"""

from __future__ import annotations

import enum
import math
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from companion.integrity.protection.limits import ApproachCategory, FlightPhase, alert_limit
from companion.mavlink.ids import MAV_COMP_ID_ONBOARD_COMPUTER
from companion.mavlink.params import param_name
from companion.mavlink.readback import (
    PublishedFix,
    PublishedHeartbeat,
    PublishedPosition,
    PublishedText,
    parse_alert,
    read_message,
)
from companion.nav import earth
from companion.nav.frames import LocalFrame
from companion.nav.heading import HeadingStatus
from companion.nav.rotations import euler_to_mat_nb
from companion.types import NamedValue, Severity

STALE_S = 2.5
"""A link silent this long is STALE: its values are no longer current (drawn every 0.5 s,
so STALE shows within 3 s of the last message)."""
HISTORY_S = 300.0
"""Seconds of accuracy / protection-level history kept for the plots."""
ALERTS_KEPT = 1000
TRACK_KEPT = 3000
AUTOPILOT_COMPONENT = 1
MAV_STATE_CRITICAL = 5
GRAVITY_MG = 9.80665 / 1000.0
"""SCALED_IMU's accelerations are in mG."""
PLOTTED = ("CMP_HACC", "CMP_VACC", "CMP_HPL", "CMP_VPL")

SEVERITY_NAMES: dict[int, str] = {
    Severity.EMERGENCY: "EMERG",
    Severity.ALERT: "ALERT",
    Severity.CRITICAL: "CRIT",
    Severity.ERROR: "ERROR",
    Severity.WARNING: "WARN",
    Severity.NOTICE: "NOTICE",
    Severity.INFO: "INFO",
    Severity.DEBUG: "DEBUG",
}
FIX_NAMES = ("no GPS", "no fix", "2D", "3D", "DGPS", "RTK float", "RTK fixed", "static", "PPP")
MAV_RESULTS = {
    0: "ACCEPTED",
    1: "TEMPORARILY_REJECTED",
    2: "DENIED",
    3: "UNSUPPORTED",
    4: "FAILED",
    5: "IN_PROGRESS",
    6: "CANCELLED",
}


class NavMode(enum.Enum):
    """The navigation's mode as the console reads it from what is published."""

    WAITING = "waiting"
    NORMAL = "normal"
    DEGRADED = "degraded"
    BRIDGING = "bridging"
    LOST = "lost"


@dataclass(slots=True)
class Alert:
    """One STATUSTEXT of the service: receive time, autopilot time, severity, text."""

    t_rx_s: float
    t_boot_s: float | None
    severity: int
    text: str
    acked: bool = False

    @property
    def severity_name(self) -> str:
        return SEVERITY_NAMES.get(self.severity, "?")


@dataclass(slots=True)
class ParamEntry:
    """A parameter of the service as its last PARAM_VALUE said."""

    name: str
    value: float
    param_type: int
    index: int
    t_rx_s: float


@dataclass(slots=True)
class Ack:
    """A COMMAND_ACK from the service."""

    t_rx_s: float
    command: int
    result: int

    @property
    def result_name(self) -> str:
        return MAV_RESULTS.get(self.result, str(self.result))


@dataclass(slots=True)
class ConsoleModel:
    """Everything the console shows, updated message by message (see the module doc)."""

    station: LocalFrame | None = None
    lat_deg: float | None = None
    lon_deg: float | None = None
    alt_msl_m: float | None = None
    speed_mps: float | None = None
    hdg_deg: float | None = None
    fix_type: int | None = None
    h_acc_m: float | None = None
    v_acc_m: float | None = None
    system_status: int | None = None
    integrity_lost: bool = False
    values: dict[str, float] = field(default_factory=dict)
    alerts: deque[Alert] = field(default_factory=lambda: deque(maxlen=ALERTS_KEPT))
    history: dict[str, deque[tuple[float, float]]] = field(
        default_factory=lambda: {name: deque() for name in PLOTTED}
    )
    track: deque[tuple[float, float]] = field(default_factory=lambda: deque(maxlen=TRACK_KEPT))
    params: dict[str, ParamEntry] = field(default_factory=dict)
    param_count: int | None = None
    acks: deque[Ack] = field(default_factory=lambda: deque(maxlen=50))
    heartbeats: int = 0
    messages: int = 0
    service_system: int | None = None
    last_rx_s: float | None = None
    last_autopilot_rx_s: float | None = None
    t_boot_s: float | None = None
    """Autopilot time of the newest time-stamped message, s; at receive time ``t_boot_rx_s``."""
    t_boot_rx_s: float | None = None
    _attitude: tuple[float, float, float, float] | None = None
    tracker: Any = None
    aircraft_system: int | None = None
    """System id of the autopilot heard (component 1): the aircraft an antenna follows."""
    aircraft_type: int | None = None
    """Its HEARTBEAT's MAV_TYPE."""

    def __post_init__(self) -> None:
        if self.station is not None and self.tracker is None:
            from companion.nav.tracking import Tracker

            self.tracker = Tracker("dynamic")

    # ------------------------------------------------------------------ input
    def take(self, msg: Any, t_rx_s: float) -> bool:
        """Update from one message heard at ``t_rx_s``; True if it was the service's."""
        comp = msg.get_srcComponent()
        if comp == MAV_COMP_ID_ONBOARD_COMPUTER:
            self._take_service(msg, t_rx_s)
            return True
        if comp == AUTOPILOT_COMPONENT and msg.get_type() != "BAD_DATA":
            self.last_autopilot_rx_s = t_rx_s
            self.aircraft_system = msg.get_srcSystem()
            self._take_autopilot(msg, t_rx_s)
        return False

    def _clock(self, t_boot_s: float, t_rx_s: float) -> None:
        if self.t_boot_s is None or t_boot_s >= self.t_boot_s:
            self.t_boot_s = t_boot_s
            self.t_boot_rx_s = t_rx_s

    def _take_service(self, msg: Any, t_rx_s: float) -> None:
        self.messages += 1
        self.last_rx_s = t_rx_s
        self.service_system = msg.get_srcSystem()
        kind = msg.get_type()
        if kind == "COMMAND_ACK":
            self.acks.append(Ack(t_rx_s, int(msg.command), int(msg.result)))
            return
        if kind == "PARAM_VALUE":
            name = param_name(msg.param_id)
            self.params[name] = ParamEntry(
                name, float(msg.param_value), int(msg.param_type), int(msg.param_index), t_rx_s
            )
            self.param_count = int(msg.param_count)
            return
        item = read_message(msg)
        if isinstance(item, PublishedPosition):
            self._clock(item.t_s, t_rx_s)
            self.lat_deg = math.degrees(item.lat_rad)
            self.lon_deg = math.degrees(item.lon_rad)
            self.alt_msl_m = item.alt_msl_m
            self.speed_mps = math.hypot(item.vel_ned_mps[0], item.vel_ned_mps[1])
            self.hdg_deg = None if item.yaw_rad is None else math.degrees(item.yaw_rad)
            if not self.track or self.track[-1] != (self.lat_deg, self.lon_deg):
                self.track.append((self.lat_deg, self.lon_deg))
            self._track_position(item.t_s, item.lat_rad, item.lon_rad, item.alt_msl_m)
        elif isinstance(item, PublishedFix):
            self.fix_type = item.fix_type
            self.h_acc_m, self.v_acc_m = item.h_acc_m, item.v_acc_m
        elif isinstance(item, NamedValue):
            self._clock(item.t_s, t_rx_s)
            self.values[item.name] = item.value
            if item.name in self.history:
                hist = self.history[item.name]
                hist.append((item.t_s, item.value))
                while hist and hist[0][0] < item.t_s - HISTORY_S:
                    hist.popleft()
        elif isinstance(item, PublishedText):
            self.alerts.append(Alert(t_rx_s, self.boot_time(t_rx_s), item.severity, item.text))
            parsed = parse_alert(item.text)
            if parsed is not None and parsed[0] == "INTEGRITY":
                self.integrity_lost = not parsed[1].startswith("restored")
        elif isinstance(item, PublishedHeartbeat):
            self.heartbeats += 1
            self.system_status = item.system_status

    def _take_autopilot(self, msg: Any, t_rx_s: float) -> None:
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            self.aircraft_type = int(msg.type)
        elif kind == "ATTITUDE":
            t = msg.time_boot_ms / 1000.0
            self._attitude = (t, float(msg.roll), float(msg.pitch), float(msg.yaw))
        elif kind in ("SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3"):
            f_b = np.array([msg.xacc, msg.yacc, msg.zacc], dtype=float) * GRAVITY_MG
            self._track_dynamics(msg.time_boot_ms / 1000.0, f_b)
        elif kind == "RAW_IMU":  # ArduPilot sends it in mG, stamped in µs since boot
            f_b = np.array([msg.xacc, msg.yacc, msg.zacc], dtype=float) * GRAVITY_MG
            self._track_dynamics(msg.time_usec / 1e6, f_b)
        elif kind == "HIGHRES_IMU":
            f_b = np.array([msg.xacc, msg.yacc, msg.zacc], dtype=float)
            self._track_dynamics(msg.time_usec / 1e6, f_b)

    # --------------------------------------------------------------- tracking
    def _track_time(self, t_s: float) -> float | None:
        """Samples a little out of order (IMU vs position) join at the filter's time."""
        trk = self.tracker
        if trk.t_s is not None and t_s < trk.t_s:
            return trk.t_s if trk.t_s - t_s < 0.2 else None
        return t_s

    def _track_position(self, t_s: float, lat_rad: float, lon_rad: float, alt_m: float) -> None:
        if self.tracker is None or self.station is None:
            return
        t = self._track_time(t_s)
        if t is not None:
            # the published 1σ accuracies are the position's noise, when they are known
            sigma = None
            if self.h_acc_m is not None and self.v_acc_m is not None:
                sigma = np.array([self.h_acc_m, self.h_acc_m, self.v_acc_m])
            self.tracker.position(t, self.station.lla_to_ned(lat_rad, lon_rad, alt_m), sigma)

    def _track_dynamics(self, t_s: float, f_b_mps2: np.ndarray) -> None:
        from companion.nav.tracking import acceleration_ned

        if self.tracker is None or self._attitude is None or not self.tracker.started:
            return
        t_att, roll, pitch, yaw = self._attitude
        if abs(t_att - t_s) > 0.2 or not np.all(np.isfinite(f_b_mps2)):
            return
        t = self._track_time(t_s)
        if t is None or self.lat_deg is None or self.alt_msl_m is None:
            return
        g = earth.gravity_mps2(math.radians(self.lat_deg), self.alt_msl_m)
        # the aircraft's NED and the station's differ by the Earth's curvature between
        # them: well under a degree within tracking range, neglected here
        mat_nb = euler_to_mat_nb(roll, pitch, yaw)
        self.tracker.acceleration(t, acceleration_ned(mat_nb, f_b_mps2, g), mat_nb)

    # ----------------------------------------------------------------- output
    def boot_time(self, now_s: float) -> float | None:
        """Autopilot time now, from the newest time-stamped message and the wall clock."""
        if self.t_boot_s is None or self.t_boot_rx_s is None:
            return None
        return self.t_boot_s + max(now_s - self.t_boot_rx_s, 0.0)

    def service_age(self, now_s: float) -> float | None:
        return None if self.last_rx_s is None else now_s - self.last_rx_s

    def autopilot_age(self, now_s: float) -> float | None:
        return None if self.last_autopilot_rx_s is None else now_s - self.last_autopilot_rx_s

    def service_stale(self, now_s: float) -> bool:
        age = self.service_age(now_s)
        return age is None or age >= STALE_S

    def autopilot_stale(self, now_s: float) -> bool:
        age = self.autopilot_age(now_s)
        return age is None or age >= STALE_S

    def mode(self, now_s: float) -> NavMode:
        """normal / degraded / bridging / lost, as published (WAITING before the first fix)."""
        if self.lat_deg is None:
            return NavMode.WAITING
        if self.system_status == MAV_STATE_CRITICAL:
            return NavMode.LOST
        if self.values.get("CMP_OUTG", 0.0) > 0.0:
            return NavMode.BRIDGING
        if self.integrity_lost or (self.fix_type is not None and self.fix_type < 3):
            return NavMode.DEGRADED
        return NavMode.NORMAL

    def heading_state(self) -> str:
        """``CMP_HDGS`` by name, ``—`` before the first."""
        code = self.values.get("CMP_HDGS")
        if code is None:
            return "—"
        try:
            return HeadingStatus(int(code)).name.lower()
        except ValueError:
            return f"state {code:g}"

    def unacked(self) -> int:
        return sum(1 for a in self.alerts if not a.acked and a.severity <= Severity.WARNING)

    def acknowledge(self) -> int:
        """Mark every alert acknowledged; returns how many were not."""
        n = 0
        for a in self.alerts:
            n += not a.acked
            a.acked = True
        return n

    def track_estimate(self, now_s: float) -> Any:
        """The tracking channel's estimate now (None without a station or before a fix)."""
        if self.tracker is None:
            return None
        t = self.boot_time(now_s)
        return None if t is None else self.tracker.estimate(t)

    def snapshot(self, now_s: float) -> dict[str, Any]:
        """What the panels show (and ``--json`` prints), plain types only."""
        v = self.values
        hpl, vpl = v.get("CMP_HPL"), v.get("CMP_VPL")
        limits = {
            cat.name: {"hal_m": lim.hal_m, "val_m": lim.val_m}
            for cat in (ApproachCategory.CAT_I, ApproachCategory.CAT_II, ApproachCategory.CAT_III)
            for lim in [alert_limit(FlightPhase.APPROACH, cat)]
        }
        est = self.track_estimate(now_s)
        track = None
        if est is not None:
            track = {
                "az_deg": math.degrees(est.az_rad) % 360.0,
                "el_deg": math.degrees(est.el_rad),
                "range_m": est.range_m,
                "az_rate_dps": math.degrees(est.az_rate_radps),
                "el_rate_dps": math.degrees(est.el_rate_radps),
                "range_rate_mps": est.range_rate_mps,
                "pointing_sigma_deg": math.degrees(est.pointing_sigma_rad),
                "range_sigma_m": est.range_sigma_m,
                "predicted_s": est.since_position_s,
            }
        age_s, ap_age_s = self.service_age(now_s), self.autopilot_age(now_s)
        return {
            "link": {
                "service_age_s": age_s,
                "service_stale": self.service_stale(now_s),
                "autopilot_age_s": ap_age_s,
                "autopilot_stale": self.autopilot_stale(now_s),
                "messages": self.messages,
                "heartbeats": self.heartbeats,
            },
            "navigation": {
                "mode": self.mode(now_s).value,
                "lat_deg": self.lat_deg,
                "lon_deg": self.lon_deg,
                "alt_msl_m": self.alt_msl_m,
                "speed_mps": self.speed_mps,
                "heading_deg": self.hdg_deg,
                "fix": None if self.fix_type is None else _fix_name(self.fix_type),
                "h_acc_m": v.get("CMP_HACC", self.h_acc_m),
                "v_acc_m": v.get("CMP_VACC", self.v_acc_m),
            },
            "integrity": {
                "hpl_m": hpl,
                "vpl_m": vpl,
                "category": v.get("CMP_CAT"),
                "category_name": _cat_name(v.get("CMP_CAT")),
                "lost": self.integrity_lost,
                "limits": limits,
            },
            "outage_s": v.get("CMP_OUTG"),
            "heading": {
                "state": self.heading_state(),
                "correction_deg": v.get("CMP_HDGC"),
                "uncertainty95_deg": v.get("CMP_HDGE"),
                "cycles": _cycles(self.alerts),
            },
            "alerts": [
                {
                    "t_boot_s": a.t_boot_s,
                    "severity": a.severity_name,
                    "text": a.text,
                    "acked": a.acked,
                }
                for a in list(self.alerts)[-20:]
            ],
            "last_ack": None
            if not self.acks
            else {"command": self.acks[-1].command, "result": self.acks[-1].result_name},
            "track": track,
        }

    def render(self, now_s: float) -> str:
        """The status screen as text (``--once``)."""
        s = self.snapshot(now_s)
        nav, integ, hdg, link = s["navigation"], s["integrity"], s["heading"], s["link"]
        head = "companion console"
        if self.last_rx_s is None:
            head += "  (waiting for the service)"
        elif link["service_stale"]:
            head += f"  STALE: service silent for {link['service_age_s']:.0f} s"
        lines = [head, f"mode      {nav['mode']}", ""]
        if self.lat_deg is None:
            lines.append("no solution published yet")
        else:
            lines.append(
                f"position  {self.lat_deg:11.7f} {self.lon_deg:12.7f}  "
                f"alt {self.alt_msl_m:8.1f} m MSL"
            )
            hdg_txt = "—" if self.hdg_deg is None else f"{self.hdg_deg:6.1f}°"
            lines.append(f"speed     {self.speed_mps:6.1f} m/s   heading {hdg_txt}")
        lines.append(
            f"fix       {nav['fix'] or '—':<10} accuracy H {_f(nav['h_acc_m'])} "
            f"V {_f(nav['v_acc_m'])} m (1σ)"
        )
        lines.append(
            f"outage    {_f(s['outage_s'])} s   protection HPL {_f(integ['hpl_m'])} "
            f"VPL {_f(integ['vpl_m'])} m   category {integ['category_name']}"
        )
        lines.append(
            f"heading   correction {_f(hdg['correction_deg'])}° ± "
            f"{_f(hdg['uncertainty95_deg'])}°   {hdg['state']}"
        )
        if s["track"] is not None:
            t = s["track"]
            lines.append(
                f"track     az {t['az_deg']:6.2f}° el {t['el_deg']:5.2f}° "
                f"range {t['range_m']:8.1f} m  ±{t['pointing_sigma_deg']:.2f}°"
            )
        lines += ["", "alerts:"]
        if not self.alerts:
            lines.append("  (none)")
        for a in list(self.alerts)[-8:][::-1]:
            lines.append(f"  {boot_text(a.t_boot_s)} {a.severity_name:<6} {a.text}")
        return "\n".join(lines)


def _fix_name(fix_type: int) -> str:
    return FIX_NAMES[fix_type] if 0 <= fix_type < len(FIX_NAMES) else f"type {fix_type}"


def _cat_name(value: float | None) -> str:
    if value is None:
        return "—"
    try:
        cat = ApproachCategory(int(value))
    except ValueError:
        return f"{value:g}"
    return "none" if cat is ApproachCategory.NONE else cat.name.replace("_", " ")


def _cycles(alerts: deque[Alert]) -> int | None:
    """Cycles of the heading correction, from the newest ``HDG_READY ... n=<cycles>``."""
    for a in reversed(alerts):
        parsed = parse_alert(a.text)
        if parsed and parsed[0] in ("HDG_READY", "HDG_UNDONE", "HDG_RESTORED"):
            for word in parsed[1].split():
                if word.startswith("n="):
                    try:
                        return int(word[2:])
                    except ValueError:
                        return None
    return None


def _f(value: float | None, fmt: str = ".2f") -> str:
    return "—" if value is None else format(value, fmt)


def boot_text(t_boot_s: float | None) -> str:
    """Autopilot time as ``T+mm:ss.s`` (since boot)."""
    if t_boot_s is None:
        return "T+--:--.-"
    m, s = divmod(t_boot_s, 60.0)
    return f"T+{int(m):02d}:{s:04.1f}"


def wall_clock() -> float:
    """The receive clock (the only place the model's users read time)."""
    return time.time()

"""Scenarios: what to fly, which sensors, which scheduled events; the named catalogue.

A :class:`Scenario` is a frozen description; :func:`build_script` turns it into
the phase script (:class:`~companion.sim.trajectory.ScriptBuilder`), whose
segment times :func:`make_scenario` uses to place each named scenario's events
(e.g. "an RTK outage 40 s into the glide").

Event kinds (``Event.kind``), all on the autopilot clock ``t_s``:

``outage``       no GNSS messages from the receiver in the window
``rtk_outage``   corrections lost: RTK fixed held ``extrap_s`` (receiver extrapolates),
                 then RTK float for ``float_s``, then ``fallback`` ("3d" or "dgps");
                 after the window RTK float for ``refix_s``, then fixed again
``downgrade``    the fix is ``mode`` ("rtk_float", "dgps", "3d", "none") in the window
``stale``        the receiver repeats its last fix (position, velocity, fix type,
                 accuracies) with a fresh time stamp while the aircraft moves
``step``         ``offset_ned_m`` added to the reported position
``ramp``         ``rate_ned_mps * (t - t_start)`` added (e.g. 4 cm/s)
``dither``       ``amplitude_m * sin(2 pi (t - t_start) / period_s) * axis_ned``
                 added (e.g. 1 m)
``drag``         a spoofer drags position and velocity together (``accel_mps2`` up to
                 ``max_speed_mps`` along ``direction_ned``), lets go at the end
``meaconing``    the true signal replayed ``delay_s`` (+ ``delay_rate`` per s) late
``jamming``      satellites drop and accuracies grow over ``degrade_s``, then no fix,
                 then ``recover_s`` of recovery (:mod:`companion.sim.attacks`)

The catalogue's one-line descriptions are written into each flight's JSON
sidecar (and the committed fixtures'): they are output, their parenthesised
source tags included, and stay as they are; the sources are cited below.

References
----------
Grzegorzewski (2005), "Navigating by a position potential in 3-D" (stale fixes).
El-Mowafy (2005), RTK networks for precision approach with an adaptive GPS/INS
blend (RTK outages, accuracies). Kim, Walter and Powell, "Standalone GPS-based
flight inspection system" (ramp and dither faults: 4 cm/s, 1 m). Markelov et
al., "INS course correction from satellite navigation before take-off" (taxi
with a heading error, straight legs, GNSS speed noise). ``docs/replay.md``
(the fixtures).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from companion.nav.frames import LocalFrame
from companion.ranges import check_ranges, ranged
from companion.sim.attacks import ATTACK_KINDS, check_params
from companion.sim.realism import Realism, realistic
from companion.sim.trajectory import ScriptBuilder
from companion.types import AutopilotFlavour

PROFILES = ("fixed_wing", "rotorcraft")
FLIGHTS = ("full", "taxi", "approach", "cruise")
IMU_GRADES = ("tactical", "mems", "perfect")
IMU_MESSAGES = ("HIGHRES_IMU", "RAW_IMU", "SCALED_IMU2")
GNSS_MODES = ("rtk_fixed", "rtk_float", "dgps", "3d")
DOWNGRADE_MODES = ("rtk_fixed", "rtk_float", "dgps", "3d", "none")
EVENT_KINDS = (
    "outage", "rtk_outage", "downgrade", "stale", "step", "ramp", "dither", *ATTACK_KINDS,
)  # fmt: skip

_G0 = 9.80665


@dataclass(frozen=True, slots=True)
class Event:
    """A scheduled event on one receiver, active for ``t_start_s <= t < t_end_s``."""

    kind: str
    t_start_s: float
    t_end_s: float
    receiver_id: int = 0
    params: Mapping[str, Any] = field(default_factory=dict, hash=False)

    def __post_init__(self) -> None:
        if self.kind not in EVENT_KINDS:
            raise ValueError(f"unknown event kind {self.kind!r} (known: {', '.join(EVENT_KINDS)})")
        if not (math.isfinite(self.t_start_s) and math.isfinite(self.t_end_s)):
            raise ValueError(f"event {self.kind}: non-finite window")
        if not self.t_end_s > self.t_start_s:
            raise ValueError(f"event {self.kind}: t_end_s must exceed t_start_s")
        if self.receiver_id not in (0, 1):
            raise ValueError(f"event {self.kind}: receiver_id must be 0 or 1")
        if self.kind == "downgrade" and self.params.get("mode") not in DOWNGRADE_MODES:
            raise ValueError(f"downgrade event needs params mode in {DOWNGRADE_MODES}")
        if self.kind in ATTACK_KINDS:
            check_params(self.kind, self.t_end_s - self.t_start_s, self.params)
        object.__setattr__(self, "params", MappingProxyType(dict(self.params)))

    def active(self, t_s: float) -> bool:
        """True when ``t_s`` is inside the window."""
        return self.t_start_s <= t_s < self.t_end_s

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "kind": self.kind,
            "t_start_s": self.t_start_s,
            "t_end_s": self.t_end_s,
            "receiver_id": self.receiver_id,
            "params": {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.params.items()},
        }


@dataclass(frozen=True, slots=True)
class Scenario:
    """Everything that defines a simulated flight (SI units unless the name says deg)."""

    name: str
    profile: str = ranged("fixed_wing", choices=PROFILES)
    flight: str = ranged("full", choices=FLIGHTS)
    flavour: AutopilotFlavour = AutopilotFlavour.ARDUPILOT
    duration_s: float | None = ranged(None, gt=0.0, optional=True)
    """None: the script's natural length; shorter truncates, longer holds the last state."""
    imu_grade: str = ranged("mems", choices=IMU_GRADES)
    imu_message: str = ranged("RAW_IMU", choices=IMU_MESSAGES)
    imu_rate_hz: float = ranged(50.0, gt=0.0, le=1000.0)
    attitude_rate_hz: float = ranged(25.0, gt=0.0, le=400.0)
    gnss_rate_hz: float = ranged(10.0, gt=0.0, le=50.0)
    gnss_latency_s: float = ranged(0.08, ge=0.0, lt=1.0)
    gnss_mode: str = ranged("rtk_fixed", choices=GNSS_MODES)
    gnss_vel_noise_mps: float = ranged(0.05, ge=0.0, lt=10.0)
    heading_error_deg: float = ranged(0.0, ge=-180.0, le=180.0)
    crab_deg: float = ranged(0.0, gt=-45.0, lt=45.0)
    wind_ned_mps: tuple[float, float, float] = ranged((0.0, 0.0, 0.0), gt=-60.0, lt=60.0, length=3)
    second_receiver: bool = False
    noise: bool = True
    events: tuple[Event, ...] = ()
    # geometry
    lat0_deg: float = ranged(52.1650, gt=-85.0, lt=85.0)
    lon0_deg: float = 20.9670
    alt0_m: float = 110.0
    geoid_undulation_m: float = 33.5
    stand_heading_deg: float = 0.0
    parked_s: float = ranged(30.0, gt=0.0, le=3600.0)
    taxi_speed_mps: float = ranged(8.0, gt=0.0, le=30.0)
    taxi_legs: tuple[tuple[float, float], ...] = ((300.0, 90.0), (450.0, -90.0), (250.0, 45.0))
    """(straight length m, turn deg after it) pairs; positive turns to the right."""
    taxi_turn_rate_dps: float = ranged(8.0, gt=0.0, le=45.0)
    lineup_turn_deg: float = 90.0
    cruise_alt_m: float = ranged(300.0, gt=0.0, le=15000.0)
    """Height above the airfield, m."""
    cruise_speed_mps: float = ranged(40.0, gt=0.0, le=300.0)
    cruise_s: float = ranged(240.0, gt=0.0, le=36000.0)
    cruise_turns_deg: tuple[float, ...] = (180.0, -90.0, 180.0)
    bank_deg: float = ranged(20.0, gt=0.0, le=45.0)
    approach_speed_mps: float = ranged(33.0, gt=0.0, le=300.0)
    approach_alt_m: float = ranged(250.0, gt=0.0, le=5000.0)
    glide_deg: float = ranged(3.0, gt=0.0, le=10.0)
    # timing of the record
    t_boot0_s: float = ranged(10.0, gt=0.0, le=1e6)
    epoch0_s: float = 1_768_471_200.0
    """UNIX time of autopilot boot (2026-01-15 10:00 UTC): fixed, no clock is read."""
    truth_rate_hz: float = ranged(10.0, gt=0.0, le=1000.0)
    realism: Realism | None = None
    """The autopilot's imperfections (:mod:`companion.sim.realism`); None: none (left out
    of :meth:`as_dict`, so existing sidecars stay as they are)."""
    gnss_integrity_relay: bool = False
    """The autopilot relays receiver 0's own jamming/spoofing state in GNSS_INTEGRITY (as
    PX4 does; MAVLink's development dialect, which ardupilotmega readers do not know):
    off by default, and then left out of :meth:`as_dict`."""

    def __post_init__(self) -> None:
        def bad(msg: str) -> ValueError:
            return ValueError(f"scenario {self.name!r}: {msg}")

        try:
            check_ranges(self)
        except ValueError as exc:
            raise bad(str(exc)) from None
        if self.profile == "rotorcraft" and self.flight != "full":
            raise bad("the rotorcraft profile has only the 'full' flight")
        if (
            not isinstance(self.flavour, AutopilotFlavour)
            or self.flavour is AutopilotFlavour.UNKNOWN
        ):
            raise bad("flavour must be AutopilotFlavour.ARDUPILOT or PX4")
        for length, turn in self.taxi_legs:
            if not (length > 0.0 and abs(turn) <= 180.0):
                raise bad(f"taxi leg ({length}, {turn}) needs length > 0 and |turn| <= 180")
        if self.realism is not None and not isinstance(self.realism, Realism):
            raise bad("realism must be a Realism or None")
        if not isinstance(self.gnss_integrity_relay, bool):
            raise bad("gnss_integrity_relay must be true or false")
        for ev in self.events:
            if not isinstance(ev, Event):
                raise bad("events must be Event instances")
            if ev.receiver_id == 1 and not self.second_receiver:
                raise bad(f"event {ev.kind} on receiver 1 needs second_receiver=True")

    @property
    def frame(self) -> LocalFrame:
        """The local NED frame anchored at the stand / airfield reference (MSL height)."""
        return LocalFrame(math.radians(self.lat0_deg), math.radians(self.lon0_deg), self.alt0_m)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form (enums by value, events as dicts)."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if f.name == "realism":
                if v is None:
                    continue
                v = v.as_dict()
            elif f.name == "gnss_integrity_relay" and not v:
                continue
            elif f.name == "events":
                v = [e.as_dict() for e in v]
            elif isinstance(v, AutopilotFlavour):
                v = v.value
            elif isinstance(v, tuple):
                v = [list(x) if isinstance(x, tuple) else x for x in v]
            out[f.name] = v
        return out


# --------------------------------------------------------------------------- scripts


def _ramp_s(dv: float, a_max: float) -> float:
    """Duration of a smoothstep speed change of dv with peak acceleration a_max (S' max 2.1875)."""
    return max(2.0, 2.1875 * abs(dv) / a_max)


def _land(b: ScriptBuilder, sc: Scenario, fixed_wing: bool) -> None:
    """From level flight: glide at the path angle, flare, land, roll out, stop, park."""
    d2r = math.radians
    if fixed_wing:
        v_app = sc.approach_speed_mps
        vg = v_app * math.tan(d2r(sc.glide_deg))
        b.seg(_ramp_s(b.value["speed"] - v_app, 1.0), "descent", speed=v_app, pitch=d2r(3.0))
        entry_s, flare_s, td_s, v_td = 6.0, 6.0, 1.5, 0.3
        lost = 0.5 * vg * entry_s + 0.5 * (vg + v_td) * flare_s + 0.5 * v_td * td_s
        hold = (b.height_m - lost) / vg
        if hold <= 0.0:
            raise ValueError(f"scenario {sc.name!r}: too low to fly the glide path")
        b.seg(entry_s, "descent", vd=vg, pitch=d2r(1.0))
        b.seg(hold, "descent")
        b.seg(flare_s, "flare", vd=v_td, pitch=d2r(5.0), speed=v_app - 3.0)
        b.seg(td_s, "landing_roll", vd=0.0, air=0.0, pitch=d2r(3.0))
        b.seg(3.0, "landing_roll", pitch=0.0)
        v_now = b.value["speed"]
        b.seg(_ramp_s(v_now - sc.taxi_speed_mps, 2.0), "landing_roll", speed=sc.taxi_speed_mps)
        b.seg(_ramp_s(sc.taxi_speed_mps, 1.0), "landing_roll", speed=0.0)
    else:
        v_dn = 1.0
        entry_s, td_s = 3.0, 3.0
        lost = 0.5 * v_dn * entry_s + 0.5 * v_dn * td_s
        hold = (b.height_m - lost) / v_dn
        if hold <= 0.0:
            raise ValueError(f"scenario {sc.name!r}: too low to descend")
        b.seg(entry_s, "descent", vd=v_dn)
        b.seg(hold, "descent")
        b.seg(td_s, "descent", vd=0.0, air=0.0)
    b.seg(10.0, "parked")


def _cruise(b: ScriptBuilder, sc: Scenario, speed: float) -> None:
    """Level cruise of ``cruise_s`` with coordinated turns spread between equal straights."""
    rate = _G0 * math.tan(math.radians(sc.bank_deg)) / speed
    ramp = 3.0
    turn_s = sum(max(abs(math.radians(a)) / rate, ramp) + ramp for a in sc.cruise_turns_deg)
    straight = (sc.cruise_s - turn_s) / (len(sc.cruise_turns_deg) + 1)
    if straight <= 0.0:
        raise ValueError(f"scenario {sc.name!r}: cruise_s too short for its turns")
    for a in sc.cruise_turns_deg:
        b.seg(straight, "cruise")
        b.turn(math.radians(a), rate, ramp, "cruise")
    b.seg(straight, "cruise")


def _taxi(b: ScriptBuilder, sc: Scenario) -> None:
    """Taxi legs (straights and turns at taxi speed), then line up and stop on the runway."""
    v = sc.taxi_speed_mps
    ramp = 2.0
    rate = min(math.radians(sc.taxi_turn_rate_dps), 0.8 / v)
    b.seg(_ramp_s(v, 0.6), "taxi", speed=v)
    for length, turn in sc.taxi_legs:
        b.seg(length / v, "taxi")
        b.turn(math.radians(turn), rate, ramp, "taxi")
    v_lu = min(3.0, v)
    b.seg(_ramp_s(v - v_lu, 0.8), "lineup", speed=v_lu)
    b.turn(math.radians(sc.lineup_turn_deg), min(0.25, 0.8 / v_lu), ramp, "lineup")
    b.seg(_ramp_s(v_lu, 0.8), "lineup", speed=0.0)
    b.seg(10.0, "lineup")


def build_script(sc: Scenario) -> ScriptBuilder:
    """The phase script of a scenario (no duration truncation/extension applied).

    Raises
    ------
    ValueError
        If the scenario's geometry cannot be flown (e.g. too low for the glide).
    """
    d2r = math.radians
    t0 = sc.t_boot0_s
    psi0 = d2r(sc.stand_heading_deg)
    crab = d2r(sc.crab_deg)
    if sc.profile == "rotorcraft":
        b = ScriptBuilder(t0, (0.0, 0.0, 0.0), psi0, crab=crab)
        b.seg(sc.parked_s, "parked")
        b.seg(4.0, "takeoff", air=1.0, vd=-1.5)
        climb_h = sc.cruise_alt_m - b.height_m - 0.5 * 1.5 * 3.0
        b.seg(max(climb_h / 1.5, 1.0), "takeoff")
        b.seg(3.0, "takeoff", vd=0.0)
        b.seg(10.0, "hover")
        b.turn(d2r(90.0), d2r(15.0), 2.0, "hover")
        b.seg(10.0, "transition", speed=sc.cruise_speed_mps, pitch=d2r(-6.0))
        _cruise(b, sc, sc.cruise_speed_mps)
        b.seg(10.0, "transition", speed=0.0, pitch=0.0)
        b.seg(10.0, "hover")
        _land(b, sc, fixed_wing=False)
        return b
    if sc.flight in ("full", "taxi"):
        b = ScriptBuilder(t0, (0.0, 0.0, 0.0), psi0, crab=crab)
        b.seg(sc.parked_s, "parked")
        _taxi(b, sc)
        if sc.flight == "taxi":
            return b
        v_r = 0.75 * sc.cruise_speed_mps
        b.seg(_ramp_s(v_r, 2.5), "takeoff_roll", speed=v_r)
        b.seg(3.0, "rotation", pitch=d2r(8.0), crab=0.0, speed=v_r + 1.0)
        b.seg(4.0, "climb", air=1.0, vd=-3.0, pitch=d2r(10.0), speed=v_r + 3.0)
        v_c = -4.0
        b.seg(5.0, "climb", vd=v_c, speed=sc.cruise_speed_mps)
        level_s = 8.0
        climb_h = sc.cruise_alt_m - b.height_m - 0.5 * (-v_c) * level_s
        if climb_h <= 0.0:
            raise ValueError(f"scenario {sc.name!r}: cruise_alt_m too low")
        b.seg(climb_h / -v_c, "climb")
        b.seg(level_s, "climb", vd=0.0, pitch=d2r(2.0))
        _cruise(b, sc, sc.cruise_speed_mps)
        _land(b, sc, fixed_wing=True)
        return b
    if sc.flight == "approach":
        b = ScriptBuilder(
            t0,
            (0.0, 0.0, -sc.approach_alt_m),
            psi0,
            speed=sc.approach_speed_mps,
            pitch=d2r(3.0),
            air=1.0,
        )
        b.seg(20.0, "cruise")
        _land(b, sc, fixed_wing=True)
        return b
    # cruise only
    b = ScriptBuilder(
        t0,
        (0.0, 0.0, -sc.cruise_alt_m),
        psi0,
        speed=sc.cruise_speed_mps,
        pitch=d2r(2.0),
        air=1.0,
    )
    _cruise(b, sc, sc.cruise_speed_mps)
    return b


def phase_window(b: ScriptBuilder, phase: str) -> tuple[float, float]:
    """First start and last end time of a phase in a script, s."""
    segs = [s for s in b.segments if s.phase == phase]
    if not segs:
        raise ValueError(f"phase {phase!r} not in the script")
    return segs[0].t0_s, segs[-1].t1_s


def natural_duration_s(sc: Scenario) -> float:
    """Length of the scenario's script, s."""
    b = build_script(sc)
    return b.t_s - sc.t_boot0_s


# --------------------------------------------------------------------------- catalogue

EventFactory = Callable[[ScriptBuilder], tuple[Event, ...]]


def _no_events(b: ScriptBuilder) -> tuple[Event, ...]:
    return ()


def _rtk_outage(length_s: float) -> EventFactory:
    def make(b: ScriptBuilder) -> tuple[Event, ...]:
        t0, _ = phase_window(b, "descent")
        return (
            Event(
                "rtk_outage",
                t0 + 40.0,
                t0 + 40.0 + length_s,
                params={"extrap_s": 3.0, "float_s": 5.0, "fallback": "3d", "refix_s": 8.0},
            ),
        )

    return make


def _gnss_loss(b: ScriptBuilder) -> tuple[Event, ...]:
    t0, t1 = phase_window(b, "cruise")
    mid = 0.5 * (t0 + t1)
    return (Event("outage", mid - 30.0, mid + 30.0),)


def _stale(b: ScriptBuilder) -> tuple[Event, ...]:
    c0, _ = phase_window(b, "cruise")
    d0, _ = phase_window(b, "descent")
    return (Event("stale", c0 + 5.0, c0 + 15.0), Event("stale", d0 + 60.0, d0 + 75.0))


def _ramp(b: ScriptBuilder) -> tuple[Event, ...]:
    d0, _ = phase_window(b, "descent")
    return (Event("ramp", d0 + 30.0, d0 + 90.0, params={"rate_ned_mps": (0.0, 0.0, 0.04)}),)


def _dither(b: ScriptBuilder) -> tuple[Event, ...]:
    d0, _ = phase_window(b, "descent")
    return (
        Event(
            "dither",
            d0 + 30.0,
            d0 + 90.0,
            params={"amplitude_m": 1.0, "period_s": 20.0, "axis_ned": (0.0, 0.0, 1.0)},
        ),
    )


def _px4(b: ScriptBuilder) -> tuple[Event, ...]:
    c0, _ = phase_window(b, "cruise")
    return (Event("downgrade", c0 + 20.0, c0 + 40.0, params={"mode": "3d"}),)


def _downgrade(b: ScriptBuilder) -> tuple[Event, ...]:
    d0, _ = phase_window(b, "descent")
    t = d0 + 30.0
    return (
        Event("downgrade", t, t + 10.0, params={"mode": "rtk_float"}),
        Event("downgrade", t + 10.0, t + 20.0, params={"mode": "3d"}),
        Event("downgrade", t + 20.0, t + 30.0, params={"mode": "none"}),
    )


_TACTICAL = {"imu_grade": "tactical", "imu_message": "HIGHRES_IMU", "imu_rate_hz": 100.0}
_APPROACH = {"flight": "approach", **_TACTICAL}

_CATALOGUE: dict[str, tuple[dict[str, Any], EventFactory, str]] = {
    "taxi": (
        {
            "flight": "taxi",
            **_TACTICAL,
            "imu_rate_hz": 50.0,
            "heading_error_deg": 1.0,
            "gnss_vel_noise_mps": 0.1,
        },
        _no_events,
        "parked 30 s, taxi legs with turns at 8 m/s, line-up; "
        "ATTITUDE yaw off by 1 deg (Markelov et al.)",
    ),
    "approach": (
        dict(_APPROACH),
        _no_events,
        "3 deg approach from 250 m, flare, landing roll; RTK fixed throughout",
    ),
    "approach_rtk20": (
        dict(_APPROACH),
        _rtk_outage(20.0),
        "3 deg approach with a 20 s RTK correction outage in the glide (El-Mowafy 2005)",
    ),
    "approach_rtk40": (
        dict(_APPROACH),
        _rtk_outage(40.0),
        "3 deg approach with a 40 s RTK correction outage in the glide (El-Mowafy 2005)",
    ),
    "cruise_gnss_loss": (
        {"flight": "cruise", "gnss_mode": "dgps", "cruise_s": 300.0},
        _gnss_loss,
        "cruise with coordinated turns, 60 s with no GNSS at all, MEMS IMU",
    ),
    "stale_fix": (
        {
            "flight": "approach",
            "gnss_mode": "dgps",
            "imu_message": "SCALED_IMU2",
            "approach_alt_m": 400.0,
        },
        _stale,
        "DGPS descent from 400 m; the receiver repeats its last fix for 10 s level, "
        "15 s on the descent (Grzegorzewski 2005)",
    ),
    "ramp_fault": (
        {**_APPROACH, "imu_rate_hz": 50.0, "second_receiver": True},
        _ramp,
        "approach, receiver 0 position ramps down 4 cm/s for 60 s; "
        "second receiver clean (Kim, Walter and Powell)",
    ),
    "dither_fault": (
        {**_APPROACH, "imu_rate_hz": 50.0, "second_receiver": True},
        _dither,
        "approach, receiver 0 height dithers 1 m (20 s period) for 60 s; "
        "second receiver clean (Kim, Walter and Powell)",
    ),
    "px4_rotorcraft": (
        {
            "profile": "rotorcraft",
            "flavour": AutopilotFlavour.PX4,
            **_TACTICAL,
            "imu_rate_hz": 50.0,
            "attitude_rate_hz": 50.0,
            "gnss_rate_hz": 5.0,
            "cruise_speed_mps": 12.0,
            "cruise_alt_m": 40.0,
            "cruise_s": 150.0,
            "bank_deg": 15.0,
            "parked_s": 20.0,
        },
        _px4,
        "PX4 multirotor: take-off, hover turn, forward flight with turns, landing; 20 s of 3D fix",
    ),
    "downgrade": (
        dict(_APPROACH),
        _downgrade,
        "approach with the fix stepping RTK fixed -> float -> 3D -> none, 10 s each",
    ),
    "nominal": (
        {"flight": "full", "cruise_s": 300.0},
        _no_events,
        "complete flight > 10 min: stand, taxi, take-off, climb, cruise with turns, "
        "3 deg approach, landing; MEMS IMU, RTK fixed, no events",
    ),
}


def _realistic_variant(
    name: str, vehicle: str, label: str, extra: dict[str, Any]
) -> tuple[dict[str, Any], EventFactory, str]:
    """A catalogued flight as a realistic autopilot of ``vehicle`` delivers it (its GNSS
    mode kept: the realism is the autopilot's, the receiver's mode is the scenario's)."""
    base, factory, desc = _CATALOGUE[name]
    over = {k: v for k, v in realistic(vehicle).items() if k != "gnss_mode"}
    return {**base, **over, **extra}, factory, f"{desc}; as a realistic {label} delivers it"


_REALISTIC_VARIANTS: dict[str, tuple[Any, ...]] = {
    "taxi_realistic": ("taxi", "plane", "ArduPlane (RAW_IMU 10 Hz)"),
    "approach_rtk20_realistic": ("approach_rtk20", "plane", "ArduPlane (RAW_IMU 10 Hz)"),
    "cruise_gnss_loss_realistic": ("cruise_gnss_loss", "plane", "ArduPlane (RAW_IMU 10 Hz)"),
    "nominal_realistic": ("nominal", "plane", "ArduPlane (RAW_IMU 10 Hz)"),
    "copter_realistic": ("px4_rotorcraft", "copter", "ArduCopter on a serial port (50 Hz)"),
    "copter_radio_realistic": (
        "px4_rotorcraft", "copter_radio", "ArduCopter through a telemetry radio (~1 Hz)",
    ),
    "px4_rotorcraft_realistic": (
        "px4_rotorcraft", "px4", "PX4 (HIGHRES_IMU 250 Hz; the first 150 s)",
        {"duration_s": 150.0},
    ),
}  # fmt: skip
"""Realistic variants of the bundled flights (companion.sim.realism's profiles)."""
for _name, (_base, _vehicle, _label, *_extra) in _REALISTIC_VARIANTS.items():
    _CATALOGUE[_name] = _realistic_variant(_base, _vehicle, _label, *(_extra or [{}]))

BARO_REALISM = {"baro_rate_hz": 10.0, "baro_noise_hpa": 0.025, "baro_drift_hpa_per_h": 1.0,
                "baro_ground_effect_hpa": 0.1}  # fmt: skip
"""A barometer as the realistic simulator makes one: the radio copter's noise, drift and
ground effect (measured on its logs, docs/simulator.md) at 10 Hz."""


def spoofing_cruise() -> dict[str, Any]:
    """The flight the spoofing scenarios attack: level cruise at 300 m with turns, as a
    realistic ArduPlane with a barometer delivers it, one standalone receiver (3D fix)."""
    plane = realistic("plane")
    rl = dataclasses.replace(plane["realism"], **BARO_REALISM)
    return {**plane, "flight": "cruise", "cruise_s": 300.0, "realism": rl}


def _in_cruise(kind: str, length_s: float, params: dict[str, Any]) -> EventFactory:
    def make(b: ScriptBuilder) -> tuple[Event, ...]:
        c0, _ = phase_window(b, "cruise")
        return (Event(kind, c0 + 120.0, c0 + 120.0 + length_s, params=params),)

    return make


_ATTACKED = "cruise with turns as a realistic ArduPlane with a barometer delivers it, 3D fix"
_CATALOGUE["cruise_spoof_drag"] = (
    spoofing_cruise(),
    _in_cruise("drag", 120.0, {"accel_mps2": 0.5, "direction_ned": (0.5, 0.866, 0.0)}),
    f"{_ATTACKED}; 120 s in, a spoofer drags receiver 0 at 0.5 m/s^2 up to 5 m/s toward "
    "060 deg for 120 s, then lets go (Tanil et al. 2018)",
)
_CATALOGUE["cruise_meaconing"] = (
    spoofing_cruise(),
    _in_cruise("meaconing", 120.0, {"delay_s": 1.0, "delay_rate": 0.02}),
    f"{_ATTACKED}; 120 s in, receiver 0 hears the true signal replayed 1 s late, the delay "
    "growing 0.02 s per s, for 120 s",
)
_CATALOGUE["cruise_jamming"] = (
    spoofing_cruise(),
    _in_cruise("jamming", 50.0, {"degrade_s": 20.0, "recover_s": 10.0}),
    f"{_ATTACKED}; 120 s in, receiver 0 is jammed: 20 s of satellites dropping and "
    "accuracies growing 8 times, 30 s without a fix, 10 s of recovery",
)

SCENARIO_NAMES: tuple[str, ...] = tuple(_CATALOGUE)
"""The named scenarios :func:`make_scenario` knows."""


def describe(name: str) -> str:
    """One-line description of a named scenario."""
    if name not in _CATALOGUE:
        raise ValueError(f"unknown scenario {name!r} (known: {', '.join(SCENARIO_NAMES)})")
    return _CATALOGUE[name][2]


def make_scenario(name: str, **overrides: Any) -> Scenario:
    """A named scenario, with any :class:`Scenario` field overridden.

    Events are placed from the (possibly overridden) script unless ``events`` is
    given; ``duration_s`` defaults to the script's natural length.

    Raises
    ------
    ValueError
        Unknown name, unknown field, or a value out of range (one-line message).
    """
    if name not in _CATALOGUE:
        raise ValueError(f"unknown scenario {name!r} (known: {', '.join(SCENARIO_NAMES)})")
    base, factory, _ = _CATALOGUE[name]
    known = {f.name for f in dataclasses.fields(Scenario)}
    unknown = set(overrides) - known
    if unknown:
        raise ValueError(f"unknown scenario field(s): {', '.join(sorted(unknown))}")
    kw = {**base, **overrides}
    kw["name"] = name
    for key in ("wind_ned_mps", "cruise_turns_deg"):
        if key in kw:
            kw[key] = tuple(float(x) for x in kw[key])
    if "taxi_legs" in kw:
        kw["taxi_legs"] = tuple((float(a), float(b)) for a, b in kw["taxi_legs"])
    if "events" in kw:
        kw["events"] = tuple(kw["events"])
    try:
        sc = Scenario(**kw)
    except TypeError as exc:  # wrong value types reach here
        raise ValueError(f"scenario {name!r}: {exc}") from exc
    script = build_script(sc)
    if "events" not in overrides:
        sc = dataclasses.replace(sc, events=factory(script))
    if sc.duration_s is None:
        sc = dataclasses.replace(sc, duration_s=script.t_s - sc.t_boot0_s)
    return sc

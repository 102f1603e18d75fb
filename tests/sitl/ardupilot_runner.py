"""ArduPilot SITL scenarios with the service beside it. Run only inside ``private-net``
(``tests.sitl.harness.run_scenario`` does that); writes its result as JSON.

Scenarios:

* ``flight``: ArduPlane takes off on a mission circuit (a rectangle, 900 x 600 m, flown
  in a loop; ``--vehicle copter``: ArduCopter, a guided take-off to 25 m, then a
  200 x 120 m rectangle), cruises with a healthy GPS for ``--cruise-s``, then (``--outage-s`` > 0)
  loses GPS 1 (``SIM_GPS1_ENABLE = 0``) for that long and flies ``--after-s`` more.
  ``--hover-s``: the copter first hovers where its take-off ended (scored as ``hover``);
  ``--outage-at-corner``: the GPS is cut when the mission next turns to a new corner.
  Scored from SITL's DataFlash log: the service's and the autopilot's (POS, EKF3)
  horizontal errors against the simulator's truth (SIM) over the healthy cruise and over
  the outage (also EKF3's last position held where it published none:
  ``autopilot_held``; and how far the true course turned), and the service's alerts
  with their times. ``--feed``: the autopilot takes
  the service's GPS_INPUT as its GPS 2 and switches to it while GPS 1 has no 3-D fix
  (:data:`FEED_PARAMS`); the result then also says how far the autopilot's stamps of our
  fixes trail the truth and how often the service's error exceeded 2.45 times its
  published accuracy over the outage.
* ``reboot``: on the ground, the autopilot is rebooted (MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN),
  then SITL is killed and started again; the service keeps running. Result: how long
  after the autopilot is back (its first HEARTBEAT) the service publishes again, on the
  autopilot's clock.
* ``taxi``: ArduPlane rolls along the runway in FBWA (``GROUND_STEER_ALT`` = 5, throttle
  ``--throttle-pwm`` by RC override) for ``--cruise-s``. Result: the service's alerts,
  the landed states and ground speeds the autopilot reported.

``python -m tests.sitl.ardupilot_runner flight --speedup 4 --cruise-s 60 --out r.json``
"""

from __future__ import annotations

import argparse
import bisect
import collections
import json
import math
import statistics
import sys
import time
import traceback
from pathlib import Path
from typing import Any

from pymavlink import mavutil

from tests.sitl import harness
from tests.sitl.dataflash import (
    SitlLog,
    Track,
    newest_log,
    read_gps_instance,
    read_gps_raw,
    read_log,
)
from tests.sitl.harness import GroundStation, Processes, ServiceTap

MAV = mavutil.mavlink
PLANE_AUTO = 10
PLANE_FBWA = 5
COPTER_AUTO, COPTER_GUIDED = 3, 4
COPTER_ALT_M = 25.0
HOME_LAT, HOME_LON, HOME_ALT = -35.363261, 149.165230, 584.0
CRUISE_ALT_M = 80.0
HOVER_SETTLE_S = 5.0
"""Copter ``--hover-s``: held this long after the take-off before the hover is scored."""
FEED_LAG_MS = 30
"""``GPS2_DELAY_MS`` for the service's GPS_INPUT: it carries its solution to the newest
autopilot time it has, so the lag is the link's and its own processing (measured against
the truth: 30-36 ms of autopilot time at speed-up 5, ``feed_lag_s`` in the result)."""
FEED_PARAMS = {
    "GPS2_TYPE": 14,
    "GPS_AUTO_SWITCH": 4,
    "GPS_PRIMARY": 0,
    "GPS2_DELAY_MS": FEED_LAG_MS,
}
"""The autopilot fed by the service (``--feed``): GPS 2 is MAVLink (GPS_INPUT), and the
GPS in use is GPS 1 whenever it has a 3-D fix, else the best of the others
(``GPS_AUTO_SWITCH = 4``, AP_GPS::update_primary): EKF3 takes the service's solution only
while its own GPS is lost, never what the service derived from that GPS while it was
good (``UseBest``, 1, would keep whichever had more satellites; blending, 2, would mix
them in weighted by the reported accuracies)."""
COVERAGE_K = 2.45
"""95 % of a circular 2-D normal error lies within 2.45 sigma."""
ALERT_CODES = (
    "GNSS_LOST",
    "GNSS_BACK",
    "GNSS_STALE",
    "BRIDGING",
    "FAULT",
    "INTEGRITY",
    "NO_GNSS",
    "NO_DATA",
    "AP_CONFIG",
)


MissionItem = tuple[int, int, tuple[float, ...], float, float, float]
"""(frame, command, params 1-4, lat deg, lon deg, alt m) of one mission item."""


def _circuit(
    takeoff_ne_m: tuple[float, float],
    takeoff_pitch_deg: float,
    takeoff_alt_m: float,
    corners_ne_m: list[tuple[float, float]],
    alt_m: float,
) -> list[MissionItem]:
    """Home, a take-off towards ``takeoff_ne_m`` (north, east of home, m) to
    ``takeoff_alt_m``, the corners (``alt_m`` above home) and a DO_JUMP back to the first
    corner: the rectangle flown in a loop."""
    rel = MAV.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
    wp, pad = MAV.MAV_CMD_NAV_WAYPOINT, (0, 0, 0, 0)
    items: list[MissionItem] = [(MAV.MAV_FRAME_GLOBAL, wp, pad, HOME_LAT, HOME_LON, HOME_ALT)]
    tk_lat, tk_lon = harness.offset_deg(HOME_LAT, HOME_LON, *takeoff_ne_m)
    takeoff_params = (takeoff_pitch_deg, 0, 0, 0)
    items.append((rel, MAV.MAV_CMD_NAV_TAKEOFF, takeoff_params, tk_lat, tk_lon, takeoff_alt_m))
    for n, e in corners_ne_m:
        lat, lon = harness.offset_deg(HOME_LAT, HOME_LON, n, e)
        items.append((rel, wp, pad, lat, lon, alt_m))
    items.append((rel, MAV.MAV_CMD_DO_JUMP, (2, 100, 0, 0), 0.0, 0.0, 0.0))
    return items


def plane_circuit() -> list[MissionItem]:
    """Home, a take-off along the runway (353 deg) and a 900 x 600 m rectangle flown in a
    loop (DO_JUMP back to its first corner)."""
    corners = [(700.0, -80.0), (700.0, 520.0), (-200.0, 520.0), (-200.0, -80.0)]
    return _circuit((300.0, -40.0), 15.0, 40.0, corners, CRUISE_ALT_M)


def copter_circuit() -> list[MissionItem]:
    """Home, a take-off to 25 m and a 200 x 120 m rectangle flown in a loop."""
    corners = [(100.0, 0.0), (100.0, 120.0), (-100.0, 120.0), (-100.0, 0.0)]
    return _circuit((0.0, 0.0), 0.0, COPTER_ALT_M, corners, COPTER_ALT_M)


def _start(
    procs: Processes, vehicle: str, args: argparse.Namespace
) -> tuple[ServiceTap, GroundStation]:
    """The autopilot, the service (``--config``) and a ground station, started in this
    namespace; the tap listening to what the service sends."""
    tap = ServiceTap()
    harness.start_ardupilot(procs, vehicle, args.speedup)
    config: dict[str, dict[str, Any]] = json.loads(args.config) if args.config else {}
    harness.start_companion(procs, config)
    return tap, GroundStation()


def _stop(procs: Processes, tap: ServiceTap, gcs: GroundStation) -> None:
    """Close the ground station, stop the service and the autopilot, close the tap."""
    gcs.close()
    procs.stop("companion")
    procs.stop("sitl")
    tap.close()


def _stats(errors: list[float]) -> dict[str, float | int | None]:
    if not errors:
        return {"n": 0, "mean_m": None, "p95_m": None, "max_m": None}
    s = sorted(errors)
    return {
        "n": len(s),
        "mean_m": statistics.fmean(s),
        "p95_m": s[min(len(s) - 1, int(math.ceil(0.95 * len(s))) - 1)],
        "max_m": s[-1],
    }


def _alerts_in(tap: ServiceTap, t0: float, t1: float) -> list[tuple[float, str]]:
    return [(t, a) for t, a in tap.alerts if t0 <= t <= t1]


def _timed_errors(
    log: SitlLog, track: Track, t0: float, t1: float
) -> tuple[list[float], list[float]]:
    """Times and horizontal errors against the truth of the points of ``track`` in [t0, t1]."""
    times, errors = [], []
    for t, lat, lon in zip(track.t_s, track.lat_deg, track.lon_deg, strict=True):
        if t0 <= t <= t1 and (ref := log.truth.at(t)) is not None:
            times.append(t)
            errors.append(harness.horizontal_m(ref[0], ref[1], lat, lon))
    return times, errors


def held_errors(
    log: SitlLog, track: Track, t0: float, t1: float, step_s: float = 0.1
) -> list[float]:
    """Horizontal errors against the truth every ``step_s`` in [t0, t1] of ``track``
    (interpolated), and across its gaps of its newest point before: where the autopilot
    publishes no position (EKF3 given up) its last one stands for it, the best a user of
    it could do."""
    out = []
    for k in range(int((t1 - t0) / step_s) + 1):
        t = t0 + k * step_s
        ref = log.truth.at(t)
        pos = track.at(t)
        if pos is None and (i := bisect.bisect_right(track.t_s, t)) > 0:
            pos = (track.lat_deg[i - 1], track.lon_deg[i - 1])
        if ref is not None and pos is not None:
            out.append(harness.horizontal_m(ref[0], ref[1], pos[0], pos[1]))
    return out


def truth_turn_deg(log: SitlLog, t0: float, t1: float, step_s: float = 1.0) -> float:
    """How far the simulator's true course turned in [t0, t1], deg: the sum of the absolute
    changes of the course over ``step_s`` chords (chords under 1 m/s left out: a hover has
    no course)."""
    courses: list[float] = []
    t = t0
    while t + step_s <= t1:
        a, b = log.truth.at(t), log.truth.at(t + step_s)
        if a is not None and b is not None:
            north = (b[0] - a[0]) * math.radians(1.0) * harness.EARTH_RADIUS_M
            east = (
                (b[1] - a[1])
                * math.radians(1.0)
                * harness.EARTH_RADIUS_M
                * math.cos(math.radians(a[0]))
            )
            if math.hypot(north, east) >= 1.0 * step_s:
                courses.append(math.degrees(math.atan2(east, north)))
        t += step_s
    turns = [
        (b - a + 180.0) % 360.0 - 180.0 for a, b in zip(courses[:-1], courses[1:], strict=True)
    ]
    return sum(abs(d) for d in turns)


def score_flight(
    log: SitlLog,
    tap: ServiceTap,
    t_cruise_s: float,
    t_end_s: float,
    outage: bool,
    hover: tuple[float, float] | None = None,
) -> dict[str, Any]:
    service = Track()
    for t, lat, lon, _alt in tap.positions:
        service.append(t, lat, lon)
    gps = log.param_changes("SIM_GPS1_ENABLE")
    t_off = next((t for t, v in gps if v == 0), None)
    t_on = next((t for t, v in gps if v == 1 and t_off is not None and t > t_off), None)
    healthy_end = t_off if (outage and t_off is not None) else t_end_s
    out: dict[str, Any] = {
        "t_cruise_s": t_cruise_s,
        "t_end_s": t_end_s,
        "healthy": {
            "t0_s": t_cruise_s,
            "t1_s": healthy_end,
            "service": _stats(log.errors(service, t_cruise_s, healthy_end)),
            "autopilot": _stats(log.errors(log.autopilot, t_cruise_s, healthy_end)),
            "alerts": _alerts_in(tap, t_cruise_s, healthy_end),
        },
        "truth_points": len(log.truth.t_s),
        "service_points": len(service.t_s),
    }
    # once the service has measured the GNSS lag and placed its fixes with it (its
    # AP_CONFIG saying the lag disagrees with GPS1_DELAY_MS), 10 s to carry it in
    placed = [t for t, a in tap.alerts if a.startswith("CMP AP_CONFIG GPS1_DELAY_MS")]
    if placed and placed[0] + 10.0 < healthy_end:
        t_placed = max(t_cruise_s, placed[0] + 10.0)
        out["placed"] = {
            "t_lag_s": placed[0],
            "t0_s": t_placed,
            "t1_s": healthy_end,
            "service": _stats(log.errors(service, t_placed, healthy_end)),
            "autopilot": _stats(log.errors(log.autopilot, t_placed, healthy_end)),
        }
    if hover is not None:
        out["hover"] = {
            "t0_s": hover[0],
            "t1_s": hover[1],
            "service": _stats(log.errors(service, *hover)),
            "autopilot": _stats(log.errors(log.autopilot, *hover)),
            "alerts": _alerts_in(tap, *hover),
        }
    if outage:
        if t_off is None or t_on is None:
            raise RuntimeError(f"outage not found in the log's PARM records: {gps}")
        lost = [t for t in tap.alert_times("GNSS_LOST") if t >= t_off - 1.0]
        back = [t for t in tap.alert_times("GNSS_BACK") if t >= t_on - 1.0]
        ap_times = [t_off] + [t for t in log.autopilot.t_s if t_off <= t <= t_on] + [t_on]
        out["outage"] = {
            "t_off_s": t_off,
            "t_on_s": t_on,
            "autopilot_max_gap_s": max(
                b - a for a, b in zip(ap_times[:-1], ap_times[1:], strict=True)
            ),
            "service": _stats(log.errors(service, t_off, t_on)),
            "autopilot": _stats(log.errors(log.autopilot, t_off, t_on)),
            "autopilot_held": _stats(held_errors(log, log.autopilot, t_off, t_on)),
            "truth_turn_deg": truth_turn_deg(log, t_off, t_on),
            "gnss_lost_latency_s": (lost[0] - t_off) if lost else None,
            "gnss_back_latency_s": (back[0] - t_on) if back else None,
            "alerts": _alerts_in(tap, t_off - 1.0, t_end_s),
        }
        # each error against the accuracy published last at or before it
        acc_t = [t for t, _ in tap.accuracies]
        acc_m = [h for _, h in tap.accuracies]
        timed = [
            (t, e, acc_m[i - 1])
            for t, e in zip(*_timed_errors(log, service, t_off, t_on), strict=True)
            if (i := bisect.bisect_right(acc_t, t)) > 0
        ]
        errs = [(e, h) for _, e, h in timed]
        out["outage"]["service_h_acc_m_max"] = max((h for _, h in errs), default=None)
        out["outage"]["service_beyond_coverage"] = sum(e > COVERAGE_K * h for e, h in errs)
        out["outage"]["service_with_accuracy"] = len(errs)
        # per whole second of the outage: the first position at or after it, its error
        # and the 1-sigma published with it
        per_second: list[tuple[float, float, float]] = []
        for t, e, h in timed:
            if not per_second or t - t_off >= per_second[-1][0] + 1.0:
                per_second.append((float(math.floor(t - t_off)), e, h))
        out["outage"]["service_per_second"] = per_second
        out["after"] = {
            "service": _stats(log.errors(service, t_on + 5.0, t_end_s)),
            "autopilot": _stats(log.errors(log.autopilot, t_on + 5.0, t_end_s)),
        }
    return out


def fly(args: argparse.Namespace, procs: Processes) -> dict[str, Any]:
    tap, gcs = _start(procs, args.vehicle, args)
    hover: tuple[float, float] | None = None
    try:
        gcs.wait_booted()
        # the service runs before the take-off, as beside a real aircraft (on a loaded
        # machine its start can otherwise come in the take-off roll)
        gcs.wait_until(lambda: tap.counts["HEARTBEAT"] > 0, 120.0, "the service running")
        gcs.set_message_rate("GLOBAL_POSITION_INT", 5.0)
        gcs.set_message_rate("MISSION_CURRENT", 5.0)
        gcs.set_param("LOG_DISARMED", 1)
        gcs.set_param("SIM_GPS1_ENABLE", 1)
        params = {**(FEED_PARAMS if args.feed else {}), **json.loads(args.params)}
        for name, value in params.items():
            gcs.set_param(name, float(value))

        def rel_alt() -> float:
            gpi = gcs.latest.get("GLOBAL_POSITION_INT")
            return -1.0 if gpi is None else gpi.relative_alt / 1000.0

        if args.vehicle == "plane":
            gcs.upload_mission(plane_circuit())
            gcs.set_mode(PLANE_AUTO)
            gcs.arm()
            t_armed = gcs.now()
            gcs.wait_until(lambda: rel_alt() > 35.0, 120.0, "take-off to 35 m")
        else:  # copter: a guided take-off, then the mission
            gcs.upload_mission(copter_circuit())
            gcs.set_mode(COPTER_GUIDED)
            gcs.arm()
            t_armed = gcs.now()
            gcs.command(MAV.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, COPTER_ALT_M)
            gcs.wait_until(lambda: rel_alt() > COPTER_ALT_M - 3.0, 120.0, "take-off")
            if args.hover_s > 0:  # held where the take-off ended, then scored
                gcs.sleep(HOVER_SETTLE_S)
                hover = (gcs.now(), gcs.now() + args.hover_s)
                gcs.sleep(args.hover_s)
            gcs.set_mode(COPTER_AUTO)
        gcs.sleep(args.settle_s)
        t_cruise = gcs.now()
        gcs.sleep(args.cruise_s)
        if args.outage_at_corner:  # the gap starts as the vehicle turns at the next corner

            def corner() -> bool:
                seq = gcs.latest.get("MISSION_CURRENT")
                return seq is not None and seq.seq != seq_at_cruise_end

            current = gcs.latest.get("MISSION_CURRENT")
            seq_at_cruise_end = None if current is None else current.seq
            gcs.wait_until(corner, 120.0, "the next corner")
        if args.outage_s > 0:
            gcs.set_param("SIM_GPS1_ENABLE", 0)
            gcs.sleep(args.outage_s)
            gcs.set_param("SIM_GPS1_ENABLE", 1)
            gcs.sleep(args.after_s)
        t_end = gcs.now()
        gcs.sleep(1.0)
        if not procs.alive("companion"):
            raise RuntimeError("companion died:\n" + procs.tail("companion"))
    finally:
        _stop(procs, tap, gcs)
    log_path = newest_log(procs.workdir)
    log = read_log(log_path)
    result = score_flight(log, tap, t_cruise, t_end, args.outage_s > 0, hover)
    # how far GPS_RAW_INT's time_usec trails the fix's time of validity: what GPS1_DELAY_MS
    # should be (the simulator's SIM_GPS1_LAG_MS is not that lag as the autopilot stamps it)
    tlogs = sorted((procs.workdir / "companion-logs").glob("*.tlog"))
    result["gps_lag_s"] = (
        log.lag_s(read_gps_raw(tlogs[0]), t_cruise, result["healthy"]["t1_s"]) if tlogs else None
    )
    result["feed_lag_s"] = (
        log.lag_s(read_gps_instance(log_path, 1), t_cruise, result["healthy"]["t1_s"])
        if args.feed
        else None
    )
    result["t_armed_s"] = t_armed
    result["service_messages"] = dict(tap.counts)
    result["all_alerts"] = [
        (t, a) for t, a in tap.alerts if a.split()[1:2] and a.split()[1] in ALERT_CODES
    ]
    result["autopilot_statustexts"] = gcs.statustexts[-60:]
    result["companion_log_tail"] = procs.tail("companion", 4000)
    return result


def taxi(args: argparse.Namespace, procs: Processes) -> dict[str, Any]:
    """ArduPlane rolls along the runway in FBWA (``GROUND_STEER_ALT`` = 5, throttle by RC
    override) for ``--cruise-s``: the service's heading alerts and the landed states the
    autopilot reported."""
    tap, gcs = _start(procs, "plane", args)
    landed: collections.Counter[int] = collections.Counter()
    speeds: list[float] = []
    try:
        gcs.wait_booted()
        gcs.set_message_rate("EXTENDED_SYS_STATE", 2.0)
        gcs.set_message_rate("VFR_HUD", 2.0)
        gcs.set_param("GROUND_STEER_ALT", 5)
        for name, value in json.loads(args.params).items():
            gcs.set_param(name, float(value))
        gcs.set_mode(PLANE_FBWA)
        gcs.arm()
        t0 = gcs.now()
        keep = 65535  # RC_CHANNELS_OVERRIDE: leave the channel alone
        while gcs.now() - t0 < args.cruise_s:
            gcs.conn.mav.rc_channels_override_send(
                gcs.conn.target_system,
                gcs.conn.target_component,
                keep,
                keep,
                args.throttle_pwm,
                keep,
                keep,
                keep,
                keep,
                keep,
            )
            gcs.sleep(0.5)
            ess = gcs.latest.get("EXTENDED_SYS_STATE")
            vfr = gcs.latest.get("VFR_HUD")
            if ess is not None:
                landed[int(ess.landed_state)] += 1
            if vfr is not None:
                speeds.append(float(vfr.groundspeed))
        t_end = gcs.now()
        if not procs.alive("companion"):
            raise RuntimeError("companion died:\n" + procs.tail("companion"))
    finally:
        _stop(procs, tap, gcs)
    return {
        "t0_s": t0,
        "t1_s": t_end,
        "landed_states": {str(k): n for k, n in landed.items()},
        "ground_speeds_mps": speeds,
        "alerts": list(tap.alerts),
        "service_messages": dict(tap.counts),
        "autopilot_statustexts": gcs.statustexts[-60:],
        "companion_log_tail": procs.tail("companion", 4000),
    }


def reboot(args: argparse.Namespace, procs: Processes) -> dict[str, Any]:
    tap, gcs = _start(procs, "plane", args)
    out: dict[str, Any] = {"events": []}
    try:
        gcs.wait_booted()

        def publishing_since(t_wall: float) -> bool:
            return tap.counts["GLOBAL_POSITION_INT"] > 0 and tap_last_wall[0] > t_wall

        tap_last_wall = [0.0]
        n_seen = [0]

        def watch_tap() -> None:
            if tap.counts["GLOBAL_POSITION_INT"] != n_seen[0]:
                n_seen[0] = tap.counts["GLOBAL_POSITION_INT"]
                tap_last_wall[0] = time.monotonic()

        gcs.wait_until(
            lambda: (watch_tap(), tap.counts["GLOBAL_POSITION_INT"] > 20)[1],
            90.0,
            "the service publishing",
        )
        for kind in ("reboot", "restart"):
            boots = gcs.boot_count
            if kind == "reboot":
                gcs.reboot()
            else:
                procs.stop("sitl", wait_s=5.0)
                time.sleep(2.0)
                harness.start_ardupilot(procs, "plane", args.speedup, wipe=False)
            # the autopilot is back: its clock restarted and a HEARTBEAT came after that
            deadline = time.monotonic() + 120.0
            while not (gcs.boot_count > boots and gcs.heartbeats_after_boot > 0):
                if time.monotonic() > deadline:
                    raise TimeoutError(f"autopilot not back after the {kind}")
                time.sleep(0.02)
            t_back = gcs.now()
            tap_before = tap.counts["GLOBAL_POSITION_INT"]
            first_pub: list[float] = []

            def published(
                tap_before: int = tap_before,
                t_back: float = t_back,
                first_pub: list[float] = first_pub,
            ) -> bool:
                with tap.lock:
                    new = [p[0] for p in tap.positions[tap_before:] if p[0] < t_back + 60.0]
                if new:
                    first_pub.append(min(new))
                return bool(new)

            try:
                gcs.wait_until(published, 30.0, f"publishing after the {kind}")
                delay: float | None = first_pub[-1] - t_back
            except TimeoutError:
                delay = None
            out["events"].append({"kind": kind, "t_back_s": t_back, "resume_delay_s": delay})
            gcs.sleep(5.0)
        out["companion_alive"] = procs.alive("companion")
    finally:
        _stop(procs, tap, gcs)
    out["companion_log_tail"] = procs.tail("companion", 4000)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("scenario", choices=["flight", "reboot", "taxi"])
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--vehicle", choices=["plane", "copter"], default="plane")
    p.add_argument("--speedup", type=float, default=4.0)
    p.add_argument("--settle-s", type=float, default=20.0, help="after take-off, before scoring")
    p.add_argument("--cruise-s", type=float, default=60.0)
    p.add_argument("--outage-s", type=float, default=0.0)
    p.add_argument("--after-s", type=float, default=30.0)
    p.add_argument(
        "--hover-s",
        type=float,
        default=0.0,
        help="copter: hover where the take-off ends this long (scored) before the mission",
    )
    p.add_argument(
        "--outage-at-corner",
        action="store_true",
        help="after the cruise, cut the GPS as the mission turns to its next corner",
    )
    p.add_argument("--throttle-pwm", type=int, default=1350, help="taxi: RC 3 override")
    p.add_argument("--params", default="{}", help="autopilot parameters to set (JSON)")
    p.add_argument(
        "--feed",
        action="store_true",
        help="the autopilot takes the service's GPS_INPUT as GPS 2 while GPS 1 is lost",
    )
    p.add_argument("--config", default="", help="service configuration sections (JSON)")
    p.add_argument("--keep", type=Path, help="work in this folder and keep it")
    args = p.parse_args(argv)
    with harness.workdir(args.keep) as wd, Processes(wd) as procs:
        try:
            scenario = {"flight": fly, "reboot": reboot, "taxi": taxi}[args.scenario]
            result = scenario(args, procs)
        except Exception:
            for name in ("sitl", "companion"):
                print(f"--- {name} log tail ---\n{procs.tail(name)}", file=sys.stderr)
            # last: the test shows only the output's tail
            print("--- runner ---", file=sys.stderr)
            traceback.print_exc()
            return 1
    result["args"] = {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()}
    args.out.write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

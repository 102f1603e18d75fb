"""The tracking channel's prediction for an antenna tracker: encoded frames, no I/O.

ArduPilot's AntennaTracker points at the vehicle whose GLOBAL_POSITION_INT it
hears (position, altitude MSL, ground velocity, heading), bridging 5 s of silence
itself by its last velocity. :class:`AntennaFeed` sends it the console's
prediction instead, so the antenna keeps following a manoeuvring aircraft through
telemetry loss: GLOBAL_POSITION_INT as the aircraft's system id (the tracker's
``SYSID_TARGET``) and a HEARTBEAT a second with the aircraft's type (the tracker
takes the first vehicle heartbeat it hears as its target when ``SYSID_TARGET``
is 0). Nothing is sent before the first position, nor once the prediction has
gone on for ``max_prediction_s`` without one (the tracker then stops on its own).
"""

from __future__ import annotations

import math
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.console.send import GCS_COMPONENT
from companion.nav.frames import LocalFrame
from companion.nav.tracking import TrackEstimate

MAX_PREDICTION_S = 20.0
HEARTBEAT_PERIOD_S = 1.0
MAV_TYPE_FIXED_WING = 1
MAV_AUTOPILOT_INVALID = 8
MAV_STATE_ACTIVE = 4


class AntennaFeed:
    """Encodes the predicted position as the aircraft's GLOBAL_POSITION_INT."""

    def __init__(self, station: LocalFrame, max_prediction_s: float = MAX_PREDICTION_S) -> None:
        self.station = station
        self.max_prediction_s = max_prediction_s
        self._mav: Any = None
        self._system: int | None = None
        self._last_heartbeat_s: float | None = None
        self.sent = 0

    def _encoder(self, system: int) -> Any:
        if self._mav is None or self._system != system:
            self._mav = mavlink.MAVLink(None, srcSystem=system, srcComponent=GCS_COMPONENT)
            self._system = system
        return self._mav

    def frames(
        self, now_s: float, est: TrackEstimate | None, system: int | None, vehicle_type: int | None
    ) -> list[bytes]:
        """What to send now (wall time ``now_s``) for the estimate ``est`` of aircraft
        ``system``; empty without an estimate or past the prediction limit."""
        if est is None or system is None or est.since_position_s > self.max_prediction_s:
            return []
        mav = self._encoder(system)
        out = []
        if self._last_heartbeat_s is None or now_s - self._last_heartbeat_s >= HEARTBEAT_PERIOD_S:
            hb = mav.heartbeat_encode(
                MAV_TYPE_FIXED_WING if vehicle_type is None else vehicle_type,
                MAV_AUTOPILOT_INVALID,
                0,
                0,
                MAV_STATE_ACTIVE,
            )
            out.append(bytes(hb.pack(mav)))
            self._last_heartbeat_s = now_s
        lat, lon, alt = self.station.ned_to_lla(est.pos_ned_m)
        vn, ve, vd = (float(v) for v in est.vel_ned_mps)
        course = math.degrees(math.atan2(ve, vn)) % 360.0
        msg = mav.global_position_int_encode(
            int(est.t_s * 1000.0) & 0xFFFFFFFF,
            round(math.degrees(lat) * 1e7),
            round(math.degrees(lon) * 1e7),
            round(alt * 1000.0),
            round((alt - self.station.alt0_m) * 1000.0),
            _cm(vn),
            _cm(ve),
            _cm(vd),
            round(course * 100.0) % 36000 if math.hypot(vn, ve) > 0.5 else 65535,
        )
        out.append(bytes(msg.pack(mav)))
        self.sent += 1
        return out


def _cm(v_mps: float) -> int:
    return max(-32768, min(32767, round(v_mps * 100.0)))

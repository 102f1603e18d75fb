"""The autopilot itself: who it is, and its own view of the vehicle.

* HEARTBEAT of the autopilot -> :class:`HeartbeatSample`. HEARTBEATs with
  ``autopilot == MAV_AUTOPILOT_INVALID`` (ground stations, companions) are
  rejected ``not_autopilot``. With ``DecoderConfig.system_id = None`` the first
  autopilot HEARTBEAT locks the system id (and the first one of that system its
  component); the HEARTBEAT's ``autopilot`` sets the flavour. A HEARTBEAT that
  arrives before any boot-clock time still locks the system id and sets the
  flavour, but yields no sample (``no_time_yet``).
* GLOBAL_POSITION_INT from the autopilot's component -> :class:`AutopilotSolution`.
* EXTENDED_SYS_STATE -> :class:`LandedStateSample`; VFR_HUD -> :class:`VfrHudSample`.

Checks: position as for GNSS (``lat_out_of_range``, ``lon_out_of_range``,
``alt_out_of_range``), speeds above ``max_speed_mps`` (``speed_out_of_range``),
heading above 360 deg (``bad_course``), unknown landed state (``bad_enum``),
non-finite VFR_HUD values (``nan_field``).
"""

from __future__ import annotations

import logging
import math
from typing import Any

import numpy as np

from companion.mavlink import units
from companion.mavlink.decode.clock import BootClock
from companion.mavlink.decode.config import DecoderConfig
from companion.mavlink.decode.gnss import check_latlon_alt
from companion.mavlink.decode.rejections import Rejected
from companion.mavlink.ids import (
    MAV_AUTOPILOT_ARDUPILOTMEGA,
    MAV_AUTOPILOT_INVALID,
    MAV_AUTOPILOT_PX4,
    MAV_MODE_FLAG_SAFETY_ARMED,
)
from companion.types import (
    AutopilotFlavour,
    AutopilotSolution,
    HeartbeatSample,
    LandedState,
    LandedStateSample,
    VfrHudSample,
)

logger = logging.getLogger(__name__)

_AUTOPILOT_FLAVOUR = {
    MAV_AUTOPILOT_ARDUPILOTMEGA: AutopilotFlavour.ARDUPILOT,
    MAV_AUTOPILOT_PX4: AutopilotFlavour.PX4,
}
_RAD_PER_DEGE7 = 1.0 / units.DEGE7_PER_RAD
_RAD_PER_CDEG = 1.0 / units.CDEG_PER_RAD
_CM_PER_M = units.CM_PER_M
_LANDED_STATES = {int(s): s for s in LandedState}


class VehicleDecoder:
    """The autopilot's identity and its HEARTBEAT, GLOBAL_POSITION_INT, VFR_HUD and
    EXTENDED_SYS_STATE handlers (raising :class:`Rejected`).

    Attributes
    ----------
    system_id : int | None
        The autopilot's system id (configured or locked).
    autopilot_component : int | None
        Component of the locked autopilot HEARTBEAT.
    flavour : AutopilotFlavour
        From the autopilot's HEARTBEAT (3 -> ARDUPILOT, 12 -> PX4).
    heartbeats : int
        HEARTBEATs recognised as the autopilot's, including those rejected
        ``no_time_yet`` (the link carries the autopilot all the same).
    """

    def __init__(self, config: DecoderConfig, clock: BootClock) -> None:
        self.system_id: int | None = config.system_id
        self.autopilot_component: int | None = None
        self.flavour = AutopilotFlavour.UNKNOWN
        self.heartbeats = 0
        self._time_ms = clock.time_ms
        self._now = clock.now
        self._max_speed = config.max_speed_mps
        self._alt_min_m = config.alt_min_m
        self._alt_max_m = config.alt_max_m
        self._alt_lo_mm = config.alt_min_m * units.MM_PER_M
        self._alt_hi_mm = config.alt_max_m * units.MM_PER_M

    def heartbeat(self, msg: Any, src_sys: int, src_comp: int, t_rx_s: float) -> HeartbeatSample:
        """HEARTBEAT: lock onto the autopilot, follow its flavour, report its state."""
        if msg.autopilot == MAV_AUTOPILOT_INVALID:
            raise Rejected("not_autopilot")
        if self.system_id is None:
            self.system_id = src_sys
            logger.info("locked onto autopilot system %d component %d", src_sys, src_comp)
        elif src_sys != self.system_id:
            raise Rejected("wrong_sysid")
        if self.autopilot_component is None:
            self.autopilot_component = src_comp
        elif src_comp != self.autopilot_component:
            raise Rejected("not_autopilot_component")
        self.heartbeats += 1
        flavour = _AUTOPILOT_FLAVOUR.get(msg.autopilot, AutopilotFlavour.UNKNOWN)
        if flavour != self.flavour:
            logger.info("autopilot flavour: %s (MAV_AUTOPILOT %d)", flavour.value, msg.autopilot)
            self.flavour = flavour
        # identity and flavour are recorded; without a clock the sample is rejected
        t_s = self._now()
        return HeartbeatSample(
            t_s=t_s,
            t_rx_s=t_rx_s,
            system_id=src_sys,
            autopilot=msg.autopilot,
            vehicle_type=msg.type,
            armed=bool(msg.base_mode & MAV_MODE_FLAG_SAFETY_ARMED),
            system_status=msg.system_status,
        )

    def extended_sys_state(self, msg: Any, t_rx_s: float) -> LandedStateSample:
        """EXTENDED_SYS_STATE: the landed state."""
        state = _LANDED_STATES.get(msg.landed_state)
        if state is None:
            raise Rejected("bad_enum")
        return LandedStateSample(t_s=self._now(), t_rx_s=t_rx_s, landed_state=state)

    def vfr_hud(self, msg: Any, t_rx_s: float) -> VfrHudSample:
        """VFR_HUD: air and ground speed, heading, altitude, climb."""
        air, gs, alt, climb = msg.airspeed, msg.groundspeed, msg.alt, msg.climb
        if not math.isfinite(air + gs + alt + climb):
            raise Rejected("nan_field")
        if abs(air) > self._max_speed or abs(gs) > self._max_speed or abs(climb) > self._max_speed:
            raise Rejected("speed_out_of_range")
        if alt < self._alt_min_m or alt > self._alt_max_m:
            raise Rejected("alt_out_of_range")
        heading = msg.heading
        if heading < 0 or heading > 360:
            raise Rejected("bad_course")
        return VfrHudSample(
            t_s=self._now(),
            t_rx_s=t_rx_s,
            airspeed_mps=air,
            ground_speed_mps=gs,
            heading_rad=math.radians(heading % 360),
            alt_msl_m=alt,
            climb_mps=climb,
        )

    def global_position_int(self, msg: Any, t_rx_s: float) -> AutopilotSolution:
        """GLOBAL_POSITION_INT of the autopilot's component: its own solution."""
        comp = self.autopilot_component
        if comp is not None and msg._header.srcComponent != comp:
            raise Rejected("not_autopilot_component")
        check_latlon_alt(msg.lat, msg.lon, msg.alt, self._alt_lo_mm, self._alt_hi_mm)
        # floats, one array at the end: the same float64 values as dividing an array
        vn, ve, vd = msg.vx / _CM_PER_M, msg.vy / _CM_PER_M, msg.vz / _CM_PER_M
        if vn * vn + ve * ve + vd * vd > self._max_speed**2:
            raise Rejected("speed_out_of_range")
        vel = np.array((vn, ve, vd))
        hdg = msg.hdg
        if hdg == units.UINT16_UNKNOWN:
            yaw: float | None = None
        elif hdg > 36000:
            raise Rejected("bad_course")
        else:
            yaw = hdg * _RAD_PER_CDEG
            if yaw > math.pi:
                yaw -= 2.0 * math.pi
        t_s = self._time_ms(msg.time_boot_ms, "GLOBAL_POSITION_INT", t_rx_s)
        return AutopilotSolution(
            t_s=t_s,
            t_rx_s=t_rx_s,
            lat_rad=msg.lat * _RAD_PER_DEGE7,
            lon_rad=msg.lon * _RAD_PER_DEGE7,
            alt_msl_m=msg.alt / units.MM_PER_M,
            vel_ned_mps=vel,
            yaw_rad=yaw,
        )

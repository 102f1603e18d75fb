"""GNSS receivers: GPS_RAW_INT, GPS2_RAW -> :class:`GnssFix`; GPS_RTK, GPS2_RTK -> RtkStatus.

* GPS_RAW_INT is receiver 0, GPS2_RAW receiver 1 (with ``dgps_age_s``).
  ``fix_type`` < 2 still decodes: the engine must see "no fix". ``vel`` unknown
  (65535) gives ``ground_speed_mps = 0.0`` with ``vel_ne_mps = None``; ``cog``
  unknown gives ``course_rad = vel_ne_mps = None``. The fix time is the
  message's ``time_usec`` on the boot clock minus the receiver's lag
  (``DecoderConfig.gnss_delay_s``, or the autopilot's GPSn_DELAY_MS when set).
* The autopilot's GPS instance that the service itself feeds reports our own output
  back (ArduPilot's GPS2_RAW with GPS2_TYPE = 14): rejected as ``own_injection``.
* A message repeating the previous one of its stream (same non-zero ``time_usec``,
  position and a 2-D or better fix type: ArduPlane sends its 5 Hz fixes in a 10 Hz
  GPS_RAW_INT) is no new fix: rejected as ``repeated_fix``, so a repeat never looks
  like a frozen receiver.
* GPS_RTK / GPS2_RTK: ``t_s`` is the latest autopilot time, not
  ``time_last_baseline_ms`` (which stays old while the corrections are missing
  and would look like a clock jump).

Checks: |lat| > 90 deg (``lat_out_of_range``), |lon| > 180 deg
(``lon_out_of_range``), altitude outside [``alt_min_m``, ``alt_max_m``]
(``alt_out_of_range``), accuracy above ``max_accuracy_m``
(``impossible_accuracy``), speed above ``max_speed_mps``
(``speed_out_of_range``), course above 360 deg (``bad_course``), unknown fix
type (``bad_enum``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from companion.mavlink import units
from companion.mavlink.decode.clock import BootClock
from companion.mavlink.decode.config import DecoderConfig
from companion.mavlink.decode.rejections import Rejected
from companion.mavlink.ids import MAVLINK_MSG_ID_GPS_RTK
from companion.types import FixType, GnssFix, RtkStatus

_RAD_PER_DEGE7 = 1.0 / units.DEGE7_PER_RAD
_RAD_PER_CDEG = 1.0 / units.CDEG_PER_RAD
_LAT_MAX_DEGE7 = 90 * 10_000_000
_LON_MAX_DEGE7 = 180 * 10_000_000
_FIX_TYPES = {int(f): f for f in FixType}


def check_latlon_alt(lat: int, lon: int, alt_mm: float, alt_lo_mm: float, alt_hi_mm: float) -> None:
    """Reject a position (degE7, degE7, mm) off the globe or outside the altitude range."""
    if lat > _LAT_MAX_DEGE7 or lat < -_LAT_MAX_DEGE7:
        raise Rejected("lat_out_of_range")
    if lon > _LON_MAX_DEGE7 or lon < -_LON_MAX_DEGE7:
        raise Rejected("lon_out_of_range")
    if alt_mm < alt_lo_mm or alt_mm > alt_hi_mm:
        raise Rejected("alt_out_of_range")


class GnssDecoder:
    """The GNSS handlers (``(msg, t_rx_s) -> sample``, raising :class:`Rejected`)."""

    def __init__(self, config: DecoderConfig, clock: BootClock) -> None:
        self._time_us = clock.time_us
        self._now = clock.now
        self._max_speed = config.max_speed_mps
        self._max_acc_mm = config.max_accuracy_m * units.MM_PER_M
        self._alt_lo_mm = config.alt_min_m * units.MM_PER_M
        self._alt_hi_mm = config.alt_max_m * units.MM_PER_M
        self.delay_s = [config.gnss_delay_s, config.gnss_delay_s]
        """Per receiver (0, 1), the lag subtracted from its fix times, s: ``gnss_delay_s``
        unless the autopilot's own lag parameter says otherwise (set by the pipeline)."""
        self.injected_receiver: int | None = None
        """The receiver that reports back what the service injects (the autopilot's GPS
        instance fed by our GPS_INPUT): never a receiver of ours (``own_injection``)."""
        self._last_fix: dict[str, tuple[int, int, int, int]] = {}
        """Stream -> (time_usec, lat, lon, fix_type) of its last message."""

    def _acc_mm(self, v: int) -> float | None:
        if v == 0:
            return None
        if v > self._max_acc_mm:
            raise Rejected("impossible_accuracy")
        return v / units.MM_PER_M

    def _gnss(self, msg: Any, t_rx_s: float, receiver: int, stream: str) -> GnssFix:
        if receiver == self.injected_receiver:
            raise Rejected("own_injection")
        key = (msg.time_usec, msg.lat, msg.lon, msg.fix_type)
        if key[0] != 0 and key[3] >= 2 and self._last_fix.get(stream) == key:
            raise Rejected("repeated_fix")
        self._last_fix[stream] = key
        check_latlon_alt(msg.lat, msg.lon, msg.alt, self._alt_lo_mm, self._alt_hi_mm)
        fix = _FIX_TYPES.get(msg.fix_type)
        if fix is None:
            raise Rejected("bad_enum")
        alt_ell = msg.alt_ellipsoid
        if alt_ell != 0:
            if alt_ell < self._alt_lo_mm or alt_ell > self._alt_hi_mm:
                raise Rejected("alt_out_of_range")
            alt_hae_m: float | None = alt_ell / units.MM_PER_M
        else:
            alt_hae_m = None
        h_acc = self._acc_mm(msg.h_acc)
        v_acc = self._acc_mm(msg.v_acc)
        vel_acc = self._acc_mm(msg.vel_acc)
        vel = msg.vel
        if vel == units.UINT16_UNKNOWN:
            speed = 0.0
            course: float | None = None
            vel_ne: np.ndarray | None = None
        else:
            speed = vel / units.CM_PER_M
            if speed > self._max_speed:
                raise Rejected("speed_out_of_range")
            cog = msg.cog
            if cog == units.UINT16_UNKNOWN:
                course = None
                vel_ne = None
            else:
                if cog > 36000:
                    raise Rejected("bad_course")
                course = cog * _RAD_PER_CDEG
                vel_ne = np.array([speed * math.cos(course), speed * math.sin(course)])
        eph = msg.eph
        epv = msg.epv
        sats = msg.satellites_visible
        placed_s = self.delay_s[receiver]
        t_s = self._time_us(msg.time_usec, stream, t_rx_s, clock=False) - placed_s
        # positional, in GnssFix's field order (18 keywords cost more on this path)
        return GnssFix(
            t_s,
            t_rx_s,
            receiver,  # receiver_id
            fix,
            msg.lat * _RAD_PER_DEGE7,  # lat_rad
            msg.lon * _RAD_PER_DEGE7,  # lon_rad
            msg.alt / units.MM_PER_M,  # alt_msl_m
            alt_hae_m,
            vel_ne,  # vel_ne_mps
            speed,  # ground_speed_mps
            course,  # course_rad
            h_acc,  # h_acc_m
            v_acc,  # v_acc_m
            vel_acc,  # vel_acc_mps
            None if eph == units.UINT16_UNKNOWN else eph / units.DOP_SCALE,  # hdop
            None if epv == units.UINT16_UNKNOWN else epv / units.DOP_SCALE,  # vdop
            None if sats == units.UINT8_UNKNOWN else sats,  # satellites
            (msg.dgps_age / units.MS_PER_S) if receiver == 1 else None,  # dgps_age_s
            placed_s,
        )

    def gps_raw(self, msg: Any, t_rx_s: float) -> GnssFix:
        """GPS_RAW_INT: receiver 0."""
        return self._gnss(msg, t_rx_s, 0, "GPS_RAW_INT")

    def gps2_raw(self, msg: Any, t_rx_s: float) -> GnssFix:
        """GPS2_RAW: receiver 1."""
        return self._gnss(msg, t_rx_s, 1, "GPS2_RAW")

    def gps_rtk(self, msg: Any, t_rx_s: float) -> RtkStatus:
        """GPS_RTK (receiver 0) or GPS2_RTK (receiver 1)."""
        t_s = self._now()
        return RtkStatus(
            t_s=t_s,
            t_rx_s=t_rx_s,
            receiver_id=0 if msg.get_msgId() == MAVLINK_MSG_ID_GPS_RTK else 1,
            health=msg.rtk_health,
            rate_hz=float(msg.rtk_rate),
            satellites=msg.nsats,
            baseline_m=np.array([msg.baseline_a_mm, msg.baseline_b_mm, msg.baseline_c_mm])
            / units.MM_PER_M,
            accuracy=msg.accuracy,
            iar_num_hypotheses=msg.iar_num_hypotheses,
        )

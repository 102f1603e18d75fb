"""MAVLink messages in, typed SI samples out (the input edge of the service).

Every MAVLink scaling is undone here, with the constants of
:mod:`companion.mavlink.units`; the core only ever sees :mod:`companion.types`.

Which messages become which samples
-----------------------------------
* GPS_RAW_INT -> :class:`GnssFix` (receiver 0), GPS2_RAW -> receiver 1 (with
  ``dgps_age_s``). ``fix_type`` < 2 still decodes: the engine must see "no fix".
  ``vel`` unknown (65535) gives ``ground_speed_mps = 0.0`` with
  ``vel_ne_mps = None``; ``cog`` unknown gives ``course_rad = vel_ne_mps = None``.
* GPS_RTK / GPS2_RTK -> :class:`RtkStatus`. Its ``t_s`` is the latest
  autopilot time, not ``time_last_baseline_ms`` (which stays old while the
  corrections are missing and would look like a clock jump).
* RAW_IMU, SCALED_IMU, SCALED_IMU2/3 (mG, mrad/s) and HIGHRES_IMU (m/s^2,
  rad/s) -> :class:`ImuSample` (``imu_id`` = the message's ``id`` or 0/1/2 for
  SCALED_IMU/2/3; ``source`` = message name).
* ATTITUDE, ATTITUDE_QUATERNION -> :class:`AttitudeSample`.
* HEARTBEAT of the autopilot -> :class:`HeartbeatSample` (HEARTBEATs with
  ``autopilot == MAV_AUTOPILOT_INVALID`` — ground stations, companions — are
  ignored, counted ``not_autopilot``).
* EXTENDED_SYS_STATE -> :class:`LandedStateSample`; VFR_HUD -> :class:`VfrHudSample`.
* GLOBAL_POSITION_INT from the autopilot's component -> :class:`AutopilotSolution`.
* COMMAND_LONG ``MAV_CMD_USER_1`` (31010) addressed to our system (or
  broadcast) and to component 191 (or broadcast), from anyone: the
  **heading-confirmation command**. ``param1 == 1`` -> ``HeadingCommand(apply=True)``,
  ``param1 == 0`` -> ``HeadingCommand(apply=False)``; any other value is rejected
  (``bad_command_param``).
* Anything from our own component (191) is ignored (``own_message``).

System id: with ``DecoderConfig.system_id = None`` the decoder locks onto the
first HEARTBEAT whose autopilot is not MAV_AUTOPILOT_INVALID; until then every
other message is rejected ``no_system_yet``; afterwards messages of other
systems are rejected ``wrong_sysid`` (except the heading command).

Time (one clock: the autopilot's time since boot, seconds)
----------------------------------------------------------
* ``time_boot_ms`` and a boot-based ``time_usec`` map directly. ``time_boot_ms``
  is uint32 and wraps after 49.7 days: a value below ``WRAP_WINDOW_MS`` after
  one above ``2**32 - WRAP_WINDOW_MS`` adds one wrap of 2**32 ms.
* A ``time_usec`` above ``units.EPOCH_USEC_THRESHOLD`` is UNIX-epoch time
  (ArduPilot stamps GPS_RAW_INT so). It is mapped onto the boot clock with
  ``t_s = epoch_s - offset_s``, where ``offset_s`` is the running maximum,
  over all epoch-stamped messages, of ``epoch_s - latest_boot_t_s``. Each
  difference equals the true offset minus the message's latency behind the
  latest boot-clock message, so the maximum converges to the true offset minus
  the smallest latency seen: mapped times are late by that smallest latency
  (tens of ms at most with a 50 Hz IMU stream). Before any boot-clock time has
  been seen, such messages are rejected ``no_time_yet``. Once SYSTEM_TIME
  (``time_unix_usec`` with its ``time_boot_ms``, sent at 1 Hz by ArduPilot and
  PX4) has given the offset exactly, that offset is used instead, and GNSS
  fixes land on their time of validity. Epoch-stamped messages are held back
  (rejected ``awaiting_system_time``) for up to ``system_time_wait_s`` of boot
  clock after the first of them, so that the offset does not step by the
  latency once SYSTEM_TIME arrives; without SYSTEM_TIME the estimate is used.
* ``DecoderConfig.gnss_delay_s`` is subtracted from every GNSS fix time: set it
  to the receiver's lag when the autopilot stamps fixes on arrival rather than
  at validity (ArduPilot's ``GPS_DELAY_MS`` plays the same role).
* ``time_usec == 0`` (ArduPilot's GPS_RAW_INT before the receiver has time)
  and messages without a time (HEARTBEAT, VFR_HUD, EXTENDED_SYS_STATE, GPS_RTK,
  the heading command) take the latest boot-clock time.
* Reboot: a boot-clock time more than ``reboot_backjump_s`` before the latest
  one emits :class:`RebootEvent` (before the message's own sample) and resets
  the clock state (wraps, epoch offset, per-stream times). Only the "now"
  streams (IMU, attitude, GLOBAL_POSITION_INT) detect reboots: a GNSS
  ``time_usec`` is the time of the last fix and stays put through a GNSS
  outage (equal stamps are accepted; the engine sees the fix is stale).
  A smaller backward step on one stream (a message type, per instance)
  rejects that message ``time_backwards``; equal times are accepted.
* A HEARTBEAT that arrives before any boot-clock time still locks the system
  id and sets the flavour, but yields no sample (``no_time_yet``).

Validation
----------
Non-finite floats (``nan_field``), |lat| > 90 deg (``lat_out_of_range``),
|lon| > 180 deg (``lon_out_of_range``), altitude outside
[``alt_min_m``, ``alt_max_m``] (``alt_out_of_range``), accuracy above
``max_accuracy_m`` (``impossible_accuracy``), speed above ``max_speed_mps``
(``speed_out_of_range``), IMU beyond ``max_acc_mps2`` / ``max_gyro_radps``
(``imu_out_of_range``), attitude angles out of range or rates too large
(``attitude_out_of_range``), quaternion norm far from 1 (``bad_quaternion``),
unknown fix type or landed state (``bad_enum``), course above 360 deg
(``bad_course``). A rejected message yields no sample; exactly one counter
(``accepted`` or ``rejections``) moves per call of :meth:`Decoder.decode`.

Logging: each rejection reason is logged at WARNING on its 1st, 10th, 100th,
1000th... occurrence (deterministic rate limit, no clock read), except the
benign reasons ``unhandled_type``, ``own_message``, ``not_autopilot`` and
``wrong_sysid`` which are logged at DEBUG the same way.

References
----------
MAVLink common message set (field units and sentinels):
https://mavlink.io/en/messages/common.html
"""

from __future__ import annotations

import collections
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from companion.mavlink import units
from companion.nav.rotations import quat_to_euler
from companion.types import (
    AttitudeSample,
    AutopilotFlavour,
    AutopilotSolution,
    FixType,
    GnssFix,
    HeadingCommand,
    HeartbeatSample,
    ImuSample,
    LandedState,
    LandedStateSample,
    RebootEvent,
    RtkStatus,
    Sample,
    VfrHudSample,
)

logger = logging.getLogger(__name__)

MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_AUTOPILOT_INVALID = 8
MAV_AUTOPILOT_PX4 = 12
MAV_MODE_FLAG_SAFETY_ARMED = 128
MAV_CMD_USER_1 = 31010
"""The heading-confirmation command (COMMAND_LONG, param1 = 1 apply / 0 refuse)."""

UINT32_WRAP_MS = 1 << 32
WRAP_WINDOW_MS = 600_000
"""A time_boot_ms below this after one above 2**32 minus this is a wrap (10 min)."""
_WRAP_HI_MS = UINT32_WRAP_MS - WRAP_WINDOW_MS

_BENIGN = frozenset({"unhandled_type", "own_message", "not_autopilot", "wrong_sysid"})
_AUTOPILOT_FLAVOUR = {
    MAV_AUTOPILOT_ARDUPILOTMEGA: AutopilotFlavour.ARDUPILOT,
    MAV_AUTOPILOT_PX4: AutopilotFlavour.PX4,
}
_RAD_PER_DEGE7 = 1.0 / units.DEGE7_PER_RAD
_RAD_PER_CDEG = 1.0 / units.CDEG_PER_RAD
_MPS2_PER_MG = 1.0 / units.MG_PER_MPS2
_RADPS_PER_MRADPS = 1.0 / units.MRAD_PER_RAD
_LAT_MAX_DEGE7 = 90 * 10_000_000
_LON_MAX_DEGE7 = 180 * 10_000_000
_MS_PER_S = units.MS_PER_S
_CM_PER_M = units.CM_PER_M
_US_PER_S = units.US_PER_S
_EPOCH_USEC = units.EPOCH_USEC_THRESHOLD
_TWO_PI = 2.0 * math.pi
_ROLL_MAX = math.pi + 1e-3
_PITCH_MAX = 0.5 * math.pi + 1e-3
_YAW_MAX = 2.0 * _ROLL_MAX
"""Largest plausible ATTITUDE angles, rad (a wrapped yaw may span two turns)."""
_NO_TIME = -math.inf
"""A stream's previous time before it has one (compares below every time)."""
_LANDED_STATES = {int(s): s for s in LandedState}
_FIX_TYPES = {int(f): f for f in FixType}

# Message ids (common.xml); fixed by the protocol.
ID_HEARTBEAT = 0
ID_SYSTEM_TIME = 2
ID_SCALED_IMU = 26
ID_RAW_IMU = 27
ID_GPS_RAW_INT = 24
ID_ATTITUDE = 30
ID_ATTITUDE_QUATERNION = 31
ID_GLOBAL_POSITION_INT = 33
ID_VFR_HUD = 74
ID_COMMAND_LONG = 76
ID_HIGHRES_IMU = 105
ID_SCALED_IMU2 = 116
ID_GPS2_RAW = 124
ID_GPS_RTK = 127
ID_GPS2_RTK = 128
ID_SCALED_IMU3 = 129
ID_EXTENDED_SYS_STATE = 245

LIGHT_MESSAGE_IDS = frozenset(
    {
        ID_SYSTEM_TIME,
        ID_GPS_RAW_INT,
        ID_GPS2_RAW,
        ID_GPS_RTK,
        ID_GPS2_RTK,
        ID_RAW_IMU,
        ID_SCALED_IMU,
        ID_SCALED_IMU2,
        ID_SCALED_IMU3,
        ID_HIGHRES_IMU,
        ID_ATTITUDE,
        ID_ATTITUDE_QUATERNION,
        ID_EXTENDED_SYS_STATE,
        ID_VFR_HUD,
        ID_GLOBAL_POSITION_INT,
    }
)
"""The messages :meth:`Decoder.decode` takes as
:class:`~companion.mavlink.fastdecode.LightMessage` as well as pymavlink objects (its
handlers read only fields, ``_header``, ``_type``, ``get_type()`` and ``get_msgId()``).
What receives them besides the decoder must read no more (the pipeline reads
``_type``; the service's recorder ``get_msgbuf()``)."""


class _Rejected(Exception):
    """Internal: a message failed validation (the argument is the reason)."""


@dataclass(frozen=True, slots=True)
class DecoderConfig:
    """Decoder settings.

    Attributes
    ----------
    system_id
        The autopilot's MAVLink system id; ``None`` locks onto the first
        HEARTBEAT whose autopilot is not MAV_AUTOPILOT_INVALID.
    own_component
        Our component id (messages from it are ignored).
    max_speed_mps
        Largest plausible speed (GNSS, VFR_HUD, GLOBAL_POSITION_INT), m/s.
    max_accuracy_m
        Largest plausible 1-sigma accuracy, m (also m/s for speed accuracy).
    alt_min_m, alt_max_m
        Plausible altitude range, m.
    max_acc_mps2
        Largest plausible specific-force magnitude, m/s^2 (50 g).
    max_gyro_radps
        Largest plausible angular-rate magnitude, rad/s.
    reboot_backjump_s
        A boot-clock step backwards larger than this is a reboot, s.
    gnss_delay_s
        Subtracted from GNSS fix times (receiver lag not in the stamp), s.
    system_time_wait_s
        How long epoch-stamped messages wait for SYSTEM_TIME's exact offset, s.
    """

    system_id: int | None = None
    own_component: int = units.MAV_COMP_ID_ONBOARD_COMPUTER
    max_speed_mps: float = 600.0
    max_accuracy_m: float = 1e5
    alt_min_m: float = -1000.0
    alt_max_m: float = 50_000.0
    max_acc_mps2: float = 50.0 * units.STANDARD_GRAVITY_MPS2
    max_gyro_radps: float = 50.0
    reboot_backjump_s: float = 2.0
    gnss_delay_s: float = 0.0
    system_time_wait_s: float = 3.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.system_time_wait_s <= 60.0:
            raise ValueError("system_time_wait_s must be in [0, 60]")
        if not 0.0 <= self.gnss_delay_s <= 1.0:
            raise ValueError("gnss_delay_s must be in [0, 1]")
        if self.system_id is not None and not 1 <= self.system_id <= 255:
            raise ValueError(f"system_id must be in 1..255, got {self.system_id}")
        if self.reboot_backjump_s <= 0.0:
            raise ValueError("reboot_backjump_s must be > 0")
        if not self.alt_min_m < self.alt_max_m:
            raise ValueError("alt_min_m must be < alt_max_m")
        for name in ("max_speed_mps", "max_accuracy_m", "max_acc_mps2", "max_gyro_radps"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0")


class Decoder:
    """Stateful MAVLink-to-sample decoder (clock reconstruction, validation, counting).

    Parameters
    ----------
    config
        Limits and the system id policy.

    Attributes
    ----------
    rejections : collections.Counter[str]
        Reason -> count of messages (or frames) not turned into samples.
    accepted : collections.Counter[str]
        Message type -> count of messages turned into samples.
    flavour : AutopilotFlavour
        From the autopilot's HEARTBEAT (3 -> ARDUPILOT, 12 -> PX4).
    system_id : int | None
        The autopilot's system id (configured or locked).
    autopilot_component : int | None
        Component of the locked autopilot HEARTBEAT.
    reboots : int
        Reboots detected.
    last_t_s : float | None
        Latest autopilot boot-clock time seen, s.
    epoch_offset_s : float | None
        Current UNIX-epoch minus boot-clock offset estimate, s.
    """

    def __init__(self, config: DecoderConfig | None = None) -> None:
        self.config = config if config is not None else DecoderConfig()
        self.rejections: collections.Counter[str] = collections.Counter()
        self.accepted: collections.Counter[str] = collections.Counter()
        self.flavour = AutopilotFlavour.UNKNOWN
        self.system_id: int | None = self.config.system_id
        self.autopilot_component: int | None = None
        self.reboots = 0
        self.last_t_s: float | None = None
        self.epoch_offset_s: float | None = None
        self._offset_exact = False
        self._first_epoch_boot_s: float | None = None
        self._wraps = 0
        self._last_ms_raw: int | None = None
        self._stream_t: dict[Any, float] = {}
        self._pending: list[Sample] = []
        c = self.config
        self._max_speed = c.max_speed_mps
        self._max_acc_m = c.max_accuracy_m
        self._max_acc_mm = c.max_accuracy_m * units.MM_PER_M
        self._alt_lo_mm = c.alt_min_m * units.MM_PER_M
        self._alt_hi_mm = c.alt_max_m * units.MM_PER_M
        self._own_comp = c.own_component
        self._gnss_delay_s = c.gnss_delay_s
        self._max_acc2 = c.max_acc_mps2**2
        self._max_gyro2 = c.max_gyro_radps**2
        self._backjump_s = c.reboot_backjump_s
        self._handlers: dict[int, Callable[[Any, float], Sample | None]] = {
            ID_SYSTEM_TIME: self._system_time,
            ID_GPS_RAW_INT: self._gps_raw,
            ID_GPS2_RAW: self._gps2_raw,
            ID_GPS_RTK: self._gps_rtk,
            ID_GPS2_RTK: self._gps_rtk,
            ID_RAW_IMU: self._raw_imu,
            ID_SCALED_IMU: self._scaled_imu,
            ID_SCALED_IMU2: self._scaled_imu,
            ID_SCALED_IMU3: self._scaled_imu,
            ID_HIGHRES_IMU: self._highres_imu,
            ID_ATTITUDE: self._attitude,
            ID_ATTITUDE_QUATERNION: self._attitude_quaternion,
            ID_EXTENDED_SYS_STATE: self._extended_sys_state,
            ID_VFR_HUD: self._vfr_hud,
            ID_GLOBAL_POSITION_INT: self._global_position_int,
        }

    # ------------------------------------------------------------------ public

    def decode(self, msg: Any, t_rx_s: float) -> list[Sample]:
        """Turn one message into 0..n samples (a RebootEvent may precede the sample).

        Parameters
        ----------
        msg
            A pymavlink message (BAD_DATA messages are counted ``corrupt_frame``).
        t_rx_s
            Reception time (wall or log time), s; kept for latency only.

        Returns
        -------
        list
            Samples, possibly empty. Never raises on bad input.
        """
        try:
            hdr = msg._header  # pymavlink's MAVLink_header (faster than get_header())
            msg_id = hdr.msgId
            src_sys = hdr.srcSystem
            src_comp = hdr.srcComponent
        except AttributeError:  # not a decoded pymavlink message
            self._reject("corrupt_frame")
            return []
        handler = self._handlers.get(msg_id)
        if handler is None:
            return self._unhandled(msg, msg_id, src_sys, src_comp, t_rx_s)
        if src_comp == self._own_comp:
            self._reject("own_message")
            return []
        if src_sys != self.system_id:
            self._reject("no_system_yet" if self.system_id is None else "wrong_sysid")
            return []
        try:
            sample = handler(msg, t_rx_s)
        except _Rejected as exc:
            self._reject(exc.args[0])
            return self._take_pending()
        except (TypeError, ValueError, AttributeError, OverflowError):
            self._reject("corrupt_frame")
            return self._take_pending()
        self.accepted[msg._type] += 1
        if self._pending:
            out = self._pending
            self._pending = []
            if sample is not None:
                out.append(sample)
            return out
        return [sample] if sample is not None else []

    def _unhandled(
        self, msg: Any, msg_id: int, src_sys: int, src_comp: int, t_rx_s: float
    ) -> list[Sample]:
        """Messages without a sample handler: BAD_DATA, HEARTBEAT, COMMAND_LONG, the rest."""
        if msg_id < 0:
            self._reject("corrupt_frame")
            return []
        if src_comp == self._own_comp:
            self._reject("own_message")
            return []
        if msg_id == ID_HEARTBEAT:
            return self._heartbeat(msg, src_sys, src_comp, t_rx_s)
        if msg_id == ID_COMMAND_LONG:
            return self._command_long(msg, t_rx_s)
        self._reject("unhandled_type")
        return []

    def _take_pending(self) -> list[Sample]:
        """A RebootEvent found before a message was rejected is still reported."""
        if not self._pending:
            return []
        out = self._pending
        self._pending = []
        return out

    def bad_frame(self, count: int = 1) -> None:
        """Count ``count`` corrupt frames reported by the parser (reason ``corrupt_frame``)."""
        if count > 0:
            self._reject("corrupt_frame", count)

    # ------------------------------------------------------------------ bookkeeping

    def _reject(self, reason: str, count: int = 1) -> None:
        before = self.rejections[reason]
        after = before + count
        self.rejections[reason] = after
        # log on the 1st, 10th, 100th... occurrence
        if before == 0 or len(str(after)) != len(str(before)):
            level = logging.DEBUG if reason in _BENIGN else logging.WARNING
            logger.log(level, "MAVLink input rejected: %s (%d so far)", reason, after)

    def _reset_clock(self) -> None:
        self._wraps = 0
        self._last_ms_raw = None
        self._stream_t.clear()
        self.epoch_offset_s = None
        self._offset_exact = False
        self._first_epoch_boot_s = None
        self.last_t_s = None

    def _boot_time(
        self, t_s: float, stream: Any, t_rx_s: float, t_after_reboot_s: float | None = None
    ) -> float:
        """Register a boot-clock time on ``stream``; detects reboots and backward steps.

        ``t_after_reboot_s`` is the message's time on a freshly reset clock (it
        differs from ``t_s`` only for wrapped ``time_boot_ms``).
        """
        last = self.last_t_s
        if last is not None and t_s < last - self._backjump_s:
            if t_after_reboot_s is not None:
                t_s = t_after_reboot_s
            self._reboot(last, t_s, t_rx_s)
            last = None
        stream_t = self._stream_t
        if t_s < stream_t.get(stream, _NO_TIME):
            raise _Rejected("time_backwards")
        stream_t[stream] = t_s
        if last is None or t_s > last:
            self.last_t_s = t_s
        return t_s

    def _reboot(self, last_t_s: float, t_s: float, t_rx_s: float) -> None:
        """The boot clock restarted: reset the clock state and queue the RebootEvent."""
        self.reboots += 1
        logger.warning(
            "autopilot reboot detected: boot clock went from %.3f s to %.3f s", last_t_s, t_s
        )
        self._reset_clock()
        self._pending.append(RebootEvent(t_s=t_s, t_rx_s=t_rx_s, previous_t_s=last_t_s))

    def _time_ms(self, raw_ms: int, stream: Any, t_rx_s: float) -> float:
        last_raw = self._last_ms_raw
        wraps = self._wraps
        if last_raw is not None and WRAP_WINDOW_MS <= raw_ms <= _WRAP_HI_MS:
            # the common case, far from a wrap: the general steps below with nothing to do
            t_s = (raw_ms + wraps * UINT32_WRAP_MS) / _MS_PER_S
            t_s = self._boot_time(t_s, stream, t_rx_s, raw_ms / _MS_PER_S)
            self._last_ms_raw = raw_ms  # (a reboot inside reset the wraps to 0 already)
            return t_s
        straggler = False
        if last_raw is not None:
            if last_raw > _WRAP_HI_MS and raw_ms < WRAP_WINDOW_MS:
                wraps += 1  # the uint32 wrapped
            elif raw_ms > _WRAP_HI_MS and last_raw < WRAP_WINDOW_MS and wraps > 0:
                wraps -= 1  # a late message from before the wrap
                straggler = True
        t_s = (raw_ms + wraps * UINT32_WRAP_MS) / _MS_PER_S
        t_s = self._boot_time(t_s, stream, t_rx_s, raw_ms / _MS_PER_S)
        if self._last_ms_raw is None:  # first, or just reset by a reboot
            self._wraps = 0
            self._last_ms_raw = raw_ms
        elif not straggler:
            self._wraps = wraps
            self._last_ms_raw = raw_ms
        return t_s

    def _time_us(self, raw_us: int, stream: Any, t_rx_s: float, clock: bool = True) -> float:
        """Map a ``time_usec`` onto the boot clock.

        ``clock=False`` (GNSS fix times) never detects a reboot: a GNSS stamp is
        the time of the last fix, which stays put while the receiver has no fix
        and would otherwise look like the boot clock jumping back.
        """
        if raw_us > _EPOCH_USEC:
            epoch_s = raw_us / _US_PER_S
            off = self.epoch_offset_s
            if not self._offset_exact or off is None:
                last = self.last_t_s
                if last is None:
                    raise _Rejected("no_time_yet")
                if self._first_epoch_boot_s is None:
                    self._first_epoch_boot_s = last
                if last - self._first_epoch_boot_s < self.config.system_time_wait_s:
                    raise _Rejected("awaiting_system_time")
                d = epoch_s - last
                if off is None or d > off:
                    self.epoch_offset_s = off = d
            t_s = epoch_s - off
            if t_s < self._stream_t.get(stream, _NO_TIME):
                raise _Rejected("time_backwards")
            self._stream_t[stream] = t_s
            return t_s
        if raw_us == 0:
            return self._now()
        t_s = raw_us / _US_PER_S
        if clock:
            return self._boot_time(t_s, stream, t_rx_s)
        if t_s < self._stream_t.get(stream, _NO_TIME):
            raise _Rejected("time_backwards")
        self._stream_t[stream] = t_s
        if self.last_t_s is None or t_s > self.last_t_s:
            self.last_t_s = t_s
        return t_s

    def _system_time(self, msg: Any, t_rx_s: float) -> None:
        """SYSTEM_TIME: when the autopilot has UNIX time, the exact epoch-to-boot offset."""
        if msg.time_unix_usec > units.EPOCH_USEC_THRESHOLD:
            # the pair gives the offset; the boot clock itself is left to the "now" streams
            t_boot_s = (msg.time_boot_ms + self._wraps * UINT32_WRAP_MS) / units.MS_PER_S
            self.epoch_offset_s = msg.time_unix_usec / units.US_PER_S - t_boot_s
            self._offset_exact = True
        return None

    def _now(self) -> float:
        t = self.last_t_s
        if t is None:
            raise _Rejected("no_time_yet")
        return t

    # ------------------------------------------------------------------ handlers

    def _heartbeat(self, msg: Any, src_sys: int, src_comp: int, t_rx_s: float) -> list[Sample]:
        if msg.autopilot == MAV_AUTOPILOT_INVALID:
            self._reject("not_autopilot")
            return []
        if self.system_id is None:
            self.system_id = src_sys
            logger.info("locked onto autopilot system %d component %d", src_sys, src_comp)
        elif src_sys != self.system_id:
            self._reject("wrong_sysid")
            return []
        if self.autopilot_component is None:
            self.autopilot_component = src_comp
        elif src_comp != self.autopilot_component:
            self._reject("not_autopilot_component")
            return []
        flavour = _AUTOPILOT_FLAVOUR.get(msg.autopilot, AutopilotFlavour.UNKNOWN)
        if flavour != self.flavour:
            logger.info("autopilot flavour: %s (MAV_AUTOPILOT %d)", flavour.value, msg.autopilot)
            self.flavour = flavour
        t_s = self.last_t_s
        if t_s is None:
            # identity and flavour are recorded; the sample waits for a clock
            self._reject("no_time_yet")
            return []
        self.accepted["HEARTBEAT"] += 1
        return [
            HeartbeatSample(
                t_s=t_s,
                t_rx_s=t_rx_s,
                system_id=src_sys,
                autopilot=msg.autopilot,
                vehicle_type=msg.type,
                armed=bool(msg.base_mode & MAV_MODE_FLAG_SAFETY_ARMED),
                system_status=msg.system_status,
            )
        ]

    def _command_long(self, msg: Any, t_rx_s: float) -> list[Sample]:
        if msg.command != MAV_CMD_USER_1:
            self._reject("unhandled_type")
            return []
        if msg.target_system not in (0, self.system_id) or msg.target_component not in (
            0,
            self.config.own_component,
        ):
            self._reject("not_for_us")
            return []
        p1 = msg.param1
        if p1 == 1.0:
            apply = True
        elif p1 == 0.0:
            apply = False
        else:
            self._reject("bad_command_param")
            return []
        t_s = self.last_t_s
        if t_s is None:
            self._reject("no_time_yet")
            return []
        self.accepted["COMMAND_LONG"] += 1
        return [HeadingCommand(t_s=t_s, t_rx_s=t_rx_s, apply=apply)]

    def _check_latlon_alt(self, lat: int, lon: int, alt_mm: float) -> None:
        if lat > _LAT_MAX_DEGE7 or lat < -_LAT_MAX_DEGE7:
            raise _Rejected("lat_out_of_range")
        if lon > _LON_MAX_DEGE7 or lon < -_LON_MAX_DEGE7:
            raise _Rejected("lon_out_of_range")
        if alt_mm < self._alt_lo_mm or alt_mm > self._alt_hi_mm:
            raise _Rejected("alt_out_of_range")

    def _acc_mm(self, v: int) -> float | None:
        if v == 0:
            return None
        if v > self._max_acc_mm:
            raise _Rejected("impossible_accuracy")
        return v / units.MM_PER_M

    def _gnss(self, msg: Any, t_rx_s: float, receiver: int, stream: str) -> GnssFix:
        self._check_latlon_alt(msg.lat, msg.lon, msg.alt)
        fix = _FIX_TYPES.get(msg.fix_type)
        if fix is None:
            raise _Rejected("bad_enum")
        alt_ell = msg.alt_ellipsoid
        if alt_ell != 0:
            if alt_ell < self._alt_lo_mm or alt_ell > self._alt_hi_mm:
                raise _Rejected("alt_out_of_range")
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
                raise _Rejected("speed_out_of_range")
            cog = msg.cog
            if cog == units.UINT16_UNKNOWN:
                course = None
                vel_ne = None
            else:
                if cog > 36000:
                    raise _Rejected("bad_course")
                course = cog * _RAD_PER_CDEG
                vel_ne = np.array([speed * math.cos(course), speed * math.sin(course)])
        eph = msg.eph
        epv = msg.epv
        sats = msg.satellites_visible
        t_s = self._time_us(msg.time_usec, stream, t_rx_s, clock=False) - self._gnss_delay_s
        # positional, in GnssFix's field order (18 keywords cost a third more)
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
        )

    def _gps_raw(self, msg: Any, t_rx_s: float) -> GnssFix:
        return self._gnss(msg, t_rx_s, 0, "GPS_RAW_INT")

    def _gps2_raw(self, msg: Any, t_rx_s: float) -> GnssFix:
        return self._gnss(msg, t_rx_s, 1, "GPS2_RAW")

    def _gps_rtk(self, msg: Any, t_rx_s: float) -> RtkStatus:
        t_s = self._now()
        return RtkStatus(
            t_s=t_s,
            t_rx_s=t_rx_s,
            receiver_id=0 if msg.get_msgId() == ID_GPS_RTK else 1,
            health=msg.rtk_health,
            rate_hz=float(msg.rtk_rate),
            satellites=msg.nsats,
            baseline_m=np.array([msg.baseline_a_mm, msg.baseline_b_mm, msg.baseline_c_mm])
            / units.MM_PER_M,
            accuracy=msg.accuracy,
            iar_num_hypotheses=msg.iar_num_hypotheses,
        )

    def _imu(
        self,
        t_s: float,
        t_rx_s: float,
        ax: float,
        ay: float,
        az: float,
        gx: float,
        gy: float,
        gz: float,
        imu_id: int,
        src: str,
    ) -> ImuSample:
        """Validate SI specific force (m/s^2) and rate (rad/s) and build the sample."""
        a2 = ax * ax + ay * ay + az * az
        g2 = gx * gx + gy * gy + gz * gz
        if not math.isfinite(a2 + g2):
            raise _Rejected("nan_field")
        if a2 > self._max_acc2 or g2 > self._max_gyro2:
            raise _Rejected("imu_out_of_range")
        # positional: a third faster than keywords at 50 Hz (t_s, t_rx_s, acc, gyro, id, source)
        return ImuSample(t_s, t_rx_s, np.array((ax, ay, az)), np.array((gx, gy, gz)), imu_id, src)

    def _raw_imu(self, msg: Any, t_rx_s: float) -> ImuSample:
        """RAW_IMU, the most frequent message: the common boot-clock case of
        :meth:`_time_us` written out here (the same result)."""
        imu_id = msg.id
        raw_us = msg.time_usec
        if 0 < raw_us <= _EPOCH_USEC:
            t_s = self._boot_time(raw_us / _US_PER_S, ("RAW_IMU", imu_id), t_rx_s)
        else:
            t_s = self._time_us(raw_us, ("RAW_IMU", imu_id), t_rx_s)
        k = _MPS2_PER_MG
        r = _RADPS_PER_MRADPS
        return self._imu(
            t_s, t_rx_s, msg.xacc * k, msg.yacc * k, msg.zacc * k,
            msg.xgyro * r, msg.ygyro * r, msg.zgyro * r, imu_id, "RAW_IMU",
        )  # fmt: skip

    def _scaled_imu(self, msg: Any, t_rx_s: float) -> ImuSample:
        name = msg.get_type()
        imu_id = 0 if name == "SCALED_IMU" else (1 if name == "SCALED_IMU2" else 2)
        t_s = self._time_ms(msg.time_boot_ms, name, t_rx_s)
        k = _MPS2_PER_MG
        r = _RADPS_PER_MRADPS
        return self._imu(
            t_s, t_rx_s, msg.xacc * k, msg.yacc * k, msg.zacc * k,
            msg.xgyro * r, msg.ygyro * r, msg.zgyro * r, imu_id, name,
        )  # fmt: skip

    def _highres_imu(self, msg: Any, t_rx_s: float) -> ImuSample:
        imu_id = msg.id
        ax, ay, az = msg.xacc, msg.yacc, msg.zacc
        gx, gy, gz = msg.xgyro, msg.ygyro, msg.zgyro
        if not math.isfinite(ax + ay + az + gx + gy + gz):
            raise _Rejected("nan_field")
        t_s = self._time_us(msg.time_usec, ("HIGHRES_IMU", imu_id), t_rx_s)
        return self._imu(t_s, t_rx_s, ax, ay, az, gx, gy, gz, imu_id, "HIGHRES_IMU")

    def _rates(self, msg: Any) -> np.ndarray:
        p, q, r = msg.rollspeed, msg.pitchspeed, msg.yawspeed
        r2 = p * p + q * q + r * r
        if not math.isfinite(r2):
            raise _Rejected("nan_field")
        if r2 > self._max_gyro2:
            raise _Rejected("attitude_out_of_range")
        return np.array((p, q, r))

    def _attitude(self, msg: Any, t_rx_s: float) -> AttitudeSample:
        roll, pitch, yaw = msg.roll, msg.pitch, msg.yaw
        if not math.isfinite(roll + pitch + yaw):
            raise _Rejected("nan_field")
        if abs(roll) > _ROLL_MAX or abs(pitch) > _PITCH_MAX or abs(yaw) > _YAW_MAX:
            raise _Rejected("attitude_out_of_range")
        rate = self._rates(msg)
        t_s = self._time_ms(msg.time_boot_ms, "ATTITUDE", t_rx_s)
        if yaw > math.pi:
            yaw -= _TWO_PI
        elif yaw < -math.pi:
            yaw += _TWO_PI
        # positional (25 Hz): t_s, t_rx_s, roll, pitch, yaw, rate
        return AttitudeSample(t_s, t_rx_s, roll, pitch, yaw, rate)

    def _attitude_quaternion(self, msg: Any, t_rx_s: float) -> AttitudeSample:
        q = np.array([msg.q1, msg.q2, msg.q3, msg.q4], dtype=np.float64)
        n2 = float(q @ q)
        if not math.isfinite(n2):
            raise _Rejected("nan_field")
        if abs(n2 - 1.0) > 0.1:
            raise _Rejected("bad_quaternion")
        rate = self._rates(msg)
        t_s = self._time_ms(msg.time_boot_ms, "ATTITUDE_QUATERNION", t_rx_s)
        roll, pitch, yaw = quat_to_euler(q / math.sqrt(n2))
        return AttitudeSample(
            t_s=t_s, t_rx_s=t_rx_s, roll_rad=roll, pitch_rad=pitch, yaw_rad=yaw, rate_b_radps=rate
        )

    def _extended_sys_state(self, msg: Any, t_rx_s: float) -> LandedStateSample:
        state = _LANDED_STATES.get(msg.landed_state)
        if state is None:
            raise _Rejected("bad_enum")
        return LandedStateSample(t_s=self._now(), t_rx_s=t_rx_s, landed_state=state)

    def _vfr_hud(self, msg: Any, t_rx_s: float) -> VfrHudSample:
        air, gs, alt, climb = msg.airspeed, msg.groundspeed, msg.alt, msg.climb
        if not math.isfinite(air + gs + alt + climb):
            raise _Rejected("nan_field")
        if abs(air) > self._max_speed or abs(gs) > self._max_speed or abs(climb) > self._max_speed:
            raise _Rejected("speed_out_of_range")
        if alt < self.config.alt_min_m or alt > self.config.alt_max_m:
            raise _Rejected("alt_out_of_range")
        heading = msg.heading
        if heading < 0 or heading > 360:
            raise _Rejected("bad_course")
        return VfrHudSample(
            t_s=self._now(),
            t_rx_s=t_rx_s,
            airspeed_mps=air,
            ground_speed_mps=gs,
            heading_rad=math.radians(heading % 360),
            alt_msl_m=alt,
            climb_mps=climb,
        )

    def _global_position_int(self, msg: Any, t_rx_s: float) -> AutopilotSolution:
        comp = self.autopilot_component
        if comp is not None and msg._header.srcComponent != comp:
            raise _Rejected("not_autopilot_component")
        self._check_latlon_alt(msg.lat, msg.lon, msg.alt)
        # floats, one array at the end: the same float64 values as dividing an array
        vn, ve, vd = msg.vx / _CM_PER_M, msg.vy / _CM_PER_M, msg.vz / _CM_PER_M
        if vn * vn + ve * ve + vd * vd > self._max_speed**2:
            raise _Rejected("speed_out_of_range")
        vel = np.array((vn, ve, vd))
        hdg = msg.hdg
        if hdg == units.UINT16_UNKNOWN:
            yaw: float | None = None
        elif hdg > 36000:
            raise _Rejected("bad_course")
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

"""The decoder: dispatch by message id, the system id filter, the heading command, counting.

:class:`Decoder` hands each message to its kind's handler (:mod:`.gnss`,
:mod:`.inertial`, :mod:`.baro`, :mod:`.vehicle`, :mod:`.signal`, SYSTEM_TIME to
:mod:`.clock`) after the checks every message passes:

* anything from our own component (191) is ignored (``own_message``);
* until the system id is known (configured, or locked by the first autopilot
  HEARTBEAT) every other message is rejected ``no_system_yet``; afterwards
  messages of other systems are rejected ``wrong_sysid`` (except the heading
  command);
* COMMAND_LONG or COMMAND_INT ``MAV_CMD_USER_1`` (31010) addressed to our system
  (or broadcast) and to component 191 (or broadcast), from anyone, is the
  **heading command**: ``param1`` 1 -> ``HeadingCommand(CONFIRM)``, 0 -> ``REFUSE``,
  2 -> ``UNDO``; any other value is rejected (``bad_command_param``), a heading
  command for another component ``not_for_us``. Any other command addressed to
  component 191 itself is rejected ``unsupported_command``; broadcast or addressed
  elsewhere it is ``unhandled_type``.

Every command addressed to us leaves a :class:`~companion.mavlink.commands.DecodedCommand`
for the caller to answer (:meth:`Decoder.take_command`): with its result when decoding
decided it (UNSUPPORTED, DENIED for a bad ``param1``, TEMPORARILY_REJECTED before the
autopilot's clock is known).

A message whose fields cannot be read is ``corrupt_frame``; a rejected message
yields no sample, and exactly one counter (``accepted`` or ``rejections``)
moves per call of :meth:`Decoder.decode`.
"""

from __future__ import annotations

import collections
from collections.abc import Callable
from typing import Any

from companion.mavlink.commands import (
    DecodedCommand,
    addressed_to,
    heading_action,
    read_command,
)
from companion.mavlink.decode.baro import BaroDecoder
from companion.mavlink.decode.clock import BootClock
from companion.mavlink.decode.config import DecoderConfig
from companion.mavlink.decode.gnss import GnssDecoder
from companion.mavlink.decode.inertial import InertialDecoder
from companion.mavlink.decode.rejections import Rejected, count_rejection
from companion.mavlink.decode.signal import SignalDecoder
from companion.mavlink.decode.vehicle import VehicleDecoder
from companion.mavlink.ids import (
    MAV_CMD_USER_1,
    MAV_RESULT_DENIED,
    MAV_RESULT_TEMPORARILY_REJECTED,
    MAV_RESULT_UNSUPPORTED,
    MAVLINK_MSG_ID_ATTITUDE,
    MAVLINK_MSG_ID_ATTITUDE_QUATERNION,
    MAVLINK_MSG_ID_COMMAND_INT,
    MAVLINK_MSG_ID_COMMAND_LONG,
    MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
    MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
    MAVLINK_MSG_ID_GNSS_INTEGRITY,
    MAVLINK_MSG_ID_GPS2_RAW,
    MAVLINK_MSG_ID_GPS2_RTK,
    MAVLINK_MSG_ID_GPS_RAW_INT,
    MAVLINK_MSG_ID_GPS_RTK,
    MAVLINK_MSG_ID_HEARTBEAT,
    MAVLINK_MSG_ID_HIGHRES_IMU,
    MAVLINK_MSG_ID_RAW_IMU,
    MAVLINK_MSG_ID_SCALED_IMU,
    MAVLINK_MSG_ID_SCALED_IMU2,
    MAVLINK_MSG_ID_SCALED_IMU3,
    MAVLINK_MSG_ID_SCALED_PRESSURE,
    MAVLINK_MSG_ID_SCALED_PRESSURE2,
    MAVLINK_MSG_ID_SYSTEM_TIME,
    MAVLINK_MSG_ID_VFR_HUD,
)
from companion.types import AutopilotFlavour, HeadingCommand, Sample

LIGHT_MESSAGE_IDS = frozenset(
    {
        MAVLINK_MSG_ID_SYSTEM_TIME,
        MAVLINK_MSG_ID_GPS_RAW_INT,
        MAVLINK_MSG_ID_GPS2_RAW,
        MAVLINK_MSG_ID_GPS_RTK,
        MAVLINK_MSG_ID_GPS2_RTK,
        MAVLINK_MSG_ID_RAW_IMU,
        MAVLINK_MSG_ID_SCALED_IMU,
        MAVLINK_MSG_ID_SCALED_IMU2,
        MAVLINK_MSG_ID_SCALED_IMU3,
        MAVLINK_MSG_ID_HIGHRES_IMU,
        MAVLINK_MSG_ID_SCALED_PRESSURE,
        MAVLINK_MSG_ID_SCALED_PRESSURE2,
        MAVLINK_MSG_ID_ATTITUDE,
        MAVLINK_MSG_ID_ATTITUDE_QUATERNION,
        MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
        MAVLINK_MSG_ID_VFR_HUD,
        MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
        MAVLINK_MSG_ID_GNSS_INTEGRITY,
    }
)
"""The messages :meth:`Decoder.decode` takes as
:class:`~companion.mavlink.messages.LightMessage` as well as pymavlink objects (its
handlers read only fields, ``_header``, ``_type``, ``get_type()`` and ``get_msgId()``).
What receives them besides the decoder must read no more (the pipeline reads
``_type``; the service's recorder ``get_msgbuf()``)."""


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
    """

    def __init__(self, config: DecoderConfig | None = None) -> None:
        self.config = config if config is not None else DecoderConfig()
        self.rejections: collections.Counter[str] = collections.Counter()
        self.accepted: collections.Counter[str] = collections.Counter()
        c = self.config
        self._clock = clock = BootClock(c)
        self._vehicle = vehicle = VehicleDecoder(c, clock)
        self.gnss = gnss = GnssDecoder(c, clock)
        self.inertial = inertial = InertialDecoder(c, clock)
        baro = BaroDecoder(clock)
        signal = SignalDecoder(clock, lambda: vehicle.flavour)
        self.field_rejections: collections.Counter[str] = collections.Counter()
        """Reason -> count of fields turned away inside an accepted message (HIGHRES_IMU's
        barometer): the message's IMU sample still counts as accepted."""
        self._own_comp = c.own_component
        self._pending_command: DecodedCommand | None = None
        self._handlers: dict[int, Callable[[Any, float], Sample | None]] = {
            MAVLINK_MSG_ID_SYSTEM_TIME: clock.system_time,
            MAVLINK_MSG_ID_GPS_RAW_INT: gnss.gps_raw,
            MAVLINK_MSG_ID_GPS2_RAW: gnss.gps2_raw,
            MAVLINK_MSG_ID_GPS_RTK: gnss.gps_rtk,
            MAVLINK_MSG_ID_GPS2_RTK: gnss.gps_rtk,
            MAVLINK_MSG_ID_RAW_IMU: inertial.raw_imu,
            MAVLINK_MSG_ID_SCALED_IMU: inertial.scaled_imu,
            MAVLINK_MSG_ID_SCALED_IMU2: inertial.scaled_imu,
            MAVLINK_MSG_ID_SCALED_IMU3: inertial.scaled_imu,
            MAVLINK_MSG_ID_HIGHRES_IMU: inertial.highres_imu,
            MAVLINK_MSG_ID_SCALED_PRESSURE: baro.scaled_pressure,
            MAVLINK_MSG_ID_SCALED_PRESSURE2: baro.scaled_pressure,
            MAVLINK_MSG_ID_ATTITUDE: inertial.attitude,
            MAVLINK_MSG_ID_ATTITUDE_QUATERNION: inertial.attitude_quaternion,
            MAVLINK_MSG_ID_EXTENDED_SYS_STATE: vehicle.extended_sys_state,
            MAVLINK_MSG_ID_VFR_HUD: vehicle.vfr_hud,
            MAVLINK_MSG_ID_GLOBAL_POSITION_INT: vehicle.global_position_int,
            MAVLINK_MSG_ID_GNSS_INTEGRITY: signal.gnss_integrity,
        }

    # ------------------------------------------------------------------ state

    @property
    def flavour(self) -> AutopilotFlavour:
        """From the autopilot's HEARTBEAT (3 -> ARDUPILOT, 12 -> PX4)."""
        return self._vehicle.flavour

    @property
    def system_id(self) -> int | None:
        """The autopilot's system id (configured or locked)."""
        return self._vehicle.system_id

    @property
    def autopilot_component(self) -> int | None:
        """Component of the locked autopilot HEARTBEAT."""
        return self._vehicle.autopilot_component

    @property
    def autopilot_heartbeats(self) -> int:
        """HEARTBEATs recognised as the autopilot's (identity checked), with or without a
        sample: the first ones come before any time is known (``no_time_yet``)."""
        return self._vehicle.heartbeats

    @property
    def reboots(self) -> int:
        """Reboots detected."""
        return self._clock.reboots

    @property
    def last_t_s(self) -> float | None:
        """Latest autopilot boot-clock time seen, s."""
        return self._clock.last_t_s

    @property
    def epoch_offset_s(self) -> float | None:
        """Current UNIX-epoch minus boot-clock offset estimate, s."""
        return self._clock.epoch_offset_s

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
        system_id = self._vehicle.system_id
        if src_sys != system_id:
            self._reject("no_system_yet" if system_id is None else "wrong_sysid")
            return []
        try:
            sample = handler(msg, t_rx_s)
        except Rejected as exc:
            self._reject(exc.args[0])
            return self._take_pending()
        except (TypeError, ValueError, AttributeError, OverflowError):
            self._reject("corrupt_frame")
            return self._take_pending()
        self.accepted[msg._type] += 1
        clock = self._clock
        if clock.pending:
            out = clock.pending
            clock.pending = []
            if sample is not None:
                out.append(sample)
        else:
            out = [sample] if sample is not None else []
        if msg_id == MAVLINK_MSG_ID_HIGHRES_IMU and sample is not None:
            try:
                baro = BaroDecoder.from_highres(msg, sample.t_s, t_rx_s)
            except Rejected as exc:
                count_rejection(self.field_rejections, exc.args[0])
            except (TypeError, ValueError, AttributeError, OverflowError):
                count_rejection(self.field_rejections, "corrupt_field")
            else:
                if baro is not None:
                    out.append(baro)
        return out

    def take_command(self) -> DecodedCommand | None:
        """The command addressed to us that the last :meth:`decode` read, once: the caller
        answers it with exactly one COMMAND_ACK. ``None`` when there is none."""
        command, self._pending_command = self._pending_command, None
        return command

    def bad_frame(self, count: int = 1) -> None:
        """Count ``count`` corrupt frames reported by the parser (reason ``corrupt_frame``)."""
        if count > 0:
            self._reject("corrupt_frame", count)

    def unknown_frame(self, count: int = 1) -> None:
        """Count ``count`` valid frames of message ids the dialect does not know (reason
        ``unknown_message``: benign, not corrupt)."""
        if count > 0:
            self._reject("unknown_message", count)

    # ------------------------------------------------------------------ internals

    def _unhandled(
        self, msg: Any, msg_id: int, src_sys: int, src_comp: int, t_rx_s: float
    ) -> list[Sample]:
        """Messages without a sample handler: BAD_DATA, HEARTBEAT, commands, the rest."""
        if msg_id < 0:
            self._reject("corrupt_frame")
            return []
        if src_comp == self._own_comp:
            self._reject("own_message")
            return []
        if msg_id == MAVLINK_MSG_ID_HEARTBEAT:
            try:
                heartbeat = self._vehicle.heartbeat(msg, src_sys, src_comp, t_rx_s)
            except Rejected as exc:
                self._reject(exc.args[0])
                return []
            self.accepted["HEARTBEAT"] += 1
            return [heartbeat]
        if msg_id == MAVLINK_MSG_ID_COMMAND_LONG or msg_id == MAVLINK_MSG_ID_COMMAND_INT:
            return self._command(msg, t_rx_s)
        self._reject("unhandled_type")
        return []

    def _command(self, msg: Any, t_rx_s: float) -> list[Sample]:
        """A COMMAND_LONG or COMMAND_INT: the heading command if it is one addressed to us;
        any command addressed to us is left for :meth:`take_command`."""
        try:
            request = read_command(msg)
        except (AttributeError, TypeError, ValueError, OverflowError):
            self._reject("corrupt_frame")
            return []
        ours = addressed_to(request, self._vehicle.system_id, self._own_comp)
        if request.command != MAV_CMD_USER_1:
            if ours and request.target_component == self._own_comp:
                self._reject("unsupported_command")
                self._pending_command = DecodedCommand(request, MAV_RESULT_UNSUPPORTED)
            else:  # a broadcast is answered by the components that implement it
                self._reject("unhandled_type")
            return []
        if not ours:
            self._reject("not_for_us")
            return []
        p1 = request.params[0]
        action = heading_action(p1)
        if action is None:
            self._reject("bad_command_param")
            reason = f"param1 {p1:.4g}: 0 refuse, 1 confirm, 2 undo"
            self._pending_command = DecodedCommand(request, MAV_RESULT_DENIED, reason)
            return []
        t_s = self._clock.last_t_s
        if t_s is None:
            self._reject("no_time_yet")
            reason = "no autopilot clock yet"
            self._pending_command = DecodedCommand(request, MAV_RESULT_TEMPORARILY_REJECTED, reason)
            return []
        self.accepted[request.message] += 1
        self._pending_command = DecodedCommand(request)
        return [HeadingCommand(t_s=t_s, t_rx_s=t_rx_s, action=action)]

    def _take_pending(self) -> list[Sample]:
        """A RebootEvent found before a message was rejected is still reported."""
        clock = self._clock
        if not clock.pending:
            return []
        out = clock.pending
        clock.pending = []
        return out

    def _reject(self, reason: str, count: int = 1) -> None:
        count_rejection(self.rejections, reason, count)

"""PX4's auxiliary global position fusion, as the service sets itself up for it.

PX4 turns a GLOBAL_POSITION_SENSOR into its aux global position and EKF2 fuses it only
in the slot whose ``EKF2_AGP0_ID`` equals the message's ``id``, with ``EKF2_AGP0_CTRL``
bit 0 (horizontal position) set; otherwise the message is dropped without a word on
either side. So the service reads both parameters over the parameter protocol when a PX4
autopilot appears (and after it reboots), sends its solution with ``id`` =
``EKF2_AGP0_ID``, and says so (log and a ``CMP AP_CONFIG`` STATUSTEXT) when the fusion
is off or the configured id differs. Slot 0 only: the one PX4's documentation sets up.

Nothing goes to PX4 before the id is known: measured on PX4 SIH, a GLOBAL_POSITION_SENSOR
of another id (the configured default 0) sent first kept PX4 from ever fusing the right
one afterwards. If PX4 does not answer (:data:`MAX_TIMED_RETRIES`), the configured id is
sent, with a warning.

Feeding an autopilot that feeds us: with the fusion on, PX4 gets nothing from a GNSS
gap's start until GNSS is trusted again (the encoder's ``feedback_guard``). Bridged, the
solution rests on PX4's attitude and IMU; fused back, PX4 corrects that attitude with it
and the errors feed on themselves while each side takes the other for independent
(reported on PX4 SIH before this guard: PX4 15-16 m off after a 20 s cut where it alone
was 5 m off). ArduPilot's remedy (bridge on the body rates, withdraw past 3 m) is none
here: HIGHRES_IMU and ATTITUDE's rates are PX4's sensors less EKF2's own bias estimates,
which move with what EKF2 fuses (on PX4 SIH, fed so through a 20 s cut, PX4 was 1.5-3.4 m
off on average against 0.8-1.2 m alone; docs/mavlink.md).

PX4 sends an INT32 parameter *bytewise* (the float's four bytes are the integer's:
MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE), not C-cast as ArduPilot does.

References
----------
MAVLink parameter protocol: https://mavlink.io/en/services/parameter.html; PX4
``src/modules/ekf2/EKF/aid_sources/aux_global_position`` (slot by id),
``src/modules/mavlink/mavlink_receiver.cpp`` (GLOBAL_POSITION_SENSOR).
"""

from __future__ import annotations

import logging
import math
import struct
from dataclasses import dataclass
from typing import Any

log = logging.getLogger(__name__)

AGP_ID = "EKF2_AGP0_ID"
AGP_CTRL = "EKF2_AGP0_CTRL"
NAMES = (AGP_ID, AGP_CTRL)
"""The parameters read, in request order."""
AGP_CTRL_HPOS = 0x1
"""EKF2_AGP0_CTRL bit 0: fuse the horizontal position."""
MAV_PARAM_TYPE_REAL32 = 9
RETRY_S = 1.0
"""Unanswered requests are sent again after this long (autopilot time, s)..."""
MAX_TIMED_RETRIES = 3
"""... this many times after each untimed request; then a warning, and the configured id."""
_PACK_F = struct.Struct("<f")
_UNPACK_I = struct.Struct("<i")


def px4_int(value: float, param_type: int) -> int | None:
    """The integer a PX4 PARAM_VALUE carries (bytewise for integer types; a REAL32 taken
    as is when whole). None when it is not a finite whole number."""
    if param_type != MAV_PARAM_TYPE_REAL32:
        return int(_UNPACK_I.unpack(_PACK_F.pack(value))[0])
    if not math.isfinite(value) or value != int(value):
        return None
    return int(value)


@dataclass(frozen=True, slots=True)
class AgpVerdict:
    """What the autopilot's parameters say: the id to send, and a problem (or None)."""

    sensor_id: int
    problem: str | None
    fused: bool
    """PX4 fuses the horizontal position sent with ``sensor_id``."""


class Px4AgpSetup:
    """Reads ``EKF2_AGP0_ID`` and ``EKF2_AGP0_CTRL`` from a PX4 autopilot and decides the
    GLOBAL_POSITION_SENSOR id. Pure: messages in, messages out, autopilot time given."""

    def __init__(self, configured_id: int) -> None:
        self.configured_id = configured_id
        """``[encoder] gps_id``: sent until the autopilot's id is known."""
        self.values: dict[str, int] = {}
        self.verdict: AgpVerdict | None = None
        self._next_request_s: float | None = None
        self._retries = 0
        self._gave_up = False

    def restart(self) -> None:
        """The autopilot appeared or rebooted: read its parameters again."""
        self.values.clear()
        self.verdict = None
        self._next_request_s = None
        self._retries = 0
        self._gave_up = False

    @property
    def waiting(self) -> bool:
        """The parameters are being read: send PX4 nothing yet."""
        return self.verdict is None and not self._gave_up

    @property
    def sensor_id(self) -> int:
        """The id to send now."""
        return self.configured_id if self.verdict is None else self.verdict.sensor_id

    def requests(self, mod: Any, target: tuple[int, int], t_s: float | None) -> list[Any]:
        """PARAM_REQUEST_READ for every parameter not read yet: at once without a time
        (``t_s`` None: the autopilot appeared, rebooted or its streams are asked for again),
        then every :data:`RETRY_S` of autopilot time while unanswered; ``mod`` is the
        pymavlink dialect."""
        if self.verdict is not None:
            return []
        if t_s is not None:
            due = self._next_request_s
            if due is None:
                self._next_request_s = t_s + RETRY_S
                return []
            if t_s < due or self._gave_up:
                return []
            if self._retries >= MAX_TIMED_RETRIES:
                self._gave_up = True
                log.warning(
                    "PX4 does not answer %s: GLOBAL_POSITION_SENSOR id %d (gps_id) and no "
                    "feedback guard; whether PX4 fuses it is unknown",
                    " ".join(n for n in NAMES if n not in self.values),
                    self.configured_id,
                )
                return []
            self._retries += 1
            self._next_request_s = t_s + RETRY_S
        else:
            self._next_request_s = None
            self._retries = 0
            self._gave_up = False
        sysid, compid = target
        return [
            mod.MAVLink_param_request_read_message(sysid, compid, name.encode("ascii"), -1)
            for name in NAMES
            if name not in self.values
        ]

    def on_param_value(self, msg: Any) -> AgpVerdict | None:
        """Take a PARAM_VALUE from the autopilot; the verdict once both parameters are in
        (returned once, then kept in :attr:`verdict`)."""
        try:
            raw = msg.param_id
            name = raw.decode("ascii", "replace") if isinstance(raw, bytes) else str(raw)
            name = name.rstrip("\x00")
            value = px4_int(float(msg.param_value), int(msg.param_type))
        except (AttributeError, TypeError, ValueError, struct.error):
            return None
        if name not in NAMES or value is None or self.verdict is not None:
            return None
        self.values[name] = value
        if any(n not in self.values for n in NAMES):
            return None
        self.verdict = self._judge(self.values[AGP_ID], self.values[AGP_CTRL])
        return self.verdict

    def _judge(self, agp_id: int, ctrl: int) -> AgpVerdict:
        problems = []
        if not 0 <= agp_id <= 255:
            problems.append(f"{AGP_ID}={agp_id} is not a message id (0-255)")
            agp_id = self.configured_id
        elif self.configured_id not in (0, agp_id):
            problems.append(f"gps_id {self.configured_id} != {AGP_ID} {agp_id}: sending {agp_id}")
        if not ctrl & AGP_CTRL_HPOS:
            problems.append(f"PX4 fuses no aux position: {AGP_CTRL}={ctrl}")
        problem = "; ".join(problems) or None
        log.info(
            "PX4 aux global position: %s=%d %s=%d: GLOBAL_POSITION_SENSOR id %d%s",
            AGP_ID,
            agp_id,
            AGP_CTRL,
            ctrl,
            agp_id,
            "" if problem is None else f" ({problem})",
        )
        return AgpVerdict(agp_id, problem, bool(ctrl & AGP_CTRL_HPOS))

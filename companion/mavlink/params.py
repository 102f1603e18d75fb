"""The MAVLink parameter protocol on the wire: requests in, PARAM_VALUE and STATUSTEXT out.

What the table of parameters is and what a value means is the application's
(:mod:`companion.params`); this module only knows the messages:

* :func:`decode_request` turns PARAM_REQUEST_LIST, PARAM_REQUEST_READ and PARAM_SET
  into :class:`ParamList`, :class:`ParamRead` and :class:`ParamSet` when they are
  addressed to us: our system (or broadcast 0) and our component; the list request
  also to the broadcast component 0, as ground stations send it. Anything else
  raises :class:`~companion.mavlink.decode.rejections.Rejected` with a reason.
* :class:`ParamCodec` builds PARAM_VALUE (``param_count`` and ``param_index`` given
  by the caller) and STATUSTEXT messages for :meth:`Encoder.pack
  <companion.mavlink.encode.Encoder.pack>`.
* Values travel as the float ``param_value``. Integer types (INT32, UINT8) are
  **C-cast** (the float holds the integer's value, as ArduPilot sends them and
  MAVProxy and Mission Planner read them; MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST),
  exact up to 2^24. :func:`real32` is the float a REAL32 carries, as the shortest
  decimal that the 32-bit float represents (a ground station's ``0.3`` is stored
  as 0.3, not 0.30000001192...).

References
----------
MAVLink parameter protocol: https://mavlink.io/en/services/parameter.html
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from companion.mavlink.decode.rejections import Rejected
from companion.mavlink.dialect import load_dialect
from companion.mavlink.ids import STATUSTEXT_MAX_CHARS

MAVLINK_MSG_ID_PARAM_REQUEST_READ = 20
MAVLINK_MSG_ID_PARAM_REQUEST_LIST = 21
MAVLINK_MSG_ID_PARAM_VALUE = 22
MAVLINK_MSG_ID_PARAM_SET = 23

REQUEST_TYPES = frozenset({"PARAM_REQUEST_READ", "PARAM_REQUEST_LIST", "PARAM_SET"})
"""The message types :func:`decode_request` takes (the pipeline routes them here)."""

MAV_PARAM_TYPE_UINT8 = 1
MAV_PARAM_TYPE_INT32 = 6
MAV_PARAM_TYPE_REAL32 = 9

PARAM_ID_MAX_CHARS = 16
"""PARAM_VALUE.param_id is char[16], not NUL-terminated when full."""

INT32_MIN = -(2**31)
INT32_MAX = 2**31 - 1

NOT_FOR_US = "unhandled_type"
"""How a request for another system or component is counted (benign, as before the
parameter protocol existed)."""

_ID_CHARS = frozenset("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789_")


@dataclass(frozen=True, slots=True)
class ParamList:
    """PARAM_REQUEST_LIST: every parameter, once, in index order."""


@dataclass(frozen=True, slots=True)
class ParamRead:
    """PARAM_REQUEST_READ: by ``index`` when it is >= 0, else by ``name``."""

    name: str
    index: int


@dataclass(frozen=True, slots=True)
class ParamSet:
    """PARAM_SET: ``value`` is the float on the wire (C-cast for integer types)."""

    name: str
    value: float


ParamRequest = ParamList | ParamRead | ParamSet


def param_name(raw: Any) -> str:
    """``param_id`` as text: NUL padding stripped; at most 16 characters. Bytes that are
    not ASCII become ``?`` (a name with them matches no parameter)."""
    if isinstance(raw, bytes | bytearray):
        raw = bytes(raw).split(b"\0", 1)[0].decode("ascii", "replace")
    text = str(raw).split("\0", 1)[0]
    return text[:PARAM_ID_MAX_CHARS]


def printable_name(name: str) -> str:
    """``name`` safe to put in a STATUSTEXT or a log line (letters, digits, ``_``)."""
    return "".join(c if c in _ID_CHARS else "?" for c in name) or "''"


def decode_request(msg: Any, system_id: int, component_id: int) -> ParamRequest:
    """The request ``msg`` (one of :data:`REQUEST_TYPES`) makes of us.

    Raises
    ------
    Rejected
        ``own_message`` (sent by our own component), ``unhandled_type`` (for another
        system or component: a ground station talking to the autopilot is the shared
        link's normal traffic, counted as every message we do not take),
        ``corrupt_frame`` (fields that cannot be read).
    """
    try:
        if msg.get_srcComponent() == component_id:
            raise Rejected("own_message")
        kind = msg.get_type()
        target_sys = int(msg.target_system)
        target_comp = int(msg.target_component)
        if target_sys not in (0, system_id):
            raise Rejected(NOT_FOR_US)
        if kind == "PARAM_REQUEST_LIST":
            if target_comp not in (0, component_id):
                raise Rejected(NOT_FOR_US)
            return ParamList()
        if target_comp != component_id:
            raise Rejected(NOT_FOR_US)
        if kind == "PARAM_REQUEST_READ":
            return ParamRead(param_name(msg.param_id), int(msg.param_index))
        if kind == "PARAM_SET":
            return ParamSet(param_name(msg.param_id), float(msg.param_value))
    except (AttributeError, TypeError, ValueError, OverflowError):
        raise Rejected("corrupt_frame") from None
    raise Rejected("unhandled_type")


def real32(value: float) -> float:
    """The value a REAL32 parameter carries: ``value`` rounded to 32 bits, as the shortest
    decimal that rounds to the same 32-bit float (±inf beyond its range; NaN stays NaN)."""
    with np.errstate(over="ignore"):
        single = np.float32(value)
    return float(str(single))


def wire_value(value: float | int | bool) -> float:
    """The ``param_value`` float of a parameter value (C-cast for integers)."""
    if isinstance(value, bool | int):
        return float(value)
    return real32(value)


class ParamCodec:
    """Builds the parameter protocol's outgoing messages in ``dialect``."""

    def __init__(self, dialect: str) -> None:
        self._mod = load_dialect(dialect)

    def param_value(
        self, name: str, value: float | int | bool, param_type: int, count: int, index: int
    ) -> Any:
        """PARAM_VALUE of parameter ``index`` of ``count``."""
        if len(name) > PARAM_ID_MAX_CHARS or not name.isascii():
            raise ValueError(f"parameter name must be <= 16 ASCII characters: {name!r}")
        return self._mod.MAVLink_param_value_message(
            name.encode("ascii"), wire_value(value), param_type, count, index
        )

    def statustext(self, severity: int, text: str) -> Any:
        """STATUSTEXT ``text`` (ASCII, cut at 50 characters: one line)."""
        line = " ".join(text.split())[:STATUSTEXT_MAX_CHARS].rstrip()
        return self._mod.MAVLink_statustext_message(
            int(severity), line.encode("ascii", "replace"), 0, 0
        )


def is_integral(value: float) -> bool:
    """A finite float holding an integer (what an INT32 or UINT8 parameter may be set to)."""
    return math.isfinite(value) and value == math.floor(value)

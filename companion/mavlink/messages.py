"""MAVLink message objects from frames: a fast path of pymavlink's ``MAVLink.decode``.

:func:`companion.mavlink.framing.try_frame` hands every candidate frame to
pymavlink's ``MAVLink.decode``, which spends most of its time per message on
generic bookkeeping. :class:`FastDecoder` does the same work for an unsigned
MAVLink 2 frame of a message the dialect knows, with what pymavlink generated
for that message (its ``unpacker`` struct, ``orders``, ``lengths``,
``crc_extra``, ``fieldnames``), planned once per message id, and builds the
*same* object: an instance of the dialect's message class with the same
attributes (fields, ``_header``, ``_msgbuf``, ``_payload``, ``_crc``,
``_signed`` ...). The CRC is checked with the dialect's own CRC-16/MCRF4XX.

:meth:`FastDecoder.message_at` returns the message alone (the tlog reader knows
the length of such a frame from its header); :meth:`FastDecoder.decode_at` adds the
frame length, for :func:`companion.mavlink.framing.try_frame`.

Everything else -- MAVLink 1 frames, signed frames, a CRC mismatch (so that
pymavlink raises its own error), ``MAV_IGNORE_CRC`` set -- goes to pymavlink
(:meth:`FastDecoder.decode` returns None and the caller falls back).
Truncated MAVLink 2 payloads (trailing zero bytes dropped by the sender) are
zero-extended exactly as pymavlink does. ``tests/mavlink/test_messages.py``
checks field-for-field equality with pymavlink on every message of every
fixture and on hand-made odd frames.

Light messages
--------------
Building the pymavlink object is most of what is left of the cost (an instance
dict of 12-20 fields plus 11 base attributes, two copies of the frame, a
``MAVLink_header``). For the message ids given as ``light_ids``,
:meth:`FastDecoder.light_at` and :meth:`FastDecoder.light_decode_at` build a
:class:`LightMessage` instead: a tuple subclass made once per message id, filled
by one ``struct`` unpack of the header and payload and one ``tuple.__new__``. It
has the same field values as the pymavlink object (same CRC check, same
zero-extension of a truncated payload) and what the known consumers of received
messages read: the fields as attributes, ``_type``, ``_header`` (the message
itself, with ``msgId``, ``seq``, ``srcSystem``, ``srcComponent``), ``get_type()``,
``get_msgId()``, ``get_seq()``, ``get_srcSystem()``, ``get_srcComponent()``,
``get_fieldnames()``, ``get_msgbuf()``, ``to_dict()``. It is opt-in, for readers
whose consumers are known (:class:`companion.mavlink.decode.Decoder` and the
service's recorder); :meth:`FastDecoder.decode` and :meth:`FastDecoder.decode_at`
keep returning pymavlink's own objects. Messages with array or string fields, a
field name that clashes with the header's, and every id outside ``light_ids``
are built as pymavlink objects by the same methods.

References
----------
MAVLink serialization (v2 frames, payload truncation, CRC_EXTRA):
https://mavlink.io/en/guide/serialization.html
"""

from __future__ import annotations

import collections
import operator
import struct
from collections.abc import Callable, Collection
from types import ModuleType
from typing import Any

from companion.mavlink.ids import CRC_LEN, HEADER_LEN_V2, STX_V2

_CRC_INIT = 0xFFFF


class _Plan:
    """How to turn one message id's payload into its pymavlink object."""

    __slots__ = (
        "cls",
        "unpack",
        "unpack_from",
        "size",
        "extra",
        "fields",
        "pick",
        "arrays",
        "has_bytes",
        "base",
    )

    def __init__(self, cls: Any) -> None:
        self.cls = cls
        self.unpack: Callable[[bytes | bytearray], tuple[Any, ...]] = cls.unpacker.unpack
        self.unpack_from: Callable[[bytes | bytearray, int], tuple[Any, ...]] = (
            cls.unpacker.unpack_from
        )
        self.size: int = cls.unpacker.size
        self.extra = bytes((cls.crc_extra,))
        self.fields: list[str] = list(cls.fieldnames)
        orders: list[int] = list(cls.orders)
        lengths: list[int] = list(cls.lengths)
        fmt = cls.unpacker.format
        fmt = fmt.decode() if isinstance(fmt, bytes) else fmt
        self.has_bytes = "s" in fmt or "c" in fmt
        if sum(lengths) == len(lengths):
            # no arrays: field i is wire element orders[i]
            self.arrays: list[tuple[int, int]] | None = None
            self.pick: Callable[[tuple[Any, ...]], Any] = (
                operator.itemgetter(*orders) if len(orders) > 1 else _first_as_tuple
            )
        else:
            # as pymavlink: field i starts at sum(lengths[:orders[i]]) and spans lengths[...]
            self.arrays = [(sum(lengths[:o]), lengths[o]) for o in orders]
            self.pick = tuple
        # what the message class's __init__ sets besides the fields (pymavlink 2.4.x)
        self.base: dict[str, Any] = {
            "_fieldnames": cls.fieldnames,
            "_type": cls.msgname,
            "_signed": False,
            "_link_id": None,
            "_instances": None,
            "_instance_field": cls.instance_field,
            "_instance_offset": cls.instance_offset,
        }


def _first_as_tuple(t: tuple[Any, ...]) -> tuple[Any, ...]:
    """The one field of a single-field message (itemgetter of one index gives no tuple)."""
    return (t[0],)


def _plain(plan: _Plan) -> bool:
    """True when the message class is one :class:`FastDecoder` can build: no string
    fields (their classes keep a raw copy and decode the text in ``__init__``), and a
    constructor that sets exactly the fields and what :class:`_Plan` assumes (checked
    on an instance built from an all-zero payload)."""
    cls = plan.cls
    if plan.has_bytes or getattr(cls, "__slots__", None):
        return False
    try:
        t = plan.unpack(bytes(plan.size))
        if plan.arrays is None:
            values = list(plan.pick(t))
        else:
            values = [t[tip] if n == 1 else list(t[tip : tip + n]) for tip, n in plan.arrays]
        msg = cls(*values)
    except Exception:  # noqa: BLE001 - an unexpected message class: leave it to pymavlink
        return False
    expected = set(plan.base) | set(plan.fields) | {"_header", "_payload", "_msgbuf", "_crc"}
    state = vars(msg)
    if set(state) != expected:
        return False
    return all(state[k] == v for k, v in plan.base.items()) and all(
        state[f] == v for f, v in zip(plan.fields, values, strict=True)
    )


_HEADER_FIELDS = ("seq", "srcSystem", "srcComponent")
"""Header bytes 4..6 of a MAVLink 2 frame, the first items of a light message."""
_HEADER_FORMAT = "<BBB3x"
"""seq, system, component, then the 3 message id bytes skipped (the class knows its id)."""
_HEADER_SKIP = 4
"""Bytes before ``seq`` in a frame: STX, length, incompat and compat flags."""


class LightMessage(tuple[Any, ...]):
    """Base of the light message classes (see the module docstring).

    A light message is ``(seq, srcSystem, srcComponent, *fields in wire order,
    frame)``; its class, made by :func:`_light_class` for one message id, names the
    items. ``_header`` is the message itself, so ``msg._header.srcSystem`` reads as on
    a pymavlink message.
    """

    __slots__ = ()
    _type: str
    _fieldnames: list[str]
    msgId: int

    @property
    def _header(self) -> LightMessage:
        """The message itself: it has the header's ``msgId``, ``seq``, ``srcSystem``
        and ``srcComponent``."""
        return self

    def get_type(self) -> str:
        """The message name (``RAW_IMU``)."""
        return self._type

    def get_msgId(self) -> int:  # noqa: N802 - pymavlink's name
        """The message id."""
        return self.msgId

    def get_seq(self) -> int:
        """The sender's sequence number."""
        seq: int = self[0]
        return seq

    def get_srcSystem(self) -> int:  # noqa: N802 - pymavlink's name
        """The sender's system id."""
        system: int = self[1]
        return system

    def get_srcComponent(self) -> int:  # noqa: N802 - pymavlink's name
        """The sender's component id."""
        component: int = self[2]
        return component

    def get_fieldnames(self) -> list[str]:
        """The field names, in pymavlink's (XML) order."""
        return self._fieldnames

    def get_msgbuf(self) -> bytearray:
        """The frame's bytes, STX to CRC (a copy, as pymavlink keeps it)."""
        frame: bytearray = self[-1]
        return frame

    def to_dict(self) -> dict[str, Any]:
        """As pymavlink's ``to_dict``: ``mavpackettype`` and the fields."""
        d: dict[str, Any] = {"mavpackettype": self._type}
        for name in self._fieldnames:
            d[name] = getattr(self, name)
        return d

    def __repr__(self) -> str:
        fields = ", ".join(f"{name} : {getattr(self, name)}" for name in self._fieldnames)
        return f"{self._type} {{{fields}}}"

    __str__ = __repr__


_RESERVED = frozenset(dir(LightMessage)) | set(_HEADER_FIELDS)


def _light_class(plan: _Plan, msg_id: int) -> type[LightMessage] | None:
    """The light class of a plain message without arrays, or None (a field name would
    clash with the header's or a method's: leave it to the pymavlink object)."""
    cls = plan.cls
    wire_names = list(cls.ordered_fieldnames)
    if plan.arrays is not None or any(n in _RESERVED or n.startswith("_") for n in wire_names):
        return None
    fmt = cls.unpacker.format
    if not (fmt.decode() if isinstance(fmt, bytes) else fmt).startswith("<"):
        return None  # pymavlink's formats are little-endian; anything else is unexpected
    names = _HEADER_FIELDS + tuple(wire_names)
    try:
        # the namedtuple gives fast C item getters for the header and field names
        named = collections.namedtuple("LightFields", names)  # type: ignore[misc]
    except ValueError:
        return None
    attrs = {
        "__slots__": (),
        "__module__": __name__,
        "_type": cls.msgname,
        "_fieldnames": list(cls.fieldnames),
        "msgId": msg_id,
    }
    return type(f"Light_{cls.msgname}", (LightMessage, named), attrs)


class _LightPlan:
    """How to build one message id's light message from a frame."""

    __slots__ = ("cls", "unpack", "unpack_from", "size", "zeros", "extra")

    def __init__(self, plan: _Plan, cls: type[LightMessage]) -> None:
        fmt = plan.cls.unpacker.format
        fmt = fmt.decode() if isinstance(fmt, bytes) else fmt
        # header and payload in one unpack: (seq, system, component, *payload fields)
        whole = struct.Struct(_HEADER_FORMAT + fmt[1:])
        self.cls = cls
        self.unpack: Callable[[bytes | bytearray], tuple[Any, ...]] = whole.unpack
        self.unpack_from: Callable[[bytes | bytearray, int], tuple[Any, ...]] = whole.unpack_from
        self.size = plan.size
        self.zeros = bytes(plan.size)
        self.extra = plan.extra


class FastDecoder:
    """Decode unsigned MAVLink 2 frames of known messages as pymavlink would.

    Parameters
    ----------
    dialect
        The pymavlink dialect module (``pymavlink.dialects.v20.<name>``).
    light_ids
        Message ids that :meth:`light_at` and :meth:`light_decode_at` build as
        :class:`LightMessage` (when the message has no array or string field).
    """

    __slots__ = (
        "_mod",
        "_map",
        "_plans",
        "_crc",
        "_header_cls",
        "_new",
        "_tuple_new",
        "_light_ids",
        "_lights",
        "enabled",
    )

    def __init__(self, dialect: ModuleType, light_ids: Collection[int] = ()) -> None:
        self._mod = dialect
        self._light_ids = frozenset(light_ids)
        self._lights: dict[int, _LightPlan | None] = {}
        self._map: dict[int, Any] = dialect.mavlink_map
        self._plans: dict[int, _Plan | None] = {}
        self._crc: Callable[[bytes | bytearray, int], int] | None = getattr(
            dialect, "mcrf4xx", None
        )
        self._header_cls = dialect.MAVLink_header
        self._new = object.__new__
        self._tuple_new = tuple.__new__
        self.enabled = not getattr(dialect, "MAVLINK_IGNORE_CRC", 0)

    def _plan(self, msg_id: int) -> _Plan | None:
        """Plan (and remember) how to decode ``msg_id``; None: leave it to pymavlink."""
        cls = self._map.get(msg_id)
        plan = _Plan(cls) if cls is not None else None
        if plan is not None and not _plain(plan):
            plan = None
        self._plans[msg_id] = plan
        return plan

    def _light_plan(self, msg_id: int) -> _LightPlan | None:
        """Plan (and remember) the light message of ``msg_id``; None: a pymavlink object."""
        light: _LightPlan | None = None
        if msg_id in self._light_ids and self._crc is not None:
            try:
                plan = self._plans[msg_id]
            except KeyError:
                plan = self._plan(msg_id)
            cls = _light_class(plan, msg_id) if plan is not None else None
            if plan is not None and cls is not None:
                light = _LightPlan(plan, cls)
        self._lights[msg_id] = light
        return light

    def decode(self, frame: bytearray) -> Any | None:
        """The pymavlink message of one complete frame, or None to let pymavlink decode it.

        ``frame`` is exactly one frame (STX to CRC, and signature if any).
        """
        found = self.decode_at(frame, 0)
        if found is None or found[1] != len(frame):
            return None
        return found[0]

    def decode_at(self, buf: bytearray, pos: int) -> tuple[Any, int] | None:
        """``(message, frame length)`` of the frame whose STX is at ``buf[pos]``, or None
        to let pymavlink decide (not an unsigned MAVLink 2 frame of a plain message, too
        short yet, or a CRC mismatch). The frame's bytes are copied into the message's
        ``_msgbuf`` (a bytearray, as pymavlink keeps it)."""
        msg = self.message_at(buf, pos)
        if msg is None:
            return None
        return msg, HEADER_LEN_V2 + buf[pos + 1] + CRC_LEN

    def _frame_at(self, buf: bytearray, pos: int) -> tuple[int, int, int] | None:
        """``(payload length, frame length, message id)`` of the unsigned MAVLink 2 frame
        whose STX is at ``buf[pos]``, or None (short, not MAVLink 2, signed or unknown
        flags, or no CRC check)."""
        avail = len(buf) - pos
        if avail < HEADER_LEN_V2 or buf[pos] != STX_V2 or buf[pos + 2] != 0 or not self.enabled:
            return None
        mlen = buf[pos + 1]
        n = HEADER_LEN_V2 + mlen + CRC_LEN
        if n > avail:
            return None
        return mlen, n, buf[pos + 7] | (buf[pos + 8] << 8) | (buf[pos + 9] << 16)

    def message_at(self, buf: bytearray, pos: int) -> Any | None:
        """The message of :meth:`decode_at` alone (its frame is ``12 + buf[pos + 1]``
        bytes long, an unsigned MAVLink 2 frame), or None."""
        found = self._frame_at(buf, pos)
        if found is None:
            return None
        return self._pymavlink_at(buf, pos, *found)

    def _pymavlink_at(self, buf: bytearray, pos: int, mlen: int, n: int, msg_id: int) -> Any:
        """pymavlink's object of the frame :meth:`_frame_at` found, or None."""
        try:
            plan = self._plans[msg_id]
        except KeyError:
            plan = self._plan(msg_id)
        crc_fn = self._crc
        if plan is None or crc_fn is None:
            return None
        frame = buf[pos : pos + n]
        crc = frame[n - 2] | (frame[n - 1] << 8)
        if crc_fn(plan.extra, crc_fn(frame[1 : n - 2], _CRC_INIT)) != crc:
            return None  # pymavlink raises its own error for it
        size = plan.size
        if mlen == size:
            t = plan.unpack_from(frame, HEADER_LEN_V2)
        else:
            payload = frame[HEADER_LEN_V2 : n - 2]
            if mlen < size:
                payload.extend(bytes(size - mlen))  # truncated by the sender: zero-extend
            else:
                payload = payload[:size]
            t = plan.unpack(payload)
        arrays = plan.arrays
        if arrays is None:
            values: Any = plan.pick(t)
        else:
            values = []
            for tip, length in arrays:
                field = t[tip]
                if length == 1 or isinstance(field, bytes):
                    values.append(field)
                else:
                    values.append(list(t[tip : tip + length]))
        msg = self._new(plan.cls)
        d = msg.__dict__
        d.update(plan.base)
        d.update(zip(plan.fields, values, strict=False))  # as many as fields, by construction
        d["_msgbuf"] = frame
        d["_payload"] = frame[6 : n - 2]
        d["_crc"] = crc
        d["_header"] = self._header_cls(msg_id, 0, frame[3], mlen, frame[4], frame[5], frame[6])
        return msg

    def light_decode_at(self, buf: bytearray, pos: int) -> tuple[Any, int] | None:
        """:meth:`decode_at` with a :class:`LightMessage` for the ids of ``light_ids``
        (and pymavlink's object for the others)."""
        msg = self.light_at(buf, pos)
        if msg is None:
            return None
        return msg, HEADER_LEN_V2 + buf[pos + 1] + CRC_LEN

    def light_at(self, buf: bytearray, pos: int) -> Any | None:
        """:meth:`message_at` with a :class:`LightMessage` for the ids of ``light_ids``
        (the same checks, the same field values)."""
        found = self._frame_at(buf, pos)
        if found is None:
            return None
        mlen, n, msg_id = found
        try:
            light = self._lights[msg_id]
        except KeyError:
            light = self._light_plan(msg_id)
        if light is None:
            return self._pymavlink_at(buf, pos, mlen, n, msg_id)
        crc_fn: Callable[[bytes | bytearray, int], int] = self._crc  # type: ignore[assignment]
        frame = buf[pos : pos + n]
        crc = frame[n - 2] | (frame[n - 1] << 8)
        if crc_fn(light.extra, crc_fn(frame[1 : n - 2], _CRC_INIT)) != crc:
            return None  # pymavlink raises its own error for it
        if mlen >= light.size:
            # a longer payload (newer dialect) is cut to the known fields, as message_at does
            t = light.unpack_from(frame, _HEADER_SKIP)
        else:
            head = frame[_HEADER_SKIP : n - CRC_LEN]
            head += light.zeros[mlen:]  # truncated by the sender: zero-extend
            t = light.unpack(head)
        return self._tuple_new(light.cls, t + (frame,))

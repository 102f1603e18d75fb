"""Packing messages into MAVLink 2 frames, byte for byte as pymavlink packs them.

:class:`Packer` serialises messages with our system and component id and the
next sequence number. Messages without arrays or strings are packed here with
the message class's own ``struct``, the MAVLink 2 trailing-zero truncation and
CRC_EXTRA (a plan made once per class); anything else, and every message while
signing is on, goes to pymavlink's ``msg.pack``.

References
----------
MAVLink serialization (v2 frames, payload truncation, CRC_EXTRA):
https://mavlink.io/en/guide/serialization.html
"""

from __future__ import annotations

import operator
import struct
from types import ModuleType
from typing import Any

from companion.mavlink.ids import CRC_LEN, HEADER_LEN_V2, STX_V2

_HEADER_V2 = struct.Struct("<7B3s")
"""STX, payload length, incompat and compat flags, seq, system, component, 24-bit id."""
_CRC = struct.Struct("<H")


def _pack_plan(mod: Any, cls: type) -> Any:
    """``(field getter, payload packer, id, id bytes, CRC_EXTRA byte)`` for a message class
    :meth:`Packer.pack` packs itself, or False (arrays, strings, MAVLink 1 or no fast CRC:
    pymavlink packs those)."""
    try:
        fields = list(cls.ordered_fieldnames)  # type: ignore[attr-defined]
        lengths = list(cls.lengths)  # type: ignore[attr-defined]
        fmt = cls.unpacker.format  # type: ignore[attr-defined]
        msg_id = int(cls.id)  # type: ignore[attr-defined]
        extra = bytes((int(cls.crc_extra),))  # type: ignore[attr-defined]
    except (AttributeError, TypeError, ValueError):
        return False
    fmt = fmt.decode() if isinstance(fmt, bytes) else fmt
    if (
        getattr(mod, "mcrf4xx", None) is None
        or float(mod.WIRE_PROTOCOL_VERSION) != 2.0
        or sum(lengths) != len(lengths)
        or "s" in fmt
        or "c" in fmt
        or not fields
    ):
        return False
    get = operator.attrgetter(*fields)
    getter = get if len(fields) > 1 else (lambda m, _g=get: (_g(m),))
    id_bytes = bytes((msg_id & 0xFF, (msg_id >> 8) & 0xFF, msg_id >> 16))
    return getter, cls.unpacker.pack, msg_id, id_bytes, extra  # type: ignore[attr-defined]


def _args_pack_plan(mod: Any, cls: type) -> Any:
    """``(wire-order picker, payload packer, id bytes, CRC_EXTRA byte)`` to pack a message of
    class ``cls`` straight from its constructor arguments, or False (MAVLink 1, arrays, no
    fast CRC: those are built and packed by pymavlink).

    pymavlink's ``pack`` packs the attributes its constructor stored, in wire order
    (``ordered_fieldnames``); a ``char[]`` field is packed from the raw bytes given to the
    constructor. So the payload is the constructor arguments permuted to wire order.
    """
    try:
        fields = list(cls.fieldnames)  # type: ignore[attr-defined]
        ordered = list(cls.ordered_fieldnames)  # type: ignore[attr-defined]
        lengths = list(cls.lengths)  # type: ignore[attr-defined]
        msg_id = int(cls.id)  # type: ignore[attr-defined]
        extra = bytes((int(cls.crc_extra),))  # type: ignore[attr-defined]
        pack_payload = cls.unpacker.pack  # type: ignore[attr-defined]
    except (AttributeError, TypeError, ValueError):
        return False
    if (
        getattr(mod, "mcrf4xx", None) is None
        or float(mod.WIRE_PROTOCOL_VERSION) != 2.0
        or sum(lengths) != len(lengths)
        or len(fields) < 2
        or sorted(fields) != sorted(ordered)
    ):
        return False
    pick = operator.itemgetter(*(fields.index(name) for name in ordered))
    id_bytes = bytes((msg_id & 0xFF, (msg_id >> 8) & 0xFF, msg_id >> 16))
    return pick, pack_payload, id_bytes, extra


class Packer:
    """Frames messages of one dialect with one source system and component.

    Parameters
    ----------
    mod
        The pymavlink dialect module.
    component
        Our component id.

    Attributes
    ----------
    mav
        The pymavlink ``MAVLink`` object whose ``srcSystem``, ``srcComponent``, ``seq``
        and ``signing`` the frames carry.
    """

    def __init__(self, mod: ModuleType, component: int) -> None:
        self._mod = mod
        self.mav = mod.MAVLink(None, srcSystem=0, srcComponent=0)
        self.mav.srcComponent = component
        self._pack_plans: dict[type, Any] = {}
        self._args_plans: dict[type, Any] = {}
        self._crc: Any = getattr(mod, "mcrf4xx", None)

    def pack(self, msg: Any) -> bytes:
        """Serialise ``msg`` with the next sequence number.

        Messages without arrays or strings are packed here with the message class's own
        struct, the MAVLink 2 trailing-zero truncation and CRC_EXTRA, byte for byte what
        pymavlink's ``msg.pack`` gives (and the same ``_msgbuf``, ``_payload``, ``_crc``
        and ``_header`` are left on the message); anything else goes to pymavlink.
        """
        mav = self.mav
        plan = self._pack_plans.get(type(msg))
        if plan is None:
            plan = self._pack_plans[type(msg)] = _pack_plan(self._mod, type(msg))
        if plan is False or mav.signing.sign_outgoing:
            data = bytes(msg.pack(mav))
        else:
            get, pack_payload, msg_id, id_bytes, extra = plan
            data = self._frame(pack_payload(*get(msg)), id_bytes, extra)
            msg._payload = data[HEADER_LEN_V2:-CRC_LEN]
            msg._header = self._mod.MAVLink_header(
                msg_id, 0, 0, data[1], mav.seq, mav.srcSystem, mav.srcComponent
            )
            msg._msgbuf = bytearray(data)
            msg._crc = data[-2] | (data[-1] << 8)
        mav.seq = (mav.seq + 1) % 256
        return data

    def pack_args(self, cls: type, args: tuple[Any, ...]) -> tuple[str, bytes]:
        """``(name, frame)`` of ``cls(*args)`` as :meth:`pack` would pack it."""
        plan = self._args_plans.get(cls)
        if plan is None:
            plan = self._args_plans[cls] = _args_pack_plan(self._mod, cls)
        mav = self.mav
        if plan is False or mav.signing.sign_outgoing:
            msg = cls(*args)
            return msg._type, self.pack(msg)
        pick, pack_payload, id_bytes, extra = plan
        data = self._frame(pack_payload(*pick(args)), id_bytes, extra)
        mav.seq = (mav.seq + 1) % 256
        return cls.msgname, data  # type: ignore[attr-defined]

    def _frame(self, payload: bytes, id_bytes: bytes, extra: bytes) -> bytes:
        """The unsigned MAVLink 2 frame of ``payload`` with the current sequence number
        (not advanced here), as pymavlink frames it (trailing zeros truncated)."""
        mav = self.mav
        stripped = payload.rstrip(b"\x00") or payload[:1]
        buf = _HEADER_V2.pack(
            STX_V2, len(stripped), 0, 0, mav.seq, mav.srcSystem, mav.srcComponent, id_bytes
        )
        buf += stripped
        return buf + _CRC.pack(self._crc(extra, self._crc(buf[1:], 0xFFFF)))

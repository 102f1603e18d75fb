"""Robust MAVLink framing: bytes in, good messages out, corrupt frames counted.

pymavlink's own ``robust_parsing`` drops a whole frame of the length written in
a (possibly corrupted) header when its CRC fails, so a flipped length byte can
swallow the good frames that follow. :class:`FrameParser` does its own
framing instead and, when a candidate frame fails (bad CRC, bad header,
message id unknown to the dialect, truncated), it resynchronises one byte
later. The decoding and CRC check of a candidate are pymavlink's
(``MAVLink.decode``), so what is accepted is exactly what pymavlink accepts;
the common frames go through :class:`~companion.mavlink.messages.FastDecoder`,
which builds the same message objects from pymavlink's own message
definitions, more cheaply (anything it does not handle still goes to
``MAVLink.decode``).

Counting convention: ``bad_frames`` counts *bad regions*, a maximal run of
bytes between two good frames that could not be decoded (one corrupt frame, a
burst of garbage, a frame cut short followed by a good one). ``bad_bytes``
counts the bytes in them.

A message id that the dialect does not know (PX4 sends ESC_INFO and ESC_STATUS,
newer than pymavlink's dialects) cannot be CRC-checked exactly: its CRC_EXTRA
byte is unknown. Such a frame is *unknown*, not bad, when some CRC_EXTRA byte
makes its CRC check (1 chance in 256 for random bytes: the CRC's last step is
a bijection of that byte onto 256 of the 65536 values) and the next frame's
STX follows it at once (or the data ends there): ``unknown_frames`` counts
them, they are skipped whole. Anything else with an unknown id is bad bytes.

References
----------
MAVLink serialization (v1 0xFE and v2 0xFD frames):
https://mavlink.io/en/guide/serialization.html
"""

from __future__ import annotations

import logging
import re
from collections.abc import Callable, Collection
from typing import Any

from companion.mavlink.dialect import load_dialect
from companion.mavlink.ids import (
    CRC_LEN,
    HEADER_LEN_V1,
    HEADER_LEN_V2,
    IFLAG_SIGNED,
    SIGNATURE_LEN,
    STX_V1,
    STX_V2,
)
from companion.mavlink.messages import FastDecoder

logger = logging.getLogger(__name__)

_STX_RE = re.compile(b"[\xfd\xfe]")

# Results of :func:`try_frame`.
FRAME_OK = 0
FRAME_NEED_MORE = 1
FRAME_BAD = 2
FRAME_UNKNOWN = 3


def _x25_tails() -> frozenset[int]:
    """What the X.25 CRC's step on a last byte can XOR into ``crc >> 8`` (256 values)."""
    tails = set()
    for b in range(256):
        tmp = (b ^ (b << 4)) & 0xFF
        tails.add(((tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)) & 0xFFFF)
    return frozenset(tails)


_X25_TAILS = _x25_tails()
_CRC_INIT = 0xFFFF


def _crc_x25(data: bytes | bytearray) -> int:
    """MAVLink's CRC (X.25, MCRF4XX) of ``data``, from 0xFFFF."""
    crc = _CRC_INIT
    for b in data:
        tmp = (b ^ crc) & 0xFF
        tmp = (tmp ^ (tmp << 4)) & 0xFF
        crc = ((crc >> 8) ^ (tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)) & 0xFFFF
    return crc


def unknown_frame_checks(buf: bytes | bytearray, pos: int, length: int, gap: int = 0) -> bool:
    """Is the complete frame at ``buf[pos:pos + length]``, of a message id the dialect does
    not know, a valid frame? True when its CRC checks for some CRC_EXTRA byte and the byte
    ``gap`` after its end is an STX (or the data ends there).

    ``gap`` is what separates frames in the stream: 0 on a link, the 8-byte timestamp in
    a .tlog.
    """
    signed = buf[pos] == STX_V2 and buf[pos + 2] & IFLAG_SIGNED
    crc_end = pos + length - (SIGNATURE_LEN if signed else 0)
    crc = buf[crc_end - 2] | (buf[crc_end - 1] << 8)
    partial = _crc_x25(buf[pos + 1 : crc_end - 2])
    if (crc ^ (partial >> 8)) not in _X25_TAILS:
        return False
    nxt = pos + length + gap
    return nxt >= len(buf) or buf[nxt] == STX_V2 or buf[nxt] == STX_V1


def frame_length(buf: bytes | bytearray, pos: int) -> int:
    """Total length in bytes of the frame whose STX is at ``buf[pos]``, or 0 if unknown yet.

    ``buf[pos]`` must be an STX byte. Returns 0 when the header bytes needed to
    know the length are not in ``buf`` yet.
    """
    n = len(buf) - pos
    if buf[pos] == STX_V2:
        if n < 3:
            return 0
        length = HEADER_LEN_V2 + buf[pos + 1] + CRC_LEN
        if buf[pos + 2] & IFLAG_SIGNED:
            length += SIGNATURE_LEN
        return length
    if n < 2:
        return 0
    return HEADER_LEN_V1 + buf[pos + 1] + CRC_LEN


def try_frame(
    mav: Any,
    mavlink_map: dict[int, Any],
    buf: bytearray,
    pos: int,
    fast: FastDecoder | None = None,
    light: bool = False,
    gap: int = 0,
) -> tuple[int, Any, int]:
    """Try to decode one frame whose STX byte is at ``buf[pos]``.

    Parameters
    ----------
    mav
        A pymavlink ``MAVLink`` object (its ``decode`` checks the CRC).
    mavlink_map
        The dialect's ``mavlink_map`` (message id -> class).
    buf
        The bytes; ``buf[pos]`` is 0xFD or 0xFE.
    pos
        Index of the STX byte.
    fast
        Optional :class:`~companion.mavlink.messages.FastDecoder` of the same
        dialect: it decodes the common frames to the very objects pymavlink would
        build, faster; whatever it declines goes to ``mav.decode``.
    light
        With ``fast``: light messages for the fast decoder's ``light_ids``
        (:meth:`~companion.mavlink.messages.FastDecoder.light_decode_at`).
    gap
        Bytes between one frame and the next in this stream (0 on a link, 8 in a .tlog):
        where :func:`unknown_frame_checks` looks for the next STX.

    Returns
    -------
    (status, message, length)
        ``FRAME_OK`` with the message and the frame length; ``FRAME_NEED_MORE``
        when ``buf`` ends before the frame does; ``FRAME_UNKNOWN`` (no message) for a
        valid frame of a message id the dialect does not know
        (:func:`unknown_frame_checks`); ``FRAME_BAD`` when the bytes are not a frame.
    """
    if fast is not None:
        found = fast.light_decode_at(buf, pos) if light else fast.decode_at(buf, pos)
        if found is not None:
            return FRAME_OK, found[0], found[1]
    length = frame_length(buf, pos)
    if length == 0 or len(buf) - pos < length:
        return FRAME_NEED_MORE, None, 0
    if buf[pos] == STX_V2:
        if buf[pos + 2] & ~IFLAG_SIGNED:
            return FRAME_BAD, None, length  # unknown incompatibility flag
        msg_id = buf[pos + 7] | (buf[pos + 8] << 8) | (buf[pos + 9] << 16)
    else:
        msg_id = buf[pos + 5]
    if msg_id not in mavlink_map:
        if unknown_frame_checks(buf, pos, length, gap):
            return FRAME_UNKNOWN, None, length
        return FRAME_BAD, None, length
    try:
        msg = mav.decode(buf[pos : pos + length])
    except Exception:  # noqa: BLE001 - pymavlink raises MAVError and others on corrupt input
        return FRAME_BAD, None, length
    return FRAME_OK, msg, length


class FrameParser:
    """Bytes from a link in, good MAVLink messages out; never raises on bad input.

    Parameters
    ----------
    dialect
        pymavlink v2.0 dialect module name (``ardupilotmega`` by default).
    light_ids
        Message ids returned as :class:`~companion.mavlink.messages.LightMessage`
        rather than pymavlink objects, for consumers known to read only what it has
        (see :data:`companion.mavlink.decode.LIGHT_MESSAGE_IDS`). Default: none.
    frame_check
        Optional: called with the bytes of every frame that decoded (CRC checked), it
        says whether to pass the message on; a frame it refuses is dropped (not bad
        bytes: it counts it itself). The service's signature check
        (:meth:`companion.mavlink.signing.Verifier.accept`) is one.

    Attributes
    ----------
    bad_frames : int
        Bad regions seen (see the module docstring for the convention).
    bad_bytes : int
        Bytes in those regions.
    good_frames : int
        Messages returned.
    refused_frames : int
        Frames ``frame_check`` refused.
    unknown_frames : int
        Valid frames of message ids the dialect does not know, skipped (not bad).
    """

    __slots__ = (
        "_buf",
        "_mav",
        "_map",
        "_fast",
        "_light",
        "_in_bad",
        "_check",
        "refused_frames",
        "unknown_frames",
        "bad_frames",
        "bad_bytes",
        "good_frames",
    )

    def __init__(
        self,
        dialect: str = "ardupilotmega",
        light_ids: Collection[int] = (),
        frame_check: Callable[[bytearray], bool] | None = None,
    ) -> None:
        mod = load_dialect(dialect)
        self._mav = mod.MAVLink(None)
        self._map: dict[int, Any] = mod.mavlink_map
        self._fast = FastDecoder(mod, light_ids)
        self._light = bool(light_ids)
        self._buf = bytearray()
        self._in_bad = False
        self.bad_frames = 0
        self.bad_bytes = 0
        self.good_frames = 0
        self._check = frame_check
        self.refused_frames = 0
        self.unknown_frames = 0

    def _mark_bad(self, nbytes: int) -> None:
        if not self._in_bad:
            self._in_bad = True
            self.bad_frames += 1
        self.bad_bytes += nbytes

    def feed(self, data: bytes | bytearray) -> list[Any]:
        """Add bytes and return the messages completed by them (possibly none).

        Incomplete trailing bytes are kept for the next call.
        """
        self._buf.extend(data)
        return self._scan(end_of_stream=False)

    def flush(self) -> list[Any]:
        """End of stream: decode what the tail still holds, count the rest as bad.

        A false STX inside a bad region can claim a length that runs past the
        end of the data; :meth:`feed` waits for more bytes, here there are none,
        so scanning resumes one byte later and good frames behind it are kept.
        """
        out = self._scan(end_of_stream=True)
        self._buf.clear()
        return out

    def _scan(self, end_of_stream: bool) -> list[Any]:
        """Decode the good frames of the buffer, counting bad regions.

        A frame whose length runs past the end of the buffer waits for more bytes,
        unless the stream has ended: then it is a false STX, scanning resumes one
        byte later.
        """
        buf = self._buf
        check = self._check
        out: list[Any] = []
        pos = 0
        n = len(buf)
        while pos < n:
            if buf[pos] != STX_V2 and buf[pos] != STX_V1:
                m = _STX_RE.search(buf, pos)
                nxt = n if m is None else m.start()
                self._mark_bad(nxt - pos)
                pos = nxt
                continue
            status, msg, length = try_frame(self._mav, self._map, buf, pos, self._fast, self._light)
            if status == FRAME_OK:
                if check is None or check(buf[pos : pos + length]):
                    out.append(msg)
                else:
                    self.refused_frames += 1
                self._in_bad = False
                pos += length
            elif status == FRAME_UNKNOWN:
                self.unknown_frames += 1
                self._in_bad = False
                pos += length
            elif status == FRAME_BAD or end_of_stream:
                self._mark_bad(1)
                pos += 1
            else:
                break
        if pos:
            del buf[:pos]
        self.good_frames += len(out)
        return out

    @property
    def pending_bytes(self) -> int:
        """Bytes waiting for the rest of their frame."""
        return len(self._buf)

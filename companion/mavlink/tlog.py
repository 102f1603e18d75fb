"""Telemetry logs (.tlog): read robustly, write simply.

A .tlog is a sequence of records, each an 8-byte big-endian unsigned
timestamp (microseconds since the UNIX epoch when the record was received, the
convention of MAVProxy and Mission Planner) followed by one raw MAVLink frame.
The frame's CRC does not cover the timestamp.

:class:`TlogReader` never raises on bad content, only on a file it cannot
open (:class:`TlogError`). What it skips, it counts in :attr:`TlogReader.stats`:

``bad_region``
    a run of bytes between two good records that is not a record (corrupt
    frame, garbage, a record cut short). Scanning resumes one byte later, so
    every good record around a bad one is still read.
``bad_bytes``
    the bytes in those runs.
``truncated_record``
    an incomplete record at the end of the file.
``unknown_frame``
    a valid record of a message id the dialect does not know (see
    :func:`companion.mavlink.framing.unknown_frame_checks`), skipped whole.
``time_backwards``
    a good frame whose timestamp is earlier than the previous accepted one.
``time_jump``
    a good frame whose timestamp is more than ``max_gap_s`` after the previous
    accepted one (typically a bit flip in the timestamp, which no CRC protects).
``clock_rebased``
    ``resync_records`` consecutive skipped records agreed with each other (the
    recording clock really stepped): the reader accepts the new clock from the
    last of them on. The earlier ones of the run stay skipped.

A file that is plainly something else (an ArduPilot DataFlash ``.bin``, a PX4
``.ulg`` — :mod:`companion.mavlink.logs` reads those —, an image, an archive), judged
by its first bytes and never by its name, is refused at once with a :class:`TlogError`
that says what it is and what to do; a record's 8-byte UNIX-epoch or boot-time stamp
never starts with those bytes. For a file in which no record was found,
:func:`describe_file` says what it looks like.
"""

from __future__ import annotations

import collections
import logging
import struct
from collections.abc import Collection, Iterator
from pathlib import Path
from types import TracebackType
from typing import Any, BinaryIO

from companion.mavlink.dialect import load_dialect
from companion.mavlink.framing import (
    FRAME_BAD,
    FRAME_NEED_MORE,
    FRAME_UNKNOWN,
    FrameParser,
    try_frame,
)
from companion.mavlink.ids import CRC_LEN, HEADER_LEN_V2, STX_V1, STX_V2
from companion.mavlink.messages import FastDecoder
from companion.mavlink.units import US_PER_S

logger = logging.getLogger(__name__)

TIMESTAMP_LEN = 8
_TS = struct.Struct(">Q")
_TS_PACK = _TS.pack
_MAX_T_S = 1.8e13
"""Largest record time written, s (the 8-byte microsecond field holds up to 1.8e13 s)."""
_CHUNK_BYTES = 1 << 20
_BYTES_LIKE = (bytes, bytearray, memoryview)
_V2_OVERHEAD = HEADER_LEN_V2 + CRC_LEN
"""Bytes of an unsigned MAVLink 2 frame besides its payload."""


class TlogError(Exception):
    """The log cannot be read at all (missing, unreadable, a directory, another format...)."""


_REPLAY_IT = "`companion replay` reads it and writes the .tlog this takes"
_FOREIGN_FORMATS: tuple[tuple[bytes, str], ...] = (
    (b"\xa3\x95", f"an ArduPilot DataFlash log (.bin), not a .tlog: {_REPLAY_IT}"),
    (b"ULog", f"a PX4 ULog (.ulg), not a .tlog: {_REPLAY_IT}"),
    (b"\x89PNG\r\n\x1a\n", "a PNG image, not a .tlog"),
    (b"\xff\xd8\xff", "a JPEG image, not a .tlog"),
    (b"%PDF", "a PDF document, not a .tlog"),
    (b"\x1f\x8b", "gzip-compressed: decompress it first (gunzip)"),
    (b"PK\x03\x04", "a zip archive: extract the .tlog first"),
)
"""Magic numbers of files taken for a .tlog by mistake, and what to say about them."""
_TEXT_SNIFF_BYTES = 4096
_RAW_SNIFF_BYTES = 65536
_RAW_MIN_FRAMES = 3
"""Good frames in the first 64 KiB that make a file without records a raw MAVLink stream."""


def foreign_format(head: bytes) -> str | None:
    """What a file starting with ``head`` is, when its magic number says it is no .tlog."""
    for magic, what in _FOREIGN_FORMATS:
        if head.startswith(magic):
            return what
    return None


def describe_file(path: Path | str) -> str:
    """One line on what ``path`` looks like, for a file in which no record was found:
    empty, a known other format, raw MAVLink frames without record stamps, text (with
    its first line) or other binary data."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            head = fh.read(_RAW_SNIFF_BYTES)
            size = fh.seek(0, 2)
    except OSError as exc:
        return f"unreadable: {exc.strerror or exc}"
    if not head:
        return "an empty file"
    known = foreign_format(head)
    if known is not None:
        return known
    parser = FrameParser()
    if len(parser.feed(head)) >= _RAW_MIN_FRAMES:
        return (
            f"raw MAVLink frames without the tlog's 8-byte time stamps ({size} bytes): "
            "not a .tlog (mavlogdump.py --no-timestamps reads it)"
        )
    sample = head[:_TEXT_SNIFF_BYTES]
    try:
        text = sample.decode("utf-8")
    except UnicodeDecodeError as exc:
        # a multi-byte character cut at the end of the sample is still text
        text = sample[: exc.start].decode("utf-8") if exc.start >= len(sample) - 3 else ""
    if text and all(c.isprintable() or c in "\r\n\t" for c in text):
        first = text.splitlines()[0].strip() if text.strip() else ""
        shown = first if len(first) <= 40 else first[:37] + "..."
        return f"a text file ({size} bytes, first line {shown!r}), not a .tlog"
    return f"binary data ({size} bytes), not a .tlog"


class TlogReader:
    """Iterate ``(t_rx_s, message)`` over a .tlog; robust to corruption.

    Parameters
    ----------
    path
        The file.
    dialect
        pymavlink v2.0 dialect module name.
    max_gap_s
        Largest forward step between consecutive records accepted as real, s.
    resync_records
        Consecutive mutually consistent skipped records after which the reader
        accepts that the recording clock stepped.
    light_ids
        Message ids yielded as :class:`~companion.mavlink.messages.LightMessage`
        (fields, header and pymavlink's few accessors, cheaper to build)
        rather than pymavlink objects: for consumers known to read only those, such as
        :class:`companion.mavlink.decode.Decoder` with
        :data:`companion.mavlink.decode.LIGHT_MESSAGE_IDS`. Default: none.

    Raises
    ------
    TlogError
        At construction, if the file cannot be opened or its first bytes say it is
        another format (:func:`foreign_format`).
    """

    def __init__(
        self,
        path: Path | str,
        dialect: str = "ardupilotmega",
        max_gap_s: float = 3600.0,
        resync_records: int = 5,
        light_ids: Collection[int] = (),
    ) -> None:
        self.path = Path(path)
        self._light_ids = frozenset(light_ids)
        try:
            mod = load_dialect(dialect)
        except ValueError as exc:
            raise TlogError(str(exc)) from exc
        self._mod = mod
        self._max_gap_us = int(max_gap_s * US_PER_S)
        self._resync = max(1, int(resync_records))
        try:
            fh = open(self.path, "rb")  # noqa: SIM115 - closed in __iter__
            head = fh.read(16)
            fh.seek(0)
        except OSError as exc:
            raise TlogError(f"cannot open tlog {self.path}: {exc.strerror or exc}") from exc
        foreign = foreign_format(head)
        if foreign is not None:
            fh.close()
            raise TlogError(f"{self.path}: {foreign}")
        self._fh: BinaryIO | None = fh
        self.stats: collections.Counter[str] = collections.Counter()
        self.messages = 0

    def close(self) -> None:
        """Close the file (iteration also closes it when done)."""
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def __enter__(self) -> TlogReader:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def __iter__(self) -> Iterator[tuple[float, Any]]:
        fh = self._fh
        if fh is None:
            return
        mav = self._mod.MAVLink(None)
        mmap_ = self._mod.mavlink_map
        fast = FastDecoder(self._mod, self._light_ids)
        message_at = fast.light_at if self._light_ids else fast.message_at
        timestamp_at = _TS.unpack_from
        stats = self.stats
        buf = bytearray()
        last_us: int | None = None
        cand_us: int | None = None
        cand_run = 0
        in_bad = False
        tail_cut = False
        eof = False
        max_gap = self._max_gap_us
        try:
            while True:
                if not eof:
                    try:
                        chunk = fh.read(_CHUNK_BYTES)
                    except OSError as exc:
                        logger.warning("tlog %s: read error %s; stopping", self.path, exc)
                        chunk = b""
                    if chunk:
                        buf.extend(chunk)
                    else:
                        eof = True
                pos = 0
                n = len(buf)
                while n - pos > TIMESTAMP_LEN:
                    p = pos + TIMESTAMP_LEN
                    # the usual record first: an unsigned MAVLink 2 frame the fast path decodes
                    msg = message_at(buf, p)
                    if msg is not None:
                        length = _V2_OVERHEAD + buf[p + 1]
                    else:
                        if buf[p] == STX_V2 or buf[p] == STX_V1:
                            # pymavlink decides what the fast path declined
                            status, msg, length = try_frame(mav, mmap_, buf, p, gap=TIMESTAMP_LEN)
                        else:
                            status = FRAME_BAD
                        if status == FRAME_NEED_MORE:
                            if not eof:
                                break
                            # At the end of the file this frame can never complete: either
                            # the last record is cut short, or a false STX in a bad region.
                            if not in_bad:
                                in_bad = True
                                tail_cut = True
                            stats["bad_bytes"] += 1
                            pos += 1
                            continue
                        if status == FRAME_UNKNOWN:
                            stats["unknown_frame"] += 1
                            if tail_cut:
                                stats["bad_region"] += 1
                                tail_cut = False
                            in_bad = False
                            pos = p + length
                            continue
                        if status == FRAME_BAD:
                            if not in_bad:
                                in_bad = True
                                stats["bad_region"] += 1
                            stats["bad_bytes"] += 1
                            pos += 1
                            continue
                    # FRAME_OK
                    if tail_cut:  # the region that began with a cut frame was not the tail
                        stats["bad_region"] += 1
                        tail_cut = False
                    in_bad = False
                    t_us = timestamp_at(buf, pos)[0]
                    pos = p + length
                    if last_us is not None and (t_us < last_us or t_us - last_us > max_gap):
                        stats["time_backwards" if t_us < last_us else "time_jump"] += 1
                        if cand_us is not None and 0 <= t_us - cand_us <= max_gap:
                            cand_run += 1
                        else:
                            cand_run = 1
                        cand_us = t_us
                        if cand_run < self._resync:
                            continue
                        stats["clock_rebased"] += 1
                        logger.warning(
                            "tlog %s: recording clock stepped by %.3f s; following it",
                            self.path,
                            (t_us - last_us) / US_PER_S,
                        )
                    cand_us = None
                    cand_run = 0
                    last_us = t_us
                    self.messages += 1
                    yield t_us / US_PER_S, msg
                if pos:
                    del buf[:pos]
                if eof:
                    break
            if buf:  # fewer than a timestamp and an STX left
                stats["bad_bytes"] += len(buf)
                if not in_bad:
                    tail_cut = True
            if tail_cut:
                stats["truncated_record"] += 1
        finally:
            self.close()
        if stats and self.messages:  # with none, the caller says what the file is
            logger.info("tlog %s: %d messages; skipped %s", self.path, self.messages, dict(stats))


def read_tlog(path: Path | str, dialect: str = "ardupilotmega") -> Iterator[tuple[float, Any]]:
    """Iterate ``(t_rx_s, message)`` over a .tlog (see :class:`TlogReader` for the counts).

    ``t_rx_s`` is the record's UNIX-epoch time in seconds.

    Raises
    ------
    TlogError
        Immediately (not at the first ``next``) if the file cannot be opened.
    """
    return iter(TlogReader(path, dialect))


class TlogWriter:
    """Append records to a .tlog; a context manager.

    Parameters
    ----------
    path
        The file, created or truncated.
    mav
        Optional pymavlink ``MAVLink`` object used to pack message objects that
        have never been packed (default: a dialect ``ardupilotmega`` packer with
        system 0, component 0). Messages that came from a parser or were packed
        already are written byte for byte as they were.

    Raises
    ------
    TlogError
        If the file cannot be created.
    """

    def __init__(self, path: Path | str, mav: Any = None) -> None:
        self.path = Path(path)
        try:
            self._fh: BinaryIO | None = open(self.path, "wb")  # noqa: SIM115
        except OSError as exc:
            raise TlogError(f"cannot create tlog {self.path}: {exc.strerror or exc}") from exc
        if mav is None:
            mav = load_dialect("ardupilotmega").MAVLink(None)
        self._mav = mav
        self.records = 0

    def write(self, t_s: float, msg_or_bytes: Any) -> None:
        """Append one record stamped ``t_s`` (UNIX-epoch seconds, or any clock >= 0).

        Raises
        ------
        ValueError
            If ``t_s`` is negative or not finite, or the writer is closed.
        """
        fh = self._fh
        if fh is None:
            raise ValueError("TlogWriter is closed")
        # the live recorder's path (once per message): _stamp and _frame inlined for bytes
        if not (0.0 <= t_s < _MAX_T_S):
            raise ValueError(f"tlog timestamp must be finite and >= 0, got {t_s!r}")
        frame = msg_or_bytes if type(msg_or_bytes) is bytes else self._frame(msg_or_bytes)
        fh.write(_TS_PACK(int(round(t_s * US_PER_S))) + frame)
        self.records += 1

    def write_frames(self, t_s: float, frames: list[bytes]) -> None:
        """Append one record per frame, all stamped ``t_s`` (what :meth:`write` does for
        each, in one write).

        Raises
        ------
        ValueError
            As :meth:`write`.
        """
        fh = self._fh
        if fh is None:
            raise ValueError("TlogWriter is closed")
        stamp = self._stamp(t_s)
        fh.write(b"".join([stamp + self._frame(frame) for frame in frames]))
        self.records += len(frames)

    @staticmethod
    def _stamp(t_s: float) -> bytes:
        """The 8-byte record time of ``t_s`` (s); ValueError when negative or not finite."""
        if not (0.0 <= t_s < _MAX_T_S):
            raise ValueError(f"tlog timestamp must be finite and >= 0, got {t_s!r}")
        return _TS_PACK(int(round(t_s * US_PER_S)))

    def _frame(self, msg_or_bytes: Any) -> bytes:
        """The frame's bytes: as given, or of a message (packed now if it never was)."""
        if type(msg_or_bytes) is bytes:
            return msg_or_bytes
        if isinstance(msg_or_bytes, _BYTES_LIKE):
            return bytes(msg_or_bytes)
        data = msg_or_bytes.get_msgbuf()
        if not data:
            data = msg_or_bytes.pack(self._mav)
            self._mav.seq = (self._mav.seq + 1) % 256
        return data  # type: ignore[no-any-return]

    def flush(self) -> None:
        """Flush to the OS."""
        if self._fh is not None:
            self._fh.flush()

    def close(self) -> None:
        """Close the file."""
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def __enter__(self) -> TlogWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

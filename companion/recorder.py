"""Flight recorder: every message in and out, as .tlog files with a size and an age cap.

Files are ``companion-NNNNNN-YYYYmmddTHHMMSSZ.tlog`` in the configured folder: a
sequence number one above the highest already there, then the UTC time of the file's
start. A new file is started at each service start and when the next record would
take the current one past ``max_file_mb``. The sequence number, not the clock, says
which files are oldest: a companion computer without a real-time clock may boot in
1970.

Caps (:class:`RecorderConfig`), applied when a file is started and every hour: the
oldest recorder files are deleted until the others and a full current file fit in
``max_total_mb``, so the folder never holds more; files last written more than
``max_age_days`` ago are deleted. The file being written is never deleted; files that
are not the recorder's (other names) are neither counted nor deleted. Every rotation
and deletion is logged.

Crash safety: records are handed to the OS at least every ``flush_interval_s``, by the
write that finds a flush due or, when no message comes, by :meth:`Recorder.tick` from
the service's timer (which wakes for :meth:`Recorder.next_due_s`). After a crash or
``kill -9`` every record older than that is in the file; the last may be torn, which
:class:`~companion.mavlink.tlog.TlogReader` counts as ``truncated_record``. A power
cut loses in addition what the OS had not yet written to the card (no fsync: it
would stall the event loop on a slow SD card).

A write error (card full or removed) never stops the service: it is logged and
counted, the file closed, and a new file tried ``RETRY_S`` later, then at doubling
intervals up to ``RETRY_MAX_S`` while the errors go on.
"""

from __future__ import annotations

import logging
import math
import os
import re
import time
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

from companion.mavlink.tlog import TIMESTAMP_LEN, TlogError, TlogWriter
from companion.ranges import check_ranges, ranged

log = logging.getLogger(__name__)

BYTES_PER_MB = 1_000_000
S_PER_DAY = 86_400.0
HOUSEKEEPING_PERIOD_S = 3600.0
"""How often the caps are checked besides at each new file (for the age cap of a
service that runs for days without rotating)."""
RETRY_S = 10.0
"""After a write error, how long before a new file is tried."""
RETRY_MAX_S = 600.0
"""The longest wait between tries while every new file fails too."""

_NAME = re.compile(r"companion-(\d+)-\d{8}T\d{6}Z\.tlog")
_LEGACY_NAME = re.compile(r"companion-\d{8}-\d{6}(?:-\d+)?\.tlog")
"""Files of the recorder before sequence numbers: older than any numbered file."""


@dataclass(frozen=True, slots=True)
class RecorderConfig:
    """The flight recorder's caps and flush period (its folder is [link] record_dir).

    The defaults suit a companion computer's SD card: about 25 MB an hour at the
    default stream rates, so a file holds about two and a half hours and the folder
    about three days of continuous recording. MB are 10^6 bytes.
    """

    max_file_mb: float = ranged(64.0, ge=0.01)
    """A new file is started when the next record would take the current one past this
    (MB, 10^6 bytes)."""
    max_total_mb: float = ranged(2000.0, ge=0.01)
    """The recorder's files in the folder stay within this (MB): the oldest are deleted
    until the others and a full current file fit."""
    max_age_days: float = ranged(30.0, ge=0.0)
    """Files last written longer ago than this are deleted; 0 keeps them whatever their age."""
    flush_interval_s: float = ranged(0.5, gt=0.0, le=1.0)
    """Records are handed to the OS at least this often: what a crash (kill -9) can lose."""

    def __post_init__(self) -> None:
        check_ranges(self)
        if self.max_total_mb < self.max_file_mb:
            raise ValueError(
                f"max_total_mb must be >= max_file_mb ({self.max_file_mb:g}), "
                f"got {self.max_total_mb!r}"
            )


class RecordFile(NamedTuple):
    """A recorder file in the folder."""

    seq: int
    """Sequence number; -1 for a file named before sequence numbers."""
    mtime_s: float
    size_bytes: int
    path: Path


def recorder_files(folder: Path) -> list[RecordFile]:
    """The recorder's files in ``folder``, oldest first (sequence, then last write, then
    name); files it cannot stat are left out."""
    files = []
    try:
        entries = list(os.scandir(folder))
    except OSError as exc:
        log.warning("flight recorder: cannot list %s: %s", folder, exc)
        return []
    for entry in entries:
        match = _NAME.fullmatch(entry.name)
        if match is None and _LEGACY_NAME.fullmatch(entry.name) is None:
            continue
        try:
            st = entry.stat()
        except OSError:
            continue
        seq = int(match.group(1)) if match is not None else -1
        files.append(RecordFile(seq, st.st_mtime, st.st_size, Path(entry.path)))
    files.sort(key=lambda f: (f.seq, f.mtime_s, f.path.name))
    return files


class Recorder:
    """Append raw MAVLink frames with their receive/send time to size- and age-capped .tlogs.

    Parameters
    ----------
    folder
        Created if missing.
    start_wall_s
        UNIX-epoch time of the service start (names the first file, ages the old ones).
    config
        Caps and flush period (default: :class:`RecorderConfig`'s defaults).

    Raises
    ------
    OSError
        If the folder or the first file cannot be created.
    """

    def __init__(
        self, folder: Path, start_wall_s: float, config: RecorderConfig | None = None
    ) -> None:
        self.folder = folder
        self.config = config if config is not None else RecorderConfig()
        self._max_file_bytes = int(self.config.max_file_mb * BYTES_PER_MB)
        self._max_total_bytes = int(self.config.max_total_mb * BYTES_PER_MB)
        self._max_age_s = self.config.max_age_days * S_PER_DAY
        self._flush_interval_s = self.config.flush_interval_s
        self.path: Path | None = None
        """The file being written (None after a write error until the retry)."""
        self._records_closed = 0
        self.files_started = 0
        self.files_deleted = 0
        self.write_errors = 0
        self._writer: TlogWriter | None = None
        self._file_bytes = 0
        self._next_seq = 0
        self._flushed_s = start_wall_s
        self._flush_due_s = start_wall_s + self._flush_interval_s
        self._housekeeping_due_s = start_wall_s + HOUSEKEEPING_PERIOD_S
        self._retry_s = math.inf
        self._failed_s = -math.inf
        self._failures = 0
        """Write errors since the last flush that wrote something."""
        folder.mkdir(parents=True, exist_ok=True)
        self._next_seq = max((f.seq for f in recorder_files(folder)), default=-1) + 1
        try:
            self._start_file(start_wall_s, "service start")
        except TlogError as exc:
            raise OSError(str(exc)) from exc

    # ------------------------------------------------------------------ the live path

    def record(self, t_s: float, frame: bytes) -> None:
        """Append one frame (``t_s`` UNIX-epoch seconds); flush when due. Never raises
        on an I/O error (logged and counted)."""
        size = self._file_bytes + TIMESTAMP_LEN + len(frame)
        writer = self._writer
        if size > self._max_file_bytes or writer is None:
            writer = self._make_room(t_s)
            if writer is None:
                return
            size = self._file_bytes + TIMESTAMP_LEN + len(frame)
        try:
            writer.write(t_s, frame)
        except OSError as exc:
            self._fail(t_s, exc, f"writing {self.path}")
            return
        self._file_bytes = size
        if not (self._flushed_s <= t_s < self._flush_due_s):  # due, or the clock stepped back
            self._flush(t_s)

    def tick(self, now_s: float) -> None:
        """Flush when due, retry after a write error, check the caps hourly: the service's
        timer calls it when it wakes (at :meth:`next_due_s` at the latest)."""
        if not (self._flushed_s <= now_s < self._flush_due_s):
            self._flush(now_s)
        if self._writer is None and self._retry_due(now_s):
            self._retry(now_s)
        if not (
            self._housekeeping_due_s - HOUSEKEEPING_PERIOD_S <= now_s < self._housekeeping_due_s
        ):
            self._housekeeping_due_s = now_s + HOUSEKEEPING_PERIOD_S
            self._apply_caps(now_s)

    @property
    def records(self) -> int:
        """Records written, over every file."""
        writer = self._writer
        return self._records_closed + (writer.records if writer is not None else 0)

    def next_due_s(self) -> float:
        """When :meth:`tick` next has something to do (UNIX-epoch s): the next flush, so
        that a record written meanwhile waits at most ``flush_interval_s``."""
        return min(self._flush_due_s, self._retry_s)

    def close(self) -> None:
        """Flush and close the current file."""
        writer, self._writer = self._writer, None
        self._retry_s = math.inf
        if writer is not None:
            self._records_closed += writer.records
            try:
                writer.close()
            except OSError as exc:
                self.write_errors += 1
                log.error("flight recorder: cannot close %s: %s", self.path, exc)

    # ------------------------------------------------------------------ files

    def _make_room(self, t_s: float) -> TlogWriter | None:
        """The writer for the next record: the current one, a new file when the current is
        full (an empty file takes the record whatever its size), or None after an error."""
        if self._writer is None:
            return self._retry(t_s) if self._retry_due(t_s) else None
        if self._file_bytes == 0:
            return self._writer
        full_mb = self._file_bytes / BYTES_PER_MB
        old = self.path
        self.close()
        try:
            self._start_file(t_s, f"{old.name if old else '?'} reached {full_mb:.2f} MB")
        except (OSError, TlogError) as exc:
            self._fail(t_s, exc, "starting the next file")
        return self._writer

    def _start_file(self, t_s: float, reason: str) -> None:
        """Open the next file (sequence, UTC time), then apply the caps for it."""
        stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime(t_s))
        path = self.folder / f"companion-{self._next_seq:06d}-{stamp}.tlog"
        while path.exists():  # another writer took the number: never overwrite
            self._next_seq += 1
            path = self.folder / f"companion-{self._next_seq:06d}-{stamp}.tlog"
        self._writer = TlogWriter(path)
        self._next_seq += 1
        self.path = path
        self._file_bytes = 0
        self._retry_s = math.inf
        self._flushed_s = t_s
        self._flush_due_s = t_s + self._flush_interval_s
        self.files_started += 1
        log.info("flight recorder: recording to %s (%s)", path, reason)
        self._housekeeping_due_s = t_s + HOUSEKEEPING_PERIOD_S
        self._apply_caps(t_s)

    def _apply_caps(self, now_s: float) -> None:
        """Delete files older than ``max_age_days``, then the oldest until the others and a
        full current file fit in ``max_total_mb``; never the current file."""
        others = [f for f in recorder_files(self.folder) if f.path != self.path]
        if self._max_age_s > 0.0:
            kept = []
            for f in others:
                age_s = now_s - f.mtime_s
                reason = f"older than max_age_days {self.config.max_age_days:g}"
                if not (age_s > self._max_age_s and self._delete(f, reason, now_s)):
                    kept.append(f)
            others = kept
        total = sum(f.size_bytes for f in others) + self._max_file_bytes
        for f in others:
            if total <= self._max_total_bytes:
                break
            if self._delete(f, f"folder over max_total_mb {self.config.max_total_mb:g}", now_s):
                total -= f.size_bytes

    def _delete(self, f: RecordFile, reason: str, now_s: float) -> bool:
        try:
            f.path.unlink()
        except FileNotFoundError:
            return True
        except OSError as exc:
            log.warning("flight recorder: cannot delete %s: %s", f.path, exc)
            return False
        self.files_deleted += 1
        log.info(
            "flight recorder: deleted %s (%.2f MB, last written %.1f days ago): %s",
            f.path.name,
            f.size_bytes / BYTES_PER_MB,
            (now_s - f.mtime_s) / S_PER_DAY,
            reason,
        )
        return True

    # ------------------------------------------------------------------ flush and errors

    def _flush(self, t_s: float) -> None:
        self._flushed_s = t_s
        self._flush_due_s = t_s + self._flush_interval_s
        if self._writer is not None:
            try:
                self._writer.flush()
            except OSError as exc:
                self._fail(t_s, exc, f"flushing {self.path}")
                return
            if self._failures and self._file_bytes:
                log.info("flight recorder: writing again to %s", self.path)
                self._failures = 0

    def _retry_due(self, t_s: float) -> bool:
        """Whether a new file is to be tried after an error (also when the clock stepped
        back past the error); never after :meth:`close`."""
        return self._retry_s < math.inf and not (self._failed_s <= t_s < self._retry_s)

    def _retry(self, t_s: float) -> TlogWriter | None:
        try:
            self._start_file(t_s, "after a write error")
        except (OSError, TlogError) as exc:
            self._fail(t_s, exc, "starting the next file")
        return self._writer

    def _fail(self, t_s: float, exc: Exception, doing: str) -> None:
        """A write, flush or open failed: log, count, close, retry later (``RETRY_S``,
        doubling up to ``RETRY_MAX_S`` while the errors go on)."""
        self.write_errors += 1
        wait_s = min(RETRY_S * 2.0**self._failures, RETRY_MAX_S)
        self._failures += 1
        log.error(
            "flight recorder: %s: %s; recording suspended, retrying in %.0f s",
            doing,
            exc,
            wait_s,
        )
        writer, self._writer = self._writer, None
        if writer is not None:
            self._records_closed += writer.records
            try:
                writer.close()
            except OSError:
                pass
        self._failed_s = t_s
        self._retry_s = t_s + wait_s

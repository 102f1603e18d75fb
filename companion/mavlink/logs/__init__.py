"""Autopilot logs other than telemetry logs, read as the MAVLink streams a .tlog holds.

:func:`open_flight_log` picks the reader by the file's first bytes, never by its
name: an ArduPilot DataFlash log (0xA3 0x95, :mod:`.dataflash`), a PX4 ULog
("ULog", :mod:`.ulog`), anything else a telemetry log
(:class:`~companion.mavlink.tlog.TlogReader`, which refuses what is plainly another
format). Each reader iterates ``(t_rx_s, message)`` and counts what it skipped in
``stats``.
"""

from __future__ import annotations

from collections.abc import Collection
from pathlib import Path
from typing import Any

from companion.mavlink.tlog import TlogError, TlogReader

DATAFLASH_MAGIC = b"\xa3\x95"
ULOG_MAGIC = b"ULog"


def log_format(path: Path | str) -> str:
    """``"dataflash"``, ``"ulog"`` or ``"tlog"`` (the rest, and a file that cannot be
    opened: the tlog reader says why) from the first bytes."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
    except OSError:
        return "tlog"
    if head.startswith(DATAFLASH_MAGIC):
        return "dataflash"
    if head.startswith(ULOG_MAGIC):
        return "ulog"
    return "tlog"


def open_flight_log(
    path: Path | str, light_ids: Collection[int] = (), dialect: str = "ardupilotmega"
) -> Any:
    """A reader of ``path`` by its content: iterate ``(t_rx_s, message)``; ``stats``.

    ``dialect`` is what a telemetry log is parsed with (the service's own: a frame it
    does not know is skipped and counted, as on a link); a .bin or .ulg reader builds its
    messages itself.

    Raises
    ------
    TlogError
        If the file cannot be opened or read at all (the message says why).
    """
    kind = log_format(path)
    ids = frozenset(light_ids)
    if kind == "dataflash":
        from companion.mavlink.logs.dataflash import DataFlashError, read_dataflash

        try:
            return read_dataflash(path, ids)
        except DataFlashError as exc:
            raise TlogError(str(exc)) from exc
    if kind == "ulog":
        try:
            from companion.mavlink.logs.ulog import UlogError, read_ulog
        except ImportError as exc:  # pyulog is a dependency; a broken install says so
            raise TlogError(f"{path}: a PX4 ULog needs pyulog ({exc})") from exc
        try:
            return read_ulog(path, ids)
        except UlogError as exc:
            raise TlogError(str(exc)) from exc
    return TlogReader(path, dialect, light_ids=ids)

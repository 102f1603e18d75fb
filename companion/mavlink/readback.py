"""The service's own messages read back: frames from component 191 -> typed values.

What :mod:`companion.mavlink.encode` published, as read from a replay's output
tlog (``companion evaluate``) or from a live link (``companion console``). The
scalings are undone with :mod:`companion.mavlink.units`, as the encoder applied
them:

==========================  ===================================================
GLOBAL_POSITION_INT         :class:`PublishedPosition` (``t_s`` =
                            ``time_boot_ms`` / 1000, the solution's time of
                            validity; yaw in [0, 2 pi) or None)
GPS_INPUT                   :class:`PublishedFix` (time of validity ``time_usec``,
                            fix type, position, velocity; 1-sigma accuracies,
                            None where flagged ignored or not > 0)
GLOBAL_POSITION_SENSOR      :class:`PublishedSensorFix` (time of validity, healthy
                            flag, position, 1-sigma accuracies)
NAMED_VALUE_FLOAT           :class:`companion.types.NamedValue`
STATUSTEXT                  :class:`PublishedText` (one chunk; :class:`TextJoiner`
                            joins multi-chunk texts, :func:`parse_alert` splits
                            ``CMP <CODE> <text>``)
HEARTBEAT                   :class:`PublishedHeartbeat`
==========================  ===================================================

Anything else (COMMAND_ACK, stream requests ...) reads as None.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from companion.mavlink import units
from companion.mavlink.ids import (
    ALERT_PREFIX,
    GLOBAL_POSITION_PRIMARY,
    GLOBAL_POSITION_UNHEALTHY,
    GPS_INPUT_IGNORE_FLAG_HORIZONTAL_ACCURACY,
    GPS_INPUT_IGNORE_FLAG_VERTICAL_ACCURACY,
    MAV_COMP_ID_ONBOARD_COMPUTER,
    STATUSTEXT_MAX_CHARS,
)
from companion.mavlink.tlog import TlogReader
from companion.types import NamedValue


@dataclass(frozen=True, slots=True)
class PublishedPosition:
    """A published GLOBAL_POSITION_INT: the solution valid at autopilot time ``t_s``."""

    t_s: float
    lat_rad: float
    lon_rad: float
    alt_msl_m: float
    vel_ned_mps: tuple[float, float, float]
    yaw_rad: float | None
    """Heading in [0, 2 pi), None when published as unknown."""


@dataclass(frozen=True, slots=True)
class PublishedFix:
    """A published GPS_INPUT: the fix type and the 1-sigma accuracies (m), and the
    solution it carries, valid at autopilot time ``t_s`` (``time_usec``)."""

    fix_type: int
    h_acc_m: float | None
    v_acc_m: float | None
    t_s: float = math.nan
    lat_rad: float = math.nan
    lon_rad: float = math.nan
    alt_msl_m: float = math.nan
    vel_ned_mps: tuple[float, float, float] = (math.nan, math.nan, math.nan)


@dataclass(frozen=True, slots=True)
class PublishedSensorFix:
    """A published GLOBAL_POSITION_SENSOR (PX4): the solution valid at autopilot time
    ``t_s``, ``healthy`` when flagged PRIMARY and not UNHEALTHY (the encoder flags a fix
    below 3-D UNHEALTHY), 1-sigma accuracies (m, None when not > 0)."""

    t_s: float
    healthy: bool
    lat_rad: float
    lon_rad: float
    alt_msl_m: float
    h_acc_m: float | None
    v_acc_m: float | None


@dataclass(frozen=True, slots=True)
class PublishedText:
    """One published STATUSTEXT chunk (``chunk_id`` 0: a whole text)."""

    text: str
    severity: int
    chunk_id: int


@dataclass(frozen=True, slots=True)
class PublishedHeartbeat:
    """A published HEARTBEAT: our MAV_STATE."""

    system_status: int


Published = (
    PublishedPosition
    | PublishedFix
    | PublishedSensorFix
    | PublishedText
    | PublishedHeartbeat
    | NamedValue
)


@dataclass(frozen=True, slots=True)
class TlogContents:
    """Every record of a tlog, ``(t_rx_s, message)`` in file order (``t_rx_s`` UNIX-epoch
    seconds), and what the robust reader skipped: corrupt regions (garbage, bad CRC,
    unknown message ids) and a cut-short last record."""

    records: list[tuple[float, Any]]
    bad_regions: int
    truncated_records: int


def read_tlog(path: Path) -> TlogContents:
    """Read a tlog with the service's robust reader (:class:`TlogReader`).

    Raises
    ------
    companion.mavlink.tlog.TlogError
        If the file cannot be read at all.
    """
    reader = TlogReader(path)
    records = list(reader)
    return TlogContents(
        records=records,
        bad_regions=reader.stats["bad_region"],
        truncated_records=reader.stats["truncated_record"],
    )


def from_service(msg: Any) -> bool:
    """Whether ``msg`` was sent by the service (component 191)."""
    return bool(msg.get_srcComponent() == MAV_COMP_ID_ONBOARD_COMPUTER)


def _text(value: str | bytes) -> str:
    """A char[] field as text (pymavlink gives str; raw bytes are decoded), NULs cut."""
    text = value if isinstance(value, str) else value.decode(errors="replace")
    return text.rstrip("\x00")


def read_message(msg: Any) -> Published | None:
    """The typed value of one of the service's messages, or None for other types."""
    kind = msg.get_type()
    if kind == "GLOBAL_POSITION_INT":
        return PublishedPosition(
            t_s=msg.time_boot_ms / units.MS_PER_S,
            lat_rad=msg.lat / units.DEGE7_PER_RAD,
            lon_rad=msg.lon / units.DEGE7_PER_RAD,
            alt_msl_m=msg.alt / units.MM_PER_M,
            vel_ned_mps=(
                msg.vx / units.CM_PER_M,
                msg.vy / units.CM_PER_M,
                msg.vz / units.CM_PER_M,
            ),
            yaw_rad=None if msg.hdg == units.UINT16_UNKNOWN else msg.hdg / units.CDEG_PER_RAD,
        )
    if kind == "GPS_INPUT":
        h = float(msg.horiz_accuracy)
        v = float(msg.vert_accuracy)
        h_ok = not (msg.ignore_flags & GPS_INPUT_IGNORE_FLAG_HORIZONTAL_ACCURACY) and h > 0.0
        v_ok = not (msg.ignore_flags & GPS_INPUT_IGNORE_FLAG_VERTICAL_ACCURACY) and v > 0.0
        return PublishedFix(
            fix_type=int(msg.fix_type),
            h_acc_m=h if h_ok else None,
            v_acc_m=v if v_ok else None,
            t_s=msg.time_usec / units.US_PER_S,
            lat_rad=msg.lat / units.DEGE7_PER_RAD,
            lon_rad=msg.lon / units.DEGE7_PER_RAD,
            alt_msl_m=float(msg.alt),
            vel_ned_mps=(float(msg.vn), float(msg.ve), float(msg.vd)),
        )
    if kind == "GLOBAL_POSITION_SENSOR":
        flags = int(msg.flags)
        h = float(msg.eph)
        v = float(msg.epv)
        return PublishedSensorFix(
            t_s=msg.time_usec / units.US_PER_S,
            healthy=bool(flags & GLOBAL_POSITION_PRIMARY) and not flags & GLOBAL_POSITION_UNHEALTHY,
            lat_rad=msg.lat / units.DEGE7_PER_RAD,
            lon_rad=msg.lon / units.DEGE7_PER_RAD,
            alt_msl_m=float(msg.alt),
            h_acc_m=h if h > 0.0 else None,
            v_acc_m=v if v > 0.0 else None,
        )
    if kind == "STATUSTEXT":
        return PublishedText(
            text=_text(msg.text),
            severity=int(msg.severity),
            chunk_id=int(getattr(msg, "id", 0) or 0),
        )
    if kind == "NAMED_VALUE_FLOAT":
        return NamedValue(
            t_s=msg.time_boot_ms / units.MS_PER_S,
            name=_text(msg.name).strip(),
            value=float(msg.value),
        )
    if kind == "HEARTBEAT":
        return PublishedHeartbeat(system_status=int(msg.system_status))
    return None


class TextJoiner:
    """Joins multi-chunk STATUSTEXTs: chunks of one non-zero id, in order, until a chunk
    shorter than the field (50 characters) ends the text.

    Each text keeps the ``tag`` (whatever the caller passes: a record index, a time) and
    the severity of its first chunk.
    """

    def __init__(self) -> None:
        self._open: dict[int, tuple[Any, list[str], int]] = {}

    def add(self, tag: Any, chunk: PublishedText) -> tuple[Any, str, int] | None:
        """``(tag, text, severity)`` of the text ``chunk`` completes, or None."""
        if chunk.chunk_id == 0:
            return tag, chunk.text, chunk.severity
        prev = self._open.get(chunk.chunk_id)
        if prev is None:
            self._open[chunk.chunk_id] = (tag, [chunk.text], chunk.severity)
        else:
            prev[1].append(chunk.text)
        if len(chunk.text) < STATUSTEXT_MAX_CHARS:
            tag0, parts, severity = self._open.pop(chunk.chunk_id)
            return tag0, "".join(parts), severity
        return None

    def unfinished(self) -> list[tuple[Any, str, int]]:
        """The texts still waiting for their last chunk, as far as they came."""
        return [(tag, "".join(parts), severity) for tag, parts, severity in self._open.values()]


def parse_alert(text: str) -> tuple[str, str] | None:
    """``(code, rest)`` of an alert's text ``CMP <CODE> <rest>``, or None if not one."""
    if not text.startswith(ALERT_PREFIX):
        return None
    body = text[len(ALERT_PREFIX) :].strip()
    if not body:
        return None
    code, _, rest = body.partition(" ")
    return code, rest.strip()

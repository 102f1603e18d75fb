"""A replay's outputs as recorded for the golden comparison, and their two files.

What the service published, read back with :mod:`companion.mavlink.readback`
(pymavlink's decoding of each frame, the service's STATUSTEXT joiner):

* ``series``: every message of a repeated type, decoded field by field at full rate —
  GPS_INPUT, GLOBAL_POSITION_INT, GLOBAL_POSITION_SENSOR, each NAMED_VALUE_FLOAT name
  (``NAMED_VALUE_FLOAT:CMP_HPL``), the stream requests ... — with each message's record
  time (``t_rx_us``, microseconds after the output's first record);
* ``meta`` (JSON, readable in a diff): the STATUSTEXTs (joined, with their time and
  severity: the alerts among them), the HEARTBEAT's changes, the replay's summary
  (messages by type, rejections, alerts by code, the integrity monitor's counters) and,
  for a bundled flight replayed with the defaults, ``companion evaluate``'s figures
  against its truth.

Files: ``<stem>.json`` (``meta``) and ``<stem>.npz.xz`` (``series``: an uncompressed
``.npz`` compressed with xz; integer columns stored as second differences, floats as
float32 where that is exact: about 1.5 bytes a value).
"""

from __future__ import annotations

import dataclasses
import io
import json
import lzma
from collections import Counter, defaultdict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from companion.mavlink.readback import PublishedText, TextJoiner, read_message, read_tlog

T_RX = "t_rx_us"
"""The column of each series that holds the record time (us after the first record)."""
_SEP = "|"
"""Between a series' key and a field in the ``.npz``'s array names."""
_EVENT_TYPES = ("STATUSTEXT", "HEARTBEAT")
"""Types kept as events in ``meta`` rather than as series."""
_SKIP_FIELDS = frozenset({"mavpackettype"})


@dataclass
class ReplayRecord:
    """One case's recorded outputs (see the module docstring)."""

    meta: dict[str, Any]
    series: dict[str, dict[str, np.ndarray]]


def series_key(msg: Any) -> str:
    """``GPS_INPUT``, or ``NAMED_VALUE_FLOAT:<name>`` (one series per name)."""
    kind = str(msg.get_type())
    if kind == "NAMED_VALUE_FLOAT":
        value = read_message(msg)
        return f"{kind}:{getattr(value, 'name', '')}"
    return kind


def from_output(
    out_tlog: Path, keep: Callable[[Any], bool] | None = None, **meta: Any
) -> ReplayRecord:
    """The record of a replay's output tlog (of its messages ``keep`` keeps: all by
    default); ``meta`` adds to the JSON part (the case, the summary, the evaluation)."""
    records = read_tlog(out_tlog).records
    if keep is not None:
        records = [(t, m) for t, m in records if keep(m)]
    t0 = records[0][0] if records else 0.0
    columns: dict[str, dict[str, list[Any]]] = defaultdict(lambda: defaultdict(list))
    texts: list[list[Any]] = []
    heartbeats: list[list[Any]] = []
    joiner = TextJoiner()
    for t_rx, msg in records:
        t_us = round((t_rx - t0) * 1e6)
        kind = msg.get_type()
        if kind == "STATUSTEXT":
            chunk = read_message(msg)
            assert isinstance(chunk, PublishedText)
            done = joiner.add(t_us, chunk)
            if done is not None:
                texts.append([done[0] / 1e6, done[2], done[1]])
            continue
        fields = {k: v for k, v in msg.to_dict().items() if k not in _SKIP_FIELDS}
        if kind == "HEARTBEAT":
            if not heartbeats or heartbeats[-1][1] != fields:
                heartbeats.append([t_us / 1e6, fields])
            continue
        key = series_key(msg)
        cols = columns[key]
        cols[T_RX].append(t_us)
        for name, value in fields.items():
            if kind == "NAMED_VALUE_FLOAT" and name == "name":
                continue
            cols[name].append(value)
    for tag, text, severity in joiner.unfinished():
        texts.append([tag / 1e6, severity, text])
    series = {key: {f: np.asarray(v) for f, v in cols.items()} for key, cols in columns.items()}
    counts = Counter(msg.get_type() for _, msg in records)
    meta = {
        **meta,
        "t0_rx_s": t0,
        "records": len(records),
        "messages": dict(sorted(counts.items())),
        "series": {key: len(cols[T_RX]) for key, cols in sorted(series.items())},
        "texts": texts,
        "heartbeats": heartbeats,
    }
    # as it reads back from its file
    return ReplayRecord(meta=json.loads(json.dumps(meta, sort_keys=True)), series=series)


def summary_dict(summary: Any) -> dict[str, Any]:
    """A :class:`companion.replay.ReplaySummary` as JSON, without the wall-clock time and
    the alert log (the alerts are recorded as the STATUSTEXTs the service sent)."""
    out = dataclasses.asdict(summary)
    out.pop("wall_s", None)
    out.pop("alert_log", None)
    return {k: dict(sorted(v.items())) if isinstance(v, dict) else v for k, v in out.items()}


# --------------------------------------------------------------------------- the files


def _encode(column: np.ndarray) -> np.ndarray:
    """Integers as second differences (small numbers xz packs well); floats as float32
    where that is exact (MAVLink's floats are float32)."""
    if column.dtype.kind in "iub":
        wide = column.astype(np.int64)
        return np.diff(np.diff(wide, axis=0, prepend=0), axis=0, prepend=0)
    if column.dtype.kind == "f":
        narrow = column.astype(np.float32)
        if np.array_equal(narrow.astype(np.float64), column, equal_nan=True):
            return narrow
    return column


def _decode(column: np.ndarray) -> np.ndarray:
    if column.dtype.kind == "i":
        return np.cumsum(np.cumsum(column, axis=0), axis=0)
    if column.dtype == np.float32:
        return column.astype(np.float64)
    return column


def save(record: ReplayRecord, directory: Path, stem: str) -> list[Path]:
    """Write ``<stem>.json`` and ``<stem>.npz.xz``; returns their paths."""
    directory.mkdir(parents=True, exist_ok=True)
    meta_path = directory / f"{stem}.json"
    meta_path.write_text(json.dumps(record.meta, indent=1, sort_keys=True) + "\n")
    arrays = {
        f"{key}{_SEP}{field}": _encode(col)
        for key, cols in sorted(record.series.items())
        for field, col in cols.items()
    }
    buf = io.BytesIO()
    np.savez(buf, **arrays)  # type: ignore[arg-type]
    series_path = directory / f"{stem}.npz.xz"
    series_path.write_bytes(lzma.compress(buf.getvalue(), preset=9 | lzma.PRESET_EXTREME))
    return [meta_path, series_path]


def load(directory: Path, stem: str) -> ReplayRecord | None:
    """The record written by :func:`save`, or None if there is none."""
    meta_path = directory / f"{stem}.json"
    series_path = directory / f"{stem}.npz.xz"
    if not meta_path.is_file() or not series_path.is_file():
        return None
    meta = json.loads(meta_path.read_text())
    series: dict[str, dict[str, np.ndarray]] = defaultdict(dict)
    with np.load(io.BytesIO(lzma.decompress(series_path.read_bytes()))) as npz:
        for name in npz.files:
            key, _, field = name.partition(_SEP)
            series[key][field] = _decode(npz[name])
    return ReplayRecord(meta=meta, series=dict(series))


def files_of(directory: Path, stem: str) -> list[Path]:
    """The two files of a case (whether or not they exist)."""
    return [directory / f"{stem}.json", directory / f"{stem}.npz.xz"]

"""The truth side of an evaluation: the simulator's truth CSV and its sidecar of events.

The truth CSV has :data:`TRUTH_COLUMNS` (``t_s`` autopilot time, degrees, metres
MSL, m/s NED, degrees); rows with a missing or non-numeric value are dropped
(counted), duplicate times too. The sidecar ``<name>.json`` beside
``<name>.truth.csv`` holds the scenario, the seed, the parameters and the
scheduled ``events`` (kind, window ``t_start_s``..``t_end_s``, receiver, params).
"""

from __future__ import annotations

import csv
import json
import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from companion.evaluate.results import EvaluationError
from companion.evaluate.score import EVENT_ALERT_CODES
from companion.types import FloatArray

_log = logging.getLogger(__name__)

TRUTH_COLUMNS: tuple[str, ...] = (
    "t_s",
    "lat_deg",
    "lon_deg",
    "alt_m",
    "vn_mps",
    "ve_mps",
    "vd_mps",
    "roll_deg",
    "pitch_deg",
    "yaw_deg",
    "phase",
    "gnss_mode",
)
"""Columns the truth CSV must have (the simulator writes them: ``docs/replay.md``)."""


@dataclass(frozen=True, slots=True, eq=False)
class Truth:
    """The truth trajectory, sorted by time (s), longitude and yaw unwrapped."""

    t_s: FloatArray
    lat_rad: FloatArray
    lon_rad: FloatArray  # unwrapped
    alt_msl_m: FloatArray
    vel_ned_mps: FloatArray  # (n, 3)
    yaw_unwrapped_deg: FloatArray


def read_truth(path: Path) -> Truth:
    """Read the truth CSV (:data:`TRUTH_COLUMNS`), sorted by time, bad rows dropped (counted)."""
    try:
        with path.open(newline="") as fh:
            reader = csv.DictReader(fh)
            columns = [c.strip() for c in (reader.fieldnames or [])]
            missing = [c for c in TRUTH_COLUMNS if c not in columns]
            if missing:
                raise EvaluationError(
                    f"truth {path} lacks column(s) {', '.join(missing)} "
                    f"(needs {', '.join(TRUTH_COLUMNS)})"
                )
            reader.fieldnames = columns
            numeric = TRUTH_COLUMNS[:10]
            rows: list[list[float]] = []
            dropped = 0
            for row in reader:
                try:
                    values = [float(row[c]) for c in numeric]
                except (TypeError, ValueError):
                    dropped += 1
                    continue
                if not all(math.isfinite(v) for v in values):
                    dropped += 1
                    continue
                rows.append(values)
    except OSError as exc:
        raise EvaluationError(f"cannot read truth {path}: {exc.strerror or exc}") from exc
    except (UnicodeDecodeError, csv.Error) as exc:
        raise EvaluationError(f"truth {path} is not a readable CSV: {exc}") from exc
    if dropped:
        _log.warning(
            "%s: dropped %d truth row(s) with missing or non-numeric values", path, dropped
        )
    if len(rows) < 2:
        raise EvaluationError(f"truth {path} has fewer than 2 usable rows")
    arr = np.asarray(rows, dtype=np.float64)
    order = np.argsort(arr[:, 0], kind="stable")
    arr = arr[order]
    _, first = np.unique(arr[:, 0], return_index=True)
    if first.size < arr.shape[0]:
        _log.warning("%s: dropped %d duplicate truth time(s)", path, arr.shape[0] - first.size)
    arr = arr[first]
    if arr.shape[0] < 2:
        raise EvaluationError(f"truth {path} has fewer than 2 distinct times")
    lon_deg = np.unwrap(arr[:, 2], period=360.0)
    return Truth(
        t_s=arr[:, 0],
        lat_rad=np.radians(arr[:, 1]),
        lon_rad=np.radians(lon_deg),
        alt_msl_m=arr[:, 3],
        vel_ned_mps=arr[:, 4:7],
        yaw_unwrapped_deg=np.unwrap(arr[:, 9], period=360.0),
    )


def sidecar_path(truth_csv: Path) -> Path:
    """Where the sidecar of ``truth_csv`` is: ``<name>.json`` beside ``<name>.truth.csv``."""
    name = truth_csv.name
    if name.endswith(".truth.csv"):
        return truth_csv.with_name(name[: -len(".truth.csv")] + ".json")
    return truth_csv.with_suffix(".json")


def read_sidecar(path: Path) -> dict[str, Any]:
    """The sidecar's JSON object."""
    try:
        doc = json.loads(path.read_text())
    except OSError as exc:
        raise EvaluationError(f"cannot read events {path}: {exc.strerror or exc}") from exc
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise EvaluationError(f"events {path} is not valid JSON: {exc}") from exc
    if not isinstance(doc, dict):
        raise EvaluationError(f"events {path}: expected a JSON object")
    return doc


@dataclass(frozen=True, slots=True)
class Event:
    """One scheduled event of the sidecar: kind, window (s), receiver, params."""

    kind: str
    t_start_s: float
    t_end_s: float
    receiver_id: int
    params: Mapping[str, Any]


def parse_events(doc: Mapping[str, Any], path: Path) -> list[Event]:
    """The sidecar's events, checked and sorted by start time."""
    raw = doc.get("events", [])
    if not isinstance(raw, list):
        raise EvaluationError(f"events {path}: 'events' must be a list")
    events: list[Event] = []
    for i, item in enumerate(raw):
        try:
            kind = str(item["kind"])
            t0 = float(item["t_start_s"])
            t1 = float(item["t_end_s"])
            rx = int(item.get("receiver_id", 0))
            params = item.get("params") or {}
        except (KeyError, TypeError, ValueError) as exc:
            raise EvaluationError(f"events {path}: event {i} is malformed ({exc})") from exc
        if not (math.isfinite(t0) and math.isfinite(t1)) or t1 < t0:
            raise EvaluationError(f"events {path}: event {i} has an invalid window {t0}..{t1}")
        if not isinstance(params, Mapping):
            raise EvaluationError(f"events {path}: event {i} params must be an object")
        if kind not in EVENT_ALERT_CODES:
            _log.warning("events %s: unknown event kind %r (no alert expected)", path, kind)
        events.append(Event(kind, t0, t1, rx, dict(params)))
    return sorted(events, key=lambda e: e.t_start_s)

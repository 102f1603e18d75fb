"""What ``companion evaluate`` measured: the result types and their JSON form."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from companion.evaluate.text import evaluation_text
from companion.types import FloatArray


class EvaluationError(Exception):
    """The inputs cannot be evaluated (missing or unreadable file, bad truth): one-line message."""


@dataclass(frozen=True, slots=True)
class TlogStats:
    """What reading the tlog found: good records, corrupt regions skipped (garbage, bad
    CRC, unknown message ids), a cut-short last record."""

    records: int
    bad_records: int
    truncated_records: int


@dataclass(frozen=True, slots=True)
class ErrorStats:
    """Error statistics of the published solution over one group of solutions.

    Horizontal figures are of the 2-D error norm (m). ``v_mean_m`` is the signed mean
    vertical error (solution above truth positive); ``v_rms_m``, ``v_p95_m`` and
    ``v_max_m`` are of its absolute value. ``h95_coverage`` / ``v95_coverage`` are the
    fractions of solutions whose true error is within the published 95 % accuracy (None when
    no accuracy was published). ``vel_h_rms_mps`` is the RMS horizontal velocity error;
    ``yaw_rms_deg`` the RMS of published heading minus true yaw (None when no heading).
    Every statistic is None when ``n == 0``.
    """

    label: str
    kind: str
    t_start_s: float | None
    t_end_s: float | None
    n: int
    h_mean_m: float | None
    h_rms_m: float | None
    h_p95_m: float | None
    h_max_m: float | None
    v_mean_m: float | None
    v_rms_m: float | None
    v_p95_m: float | None
    v_max_m: float | None
    h95_coverage: float | None
    v95_coverage: float | None
    vel_h_rms_mps: float | None
    yaw_rms_deg: float | None


@dataclass(frozen=True, slots=True)
class AlertRecord:
    """One ``CMP`` STATUSTEXT: code, the rest of its text, and its autopilot time (s)."""

    t_s: float
    t_rx_s: float
    code: str
    text: str
    severity: int
    false_alert: bool


@dataclass(frozen=True, slots=True)
class EventResult:
    """One scheduled event and how the service reacted to it.

    ``latency_s`` is the alert time minus ``t_start_s`` (None when missed);
    ``fault_size_at_detection`` is in the unit of the fault's params (metres for position
    faults), None when not a fault, not detected, or its params carry no size.
    """

    kind: str
    t_start_s: float
    t_end_s: float
    receiver_id: int
    params: Mapping[str, Any]
    expected_codes: tuple[str, ...]
    detected: bool
    alert_code: str | None
    alert_t_s: float | None
    latency_s: float | None
    fault_size_at_detection: float | None


@dataclass(frozen=True, slots=True)
class HeadingResult:
    """The taxi heading correction as published (degrees, seconds).

    ``ready_*`` come from the last ``HDG_READY`` (None when never ready); ``expected_deg`` is
    ``heading_error_deg + crab_deg`` from the sidecar (None when absent); ``error_deg`` is the
    ready value minus the expected one, wrapped; ``hdgc_error_deg`` the same for the last
    ``CMP_HDGC``. ``accumulation_s`` is from the first ``CMP_HDGC`` to ``HDG_READY``.
    ``applied``: an ``HDG_APPLIED`` not followed by an ``HDG_UNDONE``.
    """

    ready_value_deg: float | None
    ready_eps_deg: float | None
    ready_cycles: int | None
    ready_t_s: float | None
    n_ready: int
    applied: bool
    rejects: tuple[str, ...]
    expected_deg: float | None
    error_deg: float | None
    hdgc_last_deg: float | None
    hdge_last_deg: float | None
    hdgc_error_deg: float | None
    accumulation_s: float | None


@dataclass(frozen=True, slots=True, eq=False)
class EvaluationSeries:
    """Time series behind the figures, for plots (not part of ``to_dict``).

    All arrays of the published solutions within the truth span have shape (n,):
    ``t_s``, ``err_h_m``, ``err_v_m``, ``acc_h95_m`` and ``acc_v95_m`` (published 95 %
    accuracies, NaN where none), ``pub_east_m``, ``pub_north_m``. ``truth_t_s``,
    ``truth_east_m``, ``truth_north_m`` (m,) are the truth track in a local frame anchored
    at the first truth point used.
    """

    t_s: FloatArray
    err_h_m: FloatArray
    err_v_m: FloatArray
    acc_h95_m: FloatArray
    acc_v95_m: FloatArray
    pub_east_m: FloatArray
    pub_north_m: FloatArray
    truth_t_s: FloatArray
    truth_east_m: FloatArray
    truth_north_m: FloatArray


@dataclass(frozen=True, slots=True, eq=False)
class Evaluation:
    """Everything ``companion evaluate`` measured. See :mod:`companion.evaluate` for the rules."""

    out_tlog: str
    truth_csv: str
    events_json: str | None
    scenario: str | None
    seed: int | None
    tlog: TlogStats
    n_published: int
    n_evaluated: int
    n_outside_truth: int
    t_first_s: float
    t_last_s: float
    publish_rate_hz: float | None
    accuracy_source: str | None
    overall: ErrorStats
    normal: ErrorStats
    windows: tuple[ErrorStats, ...]
    events: tuple[EventResult, ...]
    alerts: tuple[AlertRecord, ...]
    n_false_alerts: int
    heading: HeadingResult
    named_values_last: Mapping[str, float]
    series: EvaluationSeries = field(repr=False)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-ready dict (NaN and inf become None); the series are left out."""
        out: dict[str, Any] = {
            "out_tlog": self.out_tlog,
            "truth_csv": self.truth_csv,
            "events_json": self.events_json,
            "scenario": self.scenario,
            "seed": self.seed,
            "tlog": _asdict(self.tlog),
            "n_published": self.n_published,
            "n_evaluated": self.n_evaluated,
            "n_outside_truth": self.n_outside_truth,
            "t_first_s": self.t_first_s,
            "t_last_s": self.t_last_s,
            "publish_rate_hz": self.publish_rate_hz,
            "accuracy_source": self.accuracy_source,
            "overall": _asdict(self.overall),
            "normal": _asdict(self.normal),
            "windows": [_asdict(w) for w in self.windows],
            "events": [_asdict(e) for e in self.events],
            "alerts": [_asdict(a) for a in self.alerts],
            "n_false_alerts": self.n_false_alerts,
            "heading": _asdict(self.heading),
            "named_values_last": dict(self.named_values_last),
        }
        cleaned = _clean(out)
        if not isinstance(cleaned, dict):  # pragma: no cover - _clean keeps dicts dicts
            raise TypeError("to_dict produced a non-dict")
        return cleaned

    def to_text(self, max_alerts: int = 40) -> str:
        """A readable report: header, error table, events, alerts, heading correction."""
        return evaluation_text(self, max_alerts)


def _asdict(obj: Any) -> dict[str, Any]:
    return {f.name: getattr(obj, f.name) for f in fields(obj)}


def _clean(x: Any) -> Any:
    """JSON-ready copy: numpy scalars to Python, NaN/inf to None, tuples to lists."""
    if isinstance(x, Mapping):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_clean(v) for v in x]
    if isinstance(x, np.ndarray):
        return [_clean(v) for v in x.tolist()]
    if isinstance(x, bool | np.bool_):
        return bool(x)
    if isinstance(x, int | np.integer):
        return int(x)
    if isinstance(x, float | np.floating):
        return float(x) if math.isfinite(float(x)) else None
    return x

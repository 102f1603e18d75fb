"""Scoring a replay against truth (``companion evaluate``).

Reads what the service published (the replay output ``.tlog``: only messages from
component 191, MAV_COMP_ID_ONBOARD_COMPUTER), the simulator's truth CSV and its JSON
sidecar of scheduled events, and computes:

* the position error of the published solution against the truth interpolated at the
  solution's time of validity (``GLOBAL_POSITION_INT.time_boot_ms``), horizontal and
  vertical, for the "normal" part of the flight (outside every event window) and for each
  event window separately, with the honesty check of the published 95 % accuracy;
* for each scheduled event the time from its start to the first matching alert, or "missed",
  and for faults the size of the fault at detection;
* alerts with no event behind them (false alerts);
* the taxi heading correction (``CMP HDG_READY``) against the injected heading error.

Rules (written once, here):

Time alignment
    A published solution is compared with the truth at ``t_s = time_boot_ms / 1000``
    (autopilot time of validity), never at its tlog time. Truth is interpolated linearly in
    time (longitude unwrapped, yaw unwrapped). Solutions outside the truth's time span are
    counted and left out. One boot clock is assumed: an autopilot reboot inside the log
    (``time_boot_ms`` restarting) is not undone here.
Error
    ``published - truth`` expressed in the local NED frame of the truth point itself
    (pymap3d), so long routes do not mix vertical into horizontal. Horizontal error is the
    2-D norm; vertical error is positive when the solution is above the truth.
Alert time
    STATUSTEXT has no time field. An alert's autopilot time is its tlog time minus the offset
    ``tlog_time - time_boot_ms/1000`` of the nearest *preceding* published
    GLOBAL_POSITION_INT in the log (the first one for alerts before any solution). Its error
    is the service's publication latency (one output cycle in a replay).
Honesty check
    Published 95 % horizontal accuracy = ``sqrt(chi2.ppf(0.95, 2))`` (2.45) x the 1-sigma
    ``GPS_INPUT.horiz_accuracy``; vertical = ``norm.ppf(0.975)`` (1.96) x ``vert_accuracy``.
    When the log has no GPS_INPUT (PX4), ``CMP_HACC``/``CMP_VACC`` are used. A solution takes
    the latest accuracy at or before its time, no older than :data:`ACCURACY_MAX_AGE_S`.
    Coverage is the fraction of solutions (published at a steady rate, so of time) whose
    true error is within the published 95 % figure.
Detection
    An event is detected by the first alert whose code is in :data:`EVENT_ALERT_CODES` for
    its kind, timed within ``[t_start - ALERT_EARLY_TOLERANCE_S, t_end + RECOVERY_GRACE_S]``.
    Latency is measured from ``t_start``. The fault size at detection comes from the event's
    params (step: size; ramp: rate x elapsed time; dither: amplitude).
False alerts
    An alert whose code is in :data:`FALSE_ALERT_CODES` (GNSS_LOST, RTK_LOST, GNSS_STALE,
    FAULT, INTEGRITY) is false when it lies outside every event window extended by the same
    tolerance and grace, whatever the event's kind (a protection level may legitimately
    exceed its limit during an outage). GNSS_BACK, BRIDGING, CAT and HDG_* are status reports,
    never false alerts.
Heading
    ``HDG_READY`` carries the mismatch ``INS heading - GNSS track`` (S4), the value the
    service subtracts from its INS heading. With the sidecar's ``heading_error_deg`` (INS
    heading - true heading) and ``crab_deg`` (true heading - ground track), the expected value
    is ``heading_error_deg + crab_deg``; the error is the published value minus that, wrapped
    to +-180 deg. Both are read from the sidecar's top level or, failing that, from its
    ``parameters`` object (where the simulator writes them).

References
----------
S3 (Kim, Walter, Powell): ramp and dither faults and their detection; S4 (Markelov et al.):
the heading mismatch and its accuracy. DESIGN.md: replay and evaluation contract.
"""

from __future__ import annotations

import csv
import json
import logging
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
import pymap3d
from pymavlink.dialects.v20 import ardupilotmega as mavlink2
from scipy import stats

from companion.mavlink import units
from companion.mavlink.ids import MAV_COMP_ID_ONBOARD_COMPUTER
from companion.mavlink.tlog import TlogError, TlogReader
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
"""Columns the truth CSV must have (DESIGN.md)."""

H95_PER_SIGMA: float = float(np.sqrt(stats.chi2.ppf(0.95, 2)))
"""2-D 95 % radius per 1-sigma of a circular Gaussian (2.448)."""
V95_PER_SIGMA: float = float(stats.norm.ppf(0.975))
"""1-D two-sided 95 % bound per 1-sigma (1.960)."""

RECOVERY_GRACE_S = 5.0
"""After an event window ends, alerts within this time are still explained by it, s."""
ALERT_EARLY_TOLERANCE_S = 0.5
"""An alert this much before an event's start still belongs to it (alert-time mapping), s."""
ACCURACY_MAX_AGE_S = 1.0
"""A published accuracy older than this no longer applies to a solution, s."""
MISMATCH_MEDIAN_DISTANCE_M = 50_000.0
"""A median horizontal distance beyond this between the solution and the truth means the
truth belongs to another flight ("mismatched truth"), m."""

EVENT_ALERT_CODES: Mapping[str, tuple[str, ...]] = {
    "outage": ("GNSS_LOST",),
    "rtk_outage": ("RTK_LOST",),
    "downgrade": ("RTK_LOST", "GNSS_LOST"),
    "stale": ("GNSS_STALE",),
    "step": ("FAULT", "INTEGRITY"),
    "ramp": ("FAULT", "INTEGRITY"),
    "dither": ("FAULT", "INTEGRITY"),
}
"""Alert codes that count as detecting an event of each kind."""

FALSE_ALERT_CODES: frozenset[str] = frozenset(
    {"GNSS_LOST", "RTK_LOST", "GNSS_STALE", "FAULT", "INTEGRITY"}
)
"""Codes that are false alerts when no event window explains them."""

_ALERT_PREFIX = "CMP "
_HDG_VALUE_RE = re.compile(r"^\s*(?P<value>[-+]?\d+(?:\.\d*)?)")
_HDG_EPS_RE = re.compile(r"(?:\u00b1|\+/-|\+-|\?|\ufffd+)\s*(?P<eps>\d+(?:\.\d*)?)")
"""The "±" of ``HDG_READY <value> ±<eps> n=<cycles>`` arrives as "±" only if sent as UTF-8
and decoded as such; an ASCII encoder sends "?" and pymavlink's ASCII decoding turns UTF-8
"±" into two U+FFFD; "+-" and "+/-" are accepted too."""
_HDG_N_RE = re.compile(r"n\s*=\s*(?P<n>\d+)")

_STATUSTEXT_LEN = mavlink2.MAVLink_statustext_message.array_lengths[1]
"""Characters in one STATUSTEXT chunk; a shorter chunk ends a multi-chunk text."""


class EvaluationError(Exception):
    """The inputs cannot be evaluated (missing or unreadable file, bad truth): one-line message."""


# --------------------------------------------------------------------------- results


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
    """Everything ``companion evaluate`` measured. See the module docstring for the rules."""

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
        lines: list[str] = []
        title = f"companion evaluate: {self.out_tlog} vs {self.truth_csv}"
        if self.scenario is not None:
            title += f"  (scenario {self.scenario}, seed {self.seed})"
        lines.append(title)
        rate = "" if self.publish_rate_hz is None else f" at {self.publish_rate_hz:.1f} Hz"
        lines.append(
            f"published: {self.n_published} solutions{rate}, t {self.t_first_s:.1f}"
            f"..{self.t_last_s:.1f} s; {self.n_evaluated} within the truth"
            f" ({self.n_outside_truth} outside); accuracy from {self.accuracy_source or 'none'}"
        )
        lines.append(
            f"tlog: {self.tlog.records} records, {self.tlog.bad_records} corrupt skipped,"
            f" {self.tlog.truncated_records} truncated"
        )
        lines.append("")
        lines.append(
            "Position error (m; V signed mean = bias, up +; cover = within published 95 %)"
        )
        header = (
            f"{'group':<28}{'n':>7}{'H mean':>8}{'H rms':>8}{'H p95':>8}{'H max':>8}"
            f"{'V mean':>8}{'V rms':>8}{'V p95':>8}{'V max':>8}{'H cov':>7}{'V cov':>7}"
            f"{'vel rms':>8}{'yaw rms':>8}"
        )
        lines.append(header)
        lines.append("-" * len(header))
        for row in (self.overall, self.normal, *self.windows):
            lines.append(_stats_row(row))
        lines.append("")
        lines.append("Events (detection: first matching alert from the window start)")
        if not self.events:
            lines.append("  none scheduled (no sidecar or no events)")
        else:
            lines.append(
                f"  {'kind':<11}{'window s':<16}{'rx':>3}  {'expects':<20}{'alert':<11}"
                f"{'latency s':>10}{'size at det':>13}"
            )
            for ev in self.events:
                window = f"{ev.t_start_s:.1f}-{ev.t_end_s:.1f}"
                alert = ev.alert_code if ev.detected and ev.alert_code else "MISSED"
                lat = "-" if ev.latency_s is None else f"{ev.latency_s:.2f}"
                size = (
                    "-"
                    if ev.fault_size_at_detection is None
                    else f"{ev.fault_size_at_detection:.3g}"
                )
                lines.append(
                    f"  {ev.kind:<11}{window:<16}{ev.receiver_id:>3}  "
                    f"{'|'.join(ev.expected_codes):<20}{alert:<11}{lat:>10}{size:>13}"
                )
        lines.append("")
        lines.append(f"Alerts: {len(self.alerts)} ({self.n_false_alerts} false)")
        for al in self.alerts[:max_alerts]:
            flag = "  FALSE" if al.false_alert else ""
            lines.append(f"  {al.t_s:9.2f} s  {al.code:<12}{al.text}{flag}")
        if len(self.alerts) > max_alerts:
            lines.append(f"  ... {len(self.alerts) - max_alerts} more")
        lines.append("")
        lines.append(_heading_text(self.heading))
        if self.named_values_last:
            nv = ", ".join(f"{k}={v:.4g}" for k, v in sorted(self.named_values_last.items()))
            lines.append(f"Last named values: {nv}")
        return "\n".join(lines)


# --------------------------------------------------------------------------- inputs


def _read_tlog(path: Path) -> tuple[list[tuple[float, Any]], TlogStats]:
    """Read a tlog with the service's robust reader (:class:`TlogReader`).

    Corrupt regions (bad magic, CRC or length, unknown message ids, garbage) are
    skipped and counted; a cut-short last record is counted as truncated.

    Returns
    -------
    records : list of (t_rx_s, MAVLink_message)
        ``t_rx_s`` in UNIX-epoch seconds, in file order.
    stats : TlogStats
    """
    try:
        reader = TlogReader(path)
    except TlogError as exc:
        raise EvaluationError(str(exc)) from exc
    records = list(reader)
    bad = reader.stats["bad_region"]
    if bad:
        _log.warning("%s: skipped %d corrupt tlog region(s)", path, bad)
    return records, TlogStats(
        records=len(records),
        bad_records=bad,
        truncated_records=reader.stats["truncated_record"],
    )


@dataclass(frozen=True, slots=True, eq=False)
class _Truth:
    t_s: FloatArray
    lat_rad: FloatArray
    lon_rad: FloatArray  # unwrapped
    alt_msl_m: FloatArray
    vel_ned_mps: FloatArray  # (n, 3)
    yaw_unwrapped_deg: FloatArray


def _read_truth(path: Path) -> _Truth:
    """Read the truth CSV (DESIGN.md columns), sorted by time, bad rows dropped (counted)."""
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
    return _Truth(
        t_s=arr[:, 0],
        lat_rad=np.radians(arr[:, 1]),
        lon_rad=np.radians(lon_deg),
        alt_msl_m=arr[:, 3],
        vel_ned_mps=arr[:, 4:7],
        yaw_unwrapped_deg=np.unwrap(arr[:, 9], period=360.0),
    )


def _sidecar_path(truth_csv: Path) -> Path:
    name = truth_csv.name
    if name.endswith(".truth.csv"):
        return truth_csv.with_name(name[: -len(".truth.csv")] + ".json")
    return truth_csv.with_suffix(".json")


def _read_sidecar(path: Path) -> dict[str, Any]:
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
class _Event:
    kind: str
    t_start_s: float
    t_end_s: float
    receiver_id: int
    params: Mapping[str, Any]


def _parse_events(doc: Mapping[str, Any], path: Path) -> list[_Event]:
    raw = doc.get("events", [])
    if not isinstance(raw, list):
        raise EvaluationError(f"events {path}: 'events' must be a list")
    events: list[_Event] = []
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
        events.append(_Event(kind, t0, t1, rx, dict(params)))
    return sorted(events, key=lambda e: e.t_start_s)


# --------------------------------------------------------------------------- published


@dataclass(frozen=True, slots=True, eq=False)
class _Published:
    t_s: FloatArray
    lat_rad: FloatArray
    lon_rad: FloatArray
    alt_msl_m: FloatArray
    vel_ned_mps: FloatArray  # (n, 3)
    yaw_rad: FloatArray  # NaN when unknown
    acc_h_m: FloatArray  # 1-sigma, NaN when none
    acc_v_m: FloatArray
    accuracy_source: str | None
    alerts: list[tuple[float, float, str, str, int]]  # (t_s, t_rx_s, code, rest, severity)
    named: dict[str, list[tuple[float, float]]]


def _extract(records: Sequence[tuple[float, Any]], path: Path) -> _Published:
    """Pull the service's publications (component 191) out of the tlog records."""
    own = MAV_COMP_ID_ONBOARD_COMPUTER
    gpi_rows: list[tuple[float, ...]] = []
    gpi_stream_idx: list[int] = []
    gpi_offsets: list[float] = []
    gps_input: list[tuple[int, float, float, float]] = []  # (stream idx, t_rx, h, v)
    texts: list[tuple[int, float, str, int]] = []
    named: dict[str, list[tuple[float, float]]] = {}
    chunks: dict[int, tuple[int, float, list[str], int]] = {}
    ignore_h = mavlink2.GPS_INPUT_IGNORE_FLAG_HORIZONTAL_ACCURACY
    ignore_v = mavlink2.GPS_INPUT_IGNORE_FLAG_VERTICAL_ACCURACY
    for k, (t_rx, msg) in enumerate(records):
        if msg.get_srcComponent() != own:
            continue
        mtype = msg.get_type()
        if mtype == "GLOBAL_POSITION_INT":
            t_s = msg.time_boot_ms / units.MS_PER_S
            yaw = math.nan if msg.hdg == units.UINT16_UNKNOWN else msg.hdg / units.CDEG_PER_RAD
            gpi_rows.append(
                (
                    t_s,
                    msg.lat / units.DEGE7_PER_RAD,
                    msg.lon / units.DEGE7_PER_RAD,
                    msg.alt / units.MM_PER_M,
                    msg.vx / units.CM_PER_M,
                    msg.vy / units.CM_PER_M,
                    msg.vz / units.CM_PER_M,
                    yaw,
                )
            )
            gpi_stream_idx.append(k)
            gpi_offsets.append(t_rx - t_s)
        elif mtype == "GPS_INPUT":
            h = float(msg.horiz_accuracy)
            v = float(msg.vert_accuracy)
            h = h if not (msg.ignore_flags & ignore_h) and h > 0.0 else math.nan
            v = v if not (msg.ignore_flags & ignore_v) and v > 0.0 else math.nan
            gps_input.append((k, t_rx, h, v))
        elif mtype == "STATUSTEXT":
            text = str(msg.text)
            chunk_id = int(getattr(msg, "id", 0) or 0)
            if chunk_id == 0:
                texts.append((k, t_rx, text, int(msg.severity)))
            else:
                prev = chunks.get(chunk_id)
                if prev is None:
                    chunks[chunk_id] = (k, t_rx, [text], int(msg.severity))
                else:
                    prev[2].append(text)
                if len(text) < _STATUSTEXT_LEN:
                    k0, t0, parts, sev = chunks.pop(chunk_id)
                    texts.append((k0, t0, "".join(parts), sev))
        elif mtype == "NAMED_VALUE_FLOAT":
            name = str(msg.name).rstrip("\x00").strip()
            named.setdefault(name, []).append((msg.time_boot_ms / units.MS_PER_S, msg.value))
    for k0, t0, parts, sev in chunks.values():
        texts.append((k0, t0, "".join(parts), sev))
    if not gpi_rows:
        raise EvaluationError(
            f"{path}: no published solution (GLOBAL_POSITION_INT from component {own})"
        )
    gpi = np.asarray(gpi_rows, dtype=np.float64)
    idx_arr = np.asarray(gpi_stream_idx)
    off_arr = np.asarray(gpi_offsets)

    def to_autopilot_time(stream_idx: int, t_rx: float) -> float:
        j = int(np.searchsorted(idx_arr, stream_idx, side="right")) - 1
        return t_rx - float(off_arr[max(j, 0)])

    alerts: list[tuple[float, float, str, str, int]] = []
    for k, t_rx, text, sev in sorted(texts):
        if not text.startswith(_ALERT_PREFIX):
            continue
        body = text[len(_ALERT_PREFIX) :].strip()
        if not body:
            continue
        code, _, rest = body.partition(" ")
        alerts.append((to_autopilot_time(k, t_rx), t_rx, code, rest.strip(), sev))
    alerts.sort(key=lambda a: a[0])

    order = np.argsort(gpi[:, 0], kind="stable")
    gpi = gpi[order]
    acc_h = np.full(gpi.shape[0], np.nan)
    acc_v = np.full(gpi.shape[0], np.nan)
    source: str | None = None
    if gps_input:
        t_acc = np.asarray([to_autopilot_time(k, t_rx) for k, t_rx, _, _ in gps_input])
        acc_h = _hold(t_acc, np.asarray([g[2] for g in gps_input]), gpi[:, 0])
        acc_v = _hold(t_acc, np.asarray([g[3] for g in gps_input]), gpi[:, 0])
        source = "GPS_INPUT"
    elif "CMP_HACC" in named:
        h_series = np.asarray(named["CMP_HACC"], dtype=np.float64)
        acc_h = _hold(h_series[:, 0], h_series[:, 1], gpi[:, 0])
        if "CMP_VACC" in named:
            v_series = np.asarray(named["CMP_VACC"], dtype=np.float64)
            acc_v = _hold(v_series[:, 0], v_series[:, 1], gpi[:, 0])
        source = "CMP_HACC"
    return _Published(
        t_s=gpi[:, 0],
        lat_rad=gpi[:, 1],
        lon_rad=gpi[:, 2],
        alt_msl_m=gpi[:, 3],
        vel_ned_mps=gpi[:, 4:7],
        yaw_rad=gpi[:, 7],
        acc_h_m=acc_h,
        acc_v_m=acc_v,
        accuracy_source=source,
        alerts=alerts,
        named=named,
    )


def _hold(t_src: FloatArray, values: FloatArray, t_query: FloatArray) -> FloatArray:
    """Zero-order hold: latest value at or before each query time, NaN if older than allowed."""
    order = np.argsort(t_src, kind="stable")
    t_sorted = t_src[order]
    v_sorted = values[order]
    j = np.searchsorted(t_sorted, t_query, side="right") - 1
    out = np.full(t_query.shape, np.nan)
    ok = j >= 0
    jj = np.where(ok, j, 0)
    fresh = ok & (t_query - t_sorted[jj] <= ACCURACY_MAX_AGE_S)
    out[fresh] = v_sorted[jj[fresh]]
    return out


# --------------------------------------------------------------------------- scoring


def _group_stats(
    label: str,
    kind: str,
    window: tuple[float, float] | None,
    mask: np.ndarray,
    err_h: FloatArray,
    err_v: FloatArray,
    acc_h95: FloatArray,
    acc_v95: FloatArray,
    vel_err_h: FloatArray,
    yaw_err_deg: FloatArray,
) -> ErrorStats:
    n = int(np.count_nonzero(mask))
    t0, t1 = (None, None) if window is None else window
    if n == 0:
        return ErrorStats(label, kind, t0, t1, 0, *([None] * 12))
    h = err_h[mask]
    v = err_v[mask]
    va = np.abs(v)

    def coverage(err: FloatArray, bound: FloatArray) -> float | None:
        ok = np.isfinite(bound)
        if not np.any(ok):
            return None
        return float(np.mean(err[ok] <= bound[ok]))

    yaw = yaw_err_deg[mask]
    yaw = yaw[np.isfinite(yaw)]
    return ErrorStats(
        label=label,
        kind=kind,
        t_start_s=t0,
        t_end_s=t1,
        n=n,
        h_mean_m=float(np.mean(h)),
        h_rms_m=float(np.sqrt(np.mean(h**2))),
        h_p95_m=float(np.percentile(h, 95.0)),
        h_max_m=float(np.max(h)),
        v_mean_m=float(np.mean(v)),
        v_rms_m=float(np.sqrt(np.mean(v**2))),
        v_p95_m=float(np.percentile(va, 95.0)),
        v_max_m=float(np.max(va)),
        h95_coverage=coverage(h, acc_h95[mask]),
        v95_coverage=coverage(va, acc_v95[mask]),
        vel_h_rms_mps=float(np.sqrt(np.mean(vel_err_h[mask] ** 2))),
        yaw_rms_deg=float(np.sqrt(np.mean(yaw**2))) if yaw.size else None,
    )


def _fault_size(ev: _Event, t_detect_s: float) -> float | None:
    """Size of a fault at detection from its params (m), or None when not derivable.

    step: the norm of ``offset_ned_m`` (the simulator's), or ``size_m`` / ``step_m`` /
    ``magnitude_m`` / ``offset_m``; ramp: the norm of ``rate_ned_mps`` (or ``rate_mps`` /
    ``slope_mps``) times the time since the start; dither: ``amplitude_m``. Falls back on
    the first param whose name ends in ``_m`` (step, dither) or ``_mps`` (ramp).
    """
    if ev.kind == "step":
        return _param_magnitude(
            ev.params, ("offset_ned_m", "size_m", "step_m", "magnitude_m", "offset_m"), "_m"
        )
    if ev.kind == "dither":
        return _param_magnitude(ev.params, ("amplitude_m", "amp_m", "size_m"), "_m")
    if ev.kind == "ramp":
        rate = _param_magnitude(
            ev.params, ("rate_ned_mps", "rate_mps", "slope_mps", "ramp_mps"), "_mps"
        )
        if rate is None:
            return None
        return rate * max(t_detect_s - ev.t_start_s, 0.0)
    return None


def _param_magnitude(params: Mapping[str, Any], keys: tuple[str, ...], suffix: str) -> float | None:
    candidates = [k for k in keys if k in params]
    candidates += sorted(k for k in params if k.endswith(suffix) and k not in keys)
    for key in candidates:
        value = params[key]
        try:
            arr = np.atleast_1d(np.asarray(value, dtype=np.float64))
        except (TypeError, ValueError):
            continue
        if arr.ndim == 1 and arr.size > 0 and np.all(np.isfinite(arr)):
            return float(np.linalg.norm(arr))
    return None


def _wrap_deg(x: float) -> float:
    return (x + 180.0) % 360.0 - 180.0


def _heading_result(
    alerts: Sequence[tuple[float, float, str, str, int]],
    named: Mapping[str, list[tuple[float, float]]],
    sidecar: Mapping[str, Any],
) -> HeadingResult:
    ready: list[tuple[float, float, float | None, int | None]] = []
    rejects: list[str] = []
    applied = False
    for t_s, _, code, rest, _ in alerts:
        if code == "HDG_READY":
            m = _HDG_VALUE_RE.match(rest)
            if m is None:
                _log.warning("HDG_READY without a value: %r", rest)
                continue
            e = _HDG_EPS_RE.search(rest)
            n = _HDG_N_RE.search(rest)
            ready.append(
                (
                    t_s,
                    float(m.group("value")),
                    float(e.group("eps")) if e else None,
                    int(n.group("n")) if n else None,
                )
            )
        elif code == "HDG_REJECT":
            rejects.append(rest)
        elif code == "HDG_APPLIED":
            applied = True
    expected: float | None = None
    # The brief puts them at the top level; the simulator writes them under "parameters".
    nested = sidecar.get("parameters")
    source: Mapping[str, Any] = sidecar
    if "heading_error_deg" not in sidecar and isinstance(nested, Mapping):
        source = nested
    if "heading_error_deg" in source:
        try:
            expected = float(source["heading_error_deg"]) + float(source.get("crab_deg", 0.0))
        except (TypeError, ValueError):
            _log.warning("sidecar heading_error_deg/crab_deg not numeric")
    hdgc = named.get("CMP_HDGC", [])
    hdge = named.get("CMP_HDGE", [])
    hdgc_last = float(hdgc[-1][1]) if hdgc else None
    last = ready[-1] if ready else None
    error = None
    if last is not None and expected is not None:
        error = _wrap_deg(last[1] - expected)
    hdgc_error = None
    if hdgc_last is not None and expected is not None:
        hdgc_error = _wrap_deg(hdgc_last - expected)
    accumulation = None
    if last is not None and hdgc:
        accumulation = last[0] - min(t for t, _ in hdgc)
    return HeadingResult(
        ready_value_deg=last[1] if last else None,
        ready_eps_deg=last[2] if last else None,
        ready_cycles=last[3] if last else None,
        ready_t_s=last[0] if last else None,
        n_ready=len(ready),
        applied=applied,
        rejects=tuple(rejects),
        expected_deg=expected,
        error_deg=error,
        hdgc_last_deg=hdgc_last,
        hdge_last_deg=float(hdge[-1][1]) if hdge else None,
        hdgc_error_deg=hdgc_error,
        accumulation_s=accumulation,
    )


def evaluate(out_tlog: Path, truth_csv: Path, events_json: Path | None = None) -> Evaluation:
    """Score a replay's published output against truth.

    Parameters
    ----------
    out_tlog : Path
        The replay output tlog (only component 191's messages are read).
    truth_csv : Path
        Truth CSV with :data:`TRUTH_COLUMNS` (``t_s`` autopilot time, alt MSL).
    events_json : Path or None
        Event sidecar; None looks for ``<name>.json`` beside ``<name>.truth.csv`` (absent is
        fine: then there are no events and every loss/fault alert is false).

    Returns
    -------
    Evaluation

    Raises
    ------
    EvaluationError
        Missing or unreadable files, truth with missing columns, no published solution, or a
        truth that does not overlap the published times (or is far from them: another flight).

    References
    ----------
    DESIGN.md, replay and evaluation contract; S3 (fault kinds), S4 (heading mismatch).
    """
    out_tlog = Path(out_tlog)
    truth_csv = Path(truth_csv)
    for p in (out_tlog, truth_csv):
        if not p.is_file():
            raise EvaluationError(f"no such file: {p}")
    events_path: Path | None
    if events_json is not None:
        events_path = Path(events_json)
        if not events_path.is_file():
            raise EvaluationError(f"no such events file: {events_path}")
    else:
        candidate = _sidecar_path(truth_csv)
        events_path = candidate if candidate.is_file() else None
    records, tstats = _read_tlog(out_tlog)
    if not records:
        raise EvaluationError(f"unreadable tlog {out_tlog}: no MAVLink record found")
    pub = _extract(records, out_tlog)
    truth = _read_truth(truth_csv)
    sidecar: dict[str, Any] = {}
    events: list[_Event] = []
    if events_path is not None:
        sidecar = _read_sidecar(events_path)
        events = _parse_events(sidecar, events_path)

    inside = (pub.t_s >= truth.t_s[0]) & (pub.t_s <= truth.t_s[-1])
    n_in = int(np.count_nonzero(inside))
    if n_in == 0:
        raise EvaluationError(
            f"mismatched truth: published t {pub.t_s[0]:.1f}..{pub.t_s[-1]:.1f} s does not "
            f"overlap truth t {truth.t_s[0]:.1f}..{truth.t_s[-1]:.1f} s"
        )
    t = pub.t_s[inside]
    lat_t = np.interp(t, truth.t_s, truth.lat_rad)
    lon_t = np.interp(t, truth.t_s, truth.lon_rad)
    alt_t = np.interp(t, truth.t_s, truth.alt_msl_m)
    vel_t = np.column_stack([np.interp(t, truth.t_s, truth.vel_ned_mps[:, i]) for i in range(3)])
    yaw_t_deg = np.interp(t, truth.t_s, truth.yaw_unwrapped_deg)
    # Put the published longitude on the same branch as the (unwrapped) truth longitude.
    lon_p = lon_t + (pub.lon_rad[inside] - lon_t + math.pi) % (2.0 * math.pi) - math.pi
    n_err, e_err, d_err = pymap3d.geodetic2ned(
        pub.lat_rad[inside], lon_p, pub.alt_msl_m[inside], lat_t, lon_t, alt_t, deg=False
    )
    err_h = np.hypot(np.asarray(n_err), np.asarray(e_err))
    err_v = -np.asarray(d_err, dtype=np.float64)
    median_h = float(np.median(err_h))
    if median_h > MISMATCH_MEDIAN_DISTANCE_M:
        raise EvaluationError(
            f"mismatched truth: the published solution is {median_h / 1000.0:.0f} km from the "
            "truth (median): another flight?"
        )
    vel_err = pub.vel_ned_mps[inside] - vel_t
    vel_err_h = np.hypot(vel_err[:, 0], vel_err[:, 1])
    yaw_p_deg = np.degrees(pub.yaw_rad[inside])
    yaw_err_deg = (yaw_p_deg - yaw_t_deg + 180.0) % 360.0 - 180.0  # NaN stays NaN
    acc_h95 = H95_PER_SIGMA * pub.acc_h_m[inside]
    acc_v95 = V95_PER_SIGMA * pub.acc_v_m[inside]

    def group(label: str, kind: str, window: tuple[float, float] | None, mask: np.ndarray) -> Any:
        return _group_stats(
            label, kind, window, mask, err_h, err_v, acc_h95, acc_v95, vel_err_h, yaw_err_deg
        )

    all_mask = np.ones(t.shape, dtype=bool)
    in_any = np.zeros(t.shape, dtype=bool)
    windows: list[ErrorStats] = []
    for ev in events:
        m = (t >= ev.t_start_s) & (t <= ev.t_end_s)
        in_any |= m
        label = f"{ev.kind} {ev.t_start_s:.1f}-{ev.t_end_s:.1f}"
        windows.append(group(label, ev.kind, (ev.t_start_s, ev.t_end_s), m))
    overall = group("all", "all", None, all_mask)
    normal = group("normal (outside events)", "normal", None, ~in_any)

    alert_records, n_false = _classify_alerts(pub.alerts, events)
    event_results = tuple(_detect(ev, pub.alerts) for ev in events)
    heading = _heading_result(pub.alerts, pub.named, sidecar)

    frame_lat, frame_lon, frame_alt = lat_t[0], lon_t[0], alt_t[0]
    tru_span = (truth.t_s >= t[0]) & (truth.t_s <= t[-1])
    tn, te, _ = pymap3d.geodetic2ned(
        truth.lat_rad[tru_span],
        truth.lon_rad[tru_span],
        truth.alt_msl_m[tru_span],
        frame_lat,
        frame_lon,
        frame_alt,
        deg=False,
    )
    pn, pe, _ = pymap3d.geodetic2ned(
        pub.lat_rad[inside],
        lon_p,
        pub.alt_msl_m[inside],
        frame_lat,
        frame_lon,
        frame_alt,
        deg=False,
    )
    series = EvaluationSeries(
        t_s=t,
        err_h_m=err_h,
        err_v_m=err_v,
        acc_h95_m=acc_h95,
        acc_v95_m=acc_v95,
        pub_east_m=np.asarray(pe, dtype=np.float64),
        pub_north_m=np.asarray(pn, dtype=np.float64),
        truth_t_s=truth.t_s[tru_span],
        truth_east_m=np.atleast_1d(np.asarray(te, dtype=np.float64)),
        truth_north_m=np.atleast_1d(np.asarray(tn, dtype=np.float64)),
    )
    rate = None
    if pub.t_s.size > 1 and pub.t_s[-1] > pub.t_s[0]:
        rate = float((pub.t_s.size - 1) / (pub.t_s[-1] - pub.t_s[0]))
    seed = sidecar.get("seed")
    scenario = sidecar.get("scenario")
    return Evaluation(
        out_tlog=str(out_tlog),
        truth_csv=str(truth_csv),
        events_json=None if events_path is None else str(events_path),
        scenario=None if scenario is None else str(scenario),
        seed=seed if isinstance(seed, int) else None,
        tlog=tstats,
        n_published=int(pub.t_s.size),
        n_evaluated=n_in,
        n_outside_truth=int(pub.t_s.size - n_in),
        t_first_s=float(pub.t_s[0]),
        t_last_s=float(pub.t_s[-1]),
        publish_rate_hz=rate,
        accuracy_source=pub.accuracy_source,
        overall=overall,
        normal=normal,
        windows=tuple(windows),
        events=event_results,
        alerts=tuple(alert_records),
        n_false_alerts=n_false,
        heading=heading,
        named_values_last={k: float(v[-1][1]) for k, v in pub.named.items() if v},
        series=series,
    )


def _explained(t_s: float, events: Sequence[_Event]) -> bool:
    return any(
        ev.t_start_s - ALERT_EARLY_TOLERANCE_S <= t_s <= ev.t_end_s + RECOVERY_GRACE_S
        for ev in events
    )


def _classify_alerts(
    alerts: Sequence[tuple[float, float, str, str, int]], events: Sequence[_Event]
) -> tuple[list[AlertRecord], int]:
    out: list[AlertRecord] = []
    n_false = 0
    for t_s, t_rx, code, rest, sev in alerts:
        false = code in FALSE_ALERT_CODES and not _explained(t_s, events)
        n_false += int(false)
        out.append(AlertRecord(t_s, t_rx, code, rest, sev, false))
    if n_false:
        _log.info("%d false alert(s)", n_false)
    return out, n_false


def _detect(ev: _Event, alerts: Sequence[tuple[float, float, str, str, int]]) -> EventResult:
    codes = EVENT_ALERT_CODES.get(ev.kind, ())
    lo = ev.t_start_s - ALERT_EARLY_TOLERANCE_S
    hi = ev.t_end_s + RECOVERY_GRACE_S
    hit = next((a for a in alerts if a[2] in codes and lo <= a[0] <= hi), None)
    if hit is None:
        return EventResult(
            ev.kind, ev.t_start_s, ev.t_end_s, ev.receiver_id, ev.params, codes,
            False, None, None, None, None,
        )  # fmt: skip
    return EventResult(
        kind=ev.kind,
        t_start_s=ev.t_start_s,
        t_end_s=ev.t_end_s,
        receiver_id=ev.receiver_id,
        params=ev.params,
        expected_codes=codes,
        detected=True,
        alert_code=hit[2],
        alert_t_s=hit[0],
        latency_s=hit[0] - ev.t_start_s,
        fault_size_at_detection=_fault_size(ev, hit[0]),
    )


# --------------------------------------------------------------------------- text helpers


def _fmt(x: float | None, width: int, digits: int = 3) -> str:
    if x is None:
        return f"{'-':>{width}}"
    return f"{x:>{width}.{digits}g}" if abs(x) >= 1000 else f"{x:>{width}.{digits}f}"


def _pct(x: float | None, width: int) -> str:
    return f"{'-':>{width}}" if x is None else f"{100.0 * x:>{width - 1}.0f}%"


def _stats_row(s: ErrorStats) -> str:
    label = s.label if len(s.label) <= 27 else s.label[:26] + "~"
    return (
        f"{label:<28}{s.n:>7}{_fmt(s.h_mean_m, 8)}{_fmt(s.h_rms_m, 8)}{_fmt(s.h_p95_m, 8)}"
        f"{_fmt(s.h_max_m, 8)}{_fmt(s.v_mean_m, 8)}{_fmt(s.v_rms_m, 8)}{_fmt(s.v_p95_m, 8)}"
        f"{_fmt(s.v_max_m, 8)}{_pct(s.h95_coverage, 7)}{_pct(s.v95_coverage, 7)}"
        f"{_fmt(s.vel_h_rms_mps, 8)}{_fmt(s.yaw_rms_deg, 8, 2)}"
    )


def _heading_text(h: HeadingResult) -> str:
    parts = ["Heading correction:"]
    if h.ready_value_deg is not None:
        eps = "" if h.ready_eps_deg is None else f" +-{h.ready_eps_deg:.3f}"
        n = "" if h.ready_cycles is None else f" n={h.ready_cycles}"
        parts.append(f"HDG_READY {h.ready_value_deg:+.3f} deg{eps}{n} at t={h.ready_t_s:.1f} s")
        if h.accumulation_s is not None:
            parts.append(f"({h.accumulation_s:.1f} s after the first CMP_HDGC)")
    else:
        parts.append("never ready")
    if h.expected_deg is not None:
        parts.append(f"; expected {h.expected_deg:+.3f} deg (heading_error + crab)")
    if h.error_deg is not None:
        parts.append(f"; error {h.error_deg:+.3f} deg")
    if h.hdgc_last_deg is not None:
        extra = "" if h.hdgc_error_deg is None else f" (error {h.hdgc_error_deg:+.3f})"
        parts.append(f"; last CMP_HDGC {h.hdgc_last_deg:+.3f} deg{extra}")
    if h.applied:
        parts.append("; applied")
    if h.rejects:
        parts.append(f"; {len(h.rejects)} reject(s), last: {h.rejects[-1]}")
    return " ".join(parts).replace(" ;", ";")


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

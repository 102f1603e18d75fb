"""One flight of a batch: replay it, score it, and say it in one row of plain values.

The row (:func:`score_flight`) holds, for the flight at ``path``:

* ``path``, ``name``, ``format`` (tlog, dataflash, ulog), ``vehicle`` (the
  autopilot's first HEARTBEAT: its family and MAV_TYPE), ``duration_s`` (log time),
  ``messages_in``;
* ``scoring``: ``truth`` when ``<stem>.truth.csv`` (the simulator's) sits beside the
  log, else ``against_input`` (the receiver's own fixes);
* gaps (``gaps``, ``gap_s``: GNSS gaps of the receiver and their total length) and
  ``bridged_s`` (log time the service published with ``CMP_OUTG`` > 0, i.e. carried
  the solution without a fused fix);
* closures (``closures``, ``closure_median_m``, ``closure_max_m``,
  ``hold_median_m``, ``closure_over_hold_median``, ``closure_over_hold_max``): at
  the first fix after each gap, the horizontal distance of the bridged solution
  against that of holding the last fix;
* with truth: ``truth_h95_m`` (all solutions) and ``truth_h95_outage_m`` (in the
  scenario's event windows);
* ``alerts_per_h_<CODE>`` for every alert code (alerts per hour of log);
* ``cat_<k>_s``: log time with ``CMP_CAT`` = k (0 none, 1-3 CAT I-III);
* ``rej_<reason>``: the replay's rejections (the table fills the reasons other
  flights have with 0);
* ``error``: empty, or why the flight could not be replayed or scored (the other
  values then as far as they got).

Nothing in a row depends on the wall clock or on which worker made it.
"""

from __future__ import annotations

import logging
import math
import statistics
import tempfile
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

from companion.mavlink.logs import log_format, open_flight_log
from companion.mavlink.tlog import TlogReader, TlogWriter
from companion.types import AlertCode

log = logging.getLogger(__name__)

ALERT_CODES = tuple(code.value for code in AlertCode)
CATEGORIES = (0, 1, 2, 3)
_MAV_TYPES = {
    1: "fixed-wing", 2: "quadrotor", 4: "helicopter", 10: "rover", 12: "submarine",
    13: "hexarotor", 14: "octorotor", 19: "VTOL", 20: "VTOL", 21: "VTOL", 22: "VTOL",
}  # fmt: skip
_AUTOPILOTS = {3: "ArduPilot", 12: "PX4"}
MAV_AUTOPILOT_INVALID = 8
OUR_COMPONENT = 191


def vehicle_name(mav_type: int, autopilot: int) -> str:
    """``ArduPilot quadrotor``, ``PX4 VTOL`` ... from a HEARTBEAT's type and autopilot."""
    family = _AUTOPILOTS.get(autopilot, f"autopilot {autopilot}")
    return f"{family} {_MAV_TYPES.get(mav_type, f'type {mav_type}')}"


def _heartbeat_vehicle(msg: Any) -> str | None:
    if msg.get_type() != "HEARTBEAT" or msg.autopilot == MAV_AUTOPILOT_INVALID:
        return None
    return vehicle_name(msg.type, msg.autopilot)


def _as_tlog(path: Path, work: Path) -> tuple[Path, str, dict[str, int]]:
    """A .bin/.ulg written as the .tlog the replay reads of it (byte-identical replay:
    docs/replay.md); the vehicle; the reader's counts, as the replay names them."""
    reader = open_flight_log(path)
    vehicle = ""
    tlog = work / "input.tlog"
    with TlogWriter(tlog) as writer:
        for t_rx_s, msg in reader:
            if not vehicle:
                vehicle = _heartbeat_vehicle(msg) or ""
            writer.write(t_rx_s, bytes(msg.get_msgbuf()))
    prefix = getattr(reader, "stats_prefix", "log_")
    counts = {f"{prefix}{k}": int(v) for k, v in reader.stats.items() if v and k != "bad_bytes"}
    return tlog, vehicle, counts


def _tlog_vehicle(path: Path) -> str:
    for _t, msg in TlogReader(path):
        if msg.get_srcComponent() != OUR_COMPONENT:
            name = _heartbeat_vehicle(msg)
            if name is not None:
                return name
    return ""


def _status_times(out_tlog: Path) -> tuple[float, dict[int, float]]:
    """Log time with CMP_OUTG > 0 and with each CMP_CAT value, from the published values
    (each held until the next of its name, the last one for no time)."""
    series: dict[str, list[tuple[float, float]]] = {"CMP_OUTG": [], "CMP_CAT": []}
    for t_rx_s, msg in TlogReader(out_tlog):
        if msg.get_type() == "NAMED_VALUE_FLOAT":
            name = msg.name if isinstance(msg.name, str) else msg.name.decode(errors="replace")
            name = name.rstrip("\x00")
            if name in series:
                series[name].append((t_rx_s, float(msg.value)))

    def held(points: list[tuple[float, float]], keep: Callable[[float], bool]) -> float:
        return sum(t1 - t0 for (t0, v), (t1, _) in zip(points, points[1:], strict=False) if keep(v))

    outg = series["CMP_OUTG"]
    cats = series["CMP_CAT"]
    bridged = held(outg, lambda v: v > 0.0)
    by_cat = {k: held(cats, lambda v, k=k: int(round(v)) == k) for k in CATEGORIES}  # type: ignore[misc]
    return bridged, by_cat


def _median(values: list[float]) -> float:
    return statistics.median(values) if values else math.nan


def score_flight(path: str, config_path: str | None = None) -> dict[str, Any]:
    """The row of the flight at ``path`` (module docstring); never raises."""
    p = Path(path)
    row: dict[str, Any] = {
        "path": str(path),
        "name": p.name,
        "format": "",
        "vehicle": "",
        "duration_s": math.nan,
        "messages_in": 0,
        "scoring": "",
        "error": "",
    }
    try:
        _score(p, row, config_path)
    except Exception as exc:  # noqa: BLE001 - a flight that fails is an error row, the batch goes on
        row["error"] = f"{type(exc).__name__}: {exc}".splitlines()[0][:300]
        log.info("%s: %s", path, "".join(traceback.format_exception_only(type(exc), exc)).strip())
    return row


def _score(p: Path, row: dict[str, Any], config_path: str | None) -> None:
    from companion.config import load_config
    from companion.evaluate.against_input import evaluate_against_input
    from companion.replay import replay

    config = load_config(Path(config_path)) if config_path else None
    row["format"] = log_format(p)
    with tempfile.TemporaryDirectory(prefix="companion-batch-") as tmp:
        work = Path(tmp)
        reader_counts: dict[str, int] = {}
        if row["format"] == "tlog":
            tlog = p
            row["vehicle"] = _tlog_vehicle(p)
        else:
            tlog, row["vehicle"], reader_counts = _as_tlog(p, work)
        out = work / "out.tlog"
        summary = replay(tlog, out, config)
        row["duration_s"] = summary.log_duration_s
        row["messages_in"] = summary.messages_in
        for reason, n in sorted({**summary.rejections, **reader_counts}.items()):
            row[f"rej_{reason}"] = int(n)
        hours = summary.log_duration_s / 3600.0
        for code in ALERT_CODES:
            n = summary.alerts.get(code, 0)
            row[f"alerts_per_h_{code}"] = n / hours if hours > 0 else math.nan
        bridged, by_cat = _status_times(out)
        row["bridged_s"] = bridged
        for k, seconds in by_cat.items():
            row[f"cat_{k}_s"] = seconds
        truth = p.with_name(p.name.removesuffix(p.suffix) + ".truth.csv")
        row["scoring"] = "truth" if truth.is_file() else "against_input"
        decoder = config.decoder if config is not None else None
        scored = evaluate_against_input(out, tlog, decoder)
        gaps = scored.gaps
        row["gaps"] = len(gaps)
        row["gap_s"] = sum(g.length_s for g in gaps)
        closures = [g.closure_h_m for g in gaps if g.closure_h_m is not None]
        pairs = [
            (g.closure_h_m, g.hold_h_m)
            for g in gaps
            if g.closure_h_m is not None and g.hold_h_m is not None and g.hold_h_m > 0.0
        ]
        row["closures"] = len(closures)
        row["closure_median_m"] = _median(closures)
        row["closure_max_m"] = max(closures) if closures else math.nan
        row["hold_median_m"] = _median([h for _, h in pairs])
        ratios = [c / h for c, h in pairs]
        row["closure_over_hold_median"] = _median(ratios)
        row["closure_over_hold_max"] = max(ratios) if ratios else math.nan
        if truth.is_file():
            from companion.evaluate.run import evaluate

            ev = evaluate(out, truth)
            row["truth_h95_m"] = _none_nan(ev.overall.h_p95_m)
            outage = [w.h_p95_m for w in ev.windows if w.h_p95_m is not None]
            row["truth_h95_outage_m"] = max(outage) if outage else math.nan


def _none_nan(value: float | None) -> float:
    return math.nan if value is None else float(value)

"""One evaluation: read the inputs, align the published solution with the truth, score it."""

from __future__ import annotations

import logging
import math
from pathlib import Path
from typing import Any

import numpy as np
import pymap3d

from companion.evaluate.published import extract_publications
from companion.evaluate.results import (
    ErrorStats,
    Evaluation,
    EvaluationError,
    EvaluationSeries,
    TlogStats,
)
from companion.evaluate.score import (
    H95_PER_SIGMA,
    MISMATCH_MEDIAN_DISTANCE_M,
    V95_PER_SIGMA,
    classify_alerts,
    detect,
    group_stats,
    heading_result,
)
from companion.evaluate.truth import (
    Event,
    parse_events,
    read_sidecar,
    read_truth,
    sidecar_path,
)
from companion.mavlink.readback import read_tlog
from companion.mavlink.tlog import TlogError, describe_file

_log = logging.getLogger(__name__)


def _read_tlog(path: Path) -> tuple[list[tuple[float, Any]], TlogStats]:
    """The tlog's records, ``(t_rx_s, message)`` in file order, and what reading found.

    Corrupt regions (bad magic, CRC or length, unknown message ids, garbage) are
    skipped and counted; a cut-short last record is counted as truncated.
    """
    try:
        contents = read_tlog(path)
    except TlogError as exc:
        raise EvaluationError(str(exc)) from exc
    bad = contents.bad_regions
    if bad and contents.records:  # with none, evaluate says what the file is
        _log.warning("%s: skipped %d corrupt tlog region(s)", path, bad)
    return contents.records, TlogStats(
        records=len(contents.records),
        bad_records=bad,
        truncated_records=contents.truncated_records,
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
        candidate = sidecar_path(truth_csv)
        events_path = candidate if candidate.is_file() else None
    records, tstats = _read_tlog(out_tlog)
    if not records:
        raise EvaluationError(f"{out_tlog}: no tlog record: {describe_file(out_tlog)}")
    pub = extract_publications(records, out_tlog)
    truth = read_truth(truth_csv)
    sidecar: dict[str, Any] = {}
    events: list[Event] = []
    if events_path is not None:
        sidecar = read_sidecar(events_path)
        events = parse_events(sidecar, events_path)

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
        return group_stats(
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

    alert_records, n_false = classify_alerts(pub.alerts, events)
    event_results = tuple(detect(ev, pub.alerts) for ev in events)
    heading = heading_result(pub.alerts, pub.named, sidecar)

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

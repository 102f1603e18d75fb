"""Scoring rules: error statistics, event detection, false alerts, the heading result.

See :mod:`companion.evaluate` for the rules in words.

References
----------
Kim, Walter and Powell, "Standalone GPS-based flight inspection system": ramp and dither
faults and their detection; Markelov et al., "INS course correction from satellite
navigation before take-off": the heading mismatch and its accuracy.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy import stats

from companion.evaluate.results import AlertRecord, ErrorStats, EventResult, HeadingResult
from companion.types import FloatArray

if TYPE_CHECKING:
    from companion.evaluate.truth import Event

_log = logging.getLogger(__name__)

H95_PER_SIGMA: float = float(np.sqrt(stats.chi2.ppf(0.95, 2)))
"""2-D 95 % radius per 1-sigma of a circular Gaussian (2.448)."""
V95_PER_SIGMA: float = float(stats.norm.ppf(0.975))
"""1-D two-sided 95 % bound per 1-sigma (1.960)."""

RECOVERY_GRACE_S = 5.0
"""After an event window ends, alerts within this time are still explained by it, s."""
ALERT_EARLY_TOLERANCE_S = 0.5
"""An alert this much before an event's start still belongs to it (alert-time mapping), s."""
MISMATCH_MEDIAN_DISTANCE_M = 50_000.0
"""A median horizontal distance beyond this between the solution and the truth means the
truth belongs to another flight ("mismatched truth"), m."""

EVENT_ALERT_CODES: Mapping[str, tuple[str, ...]] = {
    "outage": ("GNSS_LOST", "NO_DATA"),  # NO_DATA: the fixes stopped with every stream
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

_HDG_VALUE_RE = re.compile(r"^\s*(?P<value>[-+]?\d+(?:\.\d*)?)")
_HDG_EPS_RE = re.compile(r"(?:\u00b1|\+/-|\+-|\?|\ufffd+)\s*(?P<eps>\d+(?:\.\d*)?)")
"""The "±" of ``HDG_READY <value> ±<eps> n=<cycles>`` arrives as "±" only if sent as UTF-8
and decoded as such; an ASCII encoder sends "?" and pymavlink's ASCII decoding turns UTF-8
"±" into two U+FFFD; "+-" and "+/-" are accepted too."""
_HDG_N_RE = re.compile(r"n\s*=\s*(?P<n>\d+)")


def group_stats(
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
    """The statistics of the solutions selected by ``mask`` (errors of shape (n,))."""
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


def fault_size(ev: Event, t_detect_s: float) -> float | None:
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


def heading_result(
    alerts: Sequence[tuple[float, float, str, str, int]],
    named: Mapping[str, list[tuple[float, float]]],
    sidecar: Mapping[str, Any],
) -> HeadingResult:
    """The last ``HDG_READY`` and ``CMP_HDGC`` against ``heading_error_deg + crab_deg``."""
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
        elif code == "HDG_UNDONE":
            applied = False
    expected: float | None = None
    # at the sidecar's top level, or under "parameters" where the simulator writes them
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


def _explained(t_s: float, events: Sequence[Event]) -> bool:
    return any(
        ev.t_start_s - ALERT_EARLY_TOLERANCE_S <= t_s <= ev.t_end_s + RECOVERY_GRACE_S
        for ev in events
    )


def classify_alerts(
    alerts: Sequence[tuple[float, float, str, str, int]], events: Sequence[Event]
) -> tuple[list[AlertRecord], int]:
    """Each alert as a record, false when no event window explains it; and the false count."""
    out: list[AlertRecord] = []
    n_false = 0
    for t_s, t_rx, code, rest, sev in alerts:
        false = code in FALSE_ALERT_CODES and not _explained(t_s, events)
        n_false += int(false)
        out.append(AlertRecord(t_s, t_rx, code, rest, sev, false))
    if n_false:
        _log.info("%d false alert(s)", n_false)
    return out, n_false


def detect(ev: Event, alerts: Sequence[tuple[float, float, str, str, int]]) -> EventResult:
    """The first alert of the event's codes within its extended window, if any."""
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
        fault_size_at_detection=fault_size(ev, hit[0]),
    )

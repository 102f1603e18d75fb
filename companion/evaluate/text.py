"""The text report of ``companion evaluate``: header, error table, events, alerts, heading."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from companion.evaluate.results import ErrorStats, Evaluation, HeadingResult


def evaluation_text(ev: Evaluation, max_alerts: int = 40) -> str:
    """A readable report of ``ev`` (at most ``max_alerts`` alerts listed)."""
    lines: list[str] = []
    title = f"companion evaluate: {ev.out_tlog} vs {ev.truth_csv}"
    if ev.scenario is not None:
        title += f"  (scenario {ev.scenario}, seed {ev.seed})"
    lines.append(title)
    rate = "" if ev.publish_rate_hz is None else f" at {ev.publish_rate_hz:.1f} Hz"
    lines.append(
        f"published: {ev.n_published} solutions{rate}, t {ev.t_first_s:.1f}"
        f"..{ev.t_last_s:.1f} s; {ev.n_evaluated} within the truth"
        f" ({ev.n_outside_truth} outside); accuracy from {ev.accuracy_source or 'none'}"
    )
    lines.append(
        f"tlog: {ev.tlog.records} records, {ev.tlog.bad_records} corrupt skipped,"
        f" {ev.tlog.truncated_records} truncated"
    )
    lines.append("")
    lines.append("Position error (m; V signed mean = bias, up +; cover = within published 95 %)")
    header = (
        f"{'group':<28}{'n':>7}{'H mean':>8}{'H rms':>8}{'H p95':>8}{'H max':>8}"
        f"{'V mean':>8}{'V rms':>8}{'V p95':>8}{'V max':>8}{'H cov':>7}{'V cov':>7}"
        f"{'vel rms':>8}{'yaw rms':>8}"
    )
    lines.append(header)
    lines.append("-" * len(header))
    for row in (ev.overall, ev.normal, *ev.windows):
        lines.append(_stats_row(row))
    lines.append("")
    lines.append("Events (detection: first matching alert from the window start)")
    if not ev.events:
        lines.append("  none scheduled (no sidecar or no events)")
    else:
        lines.append(
            f"  {'kind':<11}{'window s':<16}{'rx':>3}  {'expects':<20}{'alert':<11}"
            f"{'latency s':>10}{'size at det':>13}"
        )
        for event in ev.events:
            window = f"{event.t_start_s:.1f}-{event.t_end_s:.1f}"
            alert = event.alert_code if event.detected and event.alert_code else "MISSED"
            lat = "-" if event.latency_s is None else f"{event.latency_s:.2f}"
            size = (
                "-"
                if event.fault_size_at_detection is None
                else f"{event.fault_size_at_detection:.3g}"
            )
            lines.append(
                f"  {event.kind:<11}{window:<16}{event.receiver_id:>3}  "
                f"{'|'.join(event.expected_codes):<20}{alert:<11}{lat:>10}{size:>13}"
            )
    lines.append("")
    lines.append(f"Alerts: {len(ev.alerts)} ({ev.n_false_alerts} false)")
    for al in ev.alerts[:max_alerts]:
        flag = "  FALSE" if al.false_alert else ""
        lines.append(f"  {al.t_s:9.2f} s  {al.code:<12}{al.text}{flag}")
    if len(ev.alerts) > max_alerts:
        lines.append(f"  ... {len(ev.alerts) - max_alerts} more")
    lines.append("")
    lines.append(_heading_text(ev.heading))
    if ev.named_values_last:
        nv = ", ".join(f"{k}={v:.4g}" for k, v in sorted(ev.named_values_last.items()))
        lines.append(f"Last named values: {nv}")
    return "\n".join(lines)


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

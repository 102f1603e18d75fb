"""What ``companion evaluate --against-input`` measured: result types, text, JSON, and the
one-line acceptance row of ``bench/realdata.py``.

The rules behind each figure are in :mod:`companion.evaluate.against_input`. A ``passed``
of None means the rule does not apply to this log (no gap, no dropout, never parked ...).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

from companion.evaluate.results import _clean


@dataclass(frozen=True, slots=True)
class ConfidenceResult:
    """Published fix type >= 3 against the receiver's concurrent 3-D fix (horizontal, m)."""

    n_claims: int
    n_evaluated: int
    n_no_concurrent_fix: int
    n_wrong: int
    max_h_m: float | None
    max_h_t_s: float | None
    max_v_m: float | None
    coverage: float | None
    n_receiver_sigma_from_hdop: int
    passed_wrong: bool | None
    passed_coverage: bool | None


@dataclass(frozen=True, slots=True)
class ReceiverUseResult:
    """Seconds of good receiver (3-D, enough satellites, settled) and why it was unused."""

    good_s: float
    unused_outage_s: float
    unused_not_navigating_s: float
    unused_silent_s: float
    fraction: float | None
    passed: bool | None


@dataclass(frozen=True, slots=True)
class GapResult:
    """One GNSS gap: times on the (continuous) autopilot clock, s; distances horizontal, m."""

    t_last_fix_s: float
    t_first_fix_s: float | None
    length_s: float
    alert_latency_s: float | None
    already_in_outage: bool
    imu_hz: float | None
    imu_max_interval_s: float | None
    imu_stream: str
    imu_running: bool
    closure_h_m: float | None
    hold_h_m: float | None
    cv_h_m: float | None
    ratio: float | None
    bound99_m: float | None
    inside99: bool | None
    publication_age_s: float | None
    published_fix_type: int | None
    note: str
    rhythm_s: float | None = None
    """With the service's ``GNSS_SLOW`` in force at the last fix: the link's rhythm, the
    longest interval (under 3 s) between the receiver's 3-D fixes in the minute before
    it; the next fix was due that long after the last one (None: not slow)."""
    within_rhythm: bool = False
    """No alert of its own, and over by the time one was owed (due + the allowed latency):
    the ``GNSS_SLOW`` announcement in force was its alert."""

    @property
    def judged_latency_s(self) -> float | None:
        """The alert latency the rule judges: from the last fix, or from when the next fix
        was due by the announced slow link's rhythm (0 within it); None: missed."""
        if self.within_rhythm:
            return 0.0
        if self.alert_latency_s is None:
            return None
        return max(0.0, self.alert_latency_s - (self.rhythm_s or 0.0))


@dataclass(frozen=True, slots=True)
class GapsSummary:
    """The gap rules over a flight (ratios and bounds over the gaps with the IMU running)."""

    n_gaps: int
    max_alert_latency_s: float | None
    passed_alert: bool | None
    n_imu_running: int
    median_ratio: float | None
    max_ratio: float | None
    passed_ratio: bool | None
    n_inside99: int
    passed_inside99: bool | None
    n_missed: int


@dataclass(frozen=True, slots=True)
class DropoutResult:
    """One whole-stream dropout (record clock, s from the log's start) and the first
    solution after it against the first fix (horizontal, m)."""

    t_rx_start_s: float
    length_s: float
    error_h_m: float | None
    bound99_m: float | None
    dt_s: float | None
    published_fix_type: int | None
    inside99: bool | None
    note: str


@dataclass(frozen=True, slots=True)
class NoGnssResult:
    """No 3-D fix within the first seconds of the autopilot's messages (s from its first)."""

    applies: bool
    first_fix_after_s: float | None
    alert_latency_s: float | None
    first_any_alert_s: float | None
    passed: bool | None


@dataclass(frozen=True, slots=True)
class TextResult:
    """STATUSTEXT counts and flapping while parked."""

    total: int
    per_minute: float
    real_changes: int
    """Texts announcing a gap or dropout the input shows: not counted in the window."""
    max_in_window: int
    max_window_start_s: float | None
    passed_rate: bool
    parked_s: float
    n_parked_intervals: int
    flaps_phase_integrity: int
    flaps_all: int
    flaps_by_key: dict[str, int]
    passed_flapping: bool | None


@dataclass(frozen=True, slots=True, eq=False)
class AgainstInput:
    """Everything ``evaluate --against-input`` measured."""

    out_tlog: str
    in_tlog: str
    input_records: int
    output_records: int
    duration_s: float
    n_fixes_3d: int
    n_fixes_other: int
    receiver_sigma_from_hdop: bool
    reboots: int
    solution_source: str | None
    n_solutions: int
    confidence: ConfidenceResult
    receiver_use: ReceiverUseResult
    gaps_summary: GapsSummary
    gaps: tuple[GapResult, ...]
    dropouts: tuple[DropoutResult, ...]
    no_gnss: NoGnssResult
    texts: TextResult

    @property
    def passed_dropouts(self) -> bool | None:
        """Every dropout with a verdict inside its bound; None when there is none."""
        verdicts = [d.inside99 for d in self.dropouts if d.inside99 is not None]
        return None if not verdicts else all(verdicts)

    def verdicts(self) -> dict[str, bool | None]:
        """Each acceptance rule's pass mark (None: not applicable)."""
        c, g, t = self.confidence, self.gaps_summary, self.texts
        return {
            "never_wrong": c.passed_wrong,
            "coverage95": c.passed_coverage,
            "receiver_use": self.receiver_use.passed,
            "gap_alert": g.passed_alert,
            "gap_ratio": g.passed_ratio,
            "gap_inside99": g.passed_inside99,
            "dropout": self.passed_dropouts,
            "no_gnss_alert": self.no_gnss.passed,
            "text_rate": t.passed_rate,
            "parked_flapping": t.passed_flapping,
        }

    @property
    def passed(self) -> bool:
        """Every applicable rule passed."""
        return all(v is not False for v in self.verdicts().values())

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-ready dict (NaN and inf become None)."""
        out = {f.name: _as_plain(getattr(self, f.name)) for f in fields(self)}
        out["verdicts"] = self.verdicts()
        out["passed"] = self.passed
        cleaned = _clean(out)
        if not isinstance(cleaned, dict):  # pragma: no cover - _clean keeps dicts dicts
            raise TypeError("to_dict produced a non-dict")
        return cleaned

    def row(self) -> dict[str, str]:
        """The acceptance figures as table cells (``bench/realdata.py``), marks included."""
        c, u, g, n, t = (
            self.confidence,
            self.receiver_use,
            self.gaps_summary,
            self.no_gnss,
            self.texts,
        )
        drop = [d for d in self.dropouts if d.inside99 is not None]
        n_nc = len(self.dropouts) - len(drop)
        return {
            "wrong>25m": _cell(
                "-" if c.n_evaluated == 0 else f"{c.n_wrong} max {_m(c.max_h_m)}", c.passed_wrong
            ),
            "cover95": _cell(_pct(c.coverage), c.passed_coverage),
            "rx used": _cell(_pct(u.fraction), u.passed),
            "gap alert": _cell(
                "-"
                if not g.n_gaps
                else f"{g.n_gaps}: {_s(g.max_alert_latency_s)}"
                + (f" {g.n_missed} missed" if g.n_missed else ""),
                g.passed_alert,
            ),
            "closure x": _cell(
                "-"
                if not g.n_imu_running
                else f"{g.n_imu_running}: med {_x(g.median_ratio)} max {_x(g.max_ratio)}",
                g.passed_ratio,
            ),
            "in 99%": _cell(
                "-" if not g.n_imu_running else f"{g.n_inside99}/{g.n_imu_running}",
                g.passed_inside99,
            ),
            "dropout": _cell(
                ("-" if not drop else f"{sum(bool(d.inside99) for d in drop)}/{len(drop)}")
                + (f" ({n_nc} n/c)" if n_nc else ""),
                self.passed_dropouts,
            ),
            "no-GNSS alert": _cell(
                "-"
                if not n.applies
                else ("none" if n.alert_latency_s is None else _s(n.alert_latency_s)),
                n.passed,
            ),
            "txt/60s": _cell(f"{t.max_in_window} ({t.total})", t.passed_rate),
            "parked flaps": _cell(
                "-" if not t.n_parked_intervals else f"{t.flaps_phase_integrity} ({t.flaps_all})",
                t.passed_flapping,
            ),
        }

    def to_text(self) -> str:
        """A readable report: one line per rule, the gaps, the dropouts."""
        c, u, g, n, t = (
            self.confidence,
            self.receiver_use,
            self.gaps_summary,
            self.no_gnss,
            self.texts,
        )
        lines = [
            f"companion evaluate: {self.out_tlog} against its input {self.in_tlog}",
            f"input: {self.input_records} records, {self.duration_s:.1f} s, "
            f"{self.n_fixes_3d} 3-D fixes ({self.n_fixes_other} others), "
            f"{self.reboots} reboot(s); receiver accuracy "
            + ("from HDOP x 2.5 m (no h_acc)" if self.receiver_sigma_from_hdop else "reported"),
            f"published: {self.n_solutions} solutions from {self.solution_source or 'nothing'}",
            "",
            f"never confidently wrong: {c.n_wrong} of {c.n_evaluated} fixes >= 3D more than 25 m"
            f" from the receiver (max {_m(c.max_h_m)} at t={_s(c.max_h_t_s)} s; vertical, not"
            f" judged, max {_m(c.max_v_m)}; {c.n_no_concurrent_fix} without a concurrent fix)"
            f"  {_mark(c.passed_wrong)}",
            f"95 % bound (RSS with the receiver's) covers the fix: {_pct(c.coverage)}"
            f" (>= 95 %)  {_mark(c.passed_coverage)}",
            f"receiver used: {_pct(u.fraction)} of {u.good_s:.1f} s good (>= 98 %); unused:"
            f" outage {u.unused_outage_s:.1f} s, not navigating {u.unused_not_navigating_s:.1f}"
            f" s, silent {u.unused_silent_s:.1f} s  {_mark(u.passed)}",
            f"GNSS gaps >= 3 s: {g.n_gaps}; alert max {_s(g.max_alert_latency_s)} s, "
            f"{g.n_missed} missed (<= 1.5 s)  {_mark(g.passed_alert)}",
            f"  with the IMU >= 20 Hz: {g.n_imu_running}; closure / best(hold, cv) median "
            f"{_x(g.median_ratio)} max {_x(g.max_ratio)} (<= 1.0, <= 1.5)  "
            f"{_mark(g.passed_ratio)}; inside 99 %: {g.n_inside99}/{g.n_imu_running}  "
            f"{_mark(g.passed_inside99)}",
            f"whole-stream dropouts >= 3 s: {len(self.dropouts)}  {_mark(self.passed_dropouts)}",
            "no GNSS at start: "
            + (
                "n/a (a fix within 5 s)"
                if not n.applies
                else f"first loss alert {_s(n.alert_latency_s)} s after the first autopilot "
                f"message (any alert {_s(n.first_any_alert_s)} s; first fix "
                f"{_s(n.first_fix_after_s)} s)  {_mark(n.passed)}"
            ),
            f"STATUSTEXT: {t.total} ({t.per_minute:.1f}/min, {t.real_changes} announcing real "
            f"gaps), at most {t.max_in_window} others in 60 s (<= 6)  {_mark(t.passed_rate)}",
            f"parked {t.parked_s:.0f} s in {t.n_parked_intervals} interval(s): "
            f"{t.flaps_phase_integrity} phase/integrity flaps, {t.flaps_all} repeats in all  "
            f"{_mark(t.passed_flapping)}",
        ]
        for key, count in list(t.flaps_by_key.items())[:5]:
            lines.append(f"  {count:4d} x {key}")
        if self.gaps:
            lines += ["", "gaps (autopilot time s; horizontal m):", GAP_HEADER]
            lines += [gap_line(gp) for gp in self.gaps]
        if self.dropouts:
            lines += ["", "dropouts (s from the log's start; horizontal m):"]
            for d in self.dropouts:
                lines.append(
                    f"  at {d.t_rx_start_s:7.1f} s for {d.length_s:5.1f} s: first solution "
                    f"{_m(d.error_h_m)} from the first fix (dt {_s(d.dt_s)} s), 99 % bound "
                    f"{_m(d.bound99_m)}  {_mark(d.inside99)} {d.note}"
                )
        lines.append("")
        lines.append("overall: " + ("PASS" if self.passed else "FAIL"))
        return "\n".join(lines)


GAP_HEADER = (
    f"  {'last fix':>9}{'length':>8}{'IMU Hz':>8}{'alert s':>9}{'due s':>7}{'closure':>9}"
    f"{'hold':>8}{'cv':>8}{'ratio':>8}{'99%':>8}  in99  note"
)


def gap_line(g: GapResult) -> str:
    """One gap as a row under :data:`GAP_HEADER`."""
    alert = "missed" if g.alert_latency_s is None else _s(g.alert_latency_s)
    if g.already_in_outage:
        alert = "before"
    elif g.within_rhythm:
        alert = "rhythm"
    hz = "-" if g.imu_hz is None else f"{g.imu_hz:.0f}"
    due = "-" if g.rhythm_s is None else _s(g.rhythm_s)
    return (
        f"  {g.t_last_fix_s:9.1f}{g.length_s:8.1f}{hz:>8}{alert:>9}{due:>7}"
        f"{_m(g.closure_h_m):>9}"
        f"{_m(g.hold_h_m):>8}{_m(g.cv_h_m):>8}{_x(g.ratio):>8}{_m(g.bound99_m):>8}"
        f"  {_mark(g.inside99):<4}  {'open' if g.t_first_fix_s is None else ''}{g.note}"
    )


def _as_plain(x: Any) -> Any:
    if hasattr(x, "__dataclass_fields__"):
        return {f.name: _as_plain(getattr(x, f.name)) for f in fields(x)}
    if isinstance(x, tuple):
        return [_as_plain(v) for v in x]
    return x


def _mark(v: bool | None) -> str:
    return "n/a" if v is None else ("PASS" if v else "FAIL")


def _cell(text: str, v: bool | None) -> str:
    return text if v is None else f"{text} {'PASS' if v else 'FAIL'}"


def _m(x: float | None) -> str:
    if x is None:
        return "-"
    return f"{x:.0f}" if abs(x) >= 100 else f"{x:.1f}"


def _s(x: float | None) -> str:
    return "-" if x is None else f"{x:.1f}"


def _x(x: float | None) -> str:
    if x is None:
        return "-"
    return "inf" if x == float("inf") else (f"{x:.0f}" if x >= 100 else f"{x:.2f}")


def _pct(x: float | None) -> str:
    return "-" if x is None else f"{100.0 * x:.0f}%"

"""The real events of a flight, found in its own timestamps, and how the service said them.

``bench/realdata.py`` prints these beside :mod:`.against_input`'s figures: the texts a
minute of each real log and how many of its real events were said. A *real event* is
what the input log shows, whatever the service said (record clock, the thresholds of
:mod:`.against_input`):

Whole-stream dropout
    No decoded navigation sample (everything but HEARTBEAT and SYSTEM_TIME) for
    :data:`~.against_input.DROPOUT_MIN_S`: from the last sample's record to the next.
GNSS gap
    Consecutive 3-D fixes (any receiver) :data:`~.against_input.GAP_MIN_S` or more
    apart, or the data running on that long after the last fix (open: no end). A gap
    that overlaps a dropout is part of that dropout's event: the streams stopped, GNSS
    with them, one event.
No GNSS at start
    No 3-D fix within :data:`~.against_input.NO_GNSS_ALERT_MAX_S` of the autopilot's
    first record: from that record to the first fix (open when none comes).

An event's start is *said* when a loss alert (:data:`~.against_input.LOSS_ALERT_CODES`)
is sent after it starts and before it ends, or when the service was already saying a
loss as it started (its latest loss alert then newer than its latest return). Its end is
said when the latest loss or return alert sent by
:data:`~.against_input.GAP_ALERT_MAX_S` after the end is a return (:data:`RETURN_CODES`)
sent after the event started: the state the ground is left with is "back", said for
this event. Texts: every whole text the service sent (chunks joined), a minute of log
on average (a log shorter than a minute counts as one minute: its texts are its
minute's) and the most in any :data:`~.against_input.TEXT_WINDOW_S` starting at a
text (real changes included).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from companion.evaluate.against_input import (
    BACK_ALERT_CODES,
    DROPOUT_MIN_S,
    GAP_ALERT_MAX_S,
    GAP_MIN_S,
    LOSS_ALERT_CODES,
    NO_GNSS_ALERT_MAX_S,
    TEXT_WINDOW_S,
    _Input,
    _Output,
    _read_input,
    _read_output,
)
from companion.evaluate.results import EvaluationError
from companion.mavlink.decode import DecoderConfig

RETURN_CODES: frozenset[str] = BACK_ALERT_CODES | {"DATA_BACK"}
"""Alerts that say a loss is over: GNSS trusted again, data back after a silence."""


@dataclass(frozen=True, slots=True)
class RealEvent:
    """One real event (record clock, s from the log's first record)."""

    kind: str
    """``dropout``, ``gnss gap`` or ``no gnss``."""
    start_s: float
    end_s: float | None
    """None: still going at the log's end."""
    start_said_by: str | None
    """The code that said its start (``already`` when a loss was already said), None."""
    start_latency_s: float | None
    """From its start to that alert (0 when already said)."""
    end_said_by: str | None
    """The return that said its end, None (also for an open event)."""


@dataclass(frozen=True, slots=True)
class EventsSaid:
    """Texts of one replay and its real events (module docstring)."""

    duration_s: float
    texts: int
    per_minute: float
    max_in_window: int
    events: tuple[RealEvent, ...]

    @property
    def n_start_said(self) -> int:
        """Events whose start was said."""
        return sum(e.start_said_by is not None for e in self.events)

    @property
    def n_closed(self) -> int:
        """Events that ended within the log."""
        return sum(e.end_s is not None for e in self.events)

    @property
    def n_end_said(self) -> int:
        """Ended events whose end was said."""
        return sum(e.end_said_by is not None for e in self.events)

    def cell(self) -> str:
        """``said/events start, said/ended end`` for a table."""
        if not self.events:
            return "-"
        return (
            f"{self.n_start_said}/{len(self.events)} start, {self.n_end_said}/{self.n_closed} end"
        )


def _spans(t: np.ndarray, min_s: float) -> list[tuple[float, float]]:
    return [(float(t[i]), float(t[i + 1])) for i in np.nonzero(np.diff(t) >= min_s)[0]]


def real_events(inp: _Input) -> list[tuple[str, float, float | None]]:
    """``(kind, start, end or None)`` of the input's real events, record clock (absolute
    s), in time order (module docstring)."""
    fix_rx = np.sort(inp.fixes.take(inp.fixes.ok3d).t_rx)
    data_rx = inp.data_t_rx
    events: list[tuple[str, float, float | None]] = [
        ("dropout", a, b) for a, b in _spans(data_rx, DROPOUT_MIN_S)
    ]
    gaps: list[tuple[float, float | None]] = list(_spans(fix_rx, GAP_MIN_S))
    if fix_rx.size and data_rx.size and data_rx[-1] - fix_rx[-1] >= GAP_MIN_S:
        gaps.append((float(fix_rx[-1]), None))
    for a, b in gaps:
        end = np.inf if b is None else b
        hit = [
            k
            for k, (kind, c, d) in enumerate(events)
            if kind == "dropout" and d is not None and c < end and a < d
        ]
        if not hit:
            events.append(("gnss gap", a, b))
            continue
        k = hit[0]
        _, c, d = events[k]
        events[k] = ("dropout", min(a, c), None if b is None or d is None else max(b, d))
    first_ap = inp.first_autopilot_t_rx
    if first_ap is not None:
        first_fix = float(fix_rx[0]) if fix_rx.size else None
        if first_fix is None or first_fix - first_ap > NO_GNSS_ALERT_MAX_S:
            events.append(("no gnss", first_ap, first_fix))
    events.sort(key=lambda e: e[1])
    return events


def said(inp: _Input, out: _Output) -> EventsSaid:
    """How the texts of ``out`` said the real events of ``inp`` (module docstring)."""
    t0 = inp.first_t_rx
    duration = max(inp.last_t_rx - t0, 1e-9)
    loss = [(t, code) for t, code, _ in out.alerts if code in LOSS_ALERT_CODES]
    state = [(t, code) for t, code, _ in out.alerts if code in LOSS_ALERT_CODES | RETURN_CODES]
    events: list[RealEvent] = []
    for kind, start, end in real_events(inp):
        stop = inp.last_t_rx if end is None else end
        inside = [(t, c) for t, c in loss if start < t <= stop]
        before = [(t, c) for t, c in state if t <= start]
        by: str | None
        latency: float | None
        if inside:
            by, latency = inside[0][1], inside[0][0] - start
        elif before and before[-1][1] in LOSS_ALERT_CODES:
            by, latency = "already", 0.0
        else:
            by, latency = None, None
        end_by: str | None = None
        if end is not None:
            upto = [(t, c) for t, c in state if t <= end + GAP_ALERT_MAX_S]
            if upto and upto[-1][1] in RETURN_CODES and upto[-1][0] > start:
                end_by = upto[-1][1]
        events.append(
            RealEvent(
                kind=kind,
                start_s=start - t0,
                end_s=None if end is None else end - t0,
                start_said_by=by,
                start_latency_s=latency,
                end_said_by=end_by,
            )
        )
    t = np.asarray([x[0] for x in out.texts], dtype=np.float64)
    if t.size:
        ends = np.searchsorted(t, t + TEXT_WINDOW_S, side="left")
        max_window = int(np.max(ends - np.arange(t.size)))
    else:
        max_window = 0
    return EventsSaid(
        duration_s=duration,
        texts=int(t.size),
        per_minute=float(t.size / max(duration / 60.0, 1.0)),
        max_in_window=max_window,
        events=tuple(events),
    )


def events_said(
    out_tlog: Path, in_tlog: Path, decoder_config: DecoderConfig | None = None
) -> EventsSaid:
    """Read a replay's output and its input and say how the real events were said.

    Raises
    ------
    EvaluationError
        A missing or unreadable file.
    """
    for p in (Path(out_tlog), Path(in_tlog)):
        if not p.is_file():
            raise EvaluationError(f"no such file: {p}")
    inp = _read_input(Path(in_tlog), decoder_config)
    return said(inp, _read_output(Path(out_tlog), inp))

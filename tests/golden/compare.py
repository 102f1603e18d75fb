"""Two records of a replay compared by the rules of :mod:`tests.golden.rules`.

:func:`compare` gives one :class:`Difference` per field (or text list, or count) that
differs at all: its largest difference relative to its tolerance, where and when, the
two values, and how many values of it are beyond tolerance. A record agrees when none
is beyond (``excess > 1``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from companion.mavlink.ids import (
    GPS_INPUT_IGNORE_FLAG_HORIZONTAL_ACCURACY,
    GPS_INPUT_IGNORE_FLAG_VERTICAL_ACCURACY,
)
from tests.golden import rules
from tests.golden.record import T_RX, ReplayRecord

POSITION_SERIES = ("GPS_INPUT", "GLOBAL_POSITION_SENSOR", "GLOBAL_POSITION_INT")
"""The service's solutions: the most frequent of them sets the flight's sample period."""
DEFAULT_PERIOD_S = 1.0
"""The sample period of a flight with no solution published (our HEARTBEAT's)."""


@dataclass(frozen=True, slots=True)
class Difference:
    """The largest difference of one compared thing (a field of a series, the texts,
    a count ...): ``excess`` is |difference| / tolerance (inf: structurally different)."""

    where: str
    t_s: float | None
    """Log time after the output's first record, s (None: not a time series)."""
    ref: Any
    new: Any
    excess: float
    beyond: int = 0
    """How many values of it are beyond tolerance."""
    values: int = 1
    note: str = ""

    @property
    def fails(self) -> bool:
        return self.excess > 1.0

    def describe(self) -> str:
        """One line: where, when, the two values and how far apart."""
        at = f" at +{self.t_s:.3f} s" if self.t_s is not None else ""
        size = "differs" if math.isinf(self.excess) else f"{self.excess:.3g} x tolerance"
        count = f", {self.beyond} of {self.values} beyond" if self.beyond else ""
        note = f"; {self.note}" if self.note else ""
        return f"{self.where}{at}: {self.ref!r} vs {self.new!r} ({size}{count}{note})"


def sample_period_s(record: ReplayRecord) -> float:
    """The median interval of the flight's most frequent solution series, s."""
    best = max(
        (record.series[k][T_RX] for k in POSITION_SERIES if k in record.series),
        key=len,
        default=np.zeros(0),
    )
    if len(best) < 2:
        return DEFAULT_PERIOD_S
    return float(np.median(np.diff(best))) / 1e6


def event_tolerance_s(record: ReplayRecord) -> float:
    """How far apart in time the same event may come: ``EVENT_SAMPLES`` sample periods."""
    return rules.EVENT_SAMPLES * sample_period_s(record) * (1.0 + 1e-9)


def _accuracies(record: ReplayRecord) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(record time us, horizontal, vertical, speed 1-sigma) of every published accuracy
    (0 where flagged ignored or not > 0), from GPS_INPUT or GLOBAL_POSITION_SENSOR."""
    fix = record.series.get("GPS_INPUT")
    if fix is not None:
        flags = fix["ignore_flags"].astype(np.int64)
        h = np.where(flags & GPS_INPUT_IGNORE_FLAG_HORIZONTAL_ACCURACY, 0.0, fix["horiz_accuracy"])
        v = np.where(flags & GPS_INPUT_IGNORE_FLAG_VERTICAL_ACCURACY, 0.0, fix["vert_accuracy"])
        s = fix["speed_accuracy"]
        return fix[T_RX], *(np.maximum(np.nan_to_num(x), 0.0) for x in (h, v, s))  # type: ignore[return-value]
    sensor = record.series.get("GLOBAL_POSITION_SENSOR")
    if sensor is not None:
        h, v = (np.maximum(np.nan_to_num(sensor[k]), 0.0) for k in ("eph", "epv"))
        return sensor[T_RX], h, v, np.zeros(len(h))
    empty = np.zeros(0)
    return empty.astype(np.int64), empty, empty, empty


def sigmas_for(record: ReplayRecord, columns: dict[str, np.ndarray]) -> rules.Sigmas:
    """Each row's published accuracies: the last published at or before its record time."""
    t_acc, h, v, s = _accuracies(record)
    t = columns[T_RX]
    idx = np.searchsorted(t_acc, t, side="right") - 1
    have = idx >= 0
    pick = np.clip(idx, 0, None)

    def at(x: np.ndarray) -> np.ndarray:
        return np.where(have, x[pick], 0.0) if len(x) else np.zeros(len(t))

    lat = columns.get("lat")
    cos_lat = np.cos(np.radians(lat * 1e-7)) if lat is not None else np.ones(len(t))
    return rules.Sigmas(at(h), at(v), at(s), cos_lat)


def _excess(diff: np.ndarray, tol: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(diff == 0.0, 0.0, np.where(tol > 0.0, diff / tol, np.inf))


def _item(x: Any) -> Any:
    return x.item() if isinstance(x, np.generic) else x


def compare_series(ref: ReplayRecord, new: ReplayRecord, event_s: float) -> list[Difference]:
    """Every series, message by message and field by field."""
    out = []
    for key in sorted(set(ref.series) | set(new.series)):
        a, b = ref.series.get(key), new.series.get(key)
        if a is None or b is None:
            n_a, n_b = (0 if x is None else len(x[T_RX]) for x in (a, b))
            out.append(Difference(key, None, n_a, n_b, math.inf, note="messages"))
            continue
        n_a, n_b = len(a[T_RX]), len(b[T_RX])
        if n_a != n_b:
            m = min(n_a, n_b)
            apart = np.nonzero(np.abs(a[T_RX][:m] - b[T_RX][:m]) > event_s * 1e6)[0]
            i = int(apart[0]) if len(apart) else m
            t = (a[T_RX] if i < n_a else b[T_RX])[i] / 1e6
            out.append(Difference(key, t, n_a, n_b, math.inf, note="messages; they part here"))
            continue
        kind = key.split(":")[0]
        sigmas = sigmas_for(ref, a)
        for field in sorted(set(a) | set(b)):
            if field not in a or field not in b:
                out.append(Difference(f"{key}.{field}", None, field in a, field in b, math.inf))
                continue
            x, y = a[field], b[field]
            if n_a == 0 or (
                x.dtype == y.dtype and np.array_equal(x, y, equal_nan=x.dtype.kind == "f")
            ):
                continue
            if field == T_RX:
                diff = np.abs(y.astype(np.float64) - x) / 1e6
                tol = np.full(n_a, event_s)
                note = f"record time, s; tolerance {event_s:.3g}"
            else:
                q = rules.quantity(kind, field, _item(x[0]))
                diff = rules.difference(q, x, y)
                tol = rules.tolerance(q, x, sigmas)
                note = ""
            if tol.ndim < diff.ndim:
                tol = tol.reshape(n_a, *([1] * (diff.ndim - 1)))
            excess = _excess(diff, tol).reshape(n_a, -1).max(axis=1)
            tol = np.broadcast_to(tol, diff.shape).reshape(n_a, -1).min(axis=1)
            i = int(np.argmax(excess))
            if not note:
                note = f"tolerance {float(tol[i]):.3g}"
            out.append(
                Difference(
                    f"{key}.{field}",
                    float(a[T_RX][i]) / 1e6,
                    _item(x[i]) if x.ndim == 1 else x[i].tolist(),
                    _item(y[i]) if y.ndim == 1 else y[i].tolist(),
                    float(excess[i]),
                    beyond=int(np.count_nonzero(excess > 1.0)),
                    values=n_a,
                    note=note,
                )
            )
    return out


def compare_events(
    where: str,
    ref: list[list[Any]],
    new: list[list[Any]],
    event_s: float,
    same: Callable[[Any, Any], tuple[bool, float]],
) -> list[Difference]:
    """Two lists of ``[t_s, ...what happened]`` (texts, heartbeat changes): the same
    number, each the same (``same``) and within ``event_s`` of its time. With a different
    number, where they part (the first pair beyond tolerance, or the first extra one)."""
    worst: Difference | None = None
    first_bad: Difference | None = None
    n_beyond = 0
    for i in range(min(len(ref), len(new))):
        ok, size = same(ref[i][1:], new[i][1:])
        dt = abs(new[i][0] - ref[i][0])
        excess = math.inf if not ok else max(size, dt / event_s if event_s > 0 else math.inf)
        if excess == 0:
            continue
        note = f"{dt:.3f} s apart, tolerance {event_s:.3g} s"
        d = Difference(where, ref[i][0], ref[i][1:], new[i][1:], excess, note=note)
        if d.fails:
            n_beyond += 1
            first_bad = first_bad or d
        if worst is None or excess > worst.excess:
            worst = d
    if len(ref) != len(new):
        i = min(len(ref), len(new))
        extra = (new if len(new) > i else ref)[i]
        part = first_bad or Difference(
            where,
            extra[0],
            ref[i][1:] if i < len(ref) else None,
            new[i][1:] if i < len(new) else None,
            math.inf,
        )
        note = f"{len(ref)} vs {len(new)} of them; they part here"
        return [dataclasses.replace(part, excess=math.inf, note=note, values=len(ref))]
    if worst is None:
        return []
    return [dataclasses.replace(worst, beyond=n_beyond, values=len(ref))]


def _text_event(a: list[Any], b: list[Any]) -> tuple[bool, float]:
    """[severity, text] of two STATUSTEXTs: the same severity, the texts by the text rule."""
    if a[0] != b[0]:
        return False, math.inf
    ok, size = rules.texts_agree(a[1], b[1])
    return ok, size


def _same_dict(a: list[Any], b: list[Any]) -> tuple[bool, float]:
    """[fields] of two HEARTBEATs: the same fields, each by its rule."""
    if set(a[0]) != set(b[0]):
        return False, math.inf
    worst = 0.0
    for key, value in a[0].items():
        ok, size = rules.values_agree("HEARTBEAT", key, value, b[0][key])
        if not ok:
            return False, math.inf
        worst = max(worst, size)
    return True, worst


def _number(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool)


def compare_tree(
    where: str, ref: Any, new: Any, number_tol: Callable[[str, float, dict[str, Any]], float]
) -> list[Difference]:
    """Two JSON trees (the summary, the evaluation): the same keys and lengths, integers
    and words exactly, texts by the text rule, other numbers within ``number_tol(key,
    ref, enclosing dict)``."""
    out: list[Difference] = []

    def walk(path: str, a: Any, b: Any, parent: dict[str, Any]) -> None:
        key = path.rsplit(".", 1)[-1].split("[")[0]
        if isinstance(a, dict) and isinstance(b, dict):
            for k in sorted(set(a) | set(b)):
                if k not in a or k not in b:
                    out.append(Difference(f"{path}.{k}", None, a.get(k), b.get(k), math.inf))
                else:
                    walk(f"{path}.{k}", a[k], b[k], a)
        elif isinstance(a, list) and isinstance(b, list):
            if len(a) != len(b):
                out.append(Difference(path, None, len(a), len(b), math.inf, note="lengths"))
                return
            for i, (x, y) in enumerate(zip(a, b, strict=True)):
                walk(f"{path}[{i}]", x, y, parent)
        elif isinstance(a, str) and isinstance(b, str):
            ok, size = rules.texts_agree(a, b)
            if size > 0 or not ok:
                out.append(Difference(path, None, a, b, size if ok else math.inf))
        elif _number(a) and _number(b) and (isinstance(a, float) or isinstance(b, float)):
            diff = abs(float(b) - float(a))
            if diff > 0:
                tol = number_tol(key, float(a), parent)
                excess = diff / tol if tol > 0 else math.inf
                out.append(Difference(path, None, a, b, excess, note=f"tolerance {tol:.3g}"))
        elif a != b or type(a) is not type(b):
            out.append(Difference(path, None, a, b, math.inf))

    walk(where, ref, new, {})
    return out


def compare(ref: ReplayRecord, new: ReplayRecord) -> list[Difference]:
    """Every difference between two records of a case, largest (relative to its
    tolerance) first."""
    event_s = event_tolerance_s(ref)
    out = compare_series(ref, new, event_s)
    out += compare_events("STATUSTEXT", ref.meta["texts"], new.meta["texts"], event_s, _text_event)
    out += compare_events(
        "HEARTBEAT", ref.meta["heartbeats"], new.meta["heartbeats"], event_s, _same_dict
    )
    for key in ("records", "messages", "summary"):
        out += compare_tree(
            key,
            ref.meta.get(key),
            new.meta.get(key),
            lambda k, x, _p: max(rules.FLOAT_REL_TOL * abs(x), rules.FLOAT_ABS_TOL),
        )
    out += compare_tree(
        "evaluation",
        ref.meta.get("evaluation"),
        new.meta.get("evaluation"),
        lambda k, x, p: rules.evaluation_tolerance(k, x, p.get("n"), event_s),
    )
    return sorted(out, key=lambda d: -d.excess)


def failures(differences: list[Difference]) -> list[Difference]:
    """Those beyond tolerance."""
    return [d for d in differences if d.fails]


def report(case: str, differences: list[Difference], limit: int = 8) -> str:
    """A failure message: the largest difference first, then the next ``limit`` beyond
    tolerance."""
    bad = failures(differences)
    lines = [f"{case}: {len(bad)} thing(s) beyond tolerance; the largest:"]
    lines += [f"  {d.describe()}" for d in bad[: limit + 1]]
    if len(bad) > limit + 1:
        lines.append(f"  ... and {len(bad) - limit - 1} more")
    return "\n".join(lines)


def compare_messages(
    ref: list[tuple[float, Any]], new: list[tuple[float, Any]], time_tol_s: float = 1e-6
) -> list[Difference]:
    """Two tlogs' records (``(t_rx_s, pymavlink message)``) message by message: the same
    count, types and order, record times within ``time_tol_s`` (a tlog stamps whole
    microseconds), every field by its rule without a published accuracy beside it (the
    resolution alone). One :class:`Difference` per ``TYPE.field`` that differs at all."""
    if len(ref) != len(new):
        return [Difference("records", None, len(ref), len(new), math.inf)]
    t0 = ref[0][0] if ref else 0.0
    tol_us = max(round(time_tol_s * 1e6), 1)
    worst: dict[str, Difference] = {}
    beyond: dict[str, int] = {}
    values: dict[str, int] = {}

    def note(where: str, t: float, a: Any, b: Any, excess: float, tol: str = "") -> None:
        values[where] = values.get(where, 0) + 1
        if excess == 0.0:
            return
        beyond[where] = beyond.get(where, 0) + (excess > 1.0)
        if where not in worst or excess > worst[where].excess:
            worst[where] = Difference(where, t - t0, a, b, excess, note=tol)

    for i, ((ta, ma), (tb, mb)) in enumerate(zip(ref, new, strict=True)):
        kind = ma.get_type()
        if kind != mb.get_type():
            return [Difference(f"record {i}", ta - t0, kind, mb.get_type(), math.inf)]
        apart_us = abs(round(tb * 1e6) - round(ta * 1e6))
        note("record time", ta, ta, tb, apart_us / tol_us, f"tolerance {time_tol_s:g} s")
        da, db = ma.to_dict(), mb.to_dict()
        if da == db:
            continue
        for key, va in da.items():
            if key == "mavpackettype":
                continue
            ok, size = rules.values_agree(kind, key, va, db.get(key))
            note(f"{kind}.{key}", ta, va, db.get(key), size if ok else math.inf)
    out = [
        dataclasses.replace(d, beyond=beyond.get(w, 0), values=values[w]) for w, d in worst.items()
    ]
    return sorted(out, key=lambda d: -d.excess)

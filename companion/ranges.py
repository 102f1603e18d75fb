"""Declarative ranges for configuration fields: each range stated once, beside its field.

A configuration block declares a field with :func:`ranged` instead of a plain default::

    gnss_timeout_s: float = ranged(1.5, gt=0.0)
    \"\"\"Seconds without a fix before the receiver counts as lost.\"\"\"

and its ``__post_init__`` calls :func:`check_ranges`, the one loop that checks every
ranged field of any block. A violation is a ``ValueError`` with a one-line message
naming the field, the range and the value (``gnss_timeout_s must be > 0, got -1.0``);
:mod:`companion.config` prefixes the ``[block]``. Checks that relate two fields
(``status_rate_hz <= publish_rate_hz``) stay written out in the block's
``__post_init__`` after the call.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

_RANGE_KEY = "range"


@dataclass(frozen=True, slots=True)
class Range:
    """Bounds on a number (or on every item of a tuple of numbers), or a set of choices."""

    ge: float | None = None
    gt: float | None = None
    le: float | None = None
    lt: float | None = None
    finite: bool = True
    """Reject NaN and infinities (a bound alone lets ``inf`` through ``> 0``)."""
    choices: tuple[Any, ...] | None = None
    length: int | None = None
    """For a tuple: the exact number of items (each item is checked against the bounds)."""
    nonempty: bool = False
    """For a tuple: at least one item."""
    optional: bool = False
    """``None`` is allowed (the field is unset)."""

    def describe(self) -> str:
        """The range in words, for the error message: ``> 0``, ``in (0, 1]``, ``one of ...``."""
        if self.choices is not None:
            return f"one of {list(self.choices)}"
        lo = (
            ("[", self.ge)
            if self.ge is not None
            else ("(", self.gt)
            if self.gt is not None
            else None
        )
        hi = (
            (self.le, "]")
            if self.le is not None
            else (self.lt, ")")
            if self.lt is not None
            else None
        )
        if lo is not None and hi is not None:
            return f"in {lo[0]}{_num(lo[1])}, {_num(hi[0])}{hi[1]}"
        if lo is not None:
            return f"{'>=' if lo[0] == '[' else '>'} {_num(lo[1])}"
        if hi is not None:
            return f"{'<=' if hi[1] == ']' else '<'} {_num(hi[0])}"
        return "finite" if self.finite else "a number"

    def holds(self, value: Any) -> bool:
        """Whether one scalar value lies in the range."""
        if self.choices is not None:
            return value in self.choices
        if isinstance(value, bool) or not isinstance(value, int | float):
            return False
        v = float(value)
        if math.isnan(v) or (self.finite and math.isinf(v)):
            return False
        return (
            (self.ge is None or v >= self.ge)
            and (self.gt is None or v > self.gt)
            and (self.le is None or v <= self.le)
            and (self.lt is None or v < self.lt)
        )


def _num(x: float | None) -> str:
    return f"{x:g}" if isinstance(x, float) else str(x)


def ranged(
    default: Any,
    *,
    ge: float | None = None,
    gt: float | None = None,
    le: float | None = None,
    lt: float | None = None,
    finite: bool = True,
    choices: Iterable[Any] | None = None,
    length: int | None = None,
    nonempty: bool = False,
    optional: bool = False,
) -> Any:
    """A dataclass field with ``default`` and its range in the field's metadata."""
    rng = Range(
        ge=ge,
        gt=gt,
        le=le,
        lt=lt,
        finite=finite,
        choices=tuple(choices) if choices is not None else None,
        length=length,
        nonempty=nonempty,
        optional=optional,
    )
    return dataclasses.field(default=default, metadata={_RANGE_KEY: rng})


def field_range(field: dataclasses.Field[Any]) -> Range | None:
    """The range declared for a field, if any."""
    rng = field.metadata.get(_RANGE_KEY)
    return rng if isinstance(rng, Range) else None


def check_ranges(obj: Any) -> None:
    """Raise ``ValueError`` naming the first field of the dataclass ``obj`` out of its range."""
    for f in dataclasses.fields(obj):
        rng = field_range(f)
        if rng is None:
            continue
        value = getattr(obj, f.name)
        if value is None and rng.optional:
            continue
        if isinstance(value, tuple | list):
            if rng.length is not None and len(value) != rng.length:
                raise ValueError(f"{f.name} must have {rng.length} items, got {value!r}")
            if rng.nonempty and not value:
                raise ValueError(f"{f.name} must not be empty")
            if not all(rng.holds(v) for v in value):
                raise ValueError(f"{f.name}: every item must be {rng.describe()}, got {value!r}")
        elif not rng.holds(value):
            raise ValueError(f"{f.name} must be {rng.describe()}, got {value!r}")

"""The declarative field ranges: one loop, one-line messages naming field, range and value."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from companion.ranges import check_ranges, ranged


@dataclass(frozen=True, slots=True)
class _Block:
    rate_hz: float = ranged(10.0, gt=0.0, le=50.0)
    count: int = ranged(3, ge=1)
    prob: float = ranged(0.5, gt=0.0, lt=1.0)
    mode: str = ranged("a", choices=("a", "b"))
    floor_m: tuple[float, ...] = ranged((1.0, 2.0), gt=0.0, length=2)
    limit_m: float | None = ranged(None, gt=0.0, optional=True)
    free: float = 1.0

    def __post_init__(self) -> None:
        check_ranges(self)


def test_defaults_pass_and_the_default_is_the_field_default():
    assert _Block().rate_hz == 10.0 and _Block().limit_m is None


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"rate_hz": 0.0}, r"^rate_hz must be in \(0, 50\], got 0\.0$"),
        ({"rate_hz": 51.0}, r"^rate_hz must be in \(0, 50\], got 51\.0$"),
        ({"rate_hz": float("nan")}, r"^rate_hz must be in \(0, 50\], got nan$"),
        ({"count": 0}, r"^count must be >= 1, got 0$"),
        ({"prob": 1.0}, r"^prob must be in \(0, 1\), got 1\.0$"),
        ({"mode": "c"}, r"^mode must be one of \['a', 'b'\], got 'c'$"),
        ({"floor_m": (1.0,)}, r"^floor_m must have 2 items, got \(1\.0,\)$"),
        ({"floor_m": (1.0, -2.0)}, r"^floor_m: every item must be > 0, got \(1\.0, -2\.0\)$"),
        ({"limit_m": float("inf")}, r"^limit_m must be > 0, got inf$"),
        ({"count": True}, r"^count must be >= 1, got True$"),
    ],
)
def test_out_of_range_is_one_line_naming_field_range_and_value(kwargs, message):
    with pytest.raises(ValueError, match=message):
        _Block(**kwargs)


def test_unranged_fields_are_not_checked():
    assert _Block(free=float("nan")).limit_m is None

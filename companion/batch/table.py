"""The batch's rows as one table: fixed order, fixed columns, Parquet or CSV.

Rows are sorted by path; the columns are the fixed ones of :data:`LEADING` in that
order, then every other column any row has, sorted by name (a flight without a
rejection reason another has gets 0 for it, without a score NaN). The same rows give
the same table whatever the number of workers or the order they finished in.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

LEADING = (
    "path", "name", "format", "vehicle", "duration_s", "messages_in", "scoring", "error",
    "gaps", "gap_s", "bridged_s", "closures", "closure_median_m", "closure_max_m",
    "hold_median_m", "closure_over_hold_median", "closure_over_hold_max",
)  # fmt: skip
TEXT_COLUMNS = frozenset({"path", "name", "format", "vehicle", "scoring", "error"})
COUNT_PREFIXES = ("rej_",)


def columns(rows: Sequence[dict[str, Any]]) -> list[str]:
    """The table's columns (module docstring)."""
    seen = set().union(*(r.keys() for r in rows)) if rows else set()
    rest = sorted(seen - set(LEADING))
    return [*LEADING, *rest]


def normalise(rows: Sequence[dict[str, Any]]) -> tuple[list[str], list[dict[str, Any]]]:
    """Rows sorted by path with every column: text "" / counts 0 / values NaN when absent."""
    cols = columns(rows)
    out = []
    for row in sorted(rows, key=lambda r: (str(r.get("path", "")), str(r.get("error", "")))):
        full: dict[str, Any] = {}
        for c in cols:
            if c in row:
                full[c] = row[c]
            elif c in TEXT_COLUMNS:
                full[c] = ""
            elif c.startswith(COUNT_PREFIXES) or c in ("messages_in", "gaps", "closures"):
                full[c] = 0
            else:
                full[c] = math.nan
        out.append(full)
    return cols, out


def write_table(rows: Sequence[dict[str, Any]], out_dir: Path, fmt: str = "auto") -> Path:
    """Write ``flights.parquet`` (``fmt`` "parquet", or "auto" with pyarrow installed) or
    ``flights.csv``; return its path."""
    cols, full = normalise(rows)
    if fmt in ("auto", "parquet"):
        try:
            import pyarrow as pa
            import pyarrow.parquet as pq
        except ImportError:
            if fmt == "parquet":
                raise
        else:
            data = {c: [r[c] for r in full] for c in cols}
            schema = pa.schema(
                [
                    (
                        c,
                        pa.string()
                        if c in TEXT_COLUMNS
                        else pa.int64()
                        if all(isinstance(v, int) for v in data[c])
                        else pa.float64(),
                    )
                    for c in cols
                ]
            )
            path = out_dir / "flights.parquet"
            pq.write_table(pa.table(data, schema=schema), path)
            return path
    path = out_dir / "flights.csv"
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=cols)
        writer.writeheader()
        for r in full:
            writer.writerow({c: _csv(v) for c, v in r.items()})
    return path


def _csv(value: Any) -> Any:
    if isinstance(value, float):
        return "" if math.isnan(value) else repr(value)
    return value


def read_table(path: Path) -> list[dict[str, Any]]:
    """The rows of a table :func:`write_table` wrote (CSV values as text, "" for NaN)."""
    if path.suffix == ".parquet":
        import pyarrow.parquet as pq

        return list(pq.read_table(path).to_pylist())
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))

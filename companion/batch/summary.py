"""The fleet summary of a batch: one text, one JSON, and plots when matplotlib is there."""

from __future__ import annotations

import json
import math
import statistics
from collections.abc import Sequence
from pathlib import Path
from typing import Any


def _finite(values: list[Any]) -> list[float]:
    return [float(v) for v in values if isinstance(v, (int, float)) and math.isfinite(v)]


def fleet_summary(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Totals and distributions over the flights (rows as :mod:`.table` normalised them)."""
    ok = [r for r in rows if not r["error"]]
    hours = sum(_finite([r["duration_s"] for r in ok])) / 3600.0
    alert_cols = sorted(c for c in (rows[0] if rows else {}) if c.startswith("alerts_per_h_"))
    alerts = {}
    for c in alert_cols:
        total = sum(
            v * r["duration_s"] / 3600.0
            for r in ok
            for v in _finite([r[c]])
            if math.isfinite(r["duration_s"])
        )
        if total:
            alerts[c.removeprefix("alerts_per_h_")] = total / hours if hours > 0 else math.nan
    closures = _finite([r["closure_median_m"] for r in ok])
    ratios = _finite([r["closure_over_hold_median"] for r in ok])
    rejections: dict[str, int] = {}
    for r in ok:
        for c, v in r.items():
            if c.startswith("rej_") and v:
                rejections[c.removeprefix("rej_")] = rejections.get(
                    c.removeprefix("rej_"), 0
                ) + int(v)
    vehicles: dict[str, int] = {}
    for r in ok:
        vehicles[r["vehicle"] or "unknown"] = vehicles.get(r["vehicle"] or "unknown", 0) + 1
    cat_s = {
        c.removeprefix("cat_").removesuffix("_s"): sum(_finite([r[c] for r in ok]))
        for c in sorted(c for c in (rows[0] if rows else {}) if c.startswith("cat_"))
    }
    return {
        "flights": len(rows),
        "errors": len(rows) - len(ok),
        "errors_by_flight": {r["path"]: r["error"] for r in rows if r["error"]},
        "flight_hours": hours,
        "vehicles": vehicles,
        "gaps": int(sum(_finite([r["gaps"] for r in ok]))),
        "gap_s": sum(_finite([r["gap_s"] for r in ok])),
        "bridged_s": sum(_finite([r["bridged_s"] for r in ok])),
        "flights_with_closures": len(closures),
        "closure_median_of_flight_medians_m": statistics.median(closures) if closures else None,
        "closure_over_hold_median_of_flights": statistics.median(ratios) if ratios else None,
        "alerts_per_flight_hour": alerts,
        "time_in_category_s": cat_s,
        "rejections": dict(sorted(rejections.items())),
    }


def summary_text(s: dict[str, Any]) -> str:
    """The summary for a terminal."""
    med = s["closure_median_of_flight_medians_m"]
    alerts = s["alerts_per_flight_hour"]
    ratio = s["closure_over_hold_median_of_flights"]
    lines = [
        f"{s['flights']} flights ({s['errors']} errors), {s['flight_hours']:.2f} flight hours",
        "vehicles: " + ", ".join(f"{k} {v}" for k, v in sorted(s["vehicles"].items())),
        f"GNSS gaps {s['gaps']} ({s['gap_s']:.0f} s); bridged {s['bridged_s']:.0f} s",
        "closures: "
        + (
            f"median over flights {med:.2f} m, closure/hold median {ratio:.2f} "
            f"({s['flights_with_closures']} flights)"
            if med is not None and ratio is not None
            else "none"
        ),
        "alerts per flight hour: "
        + (", ".join(f"{k} {v:.1f}" for k, v in sorted(alerts.items())) or "none"),
        "time in approach category: "
        + ", ".join(f"{k} {v:.0f} s" for k, v in s["time_in_category_s"].items()),
    ]
    for path, err in sorted(s["errors_by_flight"].items()):
        lines.append(f"error: {path}: {err}")
    return "\n".join(lines)


def write_summary(rows: Sequence[dict[str, Any]], out_dir: Path, plots: bool = True) -> list[Path]:
    """``summary.json``, ``summary.txt`` and, with matplotlib, ``fleet.png``."""
    s = fleet_summary(rows)
    written = [out_dir / "summary.json", out_dir / "summary.txt"]
    written[0].write_text(json.dumps(s, indent=1, sort_keys=True, default=_nan_none) + "\n")
    written[1].write_text(summary_text(s) + "\n")
    if plots:
        png = _plot(rows, s, out_dir / "fleet.png")
        if png is not None:
            written.append(png)
    return written


def _nan_none(value: Any) -> Any:
    return None


def _plot(rows: Sequence[dict[str, Any]], s: dict[str, Any], path: Path) -> Path | None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    ok = [r for r in rows if not r["error"]]
    fig, axes = plt.subplots(2, 2, figsize=(11, 8))
    ax = axes[0][0]
    pairs = [
        (r["hold_median_m"], r["closure_median_m"])
        for r in ok
        if _finite([r["hold_median_m"]]) and _finite([r["closure_median_m"]])
    ]
    if pairs:
        hold, closure = zip(*pairs, strict=True)
        ax.scatter(hold, closure, s=10)
        top = max(max(hold), max(closure))
        ax.plot([0, top], [0, top], "k--", lw=0.8, label="closure = hold")
        ax.legend()
    ax.set_xlabel("holding the last fix, median per flight (m)")
    ax.set_ylabel("bridged closure, median per flight (m)")
    ax.set_title("Gap closures")
    ax = axes[0][1]
    alerts = s["alerts_per_flight_hour"]
    ax.barh(list(alerts), list(alerts.values()))
    ax.set_xlabel("alerts per flight hour")
    ax.set_title("Alerts")
    ax = axes[1][0]
    bridged = _finite([r["bridged_s"] for r in ok])
    ax.hist(bridged, bins=30)
    ax.set_xlabel("bridged per flight (s)")
    ax.set_ylabel("flights")
    ax.set_title("Bridging")
    ax = axes[1][1]
    cats = s["time_in_category_s"]
    ax.bar([f"CAT {k}" if k != "0" else "none" for k in cats], [v / 3600.0 for v in cats.values()])
    ax.set_ylabel("hours")
    ax.set_title("Time in approach category")
    fig.suptitle(f"{s['flights']} flights, {s['flight_hours']:.1f} h, {s['errors']} errors")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path

"""``companion inspect --plot``: the T-D PRP track and FIS-RAIM's statistics as a PNG.

Three panels against the time from epoch 0: East, North and Up from epoch 0; the slope
of the separation series with its limit (both signs: the test trips above the positive
one); the residual sum of squares about the window's line with its limit (logarithmic).
Epochs where FIS-RAIM alerts are marked in red on every panel, epochs where it is
unavailable shaded grey. matplotlib is the ``plot`` extra, as for ``evaluate --plot``.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

from companion.evaluate.plot import require_matplotlib
from companion.inspection import InspectSummary

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def plot_inspection(
    summary: InspectSummary, png_path: Path, title: str = "", dpi: int = 110
) -> Figure:
    """Draw the track of ``summary`` and write it as a PNG (PlotUnavailableError without
    matplotlib)."""
    require_matplotlib()
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    track = summary.track
    t = [p.t_s for p in track]
    fig = Figure(figsize=(11.0, 10.0), layout="constrained")
    FigureCanvasAgg(fig)
    ax_enu, ax_slope, ax_res = fig.subplots(3, 1, sharex=True)
    for k, (name, colour) in enumerate(
        (("East", "tab:blue"), ("North", "tab:green"), ("Up", "tab:purple"))
    ):
        ax_enu.plot(t, [p.enu_m[k] for p in track], color=colour, lw=1.0, label=name)
    ax_enu.set_ylabel("from epoch 0, m")
    ax_enu.set_title(
        title or f"T-D PRP track, epoch 0 at GPS time of week {summary.epoch0_tow_s:.2f} s"
    )
    ax_slope.plot(
        t, [p.slope_mps for p in track], color="k", lw=1.0, label="slope of the separation"
    )
    for sign in (1.0, -1.0):
        ax_slope.axhline(sign * summary.slope_limit_mps, color="tab:red", ls="--", lw=0.8)
    ax_slope.set_ylabel("slope, m/s")
    # a residual of 0 (two points on their line) has no place on a log scale
    rss = [p.residual_m2 if p.residual_m2 > 0.0 else math.nan for p in track]
    ax_res.semilogy(t, rss, color="k", lw=1.0, label="residual RSS")
    ax_res.semilogy(
        t, [p.residual_limit_m2 for p in track], color="tab:red", ls="--", lw=0.8, label="its limit"
    )
    ax_res.set_ylabel("residual, m²")
    ax_res.set_xlabel("time from epoch 0, s")
    alerts = [p for p in track if p.slope_alert or p.residual_alert]
    for ax in (ax_enu, ax_slope, ax_res):
        for p in track:
            if not p.available:
                ax.axvspan(p.t_s - 0.125, p.t_s + 0.125, color="0.85", lw=0)
        for p in alerts:
            ax.axvline(p.t_s, color="tab:red", alpha=0.25, lw=1.5)
        ax.grid(True, alpha=0.3)
    available = sum(p.available for p in track)
    ax_slope.plot(
        [p.t_s for p in alerts if p.slope_alert],
        [p.slope_mps for p in alerts if p.slope_alert],
        "rv",
        ms=4,
        label="slope alert",
    )
    ax_res.plot(
        [p.t_s for p in alerts if p.residual_alert],
        [p.residual_m2 for p in alerts if p.residual_alert],
        "rv",
        ms=4,
        label="residual alert",
    )
    ax_enu.legend(loc="upper left")
    ax_slope.legend(
        loc="upper left",
        title=f"{available} epochs available, {len(alerts)} alerts; grey: unavailable",
    )
    ax_res.legend(loc="upper left")
    png_path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png_path, dpi=dpi)
    return fig

"""The replay report picture: track, horizontal and vertical error, events and alerts.

:func:`plot_evaluation` draws what :func:`companion.evaluate.evaluate` measured on one page:

* top: the track in a local east/north frame (metres), truth in grey, the published solution
  in blue, the parts of it inside event windows in the event's colour;
* middle: the horizontal error over autopilot time with the published 95 % accuracy dashed
  (the honesty check: the error should stay under it), log-scaled when the error spans
  orders of magnitude (centimetre RTK and tens of metres in an outage);
* bottom: the signed vertical error with the published +-95 % band;
* event windows shaded and labelled in both error panels; alerts as vertical lines with their
  code (red: loss and fault alerts, dotted when false; green: status reports).

Matplotlib is used through its object API on an Agg canvas (no pyplot global state). It is
an optional extra (``pip install 'companion[plot]'``): this module imports it only when it
draws, so the service installs and runs without it, and :func:`require_matplotlib` turns its
absence into one line that names the extra.

See ``docs/replay.md`` for the replay and evaluation contract.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from companion.evaluate.results import Evaluation
from companion.evaluate.score import FALSE_ALERT_CODES

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

_log = logging.getLogger(__name__)

PLOT_EXTRA = "companion[plot]"
"""The optional extra that brings matplotlib."""


class PlotUnavailableError(RuntimeError):
    """Plotting was asked for but matplotlib cannot be imported; the message names the extra."""


def require_matplotlib() -> None:
    """Raise :class:`PlotUnavailableError` unless matplotlib imports.

    Called before any work that ends in a plot, so that a missing extra costs one line
    (``... pip install 'companion[plot]'``) and not a traceback after the evaluation.
    """
    try:
        import matplotlib  # noqa: F401
    except ImportError as exc:
        raise PlotUnavailableError(
            f"plotting needs matplotlib ({exc}): pip install '{PLOT_EXTRA}'"
        ) from None


EVENT_COLOURS: dict[str, str] = {
    "outage": "tab:red",
    "rtk_outage": "tab:orange",
    "downgrade": "tab:brown",
    "stale": "tab:purple",
    "step": "tab:pink",
    "ramp": "tab:olive",
    "dither": "tab:cyan",
}
"""Colour of each event kind (shading and track highlight)."""

LOG_SCALE_SPAN = 30.0
"""Use a log scale for the horizontal error when max / median exceeds this."""
LOG_FLOOR_M = 1e-3
"""Smallest horizontal error drawn on a log scale (quantisation is ~1 cm), m."""
LABEL_SPACING_FRACTION = 0.02
"""Alert labels of one code closer than this fraction of the time span are not repeated;
labels of different codes closer than this are staggered vertically."""
LABEL_LEVELS: tuple[float, ...] = (0.02, 0.3, 0.58)
"""Heights (axes fraction) of the staggered alert labels."""


def plot_evaluation(evaluation: Evaluation, png_path: Path, dpi: int = 110) -> Figure:
    """Draw the evaluation and write it as a PNG.

    Parameters
    ----------
    evaluation : Evaluation
        What :func:`companion.evaluate.evaluate` returned (its ``series`` are drawn).
    png_path : Path
        Where to write the PNG (parent directories are created).
    dpi : int
        Resolution of the PNG.

    Returns
    -------
    Figure
        The figure drawn (three axes: track, horizontal error, vertical error).

    Raises
    ------
    PlotUnavailableError
        matplotlib is not installed (the ``plot`` extra).
    """
    require_matplotlib()
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    s = evaluation.series
    fig = Figure(figsize=(11.0, 12.0), layout="constrained")
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(3, 1, height_ratios=(1.8, 1.0, 1.0))
    ax_track = fig.add_subplot(grid[0])
    ax_h = fig.add_subplot(grid[1])
    ax_v = fig.add_subplot(grid[2], sharex=ax_h)

    fig.suptitle(_title(evaluation), fontsize=11)

    # ---- track
    ax_track.plot(s.truth_east_m, s.truth_north_m, color="0.55", lw=3.0, label="truth", zorder=1)
    ax_track.plot(
        s.pub_east_m, s.pub_north_m, color="tab:blue", lw=1.0, label="published", zorder=2
    )
    seen_kinds: set[str] = set()
    for ev in evaluation.events:
        m = (s.t_s >= ev.t_start_s) & (s.t_s <= ev.t_end_s)
        if not np.any(m):
            continue
        colour = EVENT_COLOURS.get(ev.kind, "tab:gray")
        label = f"published in {ev.kind}" if ev.kind not in seen_kinds else None
        seen_kinds.add(ev.kind)
        ax_track.plot(s.pub_east_m[m], s.pub_north_m[m], ".", ms=3.0, color=colour, label=label)
    if s.pub_east_m.size:
        ax_track.plot(s.pub_east_m[0], s.pub_north_m[0], "^", color="k", ms=8, label="start")
        ax_track.plot(s.pub_east_m[-1], s.pub_north_m[-1], "s", color="k", ms=7, label="end")
    ax_track.set_xlabel("east (m)")
    ax_track.set_ylabel("north (m)")
    ax_track.set_aspect("equal", adjustable="datalim")
    ax_track.grid(True, alpha=0.3)
    ax_track.legend(loc="best", fontsize=8)
    ax_track.set_title("Track (local frame at the first evaluated point)", fontsize=10)

    # ---- horizontal error
    ax_h.plot(s.t_s, np.maximum(s.err_h_m, LOG_FLOOR_M), color="tab:blue", lw=1.0, label="error")
    if np.any(np.isfinite(s.acc_h95_m)):
        ax_h.plot(s.t_s, s.acc_h95_m, "--", color="tab:green", lw=1.0, label="published 95 %")
    if _wants_log(s.err_h_m):
        ax_h.set_yscale("log")
    ax_h.set_ylabel("horizontal error (m)")
    ax_h.grid(True, which="both", alpha=0.3)
    ax_h.legend(loc="upper left", fontsize=8)
    ax_h.set_title(_stats_line(evaluation), fontsize=9)

    # ---- vertical error
    ax_v.plot(s.t_s, s.err_v_m, color="tab:blue", lw=1.0, label="error (up +)")
    if np.any(np.isfinite(s.acc_v95_m)):
        ax_v.plot(s.t_s, s.acc_v95_m, "--", color="tab:green", lw=1.0, label="published 95 %")
        ax_v.plot(s.t_s, -s.acc_v95_m, "--", color="tab:green", lw=1.0)
    ax_v.axhline(0.0, color="0.3", lw=0.6)
    ax_v.set_ylabel("vertical error (m)")
    ax_v.set_xlabel("autopilot time (s)")
    ax_v.grid(True, alpha=0.3)
    ax_v.legend(loc="upper left", fontsize=8)

    for ax in (ax_h, ax_v):
        _shade_events(ax, evaluation, label=ax is ax_h)
        _mark_alerts(ax, evaluation, label=ax is ax_h)
    if s.t_s.size:
        ax_h.set_xlim(float(s.t_s[0]), float(s.t_s[-1]))

    png_path = Path(png_path)
    png_path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png_path, dpi=dpi)
    _log.info("wrote %s", png_path)
    return fig


def _wants_log(err_h_m: np.ndarray) -> bool:
    finite = err_h_m[np.isfinite(err_h_m)]
    if finite.size == 0:
        return False
    median = max(float(np.median(finite)), LOG_FLOOR_M)
    return float(np.max(finite)) / median > LOG_SCALE_SPAN


def _shade_events(ax: Axes, evaluation: Evaluation, label: bool) -> None:
    for ev in evaluation.events:
        colour = EVENT_COLOURS.get(ev.kind, "tab:gray")
        ax.axvspan(ev.t_start_s, ev.t_end_s, color=colour, alpha=0.15, lw=0)
        if label:
            status = "missed" if not ev.detected else f"+{ev.latency_s:.1f} s"
            ax.text(
                0.5 * (ev.t_start_s + ev.t_end_s),
                0.98,
                f"{ev.kind}\n{status}",
                transform=ax.get_xaxis_transform(),
                ha="center",
                va="top",
                fontsize=8,
                color=colour,
                fontweight="bold",
                bbox={"facecolor": "white", "alpha": 0.7, "linewidth": 0.0, "pad": 1.0},
            )


def _mark_alerts(ax: Axes, evaluation: Evaluation, label: bool) -> None:
    s = evaluation.series
    span = float(s.t_s[-1] - s.t_s[0]) if s.t_s.size > 1 else 1.0
    last_label_t: dict[str, float] = {}
    level_last_t = [-np.inf] * len(LABEL_LEVELS)
    for al in evaluation.alerts:
        loss_or_fault = al.code in FALSE_ALERT_CODES
        colour = "tab:red" if loss_or_fault else "tab:green"
        style = ":" if al.false_alert else "-"
        ax.axvline(al.t_s, color=colour, lw=0.9, ls=style, alpha=0.8)
        if not label:
            continue
        prev = last_label_t.get(al.code)
        if prev is not None and al.t_s - prev < LABEL_SPACING_FRACTION * span:
            continue
        last_label_t[al.code] = al.t_s
        # Stagger labels that would overlap: the lowest level whose last label is far enough.
        gap = LABEL_SPACING_FRACTION * span
        level = next(
            (i for i, t in enumerate(level_last_t) if al.t_s - t >= gap), len(LABEL_LEVELS) - 1
        )
        level_last_t[level] = al.t_s
        text = al.code + (" (false)" if al.false_alert else "")
        ax.text(
            al.t_s,
            LABEL_LEVELS[level],
            text,
            transform=ax.get_xaxis_transform(),
            rotation=90,
            ha="right",
            va="bottom",
            fontsize=7,
            color=colour,
            bbox={"facecolor": "white", "alpha": 0.7, "linewidth": 0.0, "pad": 1.0},
        )


def _title(ev: Evaluation) -> str:
    name = ev.scenario or Path(ev.truth_csv).name
    seed = "" if ev.seed is None else f", seed {ev.seed}"
    detected = sum(1 for e in ev.events if e.detected)
    parts = [
        f"{name}{seed}: {ev.n_evaluated} solutions",
        f"events detected {detected}/{len(ev.events)}",
        f"false alerts {ev.n_false_alerts}",
    ]
    h = ev.heading
    if h.error_deg is not None:
        parts.append(f"heading error {h.error_deg:+.2f} deg")
    return ";  ".join(parts)


def _stats_line(ev: Evaluation) -> str:
    n = ev.normal
    if n.n == 0 or n.h_rms_m is None or n.h_p95_m is None or n.v_rms_m is None:
        return "no solution outside event windows"
    line = f"normal: H rms {n.h_rms_m:.3f} m, p95 {n.h_p95_m:.3f} m; V rms {n.v_rms_m:.3f} m"
    for w in ev.windows:
        if w.h_max_m is not None:
            line += f";  {w.kind}: H max {w.h_max_m:.2f} m"
    return line

"""Tests of the replay report picture."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.image import imread

from companion.evaluate.plot import plot_evaluation
from tests.test_evaluate import event_case, make_truth


def test_plot_writes_png_with_three_axes(tmp_path: Path) -> None:
    truth = make_truth()
    evaluation = event_case(tmp_path, truth)
    png = tmp_path / "plots" / "report.png"
    fig = plot_evaluation(evaluation, png)
    assert png.is_file() and png.stat().st_size > 20_000
    assert len(fig.axes) == 3
    track, err_h, err_v = fig.axes
    assert track.get_xlabel() == "east (m)" and track.get_ylabel() == "north (m)"
    assert err_v.get_xlabel() == "autopilot time (s)"
    # The 5 m outage error next to centimetres elsewhere: the horizontal panel is log-scaled.
    assert err_h.get_yscale() == "log"
    # One shaded span per event in each error panel, one vertical line per alert.
    n_events, n_alerts = len(evaluation.events), len(evaluation.alerts)
    for ax in (err_h, err_v):
        spans = [p for p in ax.patches if p.get_alpha() == 0.15]
        assert len(spans) == n_events
    labels = {t.get_text() for t in err_h.texts}
    assert "outage\n+1.2 s" in labels and "stale\nmissed" in labels
    assert "FAULT (false)" in labels and "GNSS_LOST" in labels
    vlines = [ln for ln in err_h.lines if np.ndim(ln.get_xdata()) == 1 and len(ln.get_xdata()) == 2]
    assert len(vlines) >= n_alerts
    img = imread(str(png))
    assert img.shape[0] > 1000 and img.shape[1] > 1000
    assert float(np.std(img[..., :3])) > 0.05  # not a blank page

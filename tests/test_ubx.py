"""The UBX edge: frames in, raw records out, bad frames counted; the receiver set-up."""

from __future__ import annotations

import io
import math

from pyubx2 import UBXReader

from companion.ubx.pos import read_pos
from companion.ubx.reader import UbxSource, enable_raw_output, read_file
from tests.raw.helpers import POS, UBX


def test_reads_the_bundled_cut() -> None:
    epochs, nav, pvt, rejected = read_file(str(UBX))
    assert len(epochs) == 161 and len(pvt) == 161
    assert sum(rejected.values()) == 0
    sig = epochs[0].signals
    assert {s.band for s in sig if s.system == "GPS"} == {"L1", "L2", "L5"}
    assert {s.band for s in sig if s.system == "Galileo"} == {"E1", "E5a", "E6"}
    assert all(0.0 <= s.lock_time_s <= 64.5 for s in sig)
    assert pvt[0].carrier_solution == 2 and abs(pvt[0].height_m - 1580.048) < 1e-6


def test_a_corrupted_frame_is_counted_not_raised() -> None:
    data = bytearray(UBX.read_bytes()[:200_000])
    data[5000] ^= 0xFF  # inside the first RAWX frame: its checksum fails
    src = UbxSource(io.BytesIO(bytes(data)))
    items = list(src)
    assert src.rejected["bad frame"] >= 1
    assert len(items) > 10


def test_cfg_valset_turns_raw_output_on() -> None:
    frame = enable_raw_output("UART2")
    msg = UBXReader.parse(frame, msgmode=1)
    assert msg.identity == "CFG-VALSET"
    text = str(msg)
    for key in ("RXM_RAWX_UART2", "RXM_SFRBX_UART2", "NAV_PVT_UART2"):
        assert key in text


def test_reference_rows_and_malformed_lines(tmp_path) -> None:
    rows, bad = read_pos(str(POS))
    assert len(rows) == 161 and bad == 0
    assert rows[0].week == 2381 and abs(rows[0].tow_s - 408639.749) < 1e-3
    broken = tmp_path / "x.pos"
    broken.write_text(POS.read_text().replace("1601.4", "x601.4", 1))
    rows2, bad2 = read_pos(str(broken))
    assert bad2 == 1 and len(rows2) == 160


def test_inspect_writes_the_track(tmp_path) -> None:
    import csv

    from companion.cli import main

    out = tmp_path / "track.csv"
    assert main(["inspect", str(UBX), "--output", str(out)]) == 0
    rows = list(csv.DictReader(out.open()))
    assert len(rows) == 160
    assert list(rows[0]) == [
        "gps_tow_s", "lat_deg", "lon_deg", "alt_m", "e_m", "n_m", "u_m",
        "n_sats", "slope_stat", "residual_stat", "alert",
    ]  # fmt: skip
    assert abs(float(rows[0]["e_m"])) < 0.01 and int(rows[0]["n_sats"]) >= 5
    # the static start: centimetres; then the walk moves metres away
    assert math.hypot(float(rows[40]["e_m"]), float(rows[40]["n_m"])) < 0.05
    assert math.hypot(float(rows[-1]["e_m"]), float(rows[-1]["n_m"])) > 5.0
    assert abs(float(rows[0]["alt_m"]) - 1580.05) < 0.05


def test_inspect_bad_reference_is_one_line(capsys) -> None:
    from companion.cli import main

    assert main(["inspect", str(UBX), "-o", "/dev/null", "--reference", "91,0,0"]) == 1
    assert "out of range" in capsys.readouterr().err


def test_inspect_plot_draws_the_track_and_marks_alerts(tmp_path) -> None:
    import dataclasses

    from companion.cli import main
    from companion.inspection import inspect_file
    from companion.inspection_plot import plot_inspection

    png = tmp_path / "track.png"
    assert main(["inspect", str(UBX), "-o", str(tmp_path / "t.csv"), "--plot", str(png)]) == 0
    assert png.stat().st_size > 10_000
    summary = inspect_file(UBX, tmp_path / "t2.csv")
    assert len(summary.track) == summary.solved
    track = list(summary.track)
    track[20] = dataclasses.replace(track[20], slope_alert=True, slope_mps=0.02)
    fig = plot_inspection(dataclasses.replace(summary, track=tuple(track)), tmp_path / "a.png")
    slope_ax = fig.axes[1]
    marks = [ln for ln in slope_ax.get_lines() if ln.get_label() == "slope alert"]
    assert len(marks) == 1 and list(marks[0].get_xdata()) == [track[20].t_s]
    assert {ln.get_ydata()[0] for ln in slope_ax.get_lines() if ln.get_linestyle() == "--"} == {
        summary.slope_limit_mps,
        -summary.slope_limit_mps,
    }

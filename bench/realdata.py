"""Every real flight replayed through the service and scored against its own input.

For each flight folder of ``../shared/realdata/flights/`` (relative to the project root;
README there): the converted ``<folder>.tlog`` is replayed with the default configuration
(:func:`companion.replay.replay`, the code path of ``companion replay``), and the output
is scored with :func:`companion.evaluate.against_input.evaluate_against_input` (the code
path of ``companion evaluate OUT --against-input IN``; rules in that module). Prints one
table, a row per flight and a column per acceptance figure with its PASS/FAIL mark
("-": not applicable), then a row per GNSS gap, then a row per real event (a whole-stream
dropout, a GNSS gap, no GNSS at start: found in the log's own timestamps,
:mod:`companion.evaluate.events_said`) with the alerts that said its start and its end.
Two columns come from that module: ``txt/min``, the service's texts a minute of log
(PASS at most :data:`TEXTS_PER_MINUTE_MAX`; the most in any minute beside it, real
changes included), and ``events said``, the real events whose start and whose end the
service said (to compare between two versions of the code: one event, one alert and one
return). ``SPOOF`` counts the SPOOF alerts (none may come: no real flight was spoofed);
``SPF_A m/s2`` is the drag the spoofing test said it would see within 10 s (the
``CMP_SPF_A`` it published: median, 10th-90th percentile), what that autopilot's IMU
stream lets it vouch for. A folder without its tlog, or the whole data folder absent, is
skipped with the reason.

Other rows (another data set scored its own way) join the table as dicts of
column -> cell: append them to the list :func:`main` passes to :func:`print_table`.

Run: ``python bench/realdata.py [--json OUT.json] [--keep DIR] [--only NAME]``.
Progress goes to stderr.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import json
import logging
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from companion.config import load_config  # noqa: E402
from companion.evaluate.against_input import evaluate_against_input  # noqa: E402
from companion.evaluate.against_input_report import GAP_HEADER, gap_line  # noqa: E402
from companion.evaluate.events_said import EventsSaid, events_said  # noqa: E402
from companion.mavlink.tlog import TlogReader  # noqa: E402
from companion.replay import replay  # noqa: E402

FLIGHTS_DIR = ROOT.parent / "shared" / "realdata" / "flights"
BAR_WIDTH = 30
TEXTS_PER_MINUTE_MAX = 6.0
"""Texts a minute of log the service may send on average (a log shorter than a minute
counts as one)."""


def progress(done_bytes: int, total_bytes: int, label: str, t0: float) -> None:
    """A one-line progress bar on stderr (by input bytes), elapsed time."""
    frac = done_bytes / total_bytes if total_bytes else 1.0
    filled = int(round(BAR_WIDTH * frac))
    bar = "#" * filled + "." * (BAR_WIDTH - filled)
    line = f"\r[{bar}] {100 * frac:3.0f}% {time.perf_counter() - t0:6.1f} s  {label:<45.45}"
    print(line, end="", file=sys.stderr, flush=True)


def _size(path: Path) -> int:
    return path.stat().st_size if path.is_file() else 0


def run_flight(folder: Path, out_dir: Path) -> dict[str, Any]:
    """Replay and score one flight folder: its table row, gaps and JSON."""
    tlog = folder / f"{folder.name}.tlog"
    if not tlog.is_file():
        return {"flight": folder.name, "skipped": f"no {tlog.name} in the folder"}
    config = load_config(None)
    out = out_dir / f"{folder.name}.out.tlog"
    t0 = time.perf_counter()
    summary = replay(tlog, out, config)
    t1 = time.perf_counter()
    result = evaluate_against_input(out, tlog, config.decoder)
    events = events_said(out, tlog, config.decoder)
    t2 = time.perf_counter()
    return {
        "flight": folder.name,
        "result": result,
        "events": events,
        "replay_s": t1 - t0,
        "evaluate_s": t2 - t1,
        "log_s": summary.log_duration_s,
        "spoof_alerts": summary.alerts.get("SPOOF", 0),
        "spf_a": published_values(out, "CMP_SPF_A"),
    }


def published_values(out: Path, name: str) -> list[float]:
    """Every NAMED_VALUE_FLOAT ``name`` the service sent in its output .tlog."""
    return [
        float(msg.value)
        for _, msg in TlogReader(out)
        if msg.get_type() == "NAMED_VALUE_FLOAT" and str(msg.name).rstrip("\x00") == name
    ]


def spf_cell(values: list[float]) -> str:
    """The drag the spoofing test said it sees within 10 s (CMP_SPF_A): median and range."""
    if not values:
        return "-"
    v = sorted(values)
    return f"{v[len(v) // 2]:.2f} ({v[len(v) // 10]:.2f}-{v[(9 * len(v)) // 10]:.2f})"


def events_cells(ev: EventsSaid) -> dict[str, str]:
    """The texts a minute (marked) and the real events said, as table cells."""
    mark = "PASS" if ev.per_minute <= TEXTS_PER_MINUTE_MAX else "FAIL"
    return {
        "txt/min": f"{ev.per_minute:.1f} (max {ev.max_in_window}) {mark}",
        "events said": ev.cell(),
    }


def print_table(rows: list[dict[str, str]]) -> None:
    """One table: the union of the rows' columns, in first-seen order; '-' where absent."""
    columns: list[str] = []
    for row in rows:
        for key in row:
            if key not in columns:
                columns.append(key)
    widths = {c: max(len(c), *(len(r.get(c, "-")) for r in rows)) for c in columns}
    print("  ".join(c.ljust(widths[c]) for c in columns))
    print("  ".join("-" * widths[c] for c in columns))
    for row in rows:
        print("  ".join(row.get(c, "-").ljust(widths[c]) for c in columns))


def walk_table_row() -> dict[str, str]:
    """The walk_0827 recording (bench/walk_0827.py: no ATTITUDE, 15 s outages, the RTK
    solution as reference) as one row, with the device's measurement floors; its closure
    judged against the textbook filter run on the same outages in this run (printed
    beside it)."""
    spec = importlib.util.spec_from_file_location(
        "walk_0827", Path(__file__).with_name("walk_0827.py")
    )
    if spec is None or spec.loader is None:
        raise ImportError("bench/walk_0827.py not found beside bench/realdata.py")
    walk_0827 = importlib.util.module_from_spec(spec)
    sys.modules["walk_0827"] = walk_0827  # its dataclasses look their module up
    spec.loader.exec_module(walk_0827)
    row = walk_0827.walk_row()
    name = "gnss_imu/walk_0827 (handheld floors)"
    if row is None:
        return {"flight": name, "wrong>25m": f"skipped: no recording at {walk_0827.DATA_DIR}"}
    # judged against the textbook filter run in the same process on the same outages
    # (bench/textbook_lc.py), printed beside the service's figures
    close_ok = walk_0827.closure_ok(row)
    cover = min(row["cov95_h"], row["cov95_v"])
    cells = {
        "flight": name,
        "cover95": f"{100 * cover:.0f}% {'PASS' if cover >= 0.95 else 'FAIL'}",
        "walk closure H/V": (
            f"{row['close_h_m']:.2f}/{row['close_v_m']:.2f} m (textbook "
            f"{row['tb_h_m']:.2f}/{row['tb_v_m']:.2f}) {'PASS' if close_ok else 'FAIL'}"
        ),
    }
    unused_ok = row["fixes_unused"] == 0
    cells["walk unused fixes"] = f"{row['fixes_unused']} {'PASS' if unused_ok else 'FAIL'}"
    passed = close_ok and cover >= 0.95 and unused_ok
    cells["all"] = "PASS" if passed else "FAIL"
    return cells


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", type=Path, help="write the full results here")
    parser.add_argument("--keep", type=Path, help="keep the replay outputs in this folder")
    parser.add_argument("--only", help="only the flight folders whose name contains this")
    parser.add_argument("--flights", type=Path, default=FLIGHTS_DIR, help="flights folder")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.ERROR, stream=sys.stderr)
    logging.getLogger("companion").setLevel(logging.ERROR)
    if not args.flights.is_dir():
        print(f"skipped: no real data at {args.flights} (a clone without ../shared/realdata)")
        return 0
    folders = sorted(p for p in args.flights.iterdir() if p.is_dir())
    if args.only:
        folders = [p for p in folders if args.only in p.name]
    sizes = {p: _size(p / f"{p.name}.tlog") for p in folders}
    total = sum(sizes.values())
    t0 = time.perf_counter()
    done = 0
    runs: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        out_dir = args.keep if args.keep is not None else Path(tmp)
        out_dir.mkdir(parents=True, exist_ok=True)
        for folder in folders:
            progress(done, total, folder.name, t0)
            runs.append(run_flight(folder, out_dir))
            done += sizes[folder]
        progress(done, total, "done", t0)
    wall = time.perf_counter() - t0
    print(file=sys.stderr)

    rows: list[dict[str, str]] = []
    for run in runs:
        if "skipped" in run:
            rows.append({"flight": run["flight"], "wrong>25m": f"skipped: {run['skipped']}"})
            continue
        row = {
            "flight": run["flight"],
            **run["result"].row(),
            **events_cells(run["events"]),
            # no real flight was spoofed: a SPOOF on one is a false alarm
            "SPOOF": f"{run['spoof_alerts']} {'PASS' if run['spoof_alerts'] == 0 else 'FAIL'}",
            "SPF_A m/s2": spf_cell(run["spf_a"]),
        }
        texts_ok = run["events"].per_minute <= TEXTS_PER_MINUTE_MAX
        spoof_ok = run["spoof_alerts"] == 0
        row["all"] = "PASS" if run["result"].passed and texts_ok and spoof_ok else "FAIL"
        rows.append(row)
    # other data sets' rows (dicts of column -> cell) are appended here
    # the walk beside the real flights folder (not with another --flights folder)
    if args.flights == FLIGHTS_DIR and (not args.only or args.only in "walk_0827"):
        rows.append(walk_table_row())
    print_table(rows)
    print()
    print(
        "GNSS gaps >= 3 s (autopilot time s; horizontal m; ratio = closure / best of hold and"
        " cv; ratio and 99 % judged only where the IMU runs >= 20 Hz)"
    )
    print(f"  {'flight':<38}" + GAP_HEADER[2:])
    for run in runs:
        for g in getattr(run.get("result"), "gaps", ()):
            print(f"  {run['flight']:<38}" + gap_line(g)[2:])
    print()
    print(
        "Real events (s from the log's start; start: the alert that said it and its latency,"
        " 'already': a loss was being said; end: the return that said it)"
    )
    print(f"  {'flight':<38}{'event':<10}{'start':>8}{'length':>8}  {'start said':<22}end said")
    for run in runs:
        for e in getattr(run.get("events"), "events", ()):
            length = "open" if e.end_s is None else f"{e.end_s - e.start_s:.1f}"
            by = "none" if e.start_said_by is None else e.start_said_by
            if e.start_latency_s is not None and e.start_said_by != "already":
                by += f" {e.start_latency_s:.1f} s"
            end = "-" if e.end_s is None else (e.end_said_by or "none")
            print(f"  {run['flight']:<38}{e.kind:<10}{e.start_s:8.1f}{length:>8}  {by:<22}{end}")
    n_scored = sum("result" in r for r in runs)
    print()
    print(
        f"{n_scored} flight(s) replayed and scored in {wall:.1f} s "
        f"(replay {sum(r.get('replay_s', 0.0) for r in runs):.1f} s, "
        f"evaluate {sum(r.get('evaluate_s', 0.0) for r in runs):.1f} s)"
    )
    if args.json is not None:
        doc = [
            {
                "flight": r["flight"],
                **(
                    {"skipped": r["skipped"]}
                    if "skipped" in r
                    else {
                        "replay_s": r["replay_s"],
                        "evaluate_s": r["evaluate_s"],
                        "log_s": r["log_s"],
                        **r["result"].to_dict(),
                        "events_said": dataclasses.asdict(r["events"]),
                    }
                ),
            }
            for r in runs
        ]
        args.json.write_text(json.dumps(doc, indent=2, sort_keys=True))
        print(f"json: {args.json}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The console's screenshots in the README: bundled flights replayed, the app drawn at a moment.

Run: ``python docs/screenshots/make.py`` (needs the ``console`` and ``screenshots``
extras). Each scene replays a bundled flight through the service (``companion.replay``),
feeds the console's model with the autopilot's messages and the service's answers in
receive order up to a moment, and has the app (headless, Textual's test pilot) save an
SVG screenshot at that moment, converted to PNG with cairosvg. The station for the
tracking panel is placed 1.5 km from the first published position,
2 m above the airfield.
"""

from __future__ import annotations

import asyncio
import logging
import math
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from companion.console.app import ConsoleApp  # noqa: E402
from companion.console.main import parse_station  # noqa: E402
from companion.console.model import ConsoleModel  # noqa: E402
from companion.mavlink.tlog import TlogReader  # noqa: E402
from companion.presets import grade_config  # noqa: E402
from companion.replay import replay  # noqa: E402

OUT = Path(__file__).resolve().parent
SIZE = (150, 44)
MONO_FONT = "DejaVu Sans Mono"
STATION_ALT_M = 112.0
"""The station's antenna, 2 m above the simulated airfield (110 m MSL)."""


def _records(flight: str, grade: str, tmp: Path) -> list[tuple[float, object]]:
    src = ROOT / "sitl_fixtures" / f"{flight}.tlog"
    out = tmp / f"{flight}.out.tlog"
    replay(src, out, grade_config(grade))
    merged = list(TlogReader(src)) + list(TlogReader(out))
    merged.sort(key=lambda r: r[0])
    return merged


def _station(records: list[tuple[float, object]]) -> str:
    first = next(
        m
        for _, m in records
        if m.get_type() == "GLOBAL_POSITION_INT" and m.get_srcComponent() == 191  # type: ignore[attr-defined]
    )
    lat, lon = first.lat / 1e7, first.lon / 1e7  # type: ignore[attr-defined]
    dlat = 1200.0 / 111_200.0
    dlon = 900.0 / (111_200.0 * math.cos(math.radians(lat)))
    return f"{lat - dlat:.6f},{lon + dlon:.6f},{STATION_ALT_M:.1f}"


def _model_until(
    records: list[tuple[float, object]], stop: Callable[[ConsoleModel], bool], extra_s: float
) -> tuple[ConsoleModel, float]:
    model = ConsoleModel(station=parse_station(_station(records)))
    t_stop = None
    t = records[0][0]
    for t, msg in records:
        if t_stop is not None and t > t_stop:
            break
        model.take(msg, t)
        if t_stop is None and stop(model):
            t_stop = t + extra_s
    return model, t


async def _shoot(model: ConsoleModel, now: float, name: str) -> Path:
    app = ConsoleApp("udpin:127.0.0.1:0", model, clock=lambda: now)
    async with app.run_test(size=SIZE) as pilot:
        await pilot.pause(0.8)
        app.refresh_panels()
        await pilot.pause(0.3)
        svg = app.save_screenshot(f"{name}.svg", str(OUT))
    return Path(svg)


def _png(svg: Path) -> Path:
    import cairosvg

    png = svg.with_suffix(".png")
    # the SVG asks for Fira Code from the web, then "monospace", which cairosvg does not
    # resolve to a monospaced face: name one, so that every cell keeps its width
    text = svg.read_text(encoding="utf-8").replace("Fira Code, monospace", MONO_FONT)
    cairosvg.svg2png(bytestring=text.encode("utf-8"), write_to=str(png), output_width=1500)
    svg.unlink()
    return png


def _texts(model: ConsoleModel) -> list[str]:
    return [a.text for a in model.alerts]


SCENES: list[tuple[str, str, str, Callable[[ConsoleModel], bool], float]] = [
    # name, flight, grade, the moment, seconds after it
    (
        "console_normal",
        "cruise_gnss_loss",
        "mems",
        lambda m: len(m.history["CMP_HACC"]) > 50,
        0.0,
    ),
    (
        "console_outage",
        "cruise_gnss_loss",
        "mems",
        lambda m: m.values.get("CMP_OUTG", 0.0) > 25.0,
        0.0,
    ),
    (
        "console_alert",
        "ramp_fault",
        "tactical",
        lambda m: any("INTEGRITY lost" in t for t in _texts(m)),
        1.5,
    ),
    (
        "console_heading_ready",
        "taxi",
        "tactical",
        lambda m: m.heading_state() == "ready",
        2.0,
    ),
]


def main() -> int:
    logging.disable(logging.WARNING)
    with tempfile.TemporaryDirectory() as tmp:
        cache: dict[tuple[str, str], list[tuple[float, object]]] = {}
        for name, flight, grade, stop, extra in SCENES:
            key = (flight, grade)
            if key not in cache:
                cache[key] = _records(flight, grade, Path(tmp))
            model, now = _model_until(cache[key], stop, extra)
            png = _png(asyncio.run(_shoot(model, now, name)))
            print(png.relative_to(ROOT))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Entry point of ``companion console``: the Textual app, or one screen for scripts.

``--once`` prints the text screen and ``--json`` the snapshot, after the first
published solution or after ``--duration`` (default 5 s) even when nothing is
heard; ``--web PORT`` serves the same app to a browser (textual-serve).
"""

from __future__ import annotations

import asyncio
import json
import math
import shlex
import sys
import time

from companion.console.model import ConsoleModel
from companion.mavlink.framing import FrameParser
from companion.mavlink.link import LinkError, open_link
from companion.nav.frames import LocalFrame

ONCE_DURATION_S = 5.0
POLL_S = 0.25


def parse_station(text: str) -> LocalFrame:
    """``LAT,LON,ALT`` (degrees, degrees, metres above mean sea level) to the station's frame.

    Raises
    ------
    ValueError
        If it is not three finite numbers with a valid latitude.
    """
    parts = text.split(",")
    if len(parts) != 3:
        raise ValueError(f"station must be LAT,LON,ALT (deg, deg, m MSL), got {text!r}")
    lat, lon, alt = (float(p) for p in parts)
    if not all(math.isfinite(x) for x in (lat, lon, alt)) or abs(lat) > 90.0:
        raise ValueError(f"station out of range: {text!r}")
    return LocalFrame(math.radians(lat), math.radians(lon), alt)


async def watch_once(url: str, duration_s: float, model: ConsoleModel) -> None:
    """Listen until a solution and a status value are heard, or ``duration_s`` passes."""
    parser = FrameParser()
    link = await open_link(url)
    t_end = time.monotonic() + duration_s
    try:
        while (remaining := t_end - time.monotonic()) > 0.0:
            try:
                data = await asyncio.wait_for(link.recv(), timeout=min(POLL_S, remaining))
            except asyncio.TimeoutError:
                continue
            now = time.time()
            for msg in parser.feed(data):
                model.take(msg, now)
            if model.lat_deg is not None and model.values:
                break
    finally:
        await link.close()


def run_console(
    url: str,
    once: bool = False,
    duration_s: float | None = None,
    as_json: bool = False,
    station: str | None = None,
    web_port: int | None = None,
    web_url: str | None = None,
    tracker_out: str | None = None,
) -> int:
    """``companion console``; returns the exit status."""
    try:
        frame = None if station is None else parse_station(station)
    except ValueError as exc:
        print(f"companion console: {exc}", file=sys.stderr)
        return 1
    if tracker_out is not None and frame is None:
        print("companion console: --tracker-out needs --station", file=sys.stderr)
        return 1
    model = ConsoleModel(station=frame)
    if once or as_json:
        try:
            asyncio.run(watch_once(url, duration_s or ONCE_DURATION_S, model))
        except LinkError as exc:
            print(f"companion console: cannot open {url}: {exc}", file=sys.stderr)
            return 1
        except KeyboardInterrupt:
            return 0
        now = time.time()
        print(json.dumps(model.snapshot(now), indent=1) if as_json else model.render(now))
        return 0 if model.messages else 1
    try:
        from companion.console.app import ConsoleApp
    except ImportError as exc:
        print(
            f"companion console: {exc.name} is missing: pip install 'companion[console]'",
            file=sys.stderr,
        )
        return 1
    if web_port is not None:
        return _serve(url, station, web_port, web_url, tracker_out)
    app = ConsoleApp(url, model, tracker_out=tracker_out)
    app.run()
    return 0


def _serve(
    url: str, station: str | None, port: int, public_url: str | None, tracker_out: str | None
) -> int:
    """The same app in a browser: textual-serve runs ``companion console`` per session.

    ``public_url`` is the address the browser reaches this machine by (the page opens
    its websocket there): ``http://localhost:PORT`` unless given.
    """
    try:
        from textual_serve.server import Server
    except ImportError:
        print(
            "companion console: --web needs textual-serve: pip install 'companion[console]'",
            file=sys.stderr,
        )
        return 1
    cmd = [sys.executable, "-m", "companion", "console", "--master", url]
    if station is not None:
        cmd += ["--station", station]
    if tracker_out is not None:
        cmd += ["--tracker-out", tracker_out]
    Server(
        shlex.join(cmd),
        host="0.0.0.0",
        port=port,
        title="companion console",
        public_url=public_url or f"http://localhost:{port}",
    ).serve()
    return 0

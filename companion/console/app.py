"""Ground-station console: a terminal view of what the service publishes.

``companion console --master udpin:0.0.0.0:14551`` listens on a MAVLink link
(the GCS side of the autopilot, or the service's own ``--gcs`` link), keeps
only the service's messages (component 191) and redraws a status screen twice
a second: position and accuracy, the navigation mode and outage time, the
protection levels against what the service publishes, the heading correction,
and the latest ``CMP`` alerts with their severity. The messages are read back
with :mod:`companion.mavlink.readback`, as ``companion evaluate`` reads them.

``--once`` prints one screen after the first published solution (or after
``--duration``) and exits: handy in scripts and tests.
"""

from __future__ import annotations

import asyncio
import math
import sys
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any

from companion.mavlink.framing import FrameParser
from companion.mavlink.link import LinkError, open_link
from companion.mavlink.readback import (
    PublishedFix,
    PublishedHeartbeat,
    PublishedPosition,
    PublishedText,
    from_service,
    read_message,
)
from companion.nav.heading import HeadingStatus
from companion.types import NamedValue, Severity

REDRAW_S = 0.5
SEVERITY_NAMES: dict[int, str] = {
    Severity.EMERGENCY: "EMERG",
    Severity.ALERT: "ALERT",
    Severity.CRITICAL: "CRIT",
    Severity.ERROR: "ERROR",
    Severity.WARNING: "WARN",
    Severity.NOTICE: "NOTICE",
    Severity.INFO: "INFO",
    Severity.DEBUG: "DEBUG",
}
"""Short names of the STATUSTEXT severities on the screen."""
FIX_NAMES = ("no GPS", "no fix", "2D", "3D", "DGPS", "RTK float", "RTK fixed", "static", "PPP")


@dataclass(slots=True)
class ConsoleState:
    """What the console knows of the service, from its messages."""

    lat_deg: float | None = None
    lon_deg: float | None = None
    alt_msl_m: float | None = None
    speed_mps: float | None = None
    hdg_deg: float | None = None
    fix_type: int | None = None
    values: dict[str, float] = field(default_factory=dict)
    alerts: deque[tuple[float, str, str]] = field(default_factory=lambda: deque(maxlen=8))
    heartbeats: int = 0
    messages: int = 0
    last_rx_s: float | None = None

    def take(self, msg: Any, t_rx_s: float) -> bool:
        """Update from one message; False if it is not the service's."""
        if not from_service(msg):
            return False
        self.messages += 1
        self.last_rx_s = t_rx_s
        item = read_message(msg)
        if isinstance(item, PublishedPosition):
            self.lat_deg = math.degrees(item.lat_rad)
            self.lon_deg = math.degrees(item.lon_rad)
            self.alt_msl_m = item.alt_msl_m
            self.speed_mps = math.hypot(item.vel_ned_mps[0], item.vel_ned_mps[1])
            self.hdg_deg = None if item.yaw_rad is None else math.degrees(item.yaw_rad)
        elif isinstance(item, PublishedFix):
            self.fix_type = item.fix_type
        elif isinstance(item, NamedValue):
            self.values[item.name] = item.value
        elif isinstance(item, PublishedText):
            sev = SEVERITY_NAMES.get(item.severity, "?")
            self.alerts.append((t_rx_s, sev, item.text))
        elif isinstance(item, PublishedHeartbeat):
            self.heartbeats += 1
        return True

    def render(self, now_s: float) -> str:
        """The status screen as text."""
        v = self.values
        lines = ["companion console" + _age(self.last_rx_s, now_s), ""]
        if self.lat_deg is None:
            lines.append("no solution published yet")
        else:
            lines.append(
                f"position  {self.lat_deg:11.7f} {self.lon_deg:12.7f}  "
                f"alt {self.alt_msl_m:8.1f} m MSL"
            )
            hdg = "—" if self.hdg_deg is None else f"{self.hdg_deg:6.1f}°"
            lines.append(f"speed     {self.speed_mps:6.1f} m/s   heading {hdg}")
        fix = FIX_NAMES[self.fix_type] if self.fix_type is not None and self.fix_type < 9 else "—"
        lines.append(
            f"fix       {fix:<10} accuracy H {_val(v, 'CMP_HACC')} V {_val(v, 'CMP_VACC')} m (1σ)"
        )
        lines.append(
            f"outage    {_val(v, 'CMP_OUTG')} s   protection HPL {_val(v, 'CMP_HPL')} "
            f"VPL {_val(v, 'CMP_VPL')} m   category {_val(v, 'CMP_CAT', '.0f')}"
        )
        lines.append(
            f"heading   correction {_val(v, 'CMP_HDGC', '.2f')}° ± {_val(v, 'CMP_HDGE', '.2f')}°"
            f"   {_heading_state(v)}"
        )
        lines += ["", "alerts:"]
        if not self.alerts:
            lines.append("  (none)")
        for t, sev, text in reversed(self.alerts):
            lines.append(f"  {time.strftime('%H:%M:%S', time.gmtime(t))} {sev:<6} {text}")
        return "\n".join(lines)


def _heading_state(values: dict[str, float]) -> str:
    """``CMP_HDGS`` by name (docs/mavlink.md), ``—`` before the first."""
    code = values.get("CMP_HDGS")
    if code is None:
        return "—"
    try:
        return HeadingStatus(int(code)).name.lower()
    except ValueError:
        return f"state {code:g}"


def _val(values: dict[str, float], name: str, fmt: str = ".2f") -> str:
    return format(values[name], fmt) if name in values else "—"


def _age(last_rx_s: float | None, now_s: float) -> str:
    if last_rx_s is None:
        return "  (waiting for the service)"
    age = now_s - last_rx_s
    return "" if age < 3.0 else f"  (silent for {age:.0f} s)"


async def watch(url: str, once: bool = False, duration_s: float | None = None) -> ConsoleState:
    """Listen on ``url`` and redraw the screen until stopped (or once)."""
    state = ConsoleState()
    parser = FrameParser()
    link = await open_link(url)
    interactive = sys.stdout.isatty() and not once
    t_end = None if duration_s is None else time.monotonic() + duration_s
    next_draw = 0.0
    try:
        while t_end is None or time.monotonic() < t_end:
            try:
                data = await asyncio.wait_for(link.recv(), timeout=REDRAW_S)
            except asyncio.TimeoutError:
                data = b""
            now = time.time()
            for msg in parser.feed(data):
                state.take(msg, now)
            if once and state.lat_deg is not None:
                break
            if interactive and time.monotonic() >= next_draw:
                next_draw = time.monotonic() + REDRAW_S
                sys.stdout.write("\x1b[H\x1b[2J" + state.render(now) + "\n")
                sys.stdout.flush()
    finally:
        await link.close()
    return state


def run_console(url: str, once: bool = False, duration_s: float | None = None) -> int:
    """Entry point of ``companion console``; returns the exit status."""
    try:
        state = asyncio.run(watch(url, once, duration_s))
    except LinkError as exc:
        print(f"companion console: cannot open {url}: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 0
    print(state.render(time.time()))
    return 0 if state.messages else 1

"""Is the autopilot link carrying MAVLink? A warning when no autopilot HEARTBEAT arrives.

A serial link at the wrong baud rate, or a port that carries something other than
MAVLink (NMEA, a console), delivers bytes that never make a frame: the service would
wait silently for an autopilot that is there. :class:`HeartbeatWatch` counts what a
link delivers (bytes, good frames, bad regions and their bytes) and, when no autopilot
HEARTBEAT has arrived for ``timeout_s``, says so once, with those counts and the likely
cause, then every ``repeat_s`` until one arrives (then once that it did). It restarts
after every HEARTBEAT, so a link that stops carrying the autopilot later is reported
the same way.

No I/O and no clock: the driver passes its receive time ``t_rx_s`` with every call and
asks :meth:`HeartbeatWatch.next_due_s` when to call :meth:`HeartbeatWatch.check`; the
driver logs the lines returned.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(slots=True)
class LinkCounts:
    """What a link delivered since the watch's window began."""

    bytes_in: int = 0
    frames: int = 0
    """Good MAVLink frames (CRC passed)."""
    bad_frames: int = 0
    """Bad regions: runs of bytes between good frames that are not a frame."""
    bad_bytes: int = 0
    """Bytes in those regions (not MAVLink)."""


class HeartbeatWatch:
    """Warn when a link goes ``timeout_s`` without an autopilot HEARTBEAT.

    Parameters
    ----------
    name
        The link's name and URL, as the warning shows it (``"master udpin:..."``).
    timeout_s
        Silence (no autopilot HEARTBEAT) before the first warning, s.
    repeat_s
        Interval of the warnings that follow while the silence lasts, s.
    """

    def __init__(self, name: str, timeout_s: float, repeat_s: float) -> None:
        if not (timeout_s > 0.0 and repeat_s > 0.0):
            raise ValueError("timeout_s and repeat_s must be > 0")
        self.name = name
        self.timeout_s = timeout_s
        self.repeat_s = repeat_s
        self.counts = LinkCounts()
        self.warnings = 0
        """Warnings issued (all windows)."""
        self.heartbeats = 0
        self._since_s: float | None = None
        self._next_due_s = math.inf
        self._warned = False
        self._ever = False

    def start(self, t_rx_s: float) -> None:
        """The link opened at ``t_rx_s``: start the window unless one is running."""
        if self._since_s is None:
            self._since_s = t_rx_s
            self._next_due_s = t_rx_s + self.timeout_s

    def received(
        self, n_bytes: int, frames: int = 0, bad_frames: int = 0, bad_bytes: int = 0
    ) -> None:
        """Count what one read delivered (bytes, good frames, bad regions, their bytes)."""
        c = self.counts
        c.bytes_in += n_bytes
        c.frames += frames
        c.bad_frames += bad_frames
        c.bad_bytes += bad_bytes

    def heartbeat(self, t_rx_s: float) -> str | None:
        """An autopilot HEARTBEAT arrived: restart the window. Returns the line to log
        (info) when it ends a silence that was warned about, else None."""
        self.heartbeats += 1
        line = None
        if self._warned and self._since_s is not None:
            line = f"autopilot heartbeat on {self.name} after {t_rx_s - self._since_s:.0f} s"
        self._ever = True
        self._warned = False
        self._since_s = t_rx_s
        self._next_due_s = t_rx_s + self.timeout_s
        self.counts = LinkCounts()
        return line

    def next_due_s(self) -> float:
        """When :meth:`check` may next have something to say (``inf``: not started)."""
        return self._next_due_s

    def check(self, t_rx_s: float) -> str | None:
        """The warning due at ``t_rx_s``, if any (None when early or not started)."""
        if self._since_s is None or t_rx_s < self._next_due_s:
            return None
        silent_s = t_rx_s - self._since_s
        self._warned = True
        self.warnings += 1
        self._next_due_s = t_rx_s + self.repeat_s
        c = self.counts
        what = "after" if not self._ever else "for"
        head = f"no autopilot heartbeat on {self.name} {what} {silent_s:.0f} s: "
        if c.bytes_in == 0:
            return head + "nothing received (wiring, or the autopilot does not send here?)"
        got = (
            f"{c.bytes_in} bytes, {c.frames} good frames, {c.bad_frames} bad "
            f"({c.bad_bytes} bytes not MAVLink)"
        )
        # mostly noise: at a wrong baud rate a rare frame still passes its CRC by chance
        if c.frames == 0 or 2 * c.bad_bytes > c.bytes_in:
            return head + got + ": wrong baud rate or not MAVLink?"
        return head + got + ": MAVLink, but no autopilot (wrong port or system id?)"

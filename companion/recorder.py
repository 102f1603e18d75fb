"""Flight recorder: every message in and out, as a .tlog.

One file per service start, named by its UTC start time, in the configured
folder. Records are flushed at least once a second so that a crash or power
loss costs at most the last second; nothing already recorded is lost.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

from companion.mavlink.tlog import TlogWriter

log = logging.getLogger(__name__)

FLUSH_PERIOD_S = 1.0


class Recorder:
    """Append raw MAVLink frames with their receive/send time to a .tlog."""

    def __init__(self, folder: Path, start_wall_s: float) -> None:
        folder.mkdir(parents=True, exist_ok=True)
        stamp = time.strftime("%Y%m%d-%H%M%S", time.gmtime(start_wall_s))
        self.path = folder / f"companion-{stamp}.tlog"
        n = 1
        while self.path.exists():
            self.path = folder / f"companion-{stamp}-{n}.tlog"
            n += 1
        self._writer = TlogWriter(self.path)
        self._last_flush_s = start_wall_s
        self.records = 0
        log.info("recording to %s", self.path)

    def record(self, t_s: float, frame: bytes) -> None:
        """Append one frame (``t_s`` UNIX-epoch seconds)."""
        self._writer.write(t_s, frame)
        self.records += 1
        if t_s - self._last_flush_s >= FLUSH_PERIOD_S:
            self._writer.flush()
            self._last_flush_s = t_s

    def close(self) -> None:
        """Flush and close."""
        self._writer.close()

"""Whole-stream silence and no GNSS at all: what the navigation says when its inputs stop.

Two states, both on the autopilot clock (``t_s``; during a silence the drivers give
the engine their estimate of it, :meth:`companion.engine.Engine.on_clock`):

* **silent**: no navigation data (IMU, attitude or GNSS sample) for
  ``silence_timeout_s``, or, for a slow link whose samples come with longer pauses
  (a ground station's 1 Hz telemetry), ``silence_intervals`` times the longest pause
  among its last :data:`DATA_INTERVALS_KEPT` that was not itself a silence, at most
  ``silence_timeout_max_s``: a pause normal for the link is no silence and restarts
  nothing; nor shorter than the GNSS timeout in force for a slow receiver
  (:mod:`companion.nav.fix_rate`): ``NO_DATA`` then says the GNSS loss too.
  ``NO_DATA`` is raised once when it starts (the autopilot may still send its
  HEARTBEAT: a stopped stream is not a dead autopilot); the first data sample after
  it ends it with ``DATA_BACK`` and the engine restarts its navigation from the next
  usable fix (nothing is carried across a silence).
* **no GNSS**: the navigation has not started (no usable fix fused) ``no_gnss_alert_s``
  after the first sample of this boot (or after a silence): ``NO_GNSS``, repeated
  every ``no_gnss_repeat_s`` while it lasts; ``GNSS_BACK`` when the first fix starts
  the navigation after it was announced.

Pure: no I/O, no clock. :meth:`StreamWatch.next_due_s` says when :meth:`StreamWatch.tick`
next has something to raise, so a driver can call it during a silence exactly then.
"""

from __future__ import annotations

import math
from collections import deque

from companion.types import Alert, AlertCode, Severity

DATA_INTERVALS_KEPT = 200
"""Pauses between data samples (about a minute of a 1 Hz link's few streams) whose
longest sets the silence timeout."""


class StreamWatch:
    """The silence and no-GNSS states of one autopilot boot (see the module docstring)."""

    def __init__(
        self,
        silence_timeout_s: float,
        no_gnss_alert_s: float,
        no_gnss_repeat_s: float,
        silence_intervals: float = 1.0,
        silence_timeout_max_s: float = 0.0,
    ) -> None:
        self.silence_timeout_s = silence_timeout_s
        self.silence_intervals = silence_intervals
        self.silence_timeout_max_s = silence_timeout_max_s
        self._n_pauses = 0
        self._longest_queue: deque[tuple[int, float]] = deque()
        self._timeout_s = silence_timeout_s
        self._longest_s = 0.0
        self.gnss_timeout_s = 0.0
        """The GNSS timeout in force when the link is slow (0 otherwise): the silence
        timeout is never shorter, GNSS being one of the link's streams."""
        self.no_gnss_alert_s = no_gnss_alert_s
        self.no_gnss_repeat_s = no_gnss_repeat_s
        self.last_data_t_s: float | None = None
        """Time of the newest navigation data sample (s, autopilot clock)."""
        self.silent = False
        """True from ``NO_DATA`` until the next data sample."""
        self._wait_start_t_s: float | None = None
        """Start of the wait for a first usable fix (first sample, or the end of a silence);
        None once the navigation runs."""
        self.no_gnss_due_s = math.inf
        """When ``NO_GNSS`` is next due (autopilot clock, s; inf: not waiting)."""
        self.no_gnss_announced = 0
        """``NO_GNSS`` alerts raised since the wait started (0: none)."""
        self.started = False
        """:meth:`start` was called (the boot's first sample was seen)."""
        self.waiting = False
        """Waiting for a first usable fix (the navigation has not started)."""

    # ------------------------------------------------------------------ inputs

    def start(self, t_s: float) -> None:
        """The first sample of this boot, at ``t_s``: the wait for a first fix starts."""
        self.started = True
        self._start_wait(t_s)

    def gap_s(self, t_s: float) -> float:
        """Seconds since the newest data sample (0 before the first)."""
        last = self.last_data_t_s
        return 0.0 if last is None else t_s - last

    def on_data(self, t_s: float) -> float | None:
        """A navigation data sample at ``t_s``. Returns the length of the silence it ends
        (s; a gap of at least ``silence_timeout_s``, announced or not), else None."""
        gap = self.gap_s(t_s)
        ended = self.silent or (self.last_data_t_s is not None and gap >= self.timeout_s)
        if self.last_data_t_s is None or t_s > self.last_data_t_s:
            if self.last_data_t_s is not None and not ended:
                self._pause(gap)
            self.last_data_t_s = t_s
        if not ended:
            return None
        self.silent = False
        return gap

    @property
    def timeout_s(self) -> float:
        """The silence timeout in force (s; see the module docstring)."""
        return max(self._timeout_s, self.gnss_timeout_s)

    def _pause(self, gap_s: float) -> None:
        """A pause between data samples that was no silence: the timeout follows the
        longest of the last :data:`DATA_INTERVALS_KEPT` (a sliding maximum: a queue of
        the pauses not shorter than any after them)."""
        cap = self.silence_timeout_max_s
        if cap <= self.silence_timeout_s:
            return
        n = self._n_pauses
        self._n_pauses = n + 1
        queue = self._longest_queue
        while queue and queue[-1][1] <= gap_s:
            queue.pop()
        queue.append((n, gap_s))
        if queue[0][0] <= n - DATA_INTERVALS_KEPT:
            queue.popleft()
        longest = queue[0][1]
        if longest == self._longest_s:
            return
        self._longest_s = longest
        self._timeout_s = max(self.silence_timeout_s, min(cap, self.silence_intervals * longest))

    def keep_pauses(self, other: StreamWatch) -> None:
        """Take ``other``'s recent pauses and timeout: the link's, not one boot's."""
        self._n_pauses = other._n_pauses
        self._longest_queue = deque(other._longest_queue)
        self._longest_s = other._longest_s
        self._timeout_s = max(self.silence_timeout_s, other._timeout_s)

    def restarted(self, t_s: float) -> None:
        """The navigation restarted at ``t_s`` (after a silence): wait for a first fix again."""
        self.no_gnss_announced = 0
        self._start_wait(t_s)

    def navigating(self, t_s: float) -> list[Alert]:
        """The navigation runs (a fix was fused): the wait is over; ``GNSS_BACK`` if it
        was announced as ``NO_GNSS``."""
        start = self._wait_start_t_s
        self.waiting = False
        if start is None:
            return []
        announced = self.no_gnss_announced
        self._wait_start_t_s = None
        self.no_gnss_due_s = math.inf
        self.no_gnss_announced = 0
        if not announced:
            return []
        text = f"first fix after {t_s - start:.1f} s: navigating"
        return [Alert(t_s, AlertCode.GNSS_BACK, Severity.NOTICE, text)]

    # ------------------------------------------------------------------ clock

    def next_due_s(self) -> float:
        """When :meth:`tick` next raises something (autopilot clock, s; inf: nothing due)."""
        due = self.no_gnss_due_s
        last = self.last_data_t_s
        if last is not None and not self.silent:
            due = min(due, last + self.timeout_s)
        return due

    def tick(self, t_s: float) -> list[Alert]:
        """Advance to ``t_s``: ``NO_DATA`` when the data stopped, ``NO_GNSS`` when due."""
        alerts: list[Alert] = []
        last = self.last_data_t_s
        if not self.silent and last is not None and t_s - last >= self.timeout_s:
            self.silent = True
            text = f"no IMU, attitude, GNSS for {t_s - last:.1f} s"
            alerts.append(Alert(t_s, AlertCode.NO_DATA, Severity.CRITICAL, text))
        if t_s >= self.no_gnss_due_s and self._wait_start_t_s is not None:
            waited = t_s - self._wait_start_t_s
            self.no_gnss_announced += 1
            self.no_gnss_due_s = t_s + self.no_gnss_repeat_s
            text = f"no usable fix for {waited:.0f} s: not navigating"
            alerts.append(Alert(t_s, AlertCode.NO_GNSS, Severity.CRITICAL, text))
        return alerts

    def _start_wait(self, t_s: float) -> None:
        self.waiting = True
        self._wait_start_t_s = t_s
        self.no_gnss_due_s = t_s + self.no_gnss_alert_s

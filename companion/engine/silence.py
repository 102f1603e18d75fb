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
* **stalled**: when the GNSS loss falls due while every stream has been quiet longer
  than any of the link's recent pauses and longer than the receiver's usual interval
  between fixes (:meth:`StreamWatch.stalled`), the fixes are missing because
  everything is: the silence starts then, said by ``NO_DATA`` instead of the loss
  (:meth:`StreamWatch.announce`), so that a whole-stream dropout is one alert and one
  return (``DATA_BACK``) within the GNSS timeout, not ``GNSS_LOST``, ``NO_DATA`` and
  ``DATA_BACK``.
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


class SlidingMax:
    """The largest of the last ``size`` values pushed (0 before any): a queue of the
    values not smaller than any pushed after them, with their order numbers."""

    __slots__ = ("size", "_n", "_queue")

    def __init__(self, size: int) -> None:
        self.size = size
        self._n = 0
        self._queue: deque[tuple[int, float]] = deque()

    def push(self, value: float) -> float:
        """Keep ``value``; the largest of the last ``size``."""
        n = self._n
        self._n = n + 1
        queue = self._queue
        while queue and queue[-1][1] <= value:
            queue.pop()
        queue.append((n, value))
        if queue[0][0] <= n - self.size:
            queue.popleft()
        return queue[0][1]

    @property
    def value(self) -> float:
        """The largest of the last ``size`` values (0 before any)."""
        return self._queue[0][1] if self._queue else 0.0

    @property
    def full(self) -> bool:
        """``size`` values were pushed: :attr:`value` is over a whole window."""
        return self._n >= self.size

    def copy(self) -> SlidingMax:
        """An independent copy."""
        other = SlidingMax(self.size)
        other._n = self._n
        other._queue = deque(self._queue)
        return other


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
        self._pauses = SlidingMax(DATA_INTERVALS_KEPT)
        """Pauses between data samples' times that were no silence (autopilot clock)."""
        self._arrival_pauses = SlidingMax(DATA_INTERVALS_KEPT)
        """... and between their arrivals (the driver's clock, on which a silence is
        watched: a link that delivers in bursts pauses longer there)."""
        self._last_rx_s: float | None = None
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
        """True from ``NO_DATA`` until the next data sample (which restarts the
        navigation, however short the silence was)."""
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

    def on_data(self, t_s: float, t_rx_s: float | None = None) -> float | None:
        """A navigation data sample at ``t_s``, received at ``t_rx_s`` (the driver's clock,
        s; None: unknown). Returns the length of the silence it ends (s; one announced by
        ``NO_DATA``, or a gap of at least the timeout, announced or not), else None."""
        gap = self.gap_s(t_s)
        ended = self.silent or (self.last_data_t_s is not None and gap >= self.timeout_s)
        if self.last_data_t_s is None or t_s > self.last_data_t_s:
            if self.last_data_t_s is not None and not ended:
                self._pause(gap)
            self.last_data_t_s = t_s
        last_rx = self._last_rx_s
        if t_rx_s is not None and (last_rx is None or t_rx_s > last_rx):
            if last_rx is not None and not ended:
                self._arrival_pauses.push(t_rx_s - last_rx)
            self._last_rx_s = t_rx_s
        if not ended:
            return None
        self.silent = False
        return gap

    @property
    def timeout_s(self) -> float:
        """The silence timeout in force (s; see the module docstring)."""
        return max(self._timeout_s, self.gnss_timeout_s)

    def _pause(self, gap_s: float) -> None:
        """A pause between data samples that was no silence: kept as the longest of the
        last :data:`DATA_INTERVALS_KEPT` (a sliding maximum: a queue of the pauses not
        shorter than any after them), which the timeout follows."""
        longest = self._pauses.push(gap_s)
        if longest == self._longest_s:
            return
        self._longest_s = longest
        cap = self.silence_timeout_max_s
        if cap > self.silence_timeout_s:
            self._timeout_s = max(
                self.silence_timeout_s, min(cap, self.silence_intervals * longest)
            )

    def stalled(self, t_s: float, fix_interval_s: float) -> bool:
        """Has every stream been quiet at ``t_s`` longer than any of the link's last
        :data:`DATA_INTERVALS_KEPT` pauses (between the samples' times and between their
        arrivals) and than ``fix_interval_s`` (the receiver's usual interval between
        fixes, s)? A GNSS loss due then is the stream's, not the receiver's: the
        receiver's fixes stopped with everything else. False until a whole window of
        pauses was seen: before, the link's usual pauses (a radio's delivery bursts)
        are not known."""
        last = self.last_data_t_s
        if last is None or self.silent:
            return False
        pauses, arrivals = self._pauses, self._arrival_pauses
        if not (pauses.full and (arrivals.full or self._last_rx_s is None)):
            return False
        usual = max(pauses.value, arrivals.value, fix_interval_s)
        return t_s - last > usual

    def announce(self, t_s: float) -> Alert:
        """The silence starts at ``t_s``: ``NO_DATA`` (the first data sample after it
        ends it, :meth:`on_data`)."""
        self.silent = True
        text = f"no IMU, attitude, GNSS for {self.gap_s(t_s):.1f} s"
        return Alert(t_s, AlertCode.NO_DATA, Severity.CRITICAL, text)

    def keep_pauses(self, other: StreamWatch) -> None:
        """Take ``other``'s recent pauses and timeout: the link's, not one boot's."""
        self._pauses = other._pauses.copy()
        self._arrival_pauses = other._arrival_pauses.copy()
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
            alerts.append(self.announce(t_s))
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

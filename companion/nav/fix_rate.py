"""The rhythm of a receiver's fixes: is it slow and irregular, and when is a fix late?

A receiver read through a telemetry radio or a ground station's recording delivers its
fixes at about 1 Hz with jitter (intervals from 0.6 s to 3 s on a real recording): a
fixed GNSS timeout of five missed 5 Hz epochs turns every long interval into a loss
and a return. This keeps, per fix, the silence the outage clock saw before the fix
arrived (its *lateness*: the newest sample time at its arrival, or its own time if
later, less the previous fix's time), and from the last :data:`LATENESS_KEPT` of them
below ``slow_max_interval_s`` (longer ones are outages, not the link's rhythm)

* says whether the receiver is **slow**: the median lateness above ``slow_enter_s``
  (entered once, announced once: ``GNSS_SLOW``), and regular again only once it is
  below ``slow_leave_s`` (``GNSS_STEADY``): hysteresis, no flapping;
* gives the **longest** recent lateness, from which the outage monitor's timeout in
  the slow state is made (a fix is late when it is later than anything the link did
  recently, by a margin).

Compare ArduPilot's AP_GPS, which measures a receiver's average fix interval and
reports a slow one as unhealthy once, as a state, not per fix.

Pure: no I/O, no clock; time comes from the samples.
"""

from __future__ import annotations

import statistics
from collections import deque
from dataclasses import dataclass, field

LATENESS_KEPT = 60
"""Fix arrivals (about a minute at 1 Hz) whose lateness makes the rhythm."""
MIN_LATENESS_KEPT = 8
"""Arrivals before a rhythm is judged at all."""


@dataclass(slots=True)
class FixRhythm:
    """The lateness of the last fixes and the slow state (see the module docstring).
    It belongs to the link, not to one navigation: it is kept across restarts."""

    slow: bool = False
    _lateness_s: deque[float] = field(default_factory=lambda: deque(maxlen=LATENESS_KEPT))

    def on_fix(
        self, lateness_s: float, enter_s: float, leave_s: float, max_interval_s: float
    ) -> bool | None:
        """A fix arrived ``lateness_s`` after the previous one (newest sample time at
        its arrival, or its own, less the previous fix's time). Slow when the median
        lateness passes ``enter_s``, regular again below ``leave_s``; a lateness of
        ``max_interval_s`` or more is an outage and not kept. Returns the new slow
        state when it changed, else None."""
        if not 0.0 < lateness_s < max_interval_s:
            return None
        self._lateness_s.append(lateness_s)
        if len(self._lateness_s) < MIN_LATENESS_KEPT:
            return None
        median = statistics.median(self._lateness_s)
        if not self.slow and median > enter_s:
            self.slow = True
            return True
        if self.slow and median < leave_s:
            self.slow = False
            return False
        return None

    @property
    def median_s(self) -> float:
        """Median recent lateness (s; 0 before any)."""
        return statistics.median(self._lateness_s) if self._lateness_s else 0.0

    @property
    def longest_s(self) -> float:
        """Longest recent lateness (s; 0 before any)."""
        return max(self._lateness_s) if self._lateness_s else 0.0

    def clear(self) -> None:
        """Forget the rhythm (autopilot reboot)."""
        self._lateness_s.clear()
        self.slow = False

"""A vertical motion prior from the vehicle's own recent GNSS heights, for a GNSS gap.

Without a barometer nothing but the INS carries the height through a gap, and the INS's
vertical (the integral of the vertical specific force less gravity) drifts as its
accelerometer's error does. The fused fixes of the last ``window_s`` say how far the
vehicle's height moved over a time like the gap's: the mean square of the height
changes over lag ``tau`` in that window, ``m(tau)``, is the error of holding the last
fixed height for ``tau``. Taken at its upper confidence bound (about ``span / tau``
independent lags: chi-square), it is the variance of a prediction of the height's change
through the gap: none. The INS's height at the gap's start carries the error the last
fixes' does (one estimate), so what is combined is the change: the INS's change since the
gap's start (variance: the growth of its variance) and the prediction's, by their
variances, while the two agree (chi-square, 1 dof, at ``false_alarm_prob``); after the
first disagreement, and beyond lags the window cannot measure, the INS alone to the
gap's end. A vehicle that starts to climb or descend in the gap (an approach) takes its
INS beyond the test's bound within a few sigmas of the change: the INS wins; one that was
climbing or descending in the window gets a wide prediction that weighs little.

Pure: no I/O, no clock; time is the fixes' ``t_s``. Heights are local NED down
positions (m).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2


@dataclass(frozen=True)
class VerticalPriorConfig:
    window_s: float = 60.0
    """Fused fixes kept, s: the recent motion the prediction's spread is measured on."""
    confidence: float = 0.95
    """The mean square height change is taken at this upper confidence bound."""
    false_alarm_prob: float = 1e-3
    """Probability that an INS and prediction that agree fail the consistency test."""
    min_lags: float = 1.0
    """No prediction for a lag the window holds fewer independent copies of than this."""


class VerticalPrior:
    """The last fix's height as a prediction through a gap, with the spread of recent
    height changes as its variance (module docstring)."""

    def __init__(self, config: VerticalPriorConfig | None = None) -> None:
        self.config = config or VerticalPriorConfig()
        self._threshold = float(chi2.isf(self.config.false_alarm_prob, 1))
        self._fixes: deque[tuple[float, float, float]] = deque()
        """(t_s, down m, its variance m^2) of the fused fixes within ``window_s``."""
        self._gap: tuple[np.ndarray, np.ndarray] | None = None
        """The fixes' times and heights frozen at the gap's start."""
        self._cache: dict[float, float] = {}
        self._anchor: tuple[float, float] | None = None
        """The INS's down position and variance at the gap's first combination."""
        self.disagrees = False
        """The INS and the prediction failed their consistency test in this gap."""

    def add_fix(self, t_s: float, pos_d_m: float, var_d_m2: float) -> None:
        """A fused fix (ends any gap)."""
        self._gap = None
        if not all(map(math.isfinite, (t_s, pos_d_m, var_d_m2))):
            return
        fixes = self._fixes
        if fixes and t_s <= fixes[-1][0]:
            return
        fixes.append((t_s, pos_d_m, max(var_d_m2, 0.0)))
        while fixes and t_s - fixes[0][0] > self.config.window_s:
            fixes.popleft()

    def restart(self) -> None:
        """Forget the fixes (a new frame or a restarted navigation)."""
        self._fixes.clear()
        self._gap = None

    def change_var(self, t_s: float) -> float | None:
        """The variance of the vehicle's height change from the last fix to ``t_s`` (m^2:
        the upper bound of the window's mean square change over that lag), or None
        without enough history for the lag."""
        if len(self._fixes) < 3:
            return None
        if self._gap is None:
            self._gap = (
                np.array([f[0] for f in self._fixes]),
                np.array([f[1] for f in self._fixes]),
            )
            self._cache = {}
            self._anchor = None
            self.disagrees = False
        t, d = self._gap
        lag = t_s - float(t[-1])
        if lag <= 0.0:
            return 0.0
        lags = float(t[-1] - t[0]) / lag
        if lags < self.config.min_lags:
            return None
        key = round(lag, 2)
        ms = self._cache.get(key)
        if ms is None:
            starts = t[t + lag <= t[-1]]
            change = np.interp(starts + lag, t, d) - d[: len(starts)]
            dof = max(1.0, lags)  # independent lags in the window (chi-square)
            bound = dof / float(chi2.ppf(1.0 - self.config.confidence, dof))
            ms = float(np.mean(change * change)) * bound
            self._cache[key] = ms
        return ms

    def combine(self, t_s: float, pos_d_m: float, var_d_m2: float) -> tuple[float, float] | None:
        """The INS's down position and variance at ``t_s`` combined with the prediction,
        or None (the INS alone): no prediction, or the two disagree (for the rest of the
        gap once they have).

        The INS's height at the gap's first call is the anchor both share: its error is
        common to them (the INS's and the last fixes' heights are one estimate there), so
        only the INS's change since then (variance: its variance's growth) is combined
        with the prediction's (no change; variance :meth:`change_var`)."""
        var_change = self.change_var(t_s)
        if var_change is None or self.disagrees or not (var_d_m2 >= 0.0):
            return None
        if self._anchor is None:
            self._anchor = (pos_d_m, var_d_m2)
        d0, var0 = self._anchor
        growth = var_d_m2 - var0
        if growth <= 0.0:
            return None
        move = pos_d_m - d0
        if move * move > self._threshold * (growth + var_change):
            self.disagrees = True
            return None
        w = growth / (growth + var_change)
        return pos_d_m - w * move, var0 + growth * var_change / (growth + var_change)

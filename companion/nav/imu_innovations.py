"""Does the IMU match the grade it was configured with, in flight? The blend's GNSS
innovations against what that grade predicts.

Between two fixes the blend carries its state on the IMU; the innovation of the next fix
is that prediction's error plus the receiver's, and its covariance ``S = H P H^T + R``
is what the configured grade (``P`` grows with the grade's noise and biases) and the
receiver's reported accuracy (``R``) say it should be. With both right the normalised
innovation squared ``NIS = y^T S^-1 y`` of a fix with ``m`` components is ``chi2(m)``,
and over a window of fixes (nearly independent: the state is corrected at every fix)
``sum NIS`` is about ``chi2(sum m)``. An IMU noisier than its grade, in white noise or
in bias instability and random walk (which the white-noise test of
:mod:`companion.nav.imu_check` cannot see), makes the predictions worse than ``P``
says, and ``sum NIS / sum m`` stays above 1 window after window.

So the ratio ``r = sum NIS / sum m`` of windows of ``window_s`` is held against the
chi-square bound ``chi2^-1(1 - false_alarm_prob, sum m) / sum m`` and a margin
``min_ratio`` (what the NIS of a correct configuration reaches on real flights for
reasons that are not the IMU: the receivers' correlated errors, vibration); the grade
is doubted when ``windows_needed`` of the last ``windows_span`` windows exceed both.
Only fixes of a receiver that is self-consistent (its position increments agree with
its own velocity, :mod:`companion.nav.receiver_checks`) count: then a large innovation
is the prediction's error, not the receiver's. One fix adds at most ``cap`` (the
blend's gate): a single glitch cannot make a window.

Pure: no I/O, no clock; time is the fixes' ``t_s``.

References
----------
Bar-Shalom, Li and Kirubarajan, Estimation with applications to tracking and
navigation, sec. 5.4.2 (the time-average NIS test of filter consistency); Groves,
Principles of GNSS, inertial and multisensor navigation, sec. 17.3.1 (innovation-based
integrity monitoring).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from scipy.stats import chi2

from companion.ranges import check_ranges, ranged


@dataclass(frozen=True, slots=True)
class ImuInnovationConfig:
    """The in-flight IMU grade check (``companion.nav.imu_innovations``): windows of the
    blend's GNSS innovations against its configured grade, run with
    ``engine.imu_grade_check`` when that grade is narrower than a MEMS IMU's."""

    window_s: float = ranged(10.0, gt=0.0)
    """Length of one window of fixes, s."""
    min_fixes: int = ranged(10, ge=2)
    """A window with fewer counted fixes says nothing (neither passes nor fails)."""
    min_ratio: float = ranged(1.5, ge=1.0)
    """A window fails when its NIS per degree of freedom exceeds both the chi-square bound
    and this: a margin for what a correct grade's innovations reach on real flights."""
    windows_needed: int = ranged(3, ge=1)
    """The grade is doubted when this many ..."""
    windows_span: int = ranged(6, ge=1)
    """... of the last this many windows failed."""
    false_alarm_prob: float = ranged(1e-7, gt=0.0, lt=1.0)
    """Probability that a window of a correct configuration exceeds the chi-square bound."""

    def __post_init__(self) -> None:
        check_ranges(self)
        if self.windows_needed > self.windows_span:
            raise ValueError(
                f"windows_needed must be <= windows_span ({self.windows_span}), "
                f"got {self.windows_needed}"
            )


@dataclass(frozen=True, slots=True)
class InnovationWindow:
    """One window's verdict: its end, the NIS ratio, the bound it was held against
    (the chi-square bound or ``min_ratio``, the larger), the fixes counted."""

    t_s: float
    ratio: float
    bound: float
    fixes: int

    @property
    def failed(self) -> bool:
        """The predictions were worse than the configured grade says."""
        return self.ratio > self.bound


class ImuInnovationCheck:
    """Windows of the blend's NIS against the chi-square bound (module docstring)."""

    def __init__(self, config: ImuInnovationConfig | None = None) -> None:
        self.config = config or ImuInnovationConfig()
        self.windows: deque[InnovationWindow] = deque(maxlen=self.config.windows_span)
        """The last ``windows_span`` windows judged."""
        self.judged = 0
        """Windows judged (enough fixes)."""
        self.skipped_fixes = 0
        """Fixes not counted: the receiver was not self-consistent."""
        self._bounds: dict[int, float] = {}
        self.restart()

    def restart(self) -> None:
        """The navigation restarted: the open window is dropped (the judged ones stay:
        they are evidence about the IMU, not about one run of the filter)."""
        self._t0: float | None = None
        self._t_last = -math.inf
        self._sum_nis = 0.0
        self._sum_dof = 0
        self._n = 0

    @property
    def doubted(self) -> bool:
        """``windows_needed`` of the last ``windows_span`` windows failed."""
        return sum(w.failed for w in self.windows) >= self.config.windows_needed

    def on_innovation(
        self, t_s: float, nis: float, dof: int, cap: float, consistent: bool
    ) -> InnovationWindow | None:
        """Take the NIS of one fix (``dof`` components, at most ``cap`` counted) the blend
        was offered in normal navigation; ``consistent``: its receiver is self-consistent.
        Returns the window it closed, if any (judged: enough fixes)."""
        if not (math.isfinite(t_s) and math.isfinite(nis) and nis >= 0.0 and dof > 0):
            return None
        cfg = self.config
        closed: InnovationWindow | None = None
        if self._t0 is not None and t_s - self._t0 >= cfg.window_s:
            closed = self._close(self._t_last)
        if not consistent:
            self.skipped_fixes += 1
            return closed
        if self._t0 is None:
            self._t0 = t_s
        self._t_last = t_s
        self._sum_nis += min(nis, cap) if math.isfinite(cap) and cap > 0.0 else nis
        self._sum_dof += dof
        self._n += 1
        return closed

    def _close(self, t_end_s: float) -> InnovationWindow | None:
        n, sum_nis, sum_dof = self._n, self._sum_nis, self._sum_dof
        self.restart()
        if n < self.config.min_fixes or sum_dof <= 0:
            return None
        window = InnovationWindow(t_end_s, sum_nis / sum_dof, self._bound(sum_dof), n)
        self.windows.append(window)
        self.judged += 1
        return window

    def _bound(self, dof: int) -> float:
        bound = self._bounds.get(dof)
        if bound is None:
            cfg = self.config
            bound = max(float(chi2.isf(cfg.false_alarm_prob, dof)) / dof, cfg.min_ratio)
            self._bounds[dof] = bound
        return bound

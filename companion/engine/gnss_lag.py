"""Receiver 0's lag measured in flight: taken where nothing else says it, told where the
autopilot's parameter disagrees.

Each ``window_s`` of fixes gives one estimate (:mod:`companion.nav.gnss_lag`) of the
whole lag (the one in use plus the residual); the windows do not overlap and are
combined by their inverse variances, the sigma widened by the windows' own scatter where
it exceeds their sigmas (Birge's ratio). Once the combination has ``min_windows`` windows
and a sigma under ``max_sigma_s``, and differs from the lag in use by more than
``max(3 sigma, min_change_s)``, :meth:`LagTracker.take` hands it out once: the pipeline
places the fixes with it when the lag is not the autopilot's parameter (0 there means
the driver's default, unknown) or announces the disagreement when it is.

Pure: samples in, a decision out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from companion.nav.gnss_lag import GnssLagEstimator, LagConfig
from companion.nav.rotations import Quat, euler_to_quat_values, quat_rotate
from companion.types import AttitudeSample, GnssFix, ImuSample


@dataclass(frozen=True, slots=True)
class MeasuredLag:
    lag_s: float
    sigma_s: float
    windows: int


@dataclass(frozen=True, slots=True)
class LagTrackerConfig:
    window_s: float = 60.0
    min_windows: int = 3
    max_sigma_s: float = 0.02
    min_change_s: float = 0.02
    max_lag_s: float = 0.5


class LagTracker:
    """Feeds the estimator (receiver 0's fixes, the first IMU's specific force rotated by
    the newest attitude) and combines its windows."""

    def __init__(self, config: LagTrackerConfig | None = None) -> None:
        self.config = config or LagTrackerConfig()
        self.estimator = GnssLagEstimator(LagConfig(window_s=self.config.window_s))
        self.lag_in_use_s = 0.0
        self._q_nb: Quat | None = None
        self._imu_id: int | None = None
        self._window_start_s: float | None = None
        self._windows: list[tuple[float, float]] = []
        """(whole lag, sigma) of each window that gave an estimate, s."""
        self._handed: MeasuredLag | None = None
        self.last: MeasuredLag | None = None
        """The combination so far (None before a window gave an estimate)."""

    def restart(self, lag_in_use_s: float) -> None:
        """The stamps' lag changed (or the autopilot rebooted): the window starts over; the
        windows already combined stay (they measured the whole lag)."""
        self.lag_in_use_s = lag_in_use_s
        self.estimator.reset()
        self._window_start_s = None

    def on_attitude(self, s: AttitudeSample) -> None:
        self._q_nb = euler_to_quat_values(s.roll_rad, s.pitch_rad, s.yaw_rad)

    def on_imu(self, s: ImuSample) -> None:
        if self._imu_id is None:
            self._imu_id = s.imu_id
        if s.imu_id != self._imu_id or self._q_nb is None:
            return
        f = s.acc_b_mps2
        n, e, _ = quat_rotate(self._q_nb, float(f[0]), float(f[1]), float(f[2]))
        self.estimator.add_acceleration(s.t_s, (n, e))  # type: ignore[arg-type]

    def on_fix(self, s: GnssFix) -> None:
        if s.receiver_id != 0 or s.vel_ne_mps is None or s.fix_type < 3:
            return
        self.estimator.add_fix(s.t_s, s.vel_ne_mps)
        if self._window_start_s is None or s.t_s < self._window_start_s:
            self._window_start_s = s.t_s
            return
        if s.t_s - self._window_start_s < self.config.window_s:
            return
        est = self.estimator.estimate()
        self.estimator.reset()
        self._window_start_s = s.t_s
        if est is None:
            return
        self._windows.append((self.lag_in_use_s + est.lag_s, est.sigma_s))
        self.last = combine(self._windows)

    def take(self) -> MeasuredLag | None:
        """The measured lag, once, when it is sure and differs from the one in use."""
        cfg, m = self.config, self.last
        if m is None or m.windows < cfg.min_windows or m.sigma_s > cfg.max_sigma_s:
            return None
        if not 0.0 <= m.lag_s <= cfg.max_lag_s:
            return None
        if abs(m.lag_s - self.lag_in_use_s) <= max(3.0 * m.sigma_s, cfg.min_change_s):
            return None
        if self._handed is not None and abs(m.lag_s - self._handed.lag_s) <= cfg.min_change_s:
            return None
        self._handed = m
        return m


def combine(windows: list[tuple[float, float]]) -> MeasuredLag:
    """Inverse-variance mean of (lag, sigma) pairs; its sigma times Birge's ratio
    ``sqrt(chi^2 / (n - 1))`` where that is above 1 (the windows disagree more than their
    sigmas allow)."""
    w = [1.0 / (sd * sd) for _, sd in windows]
    sum_w = sum(w)
    mean = sum(wi * x for wi, (x, _) in zip(w, windows, strict=True)) / sum_w
    sigma = 1.0 / math.sqrt(sum_w)
    if len(windows) > 1:
        chi2 = sum(wi * (x - mean) ** 2 for wi, (x, _) in zip(w, windows, strict=True))
        sigma *= max(1.0, math.sqrt(chi2 / (len(windows) - 1)))
    return MeasuredLag(mean, sigma, len(windows))

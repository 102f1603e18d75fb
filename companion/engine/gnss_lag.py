"""Receiver 0's lag measured in flight: taken where the configuration does not give it,
and over the autopilot's parameter where that disagrees.

Each ``window_s`` of fixes gives one estimate (:mod:`companion.nav.gnss_lag`) of the
whole lag (the one in use plus the residual); the windows do not overlap and are
combined by their inverse variances, the sigma widened by the windows' own scatter where
it exceeds their sigmas (Birge's ratio). A lag is switched in only on evidence that stays
convincing: every ``group_windows`` windows that gave an estimate make one *verdict*
(their combination), and :meth:`LagTracker.take` hands out a lag once ``verdicts``
consecutive verdicts, each surer than ``max_sigma_s``, each differ from the lag in use
by more than ``k`` of their sigmas and by ``min_change_s``, in the same direction, and
agree with each other; the lag handed out is their combination. The verdicts use
disjoint windows, so with the lag in use right a chain of them passes with probability
``2 Phi(-k)^verdicts`` at most: ``k`` is chosen so that this is
``false_switch_prob`` (:func:`switch_threshold`). The pipeline then carries the fixes to
it (:mod:`companion.engine.lag_ramp`; announced where the autopilot's parameter says
otherwise).

The estimator measures the lag against the IMU's stamps; those may be late themselves
(filtered readings, stamped when sent). Their offset against the attitude stream is
measured alongside (:mod:`companion.nav.imu_stamp`, windows of their own combined the
same way) and added: the lag handed out is against the attitude's clock, which the
service's outputs carry.

Pure: samples in, a decision out.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from scipy.stats import chi2, norm

from companion.nav.gnss_lag import GnssLagEstimator, LagConfig
from companion.nav.imu_stamp import ImuStampEstimator, StampOffsetConfig
from companion.nav.rotations import Quat, euler_to_quat_values, quat_rotate
from companion.types import AttitudeSample, GnssFix, ImuSample


@dataclass(frozen=True, slots=True)
class MeasuredLag:
    lag_s: float
    sigma_s: float
    windows: int
    imu_offset_s: float = 0.0
    """The IMU stamps' offset included in ``lag_s`` (0: not measured)."""


@dataclass(frozen=True, slots=True)
class LagTrackerConfig:
    window_s: float = 20.0
    group_windows: int = 3
    """Windows (that gave an estimate) combined into one verdict."""
    verdicts: int = 2
    """Consecutive verdicts that must each say the same (six windows: two minutes of
    manoeuvres at least) before a lag is switched in."""
    false_switch_prob: float = 1e-5
    """Probability that a chain of ``verdicts`` switches a lag while the one in use is
    right (the windows' sigmas honest): each verdict must differ by ``k`` of its sigmas,
    ``2 Phi(-k)^verdicts`` = this (k = 2.84 for two verdicts). One verdict per minute at
    most: 6e-4 false switches per flight hour at most."""
    consistency_prob: float = 1e-3
    """The verdicts must agree with each other: their chi-square about their combination
    below its ``1 - consistency_prob`` quantile (a bias that wanders, not a lag)."""
    max_sigma_s: float = 0.02
    min_change_s: float = 0.01
    """A lag closer than this to the one in use is not switched in (a tenth of a 10 Hz
    fix interval)."""
    max_lag_s: float = 0.5
    offset_window_s: float = 30.0
    """The IMU stamp offset's windows."""
    max_offset_sigma_s: float = 0.005
    """The offset is added once its combination is surer than this."""


class LagTracker:
    """Feeds the estimator (receiver 0's fixes, the first IMU's specific force rotated by
    the attitude at its time) and combines its windows."""

    MAX_PENDING = 50

    def __init__(self, config: LagTrackerConfig | None = None) -> None:
        self.config = config or LagTrackerConfig()
        self.estimator = GnssLagEstimator(LagConfig(window_s=self.config.window_s))
        self.lag_in_use_s = 0.0
        self._q_nb: Quat | None = None
        self._att_prev: tuple[float, Quat] | None = None
        self._pending: deque[tuple[float, float, float, float]] = deque()
        """Specific forces (stamp, body x, y, z) waiting for the attitude after them."""
        self._imu_id: int | None = None
        self._window_start_s: float | None = None
        self._windows: list[tuple[float, float]] = []
        """(whole lag, sigma) of each window that gave an estimate, s."""
        self._group: list[tuple[float, float]] = []
        """The windows of the verdict being formed."""
        self._verdicts: list[MeasuredLag] = []
        """The latest verdicts since the lag in use changed (against the IMU's stamps)."""
        self.k_switch = switch_threshold(self.config.false_switch_prob, self.config.verdicts)
        """How many of its sigmas each verdict must differ by."""
        self.last: MeasuredLag | None = None
        """The combination so far, against the IMU's stamps (None before a window gave an
        estimate)."""
        self.stamps = ImuStampEstimator(StampOffsetConfig(window_s=self.config.offset_window_s))
        self._offset_start_s: float | None = None
        self._offset_windows: list[tuple[float, float]] = []
        self.imu_offset: MeasuredLag | None = None
        """The IMU stamps' offset against the attitude's so far (combined windows)."""
        self._offset_taken: MeasuredLag | None = None
        """The offset last taken in (:meth:`take_offset`)."""

    def restart(self, lag_in_use_s: float) -> None:
        """The stamps' lag changed (or the autopilot rebooted): the window starts over; the
        windows already combined stay (they measured the whole lag), the verdicts judged
        against the lag in use start again."""
        if lag_in_use_s != self.lag_in_use_s:
            self._verdicts.clear()
        self.lag_in_use_s = lag_in_use_s
        self.estimator.reset()
        self._window_start_s = None
        self._pending.clear()
        self._att_prev = None
        self.stamps.reset()
        self._offset_start_s = None

    def on_attitude(self, s: AttitudeSample) -> None:
        prev = self._att_prev
        if prev is not None and s.t_s == prev[0]:
            return  # the same attitude again (ATTITUDE and ATTITUDE_QUATERNION)
        q = euler_to_quat_values(s.roll_rad, s.pitch_rad, s.yaw_rad)
        self._rotate_pending(s.t_s, q)
        self._att_prev = (s.t_s, q)
        self._q_nb = q
        self.stamps.add_attitude(s.t_s, q)
        if self._offset_start_s is None or s.t_s < self._offset_start_s:
            self._offset_start_s = s.t_s
        elif s.t_s - self._offset_start_s >= self.config.offset_window_s:
            est = self.stamps.estimate()
            self.stamps.reset()
            self._offset_start_s = s.t_s
            if est is not None:
                self._offset_windows.append((est.offset_s, est.sigma_s))
                self.imu_offset = combine(self._offset_windows)

    def take_offset(self) -> MeasuredLag | None:
        """The IMU stamps' offset, once, when it becomes sure enough to be added to the lag
        (``max_offset_sigma_s``) or moves by more than that from the one taken before."""
        off, cfg = self.imu_offset, self.config
        if off is None or off.sigma_s > cfg.max_offset_sigma_s:
            return None
        taken = self._offset_taken
        if taken is not None and abs(off.lag_s - taken.lag_s) <= cfg.max_offset_sigma_s:
            return None
        self._offset_taken = off
        return off

    def on_imu(self, s: ImuSample) -> None:
        if self._imu_id is None:
            self._imu_id = s.imu_id
        if s.imu_id != self._imu_id:
            return
        self.stamps.add_gyro(s.t_s, s.gyro_b_radps)
        if self._q_nb is None:
            return
        f = s.acc_b_mps2
        self._pending.append((s.t_s, float(f[0]), float(f[1]), float(f[2])))
        if len(self._pending) > self.MAX_PENDING:  # no attitude comes: the oldest with the newest
            t, fx, fy, fz = self._pending.popleft()
            n, e, _ = quat_rotate(self._q_nb, fx, fy, fz)
            self.estimator.add_acceleration(t, (n, e))  # type: ignore[arg-type]

    def _rotate_pending(self, t_att_s: float, q: Quat) -> None:
        """The specific forces measured up to ``t_att_s`` rotated by the attitude at the
        time they measure (their stamp less the IMU's offset, when known), interpolated
        between the previous attitude and ``q``: the newest attitude alone, up to an
        attitude period old, would lag the acceleration in turns by half that period."""
        off = self.imu_offset
        late_s = (
            off.lag_s if off is not None and off.sigma_s <= self.config.max_offset_sigma_s else 0.0
        )
        prev = self._att_prev
        while self._pending and self._pending[0][0] - late_s <= t_att_s:
            t, fx, fy, fz = self._pending.popleft()
            t_true = t - late_s
            if prev is None or t_true <= prev[0] or t_att_s <= prev[0]:
                q_t = q if prev is None or t_true > prev[0] else prev[1]
            else:
                q_t = _nlerp(prev[1], q, (t_true - prev[0]) / (t_att_s - prev[0]))
            n, e, _ = quat_rotate(q_t, fx, fy, fz)
            self.estimator.add_acceleration(t, (n, e))  # type: ignore[arg-type]

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
        if est is not None:
            self.add_window(self.lag_in_use_s + est.lag_s, est.sigma_s)

    def add_window(self, lag_s: float, sigma_s: float) -> None:
        """One window's estimate of the whole lag (s, against the IMU's stamps): into the
        combination, and into the verdict being formed."""
        window = (lag_s, sigma_s)
        self._windows.append(window)
        self.last = combine(self._windows)
        self._group.append(window)
        if len(self._group) >= self.config.group_windows:
            self._verdicts.append(combine(self._group))
            self._group = []
            del self._verdicts[: -self.config.verdicts]

    def measured(self) -> MeasuredLag | None:
        """The combined lag against the attitude's clock: the IMU stamps' offset added
        once it is sure (before that, against the IMU's own stamps)."""
        m, off = self.last, self.imu_offset
        if m is None or off is None or off.sigma_s > self.config.max_offset_sigma_s:
            return m
        return MeasuredLag(
            m.lag_s + off.lag_s, math.hypot(m.sigma_s, off.sigma_s), m.windows, off.lag_s
        )

    def take(self) -> MeasuredLag | None:
        """The measured lag, once, when the last ``verdicts`` verdicts each say it differs
        from the one in use (surely, by more than ``k`` sigmas and ``min_change_s``, the
        same way) and agree with each other: their combination, against the attitude's
        clock. None otherwise."""
        cfg = self.config
        verdicts = self._verdicts
        if len(verdicts) < cfg.verdicts:
            return None
        off = self.imu_offset
        offset_s, offset_sd = (
            (off.lag_s, off.sigma_s)
            if off is not None and off.sigma_s <= cfg.max_offset_sigma_s
            else (0.0, 0.0)
        )
        signs = set()
        for v in verdicts:
            diff = v.lag_s + offset_s - self.lag_in_use_s
            if v.sigma_s > cfg.max_sigma_s or abs(diff) <= max(
                self.k_switch * v.sigma_s, cfg.min_change_s
            ):
                return None
            signs.add(diff > 0.0)
        if len(signs) != 1:
            return None
        merged = combine([(v.lag_s, v.sigma_s) for v in verdicts])
        spread = sum(((v.lag_s - merged.lag_s) / v.sigma_s) ** 2 for v in verdicts)
        if spread > chi2.isf(cfg.consistency_prob, len(verdicts) - 1):
            return None
        lag_s = merged.lag_s + offset_s
        if not 0.0 <= lag_s <= cfg.max_lag_s:
            return None
        self._verdicts.clear()  # handed out once
        windows = cfg.verdicts * cfg.group_windows
        return MeasuredLag(lag_s, math.hypot(merged.sigma_s, offset_sd), windows, offset_s)


def switch_threshold(false_switch_prob: float, verdicts: int) -> float:
    """How many of its sigmas each of ``verdicts`` independent verdicts must differ by for
    a chain of them, all the same way, to pass with probability ``false_switch_prob``
    when there is nothing to find: ``2 Phi(-k)^verdicts = false_switch_prob``."""
    return float(norm.isf((0.5 * false_switch_prob) ** (1.0 / verdicts)))


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


def _nlerp(q0: Quat, q1: Quat, w: float) -> Quat:
    """Normalised linear interpolation from ``q0`` (w = 0) to ``q1`` (w = 1), the shorter way."""
    a0, a1, a2, a3 = q0
    b0, b1, b2, b3 = q1
    if a0 * b0 + a1 * b1 + a2 * b2 + a3 * b3 < 0.0:
        b0, b1, b2, b3 = -b0, -b1, -b2, -b3
    c0, c1, c2, c3 = a0 + w * (b0 - a0), a1 + w * (b1 - a1), a2 + w * (b2 - a2), a3 + w * (b3 - a3)
    n = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2 + c3 * c3)
    return (c0 / n, c1 / n, c2 / n, c3 / n)

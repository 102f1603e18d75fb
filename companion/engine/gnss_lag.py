"""Receiver 0's lag measured in flight: taken where the configuration does not give it,
and over the autopilot's parameter where that disagrees.

Each ``window_s`` of fixes gives one estimate (:mod:`companion.nav.gnss_lag`) of the
whole lag (the one in use plus the residual); the windows do not overlap and are
combined by their inverse variances, the sigma widened by the windows' own scatter where
it exceeds their sigmas (Birge's ratio). A lag is switched in only on evidence that stays
convincing over several windows. Windows that gave an estimate are gathered, in order, into
*verdicts*: a verdict closes as soon as the windows gathered are convincing (combined,
surer than ``max_sigma_s`` and differing from the lag in use by more than ``k`` of their
sigma plus a margin for the IMU stamps' offset, below, and by ``min_change_s``), or, after
``group_windows`` windows that are not, as a "no" that breaks the chain (a weak window
does not break it, nor make it). Once ``verdicts`` consecutive verdicts say the same way
and agree with each other, :meth:`LagTracker.take` hands out their combination. The
verdicts use disjoint windows; each is looked at up to ``group_windows`` times, so with
the lag in use right a verdict passes one way with probability ``group_windows Phi(-k)``
at most, a chain of them ``2 (group_windows Phi(-k))^verdicts``: ``k`` is chosen so that
this is half of ``false_switch_prob`` (:func:`switch_threshold`). The pipeline then
carries the fixes to it (:mod:`companion.engine.lag_control`; announced where the
autopilot's parameter says otherwise).

The estimator measures the lag against the IMU's stamps; those may be late themselves
(filtered readings, stamped when sent). Their offset against the attitude stream is
measured alongside (:mod:`companion.nav.imu_stamp`, windows of their own combined the
same way) and added: the lag handed out is against the attitude's clock, which the
service's outputs carry. Until it is measured it is taken as 0 +/- ``offset_prior_s``,
and a verdict must then clear ``z`` times that more (the other half of
``false_switch_prob``).

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
    """A verdict gathers at most this many windows before it says "no"."""
    verdicts: int = 3
    """Consecutive verdicts that must each say the same before a lag is switched in."""
    false_switch_prob: float = 1e-5
    """Probability that a lag is switched in while the one in use is right (the windows'
    sigmas honest), split in two halves: the IMU stamps' offset off by more than the
    margin allowed for it (``z`` of its sigma, ``2 Phi(-z)`` = half), and a chain of
    ``verdicts`` each beyond ``k`` of its sigma the same way at one of its looks
    (``2 (group_windows Phi(-k))^verdicts`` = half): k = 2.61, z = 4.56. One verdict
    per window at most (20 s): 1.8e-3 false switches per flight hour at most."""
    offset_prior_s: float = 0.01
    """The IMU stamps' offset before it is measured (or while its sigma is over
    ``max_offset_sigma_s``): 0 +/- this (1-sigma). ArduPilot's 20 Hz second-order
    accelerometer and gyro filters delay the readings by 11 ms (their group delay
    sqrt(2) / (2 pi f_c)); SITL measured 11.5 ms. So before it is known a lag is switched
    in only beyond a 46 ms margin (z of this)."""
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
    MAX_REJUDGED = 30
    """Windows judged again when the IMU stamps' offset becomes known (ten minutes)."""

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
        """The windows of the verdict being gathered."""
        self._verdicts: list[MeasuredLag] = []
        """The chain of convincing verdicts, the same way, since the last "no" or change
        of the lag in use (against the attitude's clock)."""
        self._ready: MeasuredLag | None = None
        """A lag the chain has made, not handed out yet."""
        self._since: deque[tuple[float, float]] = deque(maxlen=self.MAX_REJUDGED)
        """The windows since the lag in use last changed (judged again, once, when the IMU
        stamps' offset becomes known)."""
        self._offset_known = False
        half = 0.5 * self.config.false_switch_prob
        self.k_switch = switch_threshold(half, self.config.verdicts, self.config.group_windows)
        """How many of its sigmas each verdict must differ by."""
        self.z_offset = float(norm.isf(0.5 * half))
        """How many of its sigmas the IMU stamps' offset may be off by."""
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
            self._group = []
            self._ready = None
            self._since.clear()
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
                if not self._offset_known and self._offset()[1] < self.config.offset_prior_s:
                    # known at last: the windows since the last change judged again with it
                    # (before, they had to clear the prior's margin)
                    self._offset_known = True
                    self._group, self._verdicts = [], []
                    for window in self._since:
                        self._judge(window)

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
        combination, and into the verdict being gathered (module docstring)."""
        window = (lag_s, sigma_s)
        self._windows.append(window)
        self.last = combine(self._windows)
        self._since.append(window)
        self._judge(window)

    def _judge(self, window: tuple[float, float]) -> None:
        """One window into the verdict being gathered, and the chain (module docstring)."""
        cfg = self.config
        self._group.append(window)
        gathered = combine(self._group)
        offset_s, offset_sd = self._offset()
        diff = gathered.lag_s + offset_s - self.lag_in_use_s
        convincing = gathered.sigma_s <= cfg.max_sigma_s and abs(diff) > max(
            self.k_switch * gathered.sigma_s + self.z_offset * offset_sd, cfg.min_change_s
        )
        if not convincing:
            if len(self._group) >= cfg.group_windows:  # a "no": the chain starts again
                self._group = []
                self._verdicts.clear()
            return
        self._group = []
        verdict = MeasuredLag(gathered.lag_s + offset_s, gathered.sigma_s, gathered.windows)
        chain = self._verdicts
        if chain and (chain[-1].lag_s > self.lag_in_use_s) != (diff > 0.0):
            chain.clear()  # the other way
        chain.append(verdict)
        del chain[: -cfg.verdicts]
        if len(chain) < cfg.verdicts:
            return
        merged = combine([(v.lag_s, v.sigma_s) for v in chain])
        spread = sum(((v.lag_s - merged.lag_s) / v.sigma_s) ** 2 for v in chain)
        if spread > chi2.isf(cfg.consistency_prob, len(chain) - 1):
            del chain[0]  # they disagree: the oldest goes, the chain waits for another
            return
        if not 0.0 <= merged.lag_s <= cfg.max_lag_s:
            return
        windows = sum(v.windows for v in chain)
        chain.clear()
        self._ready = MeasuredLag(
            merged.lag_s, math.hypot(merged.sigma_s, offset_sd), windows, offset_s
        )

    def _offset(self) -> tuple[float, float]:
        """The IMU stamps' offset and its sigma: measured once sure enough, else the prior."""
        off, cfg = self.imu_offset, self.config
        if off is not None and off.sigma_s <= cfg.max_offset_sigma_s:
            return off.lag_s, off.sigma_s
        return 0.0, cfg.offset_prior_s

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
        """The lag a chain of verdicts made (module docstring), once; None otherwise."""
        ready, self._ready = self._ready, None
        return ready


def switch_threshold(false_switch_prob: float, verdicts: int, looks: int = 1) -> float:
    """How many of its sigmas each of ``verdicts`` independent verdicts, each looked at up
    to ``looks`` times, must differ by for a chain of them, all the same way, to pass with
    probability ``false_switch_prob`` when there is nothing to find (a union bound over the
    looks): ``2 (looks Phi(-k))^verdicts = false_switch_prob``."""
    return float(norm.isf((0.5 * false_switch_prob) ** (1.0 / verdicts) / looks))


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

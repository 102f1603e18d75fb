"""The accelerometer's white noise measured in use, as the PSD the blend's velocity error
is driven by.

A datasheet's accelerometer density is the sensor's noise at rest. On a multirotor the
IMU stream also carries the rotors' vibration: the autopilot's low-pass filter leaves
part of it, and sampling the filtered signal at the stream's rate (50 Hz for RAW_IMU)
aliases the rest into the band the INS integrates. Recorded ArduPilot copters measure
a few to hundreds of times the density of a MEMS IMU in 1-sigma; at 100 times,
integrated between 5 Hz fixes, that is 0.07 m/s of velocity error where the datasheet
says 1 mm/s, and a filter that believes
the datasheet rejects every fix that disagrees with its prediction.

So the white noise is measured from the stream itself: the second differences of the
readings (:mod:`companion.nav.imu_check`) over short windows of ``window`` samples give
the variance per sample, and the PSD that summing the samples integrates into velocity
is that variance over the sample rate. A window above the configured density beyond
chance (the check's threshold) counts at its measured PSD, otherwise at the configured
one; the PSD in use is the mean of the windows of the last ``hold_s`` seconds, or the
latest window's when that is larger: vibration that starts (a take-off) is followed
within one window, vibration that stops is let go over ``hold_s`` (a short quiet window
does not make the filter overconfident), and steady vibration is measured over many
windows (the largest of them would be biased high by a third). It is the IMU's, not one
run of the filter's: it is kept across restarts.

Second differences measure the PSD at high frequencies; the INS integrates the PSD at
low ones, below the fix rate. They are the same for white noise, not for the rotors'
harmonics: a tone aliased near the stream's Nyquist frequency swells the second
differences (by up to 16/6 of its variance) and integrates to nothing (PX4's 250 Hz
HIGHRES_IMU on the simulated multirotor: 3e-4 m^2/s^3 by the samples, 4e-5 integrated
over 0.2-4 s). So the same second differences are also taken of the velocity increments
over :data:`BLOCK_S` (overlapping, every sample; ``var = 6 q tau`` for white noise of PSD
``q`` over increments of ``tau``: the Hadamard variance, Riley, Handbook of frequency stability analysis, NIST SP 1065,
2008), and
over the last ``hold_s`` seconds the upper ``1 - BOUND_PROB`` confidence bound of that
low-frequency PSD, when below the samples' PSD, scales the windows' PSDs down by its
ratio to it. The increments also hold the vehicle's own manoeuvres (a walker's gait), so
they are never taken above the samples' PSD: that stays the measure when the two agree or
the increments show more.

ArduPilot's EKF3 and PX4's EKF2 ship an accelerometer process noise of 0.35 m/s^2
(``EK3_ACC_P_NSE``, ``EKF2_ACC_NOISE``) for the same reason, two orders above a MEMS
datasheet; measured, the noise is the airframe's, neither assumed nor tuned.

Pure: no I/O, no clock; time is the samples' ``t_s``.
"""

from __future__ import annotations

import math
from collections import deque

from scipy.stats import chi2

from companion.nav.imu_check import ImuNoiseCheck
from companion.types import ImuSample

WINDOW_SAMPLES = 50
"""Samples per window (1 s at 50 Hz): 77 degrees of freedom, a 16 % spread of the
measured variance (:mod:`companion.nav.imu_check`). On the simulated copter, 2 s windows
followed the take-off's vibration too late: the prediction left its bound and the
navigator was reset to the receiver, alerted."""
HOLD_S = 10.0
"""The PSD in use is the mean of the windows that closed within this many seconds (or
the latest window's, when larger)."""
BLOCK_S = 0.1
"""Length of the velocity increments whose second differences measure the low-frequency
PSD, s: the blend's covariance step and the shortest fix interval (10 Hz); what varies
faster moves the velocity by less than it measures. A stream slower than 10 Hz takes
one sample per increment (the samples' own second differences)."""
BOUND_PROB = 1e-6
"""The low-frequency PSD is taken at its upper one-sided confidence bound of this
probability (a white noise is not scaled down by the spread of the increments)."""


class IncrementNoise:
    """Second differences of one stream's readings and of its overlapping velocity
    increments over about ``block_s`` (module docstring), pooled over three axes, summed
    until :meth:`take`."""

    def __init__(self, block_s: float = BLOCK_S) -> None:
        self.block_s = block_s
        self._restart()
        self._clear()

    def _restart(self) -> None:
        self._prev_t = math.nan
        self._prev_dt = math.nan
        self._m = 0
        self._acc: deque[list[float]] = deque(maxlen=3)
        self._cum: deque[list[float]] = deque()
        self._sum = [0.0, 0.0, 0.0]

    def _clear(self) -> None:
        self.sample_psd_sum = 0.0
        """Sum over readings and axes of ``d^2 dt / 6`` (``d`` the readings' second
        difference): its mean is the samples' PSD, m^2/s^3."""
        self.samples = 0
        """Readings (times three axes) in :attr:`sample_psd_sum`."""
        self.block_psd_sum = 0.0
        """Sum over readings and axes of ``D^2 / (6 tau)`` (``D`` the second difference of
        the increments over ``tau`` ending at the reading): its mean is the PSD at low
        frequencies, m^2/s^3."""
        self.block_terms = 0
        """Readings (times three axes) in :attr:`block_psd_sum`."""
        self.blocks = 0.0
        """... as non-overlapping increments (their number over the increment's length)."""

    def take(self) -> tuple[float, int, float, int, float]:
        """The sums since the last call: samples' PSD sum and count, increments' PSD sum,
        count and non-overlapping count."""
        out = (
            self.sample_psd_sum,
            self.samples,
            self.block_psd_sum,
            self.block_terms,
            self.blocks,
        )
        self._clear()
        return out

    def on_sample(self, t_s: float, acc: list[float]) -> None:
        """Take one reading (specific force, m/s^2, three axes) at ``t_s``."""
        dt = t_s - self._prev_t
        if not (dt > 0.0 and all(map(math.isfinite, acc))):
            self._restart()  # the first reading, a new clock, or a bad one
            if all(map(math.isfinite, acc)) and math.isfinite(t_s):
                self._prev_t = t_s
                self._acc.append(acc)
            return
        if math.isfinite(self._prev_dt) and abs(dt - self._prev_dt) > 0.25 * max(dt, self._prev_dt):
            self._restart()  # irregular: a dropout or jitter; the chain starts again
            self._prev_t = t_s
            self._acc.append(acc)
            return
        self._prev_t, self._prev_dt = t_s, dt
        a = self._acc
        a.append(acc)
        if len(a) == 3:
            a0, a1, a2 = a
            self.sample_psd_sum += (
                dt * sum((a2[i] - 2.0 * a1[i] + a0[i]) ** 2 for i in range(3)) / 6.0
            )
            self.samples += 3
        if self._m == 0:
            self._m = max(1, round(self.block_s / dt))
            self._cum.append(list(self._sum))
        s = self._sum
        for i in range(3):
            s[i] += acc[i] * dt
        cum = self._cum
        cum.append(list(s))
        m = self._m
        if len(cum) > 3 * m + 1:
            cum.popleft()
        if len(cum) == 3 * m + 1:
            c0, c1, c2, c3 = cum[0], cum[m], cum[2 * m], cum[3 * m]
            tau = m * dt
            self.block_psd_sum += sum(
                (c3[i] - 3.0 * c2[i] + 3.0 * c1[i] - c0[i]) ** 2 for i in range(3)
            ) / (6.0 * tau)
            self.block_terms += 3
            self.blocks += 1.0 / m


class AccelNoise:
    """The accelerometer PSD in use (module docstring): the configured one
    ``acc_density_mps2_rthz`` squared, or what windows of the stream measure above it."""

    def __init__(
        self,
        gyro_density_radps_rthz: float,
        acc_density_mps2_rthz: float,
        window: int = WINDOW_SAMPLES,
        hold_s: float = HOLD_S,
        block_s: float = BLOCK_S,
    ) -> None:
        self._check = ImuNoiseCheck(gyro_density_radps_rthz, acc_density_mps2_rthz, window)
        self._increments = IncrementNoise(block_s)
        self.configured_psd_m2ps3 = acc_density_mps2_rthz**2
        self.hold_s = hold_s
        self._windows: deque[tuple[float, float, tuple[float, int, float, int, float]]]
        self._windows = deque()
        """Per window: its end (s), its measured PSD beyond chance (0 when not), m^2/s^3,
        and its :meth:`IncrementNoise.take` sums."""
        self.low_band_ratio = 1.0
        """The low-frequency PSD's bound over the samples' PSD, at most 1 (module
        docstring)."""
        self.psd_m2ps3 = self.configured_psd_m2ps3
        """The PSD in use, m^2/s^3."""

    @property
    def measured(self) -> bool:
        """Is the PSD in use the measured one (above the configured)?"""
        return self.psd_m2ps3 > self.configured_psd_m2ps3

    def on_imu(self, sample: ImuSample) -> bool:
        """Take one reading; True when the PSD in use changed."""
        self._increments.on_sample(sample.t_s, sample.acc_b_mps2.tolist())
        verdict = self._check.on_imu(sample)
        if verdict is None:
            return False
        configured = self.configured_psd_m2ps3
        psd = 0.0  # the window's PSD, beyond chance
        if verdict.acc_ratio > verdict.threshold and math.isfinite(verdict.acc_psd_m2ps3):
            psd = verdict.acc_psd_m2ps3
        windows = self._windows
        if windows and verdict.t_s < windows[-1][0]:
            windows.clear()  # a new clock (an autopilot reboot)
        windows.append((verdict.t_s, psd, self._increments.take()))
        while windows and windows[0][0] < verdict.t_s - self.hold_s:
            windows.popleft()
        ratio = self.low_band_ratio = self._low_band_ratio()
        excess = [max(0.0, ratio * p - configured) for _, p, _ in windows]
        new = configured + max(excess[-1], sum(excess) / len(excess))
        if new == self.psd_m2ps3:
            return False
        self.psd_m2ps3 = new
        return True

    def _low_band_ratio(self) -> float:
        """Over the windows kept: the upper confidence bound of the increments' PSD over
        the samples' PSD, at most 1."""
        s_sum = b_sum = blocks = 0.0
        s_n = b_n = 0
        for _, _, (ss, sn, bs, bn, nb) in self._windows:
            s_sum += ss
            s_n += sn
            b_sum += bs
            b_n += bn
            blocks += nb
        if s_n == 0 or b_n == 0 or s_sum <= 0.0:
            return 1.0
        # non-overlapping increments, three axes, Satterthwaite's degrees of freedom of a
        # second difference (imu_check): fewer than the overlapping terms hold
        dof = 3.0 * blocks * 36.0 / 70.0
        if dof < 1.0:
            return 1.0
        upper = (b_sum / b_n) * dof / float(chi2.ppf(BOUND_PROB, dof))
        return min(1.0, upper / (s_sum / s_n))

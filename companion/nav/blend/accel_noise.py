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
over 0.2-4 s). So the same second differences are also taken of the velocity
increments over :data:`BLOCK_S` (overlapping, at every sample; ``var = 6 q tau`` for a
white noise of PSD ``q`` over increments of length ``tau``: the Hadamard variance), and
over the last ``hold_s`` seconds the upper ``1 - BOUND_PROB`` confidence bound of that
low-frequency PSD, when below the samples' PSD, scales the windows' PSDs down by its
ratio to it. The increments also hold the vehicle's own manoeuvres (a walker's gait),
so they never raise the PSD above the samples': that stays the measure when the two
agree or the increments show more.

ArduPilot's EKF3 and PX4's EKF2 ship an accelerometer process noise of 0.35 m/s^2
(``EK3_ACC_P_NSE``, ``EKF2_ACC_NOISE``) for the same reason, two orders above a MEMS
datasheet; measured, the noise is the airframe's, neither assumed nor tuned.

Pure: no I/O, no clock; time is the samples' ``t_s``.

References
----------
Riley, Handbook of frequency stability analysis, NIST SP 1065 (2008) (the Hadamard
variance); IEEE Std 952-1997 (noise densities); Satterthwaite, Biometrics Bulletin
2(6), 1946 (the degrees of freedom of a sum of squares).
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
    """Second differences of one stream's overlapping velocity increments over about
    ``block_s`` (module docstring), pooled over three axes, summed until :meth:`take`."""

    def __init__(self, block_s: float = BLOCK_S) -> None:
        self.block_s = block_s
        self._restart(math.nan)
        self.psd_sum = 0.0
        """Sum over readings and axes of ``D^2 / (6 tau)`` (``D`` the second difference of
        the increments over ``tau`` ending at the reading): its mean is the PSD at low
        frequencies, m^2/s^3."""
        self.terms = 0
        """Readings (times three axes) in :attr:`psd_sum`."""
        self.blocks = 0.0
        """... as non-overlapping increments (their number over the increment's length)."""

    def _restart(self, t_s: float) -> None:
        self._prev_t = t_s
        self._prev_dt = math.nan
        self._m = 0
        self._cum: deque[tuple[float, float, float]] = deque([(0.0, 0.0, 0.0)])
        """Velocity integrated since the chain started, one per reading, the last 3 m + 1."""

    def take(self) -> tuple[float, int, float]:
        """The sums since the last call: :attr:`psd_sum`, :attr:`terms`, :attr:`blocks`."""
        out = (self.psd_sum, self.terms, self.blocks)
        self.psd_sum, self.terms, self.blocks = 0.0, 0, 0.0
        return out

    def on_sample(self, t_s: float, ax: float, ay: float, az: float) -> None:
        """Take one reading (specific force, m/s^2, body axes) at ``t_s``."""
        dt = t_s - self._prev_t
        if not (dt > 0.0 and math.isfinite(ax + ay + az)):
            self._restart(t_s)  # the first reading, a new clock, or a bad one
            return
        prev_dt = self._prev_dt
        self._prev_t, self._prev_dt = t_s, dt
        if prev_dt == prev_dt and abs(dt - prev_dt) > 0.25 * max(dt, prev_dt):
            self._restart(t_s)  # irregular: a dropout or jitter; the chain starts again
            return
        m = self._m
        if m == 0:
            m = self._m = max(1, round(self.block_s / dt))
        cum = self._cum
        x, y, z = cum[-1]
        cum.append((x + ax * dt, y + ay * dt, z + az * dt))
        if len(cum) > 3 * m + 1:
            cum.popleft()
        if len(cum) == 3 * m + 1:
            c0, c1, c2, c3 = cum[0], cum[m], cum[2 * m], cum[3 * m]
            dx = c3[0] - 3.0 * c2[0] + 3.0 * c1[0] - c0[0]
            dy = c3[1] - 3.0 * c2[1] + 3.0 * c1[1] - c0[1]
            dz = c3[2] - 3.0 * c2[2] + 3.0 * c1[2] - c0[2]
            self.psd_sum += (dx * dx + dy * dy + dz * dz) / (6.0 * m * dt)
            self.terms += 3
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
        self._windows: deque[tuple[float, float, float, tuple[float, int, float]]]
        self._windows = deque()
        """Per window: its end (s), its samples' PSD and that PSD when beyond chance (else
        0), m^2/s^3, and its :meth:`IncrementNoise.take` sums."""
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
        ax, ay, az = sample.acc_b_mps2.tolist()
        self._increments.on_sample(sample.t_s, ax, ay, az)
        verdict = self._check.on_imu(sample)
        if verdict is None:
            return False
        configured = self.configured_psd_m2ps3
        sample_psd = verdict.acc_psd_m2ps3 if math.isfinite(verdict.acc_psd_m2ps3) else 0.0
        psd = sample_psd if verdict.acc_ratio > verdict.threshold else 0.0  # beyond chance
        windows = self._windows
        if windows and verdict.t_s < windows[-1][0]:
            windows.clear()  # a new clock (an autopilot reboot)
        windows.append((verdict.t_s, sample_psd, psd, self._increments.take()))
        while windows and windows[0][0] < verdict.t_s - self.hold_s:
            windows.popleft()
        ratio = self.low_band_ratio = self._low_band_ratio()
        excess = [max(0.0, ratio * p - configured) for _, _, p, _ in windows]
        new = configured + max(excess[-1], sum(excess) / len(excess))
        if new == self.psd_m2ps3:
            return False
        self.psd_m2ps3 = new
        return True

    def _low_band_ratio(self) -> float:
        """Over the windows kept: the upper confidence bound of the increments' PSD over
        the samples' PSD, at most 1."""
        windows = self._windows
        s_mean = sum(w[1] for w in windows) / len(windows)  # windows of equal samples
        b_sum = blocks = 0.0
        b_n = 0
        for _, _, _, (bs, bn, nb) in windows:
            b_sum += bs
            b_n += bn
            blocks += nb
        if b_n == 0 or s_mean <= 0.0:
            return 1.0
        # non-overlapping increments, three axes, Satterthwaite's degrees of freedom of a
        # second difference (imu_check): fewer than the overlapping terms hold
        dof = 3.0 * blocks * 36.0 / 70.0
        if dof < 1.0:
            return 1.0
        upper = (b_sum / b_n) * dof / float(chi2.ppf(BOUND_PROB, dof))
        return min(1.0, upper / s_mean)

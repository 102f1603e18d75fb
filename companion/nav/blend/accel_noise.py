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

ArduPilot's EKF3 and PX4's EKF2 ship an accelerometer process noise of 0.35 m/s^2
(``EK3_ACC_P_NSE``, ``EKF2_ACC_NOISE``) for the same reason, two orders above a MEMS
datasheet; measured, the noise is the airframe's, neither assumed nor tuned.

Pure: no I/O, no clock; time is the samples' ``t_s``.
"""

from __future__ import annotations

import math
from collections import deque

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


class AccelNoise:
    """The accelerometer PSD in use (module docstring): the configured one
    ``acc_density_mps2_rthz`` squared, or what windows of the stream measure above it."""

    def __init__(
        self,
        gyro_density_radps_rthz: float,
        acc_density_mps2_rthz: float,
        window: int = WINDOW_SAMPLES,
        hold_s: float = HOLD_S,
    ) -> None:
        self._check = ImuNoiseCheck(gyro_density_radps_rthz, acc_density_mps2_rthz, window)
        self.configured_psd_m2ps3 = acc_density_mps2_rthz**2
        self.hold_s = hold_s
        self._windows: deque[tuple[float, float]] = deque()
        """Per window: its end (s) and its PSD beyond the configured one (m^2/s^3)."""
        self.psd_m2ps3 = self.configured_psd_m2ps3
        """The PSD in use, m^2/s^3."""

    @property
    def measured(self) -> bool:
        """Is the PSD in use the measured one (above the configured)?"""
        return self.psd_m2ps3 > self.configured_psd_m2ps3

    def on_imu(self, sample: ImuSample) -> bool:
        """Take one reading; True when the PSD in use changed."""
        verdict = self._check.on_imu(sample)
        if verdict is None:
            return False
        configured = self.configured_psd_m2ps3
        excess = 0.0  # the window's PSD beyond the configured one
        if verdict.acc_ratio > verdict.threshold and math.isfinite(verdict.acc_psd_m2ps3):
            excess = max(0.0, verdict.acc_psd_m2ps3 - configured)
        windows = self._windows
        if windows and verdict.t_s < windows[-1][0]:
            windows.clear()  # a new clock (an autopilot reboot)
        windows.append((verdict.t_s, excess))
        while windows and windows[0][0] < verdict.t_s - self.hold_s:
            windows.popleft()
        new = configured + max(excess, sum(p for _, p in windows) / len(windows))
        if new == self.psd_m2ps3:
            return False
        self.psd_m2ps3 = new
        return True

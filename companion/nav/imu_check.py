"""Does the IMU match the grade it was configured with? Its measured white noise, at rest
or in flight, against the grade's noise densities.

The white noise of a sampled sensor shows in the second differences of its readings,
``d_k = x_k - 2 x_{k-1} + x_{k-2}`` (``var d = 6 sigma^2`` for white noise ``sigma``
per sample), which remove the vehicle's own smooth motion (a 2 deg/s^2 angular
acceleration moves them by 1e-5 rad/s at 100 Hz). Over a window of ``n`` regular
samples per axis (three axes pooled) the ratio

```
r = sum d^2 / (6 * 3 n sigma0^2) ,   sigma0^2 = q^2 f + lsb^2 / 12
```

of measured to expected variance (``q`` the configured noise density, ``f`` the
sample rate, ``lsb`` the message's resolution: 1 mG and 1 mrad/s for RAW_IMU and
SCALED_IMU, none for HIGHRES_IMU) is 1 for a correct grade. Its spread: ``sum d^2``
of one axis has mean ``6 n`` and variance ``140 n`` (``d`` is a moving sum of three
taps, autocovariances 6, -4, 1), so ``r`` is taken as ``g chi2(h) / h`` with ``h = 3 *
36 n / 70`` (Satterthwaite). The grade is doubted when ``r`` exceeds both that
distribution's ``1 - false_alarm_prob`` quantile and ``min_ratio`` (the measured
variance this many times the configured one: a margin for what white noise does not
model; the next wider grade, a MEMS autopilot IMU against a tactical one, is 4-40
times noisier by these figures).

Pure: no I/O, no clock.

References
----------
IEEE Std 952-1997 (noise densities, angle and velocity random walk); Groves, Principles
of GNSS, inertial and multisensor navigation, sec. 4.4.3. Satterthwaite, Biometrics
Bulletin 2(6), 1946.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from scipy.stats import chi2

from companion.types import ImuSample

MG_MPS2 = 9.80665e-3
"""One milli-g, m/s^2 (RAW_IMU, SCALED_IMU resolution)."""
MRAD = 1e-3
"""One milliradian per second, rad/s (RAW_IMU, SCALED_IMU resolution)."""
_QUANTISED = ("RAW_IMU", "SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3")


@dataclass(frozen=True, slots=True)
class ImuNoiseVerdict:
    """One window's measured-to-configured variance ratios (gyro, accelerometer) and the
    threshold they were held against."""

    t_s: float
    gyro_ratio: float
    acc_ratio: float
    threshold: float
    rate_hz: float = math.nan
    """The window's mean sample rate, Hz."""
    acc_white_var_m2ps4: float = math.nan
    """The accelerometer's measured white-noise variance per sample (three axes pooled,
    the message's quantisation removed), (m/s^2)^2."""

    @property
    def acc_psd_m2ps3(self) -> float:
        """The accelerometer's measured white-noise PSD, (m/s^2)^2/Hz = m^2/s^3: the
        variance per sample over the sample rate (what summing the samples times their
        interval integrates into velocity per second)."""
        return self.acc_white_var_m2ps4 / self.rate_hz

    @property
    def doubted(self) -> bool:
        """The IMU is noisier than its configured grade."""
        return self.gyro_ratio > self.threshold or self.acc_ratio > self.threshold


class ImuNoiseCheck:
    """Windows of one IMU stream's second differences against the configured densities.

    ``gyro_density_radps_rthz``, ``acc_density_mps2_rthz``: the configured white-noise
    densities; ``window`` samples per verdict.
    """

    def __init__(
        self,
        gyro_density_radps_rthz: float,
        acc_density_mps2_rthz: float,
        window: int = 500,
        false_alarm_prob: float = 1e-7,
        min_ratio: float = 3.0,
    ) -> None:
        if not (gyro_density_radps_rthz > 0.0 and acc_density_mps2_rthz > 0.0):
            raise ValueError("noise densities must be > 0")
        if window < 10:
            raise ValueError("window must be >= 10 samples")
        self.gyro_q = gyro_density_radps_rthz
        self.acc_q = acc_density_mps2_rthz
        self.window = window
        h = 3.0 * 36.0 * window / 70.0
        self.threshold = max(float(chi2.isf(false_alarm_prob, h)) / h, min_ratio)
        self.last: ImuNoiseVerdict | None = None
        self.windows = 0
        self._reset_chain()
        self._sum_g = self._sum_a = self._sum_dt = 0.0
        self._n = 0

    def _reset_chain(self) -> None:
        self._prev: list[tuple[float, list[float], list[float]]] = []

    def on_imu(self, sample: ImuSample) -> ImuNoiseVerdict | None:
        """Take one reading; returns a verdict when a window completes."""
        g = sample.gyro_b_radps.tolist()
        a = sample.acc_b_mps2.tolist()
        prev = self._prev
        if prev and sample.t_s <= prev[-1][0]:
            self._reset_chain()
            return None
        prev.append((sample.t_s, g, a))
        if len(prev) < 3:
            return None
        if len(prev) > 3:
            prev.pop(0)
        (t0, g0, a0), (t1, g1, a1), (t2, g2, a2) = prev
        dt1, dt2 = t1 - t0, t2 - t1
        if abs(dt2 - dt1) > 0.25 * max(dt1, dt2):
            self._reset_chain()  # irregular: a dropout or jitter; the chain starts again
            prev.append((sample.t_s, g, a))
            return None
        self._sum_g += sum((g2[i] - 2.0 * g1[i] + g0[i]) ** 2 for i in range(3))
        self._sum_a += sum((a2[i] - 2.0 * a1[i] + a0[i]) ** 2 for i in range(3))
        self._sum_dt += dt2
        self._n += 1
        if self._n < self.window:
            return None
        rate = self._n / self._sum_dt
        quantised = sample.source in _QUANTISED
        var_g = self.gyro_q**2 * rate + (MRAD**2 / 12.0 if quantised else 0.0)
        var_a = self.acc_q**2 * rate + (MG_MPS2**2 / 12.0 if quantised else 0.0)
        n3 = 18.0 * self._n
        lsb_var_a = MG_MPS2**2 / 12.0 if quantised else 0.0
        verdict = ImuNoiseVerdict(
            sample.t_s,
            self._sum_g / (n3 * var_g),
            self._sum_a / (n3 * var_a),
            self.threshold,
            rate,
            max(self._sum_a / n3 - lsb_var_a, 0.0),
        )
        self._sum_g = self._sum_a = self._sum_dt = 0.0
        self._n = 0
        self.windows += 1
        self.last = verdict
        return verdict

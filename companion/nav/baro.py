"""The barometer as a height: standard atmosphere, calibration against GNSS, its uncertainty.

A barometer measures static pressure. :func:`isa_height_m` turns it into the
standard atmosphere's pressure height, which differs from the height above mean
sea level by an offset that follows the weather (about 8.4 m per hPa near sea
level; a synoptic pressure tendency of 1 hPa/h is common) and the sensor's own
bias. :class:`BaroHeight` keeps that difference as a two-state Kalman filter,
offset ``b`` (m) and its rate ``d`` (m/s), integrated random walk plus random walk,

```
b' = d + w_b ,   d' = w_d ,   z = h_baro(t_fix) - h_gnss = b + v
```

updated from trusted GNSS heights at most every ``calib_interval_s`` (the receiver's
height error is correlated over minutes: a faster rate would count one error many
times; each counts the GNSS height's variance ``gnss_corr_s`` update intervals
over), each against a straight line fitted to that interval's readings (the
vertical motion taken out, the readings' white noise averaged). The calibrated
height is ``h_baro - b`` with variance ``P_bb`` (an offset over a separation
window), ``P_dd`` (a rate) and the sensor's white noise, measured from the second
differences of the readings (``var(h_k - 2 h_{k-1} + h_{k-2}) = 6 sigma^2`` for
white noise), floored at ``noise_floor_m``. The published ``P_bb`` is never below
the variance of the GNSS height it was calibrated against, nor ``P_dd`` below that
over ``memory_s`` squared: averaging a receiver's correlated error does not remove it.
A calibration resumed after a pause of more than ``resume_restart_s`` starts a new
``epoch`` (the separation series restart with it).

Bad readings are turned away and counted (``stats``): a reading that jumps from
the track of the last two by more than ``max_vertical_accel_mps2 dt^2`` plus
``jump_sigmas`` of the second-difference noise (``baro_jump``); after
``max_consecutive_jumps`` in a row the new level is taken as the sensor's and the
calibration restarts (``baro_restarted``). No reading for ``timeout_s``: no height.

Pure: no I/O, no clock; time is the samples' ``t_s``.

References
----------
ISO 2533:1975 / U.S. Standard Atmosphere 1976 (troposphere: T0 = 288.15 K,
L = 0.0065 K/m, p0 = 101325 Pa, g0 M / (R L) = 5.25588). Groves, Principles of GNSS,
inertial and multisensor navigation, sec. 6.2.1 (barometric height, its weather
drift and calibration against GNSS).
"""

from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass

from companion.ranges import check_ranges, ranged
from companion.types import BaroSample

ISA_T0_K = 288.15
ISA_LAPSE_K_PER_M = 0.0065
ISA_P0_PA = 101_325.0
ISA_EXPONENT = 1.0 / 5.255877
"""R L / (g0 M) of the standard troposphere."""


def isa_height_m(pressure_pa: float) -> float:
    """Standard-atmosphere (troposphere) pressure height of ``pressure_pa``, m.

    ``h = T0 / L (1 - (p / p0)^(R L / (g0 M)))``; ``ValueError`` for a pressure that is
    not finite and positive.
    """
    if not (math.isfinite(pressure_pa) and pressure_pa > 0.0):
        raise ValueError("pressure must be finite and > 0")
    return ISA_T0_K / ISA_LAPSE_K_PER_M * (1.0 - (pressure_pa / ISA_P0_PA) ** ISA_EXPONENT)


@dataclass(frozen=True, slots=True)
class BaroConfig:
    """The barometer's height: its noise model, its calibration against trusted GNSS and the
    checks of its readings (``companion.nav.baro``). Read when the service starts."""

    noise_floor_m: float = ranged(0.1, gt=0.0)
    """Least white noise of a reading, 1-sigma, m (the measured one is used when larger)."""
    offset_rw_m2ps: float = ranged(2.5e-6, ge=0.0)
    """Random-walk density of the offset (temperature, sensor), m^2/s: 0.1 m per hour."""
    drift_rw_m2ps3: float = ranged(1e-9, ge=0.0)
    """Random-walk density of the offset's rate (the weather's pressure tendency
    changing over hours: 1 hPa/h, about 2 mm/s, over three hours), m^2/s^3."""
    initial_drift_sigma_mps: float = ranged(7e-3, gt=0.0)
    """1-sigma of the offset's rate before calibration (3 hPa/h), m/s."""
    calib_interval_s: float = ranged(1.0, gt=0.0)
    """At most one calibration update per this long, s."""
    gnss_corr_s: float = ranged(60.0, gt=0.0)
    """Correlation time of the receiver's height error, s: each calibration update counts
    the GNSS height's variance this many update intervals over (``R = var gnss_corr_s /
    calib_interval_s``), so that the calibration follows the receiver over minutes, not
    seconds, and a slow ramp of the receiver shows against it before it is absorbed."""
    resume_restart_s: float = ranged(10.0, gt=0.0)
    """A calibration resumed after a pause longer than this (a fault, a gap) may move the
    height by more than its noise at once: the separation series restarts with it."""
    calib_min_s: float = ranged(10.0, ge=0.0)
    """The height is offered once calibrated over at least this long, s."""
    memory_s: float = ranged(600.0, gt=0.0)
    """The offset's rate is not known better than the GNSS height's sigma over this, s."""
    max_vertical_accel_mps2: float = ranged(30.0, gt=0.0)
    """Largest vertical acceleration a reading may show against the last two, m/s^2."""
    jump_sigmas: float = ranged(6.0, gt=0.0)
    """... plus this many sigmas of the second-difference noise."""
    max_consecutive_jumps: int = ranged(5, ge=1)
    """This many jumps in a row: the sensor's new level, the calibration restarts."""
    timeout_s: float = ranged(1.0, gt=0.0)
    """No reading for this long: no barometric height, s."""
    history_s: float = ranged(3.0, gt=0.0)
    """Readings kept to interpolate at a fix's (older) time of validity, s."""

    def __post_init__(self) -> None:
        check_ranges(self)


@dataclass(frozen=True, slots=True)
class BaroReference:
    """The calibrated barometric height at one time.

    ``alt_msl_m``: height, m MSL; ``white_var_m2``: the reading's white noise;
    ``offset_var_m2``: the calibration offset's variance; ``drift_var_m2ps2``: its
    rate's variance; ``epoch``: the calibration's serial number (a restart changes it).
    """

    t_s: float
    alt_msl_m: float
    white_var_m2: float
    offset_var_m2: float
    drift_var_m2ps2: float
    epoch: int

    @property
    def var_m2(self) -> float:
        """Total variance of the height (white noise and offset), m^2."""
        return self.white_var_m2 + self.offset_var_m2


class BaroHeight:
    """One barometer's height and its calibration against GNSS (module docstring).

    ``stats`` counts rejections and restarts by reason (shared with the caller's).
    """

    def __init__(self, config: BaroConfig | None = None, stats: Counter[str] | None = None) -> None:
        self.config = config or BaroConfig()
        self.stats: Counter[str] = stats if stats is not None else Counter()
        self.epoch = 0
        self._readings: deque[tuple[float, float]] = deque()
        self._d2_var = 0.0
        self._d2_n = 0
        self._jumps = 0
        self._reset_calibration()

    def _reset_calibration(self) -> None:
        self.epoch += 1
        self._x = [0.0, 0.0]
        self._p = [[0.0, 0.0], [0.0, 0.0]]
        self._t_cal: float | None = None
        self._t_cal_start: float | None = None
        self._gnss_var_m2 = 0.0

    @property
    def calibrated(self) -> bool:
        """Calibrated over at least ``calib_min_s``."""
        return (
            self._t_cal is not None
            and self._t_cal_start is not None
            and self._t_cal - self._t_cal_start >= self.config.calib_min_s
        )

    @property
    def white_var_m2(self) -> float:
        """The reading's white-noise variance: measured, floored, m^2."""
        floor = self.config.noise_floor_m**2
        if self._d2_n < 10:
            return max(floor, self._d2_var / 6.0 if self._d2_n else floor)
        return max(floor, self._d2_var / 6.0)

    def on_sample(self, sample: BaroSample) -> bool:
        """Take one reading; False when it is turned away (counted)."""
        try:
            h = isa_height_m(sample.pressure_pa)
        except ValueError:
            self.stats["baro_bad"] += 1
            return False
        t = sample.t_s
        r = self._readings
        if r and t <= r[-1][0]:
            self.stats["baro_out_of_order"] += 1
            return False
        if r and t - r[-1][0] > self.config.timeout_s:
            r.clear()  # a gap: the track starts again (no jump test across it)
        if len(r) >= 2:
            (t0, h0), (t1, h1) = r[-2], r[-1]
            dt = t - t1
            pred = h1 + (h1 - h0) * dt / (t1 - t0)
            d2 = h - pred
            cfg = self.config
            allowed = cfg.max_vertical_accel_mps2 * dt * (dt + t1 - t0) + cfg.jump_sigmas * (
                math.sqrt(6.0 * self.white_var_m2)
            )
            if abs(d2) > allowed:
                self._jumps += 1
                self.stats["baro_jump"] += 1
                if self._jumps < cfg.max_consecutive_jumps:
                    return False
                # the new level stays: the sensor's, not a glitch; calibrate again
                self.stats["baro_restarted"] += 1
                self._jumps = 0
                r.clear()
                self._reset_calibration()
            else:
                self._jumps = 0
                # exponentially weighted second-difference variance (about 200 readings)
                self._d2_n += 1
                a = max(1.0 / self._d2_n, 0.005)
                self._d2_var += a * (d2 * d2 - self._d2_var)
        r.append((t, h))
        while r and r[0][0] < t - self.config.history_s:
            r.popleft()
        return True

    def raw_height_at(self, t_s: float, max_dt_s: float) -> float | None:
        """The uncalibrated height at ``t_s`` interpolated between readings (or the
        nearest within ``max_dt_s``), m; None when there is none."""
        r = self._readings
        if not r:
            return None
        if t_s >= r[-1][0]:
            return r[-1][1] if t_s - r[-1][0] <= max_dt_s else None
        if t_s <= r[0][0]:
            return r[0][1] if r[0][0] - t_s <= max_dt_s else None
        for k in range(len(r) - 1, 0, -1):
            ta, ha = r[k - 1]
            if ta <= t_s:
                tb, hb = r[k]
                return ha + (hb - ha) * (t_s - ta) / (tb - ta)
        return None

    def fitted_height_at(self, t_s: float, span_s: float) -> tuple[float, float] | None:
        """The uncalibrated height at ``t_s`` from a straight line fitted to the readings
        of the last ``span_s`` before it (the vertical motion taken out, the white noise
        averaged), and its variance from the white noise (m, m^2); None with fewer than
        three readings there."""
        pts = [(t, h) for t, h in self._readings if t_s - span_s <= t <= t_s + 1e-9]
        n = len(pts)
        if n < 3:
            return None
        t_mean = sum(t for t, _ in pts) / n
        h_mean = sum(h for _, h in pts) / n
        sxx = sum((t - t_mean) ** 2 for t, _ in pts)
        if sxx <= 0.0:
            return None
        b = sum((t - t_mean) * (h - h_mean) for t, h in pts) / sxx
        u = t_s - t_mean
        return h_mean + b * u, self.white_var_m2 * (1.0 / n + u * u / sxx)

    def _predict(self, t_s: float) -> tuple[list[float], list[list[float]]]:
        """The calibration carried to ``t_s`` (not stored)."""
        x, p = self._x, self._p
        if self._t_cal is None:
            return list(x), [list(p[0]), list(p[1])]
        dt = max(t_s - self._t_cal, 0.0)
        cfg = self.config
        qd, qb = cfg.drift_rw_m2ps3, cfg.offset_rw_m2ps
        b = x[0] + x[1] * dt
        p00 = p[0][0] + 2.0 * dt * p[0][1] + dt * dt * p[1][1] + qd * dt**3 / 3.0 + qb * dt
        p01 = p[0][1] + dt * p[1][1] + qd * dt * dt / 2.0
        p11 = p[1][1] + qd * dt
        return [b, x[1]], [[p00, p01], [p01, p11]]

    def calibrate(self, t_s: float, alt_msl_m: float, var_m2: float) -> bool:
        """Calibrate against a trusted GNSS height (m MSL, variance m^2) at ``t_s``; False
        when skipped (too soon after the last update, no reading, a bad input)."""
        if not (math.isfinite(alt_msl_m) and math.isfinite(var_m2) and var_m2 > 0.0):
            self.stats["baro_bad_calibration"] += 1
            return False
        cfg = self.config
        if self._t_cal is not None and t_s - self._t_cal < cfg.calib_interval_s:
            return False
        fitted = self.fitted_height_at(t_s, cfg.calib_interval_s)
        if fitted is None:
            return False
        h, h_var = fitted
        z = h - alt_msl_m
        r = var_m2 * cfg.gnss_corr_s / cfg.calib_interval_s + h_var
        self._gnss_var_m2 = var_m2
        if self._t_cal is None:
            self._x = [z, 0.0]
            self._p = [[r, 0.0], [0.0, cfg.initial_drift_sigma_mps**2]]
            self._t_cal = self._t_cal_start = t_s
            return True
        if t_s - self._t_cal > cfg.resume_restart_s:
            self.epoch += 1  # resumed after a pause: a new separation series
        x, p = self._predict(t_s)
        s = p[0][0] + r
        k0, k1 = p[0][0] / s, p[0][1] / s
        nu = z - x[0]
        x = [x[0] + k0 * nu, x[1] + k1 * nu]
        # P - K H P (H = [1, 0]); symmetric by construction
        p00 = p[0][0] - k0 * p[0][0]
        p01 = p[0][1] - k0 * p[0][1]
        p11 = p[1][1] - k1 * p[0][1]
        self._x, self._p = x, [[p00, p01], [p01, p11]]
        self._t_cal = t_s
        return True

    def reference(self, t_s: float, max_dt_s: float) -> BaroReference | None:
        """The calibrated height at ``t_s`` with its variances, or None (no reading within
        ``max_dt_s`` of it, not calibrated yet)."""
        if not self.calibrated:
            return None
        h = self.raw_height_at(t_s, max_dt_s)
        if h is None:
            return None
        x, p = self._predict(t_s)
        # floors: the receiver's correlated error is not averaged away
        g = self._gnss_var_m2
        offset_var = max(p[0][0], g)
        drift_var = max(p[1][1], g / self.config.memory_s**2)
        return BaroReference(t_s, h - x[0], self.white_var_m2, offset_var, drift_var, self.epoch)

    def reset(self) -> None:
        """Forget the readings and the calibration (a reboot); ``stats`` kept."""
        self._readings.clear()
        self._d2_var = 0.0
        self._d2_n = 0
        self._jumps = 0
        self._reset_calibration()

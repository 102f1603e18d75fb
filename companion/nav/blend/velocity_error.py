"""The receiver's velocity error measured by its own positions: how far its reported
velocity strays from its position increments, beyond what its position noise explains.

A receiver's velocity error is not always the white noise its reported accuracy
describes: a slowly varying bias of 0.05-0.1 m/s (a receiver at standstill reporting
motion, multipath on the Doppler) lasts tens of seconds. Fused as white noise of the
reported 2 cm/s, it is what the blend's velocity follows once the IMU is honestly
noisy, and its integral moves the position off the receiver's own centimetre fixes (the
filter then blames those on the receiver's position error).

The receiver's positions measure it, independently of the blend's estimate: over a
baseline of ``T`` (at least :data:`BASELINE_S`) the velocity integrated by the trapezoid
rule less the position increment, divided by ``T``, is the mean velocity error over the
baseline plus the position errors' increment over ``T``. The latter's variance per axis
follows the blend's own model of the position error (white share ``f`` of the reported
variance ``r``, the rest Gauss-Markov of correlation time ``tau``):
``2 f r + 2 (1 - f) r (1 - exp(-T / tau))``, over ``T^2``; the reported velocity noise
adds its variance over the fixes averaged. Per horizontal axis, over the last
:data:`KEPT` baselines, the mean of the squared error over that expectation is
``chi2(K) / K`` for a receiver whose velocity is as good as it says. Beyond the
``1 - FALSE_ALARM_PROB`` quantile, the persistent part of the error (the squared mean
less its own spread over ``K``) is added to the reported velocity variance as the white
equivalent of an error correlated over the window: times ``2 T / dt`` (``T`` the
window, ``dt`` the fix interval: the same low-frequency PSD, ``2 sigma^2 T``). What
varies from baseline to baseline is not counted: the trapezoid rule also errs by the
motion between fixes (a walker's gait sampled at 4 Hz), which is no error of the
receiver's. RTK positions (1-2 cm) see a 0.05 m/s bias within seconds; a 3D fix's
metre-level position noise sees nothing: alone, the reported accuracy stands; after
RTK, the error last measured stands (a persistent error ``b^2`` raises the mean ratio
by ``b^2 mean(1/s)``: baselines for which that stays within the bound could not have
seen it, and the velocity did not improve because the positions became too coarse to
measure it; fused as good to 4 cm/s through 20 s of 3-D fixes, a 0.3 m/s error drifted
the blend metres off while it claimed decimetres, and the first RTK fix after was
excluded as a fault). A change of fix type or a jump of the reported position variance
(a new error regime of the position, :mod:`.receiver`) starts a new chain.

The vertical is left as reported (GPS_RAW_INT has no vertical velocity). Pure: no I/O,
no clock.

References
----------
Groves, Principles of GNSS, inertial and multisensor navigation, 2nd ed., sec. 17.3.1
(measurement consistency); Bar-Shalom, Li and Kirubarajan, Estimation with applications
to tracking and navigation, sec. 5.4.2 (the time-average chi-square test); Bryson and
Henrikson, "Estimation using sampled data containing sequentially correlated noise",
J. Spacecraft and Rockets 5(6), 1968 (time-correlated measurement errors).
"""

from __future__ import annotations

import math
from collections import deque

from scipy.stats import chi2

BASELINE_S = 1.0
"""Shortest baseline over which a velocity is compared with the position increment, s."""
MAX_INTERVAL_S = 1.0
"""Fixes further apart than this break the chain (a gap says nothing), s."""
KEPT = 10
"""Baselines whose mean is tested (10 s of fixes with 1 s baselines)."""
MIN_BASELINES = 3
"""Fewer baselines say nothing."""
FALSE_ALARM_PROB = 1e-3
"""Probability that a velocity as good as reported is found worse."""


class VelocityErrorMeter:
    """Baselines of one receiver's velocity against its positions (module docstring).

    ``white_fraction``: the blend's white share of the position variance (1 for the
    white model).
    """

    def __init__(self, white_fraction: float) -> None:
        self.white_fraction = white_fraction
        self._bounds = {k: float(chi2.isf(FALSE_ALARM_PROB, k)) / k for k in range(1, KEPT + 1)}
        self._samples: deque[tuple[float, float, float, float, float]] = deque(maxlen=KEPT)
        """Per baseline: the mean velocity error N, E (m/s), their expected variances
        (m^2/s^2), its mean fix interval (s)."""
        self.receiver_id: int | None = None
        self.excess_var_ne_m2ps2 = (0.0, 0.0)
        """The velocity variance beyond the reported one, north and east, m^2/s^2."""
        self._held = [0.0, 0.0]
        """The persistent error (m^2/s^2) last measured by baselines able to see it: it
        stands while the baselines since could not have seen it (:meth:`_excess`)."""
        self._held_corr = 1.0
        """Its white equivalent's factor, ``2 T / dt``, when it was measured."""
        self._regime: object = None
        self._last_pos_var = (0.0, 0.0)
        self.restart_chain()

    def seed_at_rest(
        self,
        receiver_id: int,
        vel_ne_mps: tuple[float, float],
        vel_var_ne_m2ps2: tuple[float, float],
    ) -> tuple[float, float]:
        """The vehicle stands still (:func:`~companion.nav.blend.rest.at_rest`): the
        receiver's horizontal velocity is its error. Beyond its reported variance by the
        test's own bound (one sample, false-alarm probability :data:`FALSE_ALARM_PROB`),
        it is held as the persistent error last measured, until baselines that could
        see it show otherwise (:meth:`_excess`). Returns the excess variance to add,
        north and east (m^2/s^2)."""
        if receiver_id != self.receiver_id:
            self.receiver_id = receiver_id
            self._samples.clear()
            self.restart_chain()
        bound = self._bounds[1]
        self._held = [
            v * v if v * v > bound * r else 0.0
            for v, r in zip(vel_ne_mps, vel_var_ne_m2ps2, strict=True)
        ]
        self.excess_var_ne_m2ps2 = (
            self._held[0] * self._held_corr,
            self._held[1] * self._held_corr,
        )
        return self.excess_var_ne_m2ps2

    def restart_chain(self) -> None:
        """Forget the open baseline (a new frame, a restart): the measured excess stays."""
        self._start: tuple[float, float, float] | None = None
        self._prev: tuple[float, float, float] | None = None
        self._prev_vel: tuple[float, float] | None = None
        self._integral = [0.0, 0.0]
        self._vel_var_sum = [0.0, 0.0]
        self._n = 0
        self._start_pos_var = (0.0, 0.0)

    def on_fix(
        self,
        receiver_id: int,
        t_s: float,
        pos_ne_m: tuple[float, float],
        vel_ne_mps: tuple[float, float],
        pos_var_ne_m2: tuple[float, float],
        vel_var_ne_m2ps2: tuple[float, float],
        tau_s: float,
        regime: object = None,
    ) -> tuple[float, float]:
        """Take one fix of ``receiver_id`` (local frame, its reported variances, the
        position error's correlation time ``tau_s``); returns the excess velocity
        variance to add, north and east (m^2/s^2). A change of ``regime`` (the fix type)
        or a jump of the reported position variance beyond 4x starts a new error regime
        (:mod:`.receiver`): the positions before it say nothing about the velocity."""
        if receiver_id != self.receiver_id:
            self.receiver_id = receiver_id
            self._samples.clear()
            self.excess_var_ne_m2ps2 = (0.0, 0.0)
            self._held = [0.0, 0.0]
            self.restart_chain()
        values = (t_s, *pos_ne_m, *vel_ne_mps, *pos_var_ne_m2, *vel_var_ne_m2ps2, tau_s)
        if not all(map(math.isfinite, values)):
            self.restart_chain()
            return self.excess_var_ne_m2ps2
        prev, prev_vel = self._prev, self._prev_vel
        if prev is not None and t_s == prev[0]:
            return self.excess_var_ne_m2ps2  # the same fix again (fused without the gate)
        last_var = self._last_pos_var
        new_regime = regime != self._regime or any(
            v > 4.0 * o or v < 0.25 * o for v, o in zip(pos_var_ne_m2, last_var, strict=True)
        )
        self._regime, self._last_pos_var = regime, pos_var_ne_m2
        if new_regime:  # baselines of another position noise: their verdict is held
            self._samples.clear()
        if (
            new_regime
            or prev is None
            or prev_vel is None
            or not 0.0 < t_s - prev[0] <= MAX_INTERVAL_S
        ):
            self.restart_chain()
            self._start = (t_s, pos_ne_m[0], pos_ne_m[1])
            self._start_pos_var = pos_var_ne_m2
            self._prev, self._prev_vel = self._start, vel_ne_mps
            return self.excess_var_ne_m2ps2
        dt = t_s - prev[0]
        for i in range(2):
            self._integral[i] += 0.5 * (prev_vel[i] + vel_ne_mps[i]) * dt
            self._vel_var_sum[i] += vel_var_ne_m2ps2[i]
        self._n += 1
        self._prev, self._prev_vel = (t_s, pos_ne_m[0], pos_ne_m[1]), vel_ne_mps
        start = self._start
        if start is None or t_s - start[0] < BASELINE_S:
            return self.excess_var_ne_m2ps2
        span = t_s - start[0]
        f = self.white_fraction
        corr = 1.0 - math.exp(-span / tau_s) if math.isfinite(tau_s) and tau_s > 0.0 else 1.0
        sample = []
        for i in range(2):
            err = (self._integral[i] - (pos_ne_m[i] - start[1 + i])) / span
            r = 0.5 * (self._start_pos_var[i] + pos_var_ne_m2[i])
            pos_term = (2.0 * f * r + 2.0 * (1.0 - f) * r * corr) / (span * span)
            vel_term = self._vel_var_sum[i] / (self._n * self._n)
            sample += [err, pos_term + vel_term]
        self._samples.append((sample[0], sample[2], sample[1], sample[3], span / self._n))
        self._start, self._start_pos_var = self._prev, pos_var_ne_m2
        self._integral = [0.0, 0.0]
        self._vel_var_sum = [0.0, 0.0]
        self._n = 0
        self.excess_var_ne_m2ps2 = self._excess()
        return self.excess_var_ne_m2ps2

    def _excess(self) -> tuple[float, float]:
        samples = self._samples
        k = len(samples)
        if k < MIN_BASELINES:
            return (self._held[0] * self._held_corr, self._held[1] * self._held_corr)
        bound = self._bounds[k]
        span = sum(s[4] for s in samples) / k
        # the persistent error (a bias lasting the window) is correlated over it: fused at
        # every fix as white noise, its white equivalent is its variance times 2 T / dt
        # (the same low-frequency PSD, 2 sigma^2 T). What varies from baseline to
        # baseline is not counted: the trapezoid rule also errs by the motion between
        # fixes (a walker's gait sampled at 4 Hz), which is no error of the receiver's
        corr = 2.0 * k * BASELINE_S / span if span > 0.0 else 1.0
        self._held_corr = corr
        out = []
        for i in range(2):
            errs = [s[i] for s in samples]
            ratio = sum(e * e / s[2 + i] for e, s in zip(errs, samples, strict=True)) / k
            if ratio <= bound:
                # a persistent error b^2 raises the mean ratio by b^2 mean(1/s): could these
                # baselines have seen the one last measured? Then it is gone. If not (a 3-D
                # fix's metre-level positions after RTK), it stands: the receiver's velocity
                # did not improve because its positions became too coarse to measure it
                held = self._held[i]
                if held * sum(1.0 / s[2 + i] for s in samples) / k > bound - 1.0:
                    self._held[i] = 0.0
                    held = 0.0
                out.append(held * corr)
                continue
            mean = sum(errs) / k
            var_about = sum((e - mean) ** 2 for e in errs) / (k - 1)
            persistent = max(0.0, mean * mean - var_about / k)
            self._held[i] = persistent
            out.append(persistent * corr)
        return (out[0], out[1])

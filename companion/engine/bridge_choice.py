"""Which motion model carries a GNSS gap: the blend's inertial prediction or constant
velocity, chosen on the flight's own evidence.

An inertial bridge is only as good as the attitude and specific force it integrates. On
real autopilot logs the autopilot's ATTITUDE and the accelerometer can disagree by
degrees, in ways no bias state follows, and a bridge that integrates that drifts metres
in seconds, further than constant velocity would. Whether it does is measured while GNSS
is good, never assumed from the IMU's datasheet:

* a probe starts at a fused fix every ``interval_s`` (the blend carrying, mode NORMAL or
  DEGRADED): it keeps the fix and the fixes' cumulative corrections of the blend's
  position (:meth:`BlendNavigator.fix_corrections`);
* at the first fused fix ``horizon_s`` or more later it closes: the inertial-only
  prediction is the blend's position before that fix less what the fixes in between
  moved it by; constant velocity is the probe's fix moved by its own velocity. Both are
  compared with the new fix horizontally, as the closure of a gap of that length would
  be.

At a gap's start, with at least ``min_probes`` of the last ``kept`` probes closed, the
gap is bridged by constant velocity when the inertial prediction's median error is both
larger than constant velocity's and beyond what the IMU's grade allows: the 99 %
horizontal radius of a specific-force error of 1-sigma ``accel_sigma_mps2`` per axis
(the configured accelerometer bias, and the attitude error times g) integrated twice over
the probe's length, ``sqrt(chi2.ppf(0.99, 2)) * a * T^2 / 2``. An IMU and attitude within
their grade keep the inertial bridge, however well constant velocity did on a straight
stretch (it would lose the next turn); only errors the grade cannot explain hand over.
(The filter's own covariance is no judge here: its adaptive noise has already grown to
cover them.) Constant velocity is then carried by the GNSS pass-through, whose
covariance grows with its white-acceleration model (it says how good the bridge is).
"""

from __future__ import annotations

import logging
import math
import statistics
from collections import deque
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from companion.nav.blend import BlendConfig, BlendNavigator
from companion.nav.navigator import GnssMeasurement
from companion.types import FloatArray

log = logging.getLogger(__name__)

H99_PER_SIGMA = math.sqrt(float(chi2.ppf(0.99, 2)))
"""99 % radius of a circular 2-D Gaussian in 1-sigmas per axis (3.035)."""
STANDARD_GRAVITY_MPS2 = 9.80665


def inertial_accel_sigma_mps2(blend: BlendConfig) -> float:
    """The blend model's horizontal specific-force error, 1-sigma per axis (m/s^2): its
    accelerometer bias and its tilt error (the autopilot attitude's, or its own
    strapdown's initial one) times g."""
    tilt = blend.init_att_sigma_rad if blend.mode == "strapdown" else blend.att_err_sigma_rad
    return math.hypot(blend.accel_bias_sigma_mps2, STANDARD_GRAVITY_MPS2 * max(tilt[0], tilt[1]))


@dataclass(frozen=True, slots=True)
class _Probe:
    t_s: float
    """Time of the fix that started it (autopilot clock)."""
    fix_pos_ned_m: FloatArray
    fix_vel_ned_mps: FloatArray
    corrections: tuple[FloatArray, FloatArray]
    """The blend's fix corrections (a, b) just after that fix."""
    generation: int


@dataclass(frozen=True, slots=True)
class ProbeResult:
    """One closed probe: horizontal errors after ``length_s`` (m)."""

    length_s: float
    inertial_m: float
    constant_velocity_m: float


class BridgeEvidence:
    """Probes of the inertial bridge against constant velocity (see the module docstring)."""

    def __init__(
        self,
        accel_sigma_mps2: float,
        horizon_s: float = 5.0,
        interval_s: float = 1.0,
        kept: int = 10,
        min_probes: int = 3,
    ) -> None:
        if not (math.isfinite(accel_sigma_mps2) and accel_sigma_mps2 > 0.0):
            raise ValueError("accel_sigma_mps2 must be finite and > 0")
        self.accel_sigma_mps2 = accel_sigma_mps2
        """The grade's horizontal specific-force error, 1-sigma per axis (m/s^2)."""
        self.horizon_s = horizon_s
        self.interval_s = interval_s
        self.min_probes = min_probes
        self._open: deque[_Probe] = deque()
        self.results: deque[ProbeResult] = deque(maxlen=kept)
        """The latest closed probes."""
        self._next_start_s = -math.inf

    def reset(self) -> None:
        """Forget the open probes (the navigation restarted); the closed ones are kept:
        they describe the IMU and attitude, not one state."""
        self._open.clear()
        self._next_start_s = -math.inf

    def before_fusion(self, meas: GnssMeasurement, blend: BlendNavigator) -> None:
        """A fix the blend is about to take: close the probes it is ``horizon_s`` after."""
        if not self._open:
            return
        t_now = blend.imu_t_s
        state = blend.predict(t_now)
        if state is None:
            self._open.clear()
            return
        a_now, b_now = blend.fix_corrections()
        vel = np.nan_to_num(np.asarray(meas.vel_ned_mps, dtype=float))
        # the fix carried to the blend's time by its own velocity (a fraction of a second)
        fix_at_ins = meas.pos_ned_m + vel * (t_now - meas.t_s)
        while self._open:
            probe = self._open[0]
            if probe.generation != blend.generation:
                self._open.popleft()
                continue
            length_s = meas.t_s - probe.t_s
            if length_s < self.horizon_s:
                break
            self._open.popleft()
            if length_s > self.horizon_s + 2.0 * self.interval_s:
                continue  # a gap in the fixes: not the comparison intended
            a0, b0 = probe.corrections
            inertial = state.pos_ned_m - ((a_now - a0) + (b_now - b0) * t_now)
            err_ins = float(np.hypot(*(inertial - fix_at_ins)[:2]))
            cv = probe.fix_pos_ned_m + probe.fix_vel_ned_mps * length_s
            err_cv = float(np.hypot(*(cv - meas.pos_ned_m)[:2]))
            self.results.append(ProbeResult(length_s, err_ins, err_cv))

    def after_fusion(self, meas: GnssMeasurement, blend: BlendNavigator) -> None:
        """The blend fused ``meas`` while carrying the solution in good GNSS: start a probe
        when one is due."""
        if meas.t_s < self._next_start_s:
            return
        vel = np.asarray(meas.vel_ned_mps, dtype=float)
        if not np.all(np.isfinite(vel[:2])):
            return
        if not blend.initialised:
            return
        self._next_start_s = meas.t_s + self.interval_s
        self._open.append(
            _Probe(
                meas.t_s,
                meas.pos_ned_m.copy(),
                np.nan_to_num(vel),
                blend.fix_corrections(),
                blend.generation,
            )
        )

    def grade_bound_m(self, length_s: float) -> float:
        """The 99 % horizontal radius the IMU's grade allows an inertial-only prediction
        after ``length_s`` (m)."""
        return H99_PER_SIGMA * 0.5 * self.accel_sigma_mps2 * length_s * length_s

    def constant_velocity_better(self) -> bool:
        """Does the evidence say constant velocity bridges better than the inertial
        prediction, which errs beyond its grade (module docstring)? False without enough
        probes."""
        results = self.results
        if len(results) < self.min_probes:
            return False
        ins = statistics.median(r.inertial_m for r in results)
        cv = statistics.median(r.constant_velocity_m for r in results)
        length = statistics.median(r.length_s for r in results)
        return ins > cv and ins > self.grade_bound_m(length)

    def describe(self) -> str:
        """The evidence in a few words (for the log)."""
        results = self.results
        if not results:
            return "no probes"
        ins = statistics.median(r.inertial_m for r in results)
        cv = statistics.median(r.constant_velocity_m for r in results)
        bound = self.grade_bound_m(statistics.median(r.length_s for r in results))
        return (
            f"{len(results)} probes of {self.horizon_s:.0f} s, median: inertial {ins:.2f} m "
            f"(its grade's 99 %: {bound:.2f} m), constant velocity {cv:.2f} m"
        )

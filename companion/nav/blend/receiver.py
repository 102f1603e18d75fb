"""The receiver's own position error as three Gauss-Markov states of the blend (15:18).

GNSS position errors are time-correlated: an RTK or DGPS error (multipath, residual
atmospheric delay) wanders over tens of seconds, so between 5-10 Hz fixes it looks like
signal. Treated as white, it is averaged away and the filter claims a position
covariance far smaller than its error. The blend therefore holds the error as a
first-order Gauss-Markov process per NED axis, of the reported variance and a
correlation time per fix type (:data:`GNSS_ERR_TAU_S`); only a small share of the
reported variance stays white (``BlendConfig.gnss_white_fraction``). The process is
re-started (estimate zero, uncorrelated with the rest of the state) when the fix type
changes or the reported variance jumps, which marks a new error regime.
"""

from __future__ import annotations

import math

import numpy as np

from companion.types import FixType, FloatArray

GNSS_ERR_TAU_S: dict[FixType, float] = {
    FixType.RTK_FIXED: 30.0,
    FixType.RTK_FLOAT: 60.0,
    FixType.DGPS: 120.0,
    FixType.FIX_3D: 300.0,
    FixType.FIX_2D: 300.0,
    FixType.STATIC: 30.0,
    FixType.PPP: 120.0,
}
"""Correlation time (s) of the receiver's position error per fix type: multipath and
residual atmospheric errors wander over tens of seconds to minutes; the order of magnitude
matters more than the figure (see the module docstring)."""

DEFAULT_TAU_S = 300.0
"""Correlation time (s) of a fix type not in :data:`GNSS_ERR_TAU_S`."""


class ReceiverError:
    """The receiver-error estimate and the Gauss-Markov model it follows.

    ``tau_s`` overrides :data:`GNSS_ERR_TAU_S` when given (``BlendConfig.gnss_err_tau_s``).

    Attributes
    ----------
    bias_ned_m : list of 3 floats
        Estimate of the receiver's position error, NED, m.
    var_ned_m2 : (3,) array
        Variance of the Gauss-Markov processes, m^2.
    fix_type : FixType or None
        The fix type the model was started for (None: not started).
    tau_s : float
        Correlation time in use, s.
    """

    __slots__ = ("bias_ned_m", "var_ned_m2", "fix_type", "tau_s", "_var_l", "_tau_override_s")

    def __init__(self, tau_s: float | None) -> None:
        self._tau_override_s = tau_s
        self.reset()

    def reset(self) -> None:
        """No error model yet: the next :meth:`follow` starts one."""
        self.bias_ned_m = [0.0, 0.0, 0.0]
        self.var_ned_m2 = np.zeros(3)
        self.fix_type: FixType | None = None
        self.tau_s = DEFAULT_TAU_S
        self._var_l = [0.0, 0.0, 0.0]

    def follow(self, fix_type: FixType, var: list[float]) -> str | None:
        """Keep the model in step with a fix of type ``fix_type`` and position variance
        ``var`` (3 floats, m^2).

        Returns ``"restart"`` when the fix type changed or the variance jumped by more than
        4x (the estimate is zeroed: the caller must decorrelate the states),
        ``"variance"`` when only the variance moved by more than 5 %, else None.
        """
        old = self._var_l
        jump = False
        small_change = True
        for v, o in zip(var, old, strict=True):
            if v > 4.0 * o or v < 0.25 * o:
                jump = True
            if abs(v - o) > 0.05 * o:
                small_change = False
        if fix_type != self.fix_type or (jump and self.fix_type is not None):
            self.tau_s = self._tau_override_s or GNSS_ERR_TAU_S.get(fix_type, DEFAULT_TAU_S)
            self.fix_type = fix_type
            self.bias_ned_m = [0.0, 0.0, 0.0]
            self._set_var(var)
            return "restart"
        if not small_change:
            self._set_var(var)
            return "variance"
        return None

    def _set_var(self, var: list[float]) -> None:
        self.var_ned_m2 = np.array(var)
        self._var_l = list(var)

    def decay(self, dt_s: float) -> None:
        """Carry the estimate over ``dt_s`` as its model does: a first-order Gauss-Markov
        error relaxes towards zero, e^(-dt/tau) (the error state's F is -1/tau; without
        this the estimate would keep whatever a disagreement once put into it)."""
        if math.isfinite(self.tau_s) and dt_s > 0.0:
            k = math.exp(-dt_s / self.tau_s)
            gb = self.bias_ned_m
            self.bias_ned_m = [gb[0] * k, gb[1] * k, gb[2] * k]

    def rotate(self, rot: FloatArray) -> None:
        """Re-express the estimate in a rotated NED frame (``rot`` (3, 3), old to new)."""
        self.bias_ned_m = (rot @ np.array(self.bias_ned_m)).tolist()

    def inject(self, d_ned_m: list[float]) -> None:
        """Apply an error-state correction (estimate minus truth), 3 floats, m."""
        gb = self.bias_ned_m
        self.bias_ned_m = [gb[0] - d_ned_m[0], gb[1] - d_ned_m[1], gb[2] - d_ned_m[2]]

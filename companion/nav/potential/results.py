"""What the potential filter returns: the test of a fix and a prediction."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from companion.types import FloatArray


@dataclass(frozen=True, slots=True)
class FixTest:
    """Result of testing (and possibly adding) a fix.

    ``chi2`` is ``dᵀ S⁻¹ d``, ``S`` the calibrated innovation covariance
    (``PotentialPrediction.innov_cov_ned_m2`` plus any excess of the fix's
    variance over the calibration's fixes'; NaN when not tested), ``threshold``
    the χ²(3) quantile at ``1 − false_alarm_prob``; ``consistent`` is
    ``chi2 ≤ threshold`` (True when untested); ``accepted`` says whether the
    fix became a source; ``reason`` is empty or names why it did not.
    """

    t_s: float
    chi2: float
    threshold: float
    consistent: bool
    tested: bool
    accepted: bool = False
    reason: str = ""


@dataclass(frozen=True, slots=True)
class PotentialPrediction:
    """Prediction of the potential filter at ``t_s``.

    ``pos_ned_m``, ``vel_ned_mps`` shape (3,); ``cov_ned_m2`` and
    ``vel_cov_ned_m2ps2`` diagonal (3, 3); ``horizon_s`` = ``t_s`` − newest fix;
    ``innov_cov_ned_m2`` diagonal (3, 3) the covariance of ``fix − prediction``
    for a fix as accurate as the newest (the fix test's ``S``; see
    :meth:`PotentialFilter.test_fix`: with slowly varying fix errors it is far
    smaller than ``cov_ned_m2 + R``);
    ``anchor_var_ned_m2`` (3,) the newest fix's reported variance, the part of
    ``cov_ned_m2`` that any other estimate anchored on the same fixes shares.
    """

    t_s: float
    pos_ned_m: FloatArray
    vel_ned_mps: FloatArray
    cov_ned_m2: FloatArray
    vel_cov_ned_m2ps2: FloatArray
    horizon_s: float
    anchor_var_ned_m2: FloatArray = field(default_factory=lambda: np.zeros(3))
    innov_cov_ned_m2: FloatArray = field(default_factory=lambda: np.zeros((3, 3)))

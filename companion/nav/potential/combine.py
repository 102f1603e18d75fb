"""The INS and potential predictions through a gap, combined by their covariances.

Both predictions are carried from the same last fixes, so their errors share
that fix's error: :func:`combine_predictions` takes the cross-covariance
(Bar-Shalom & Campo 1986) and :func:`combine_with_ins` first tests whether the
two agree at all (the track-to-track association test) before combining them.
"""

from __future__ import annotations

import math

import numpy as np

from companion.nav.potential.results import PotentialPrediction
from companion.types import FloatArray


def combine_predictions(
    pos_a: FloatArray,
    cov_a: FloatArray,
    pos_b: FloatArray,
    cov_b: FloatArray,
    cov_ab: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Combine two predictions of the same position by their covariances.

    ``x = a + K (b − a)`` with ``K = (P_a − P_ab) S⁻¹``,
    ``S = P_a + P_b − P_ab − P_abᵀ``: the minimum-variance combination of two
    unbiased estimates whose errors have cross-covariance
    ``P_ab = E[e_a e_bᵀ]`` (zero by default: ``K = P_a (P_a + P_b)⁻¹``, equal to
    ``(P_a⁻¹ + P_b⁻¹)⁻¹`` weighting but without inverting either). Two
    predictions carried from the same fixes share those fixes' error: pass it
    as ``cov_ab`` (e.g. ``PotentialPrediction.anchor_var_ned_m2`` on the
    diagonal) or the combination counts it twice.

    Parameters
    ----------
    pos_a, pos_b : ndarray, shape (n,)
        The two predictions (e.g. INS and potential, NED) [m].
    cov_a, cov_b : ndarray, shape (n, n)
        Their covariances [m²], symmetric positive semi-definite.
    cov_ab : ndarray, shape (n, n), optional
        Cross-covariance of their errors [m²]; ``S`` must be positive definite.

    Returns
    -------
    pos, cov : ndarray, shapes (n,), (n, n)
        ``cov = (I − K) P_a (I − K)ᵀ + K P_b Kᵀ + (I − K) P_ab Kᵀ + K P_abᵀ (I − K)ᵀ``.

    Raises
    ------
    ValueError
        On mismatched shapes, non-finite values or a singular ``S``.

    References
    ----------
    Grzegorzewski (2005), the prediction's place in the bridge; Bar-Shalom, Li & Kirubarajan,
    Estimation with Applications to Tracking and Navigation, §5.2 (the update
    with ``H = I``) and Bar-Shalom & Campo, "The effect of the common process
    noise on the two-sensor fused-track covariance", IEEE TAES 22(6), 1986
    (the correlated case).
    """
    a = np.asarray(pos_a, dtype=np.float64)
    b = np.asarray(pos_b, dtype=np.float64)
    pa = np.asarray(cov_a, dtype=np.float64)
    pb = np.asarray(cov_b, dtype=np.float64)
    n = a.size
    pab = np.zeros((n, n)) if cov_ab is None else np.asarray(cov_ab, dtype=np.float64)
    if (
        a.shape != (n,)
        or b.shape != (n,)
        or pa.shape != (n, n)
        or pb.shape != (n, n)
        or pab.shape != (n, n)
    ):
        raise ValueError("combine_predictions: need vectors (n,) and covariances (n, n)")
    if not all(np.all(np.isfinite(x)) for x in (a, b, pa, pb, pab)):
        raise ValueError("combine_predictions: inputs must be finite")
    s = pa + pb - pab - pab.T
    try:
        c = np.linalg.cholesky(0.5 * (s + s.T))
    except np.linalg.LinAlgError as exc:
        raise ValueError(
            "combine_predictions: P_a + P_b − P_ab − P_abᵀ is not positive definite"
        ) from exc
    # K = (P_a − P_ab) S⁻¹  ->  Kᵀ = S⁻¹ (P_a − P_ab)ᵀ
    kt = np.linalg.solve(c.T, np.linalg.solve(c, (pa - pab).T))
    k = kt.T
    pos = a + k @ (b - a)
    ik = np.eye(n) - k
    # valid for any K: keeps P symmetric positive semi-definite
    cross = ik @ pab @ k.T
    cov = ik @ pa @ ik.T + k @ pb @ k.T + cross + cross.T
    return pos, 0.5 * (cov + cov.T)


def combine_with_ins(
    ins_pos_ned_m: FloatArray,
    ins_cov_ned_m2: FloatArray,
    pred: PotentialPrediction,
    threshold: float,
) -> tuple[FloatArray, FloatArray, float]:
    """The INS and potential predictions through a gap, combined only while they agree.

    Both are carried from the same last fixes, so they share that fix's error: the
    cross-covariance is taken as the newest fix's variance, at most either's own
    (:func:`combine_predictions` with ``cov_ab``). The disagreement ``d = b − a`` is
    tested first: ``χ² = dᵀ S⁻¹ d`` with ``S = P_a + P_b − 2 P_ab``; above ``threshold``
    (a χ²(3) quantile) one of the two covariances is lying — in practice the potential
    one, whose calibration comes from horizons of seconds, in turns the particle cannot
    know — and the INS alone is returned.

    Parameters
    ----------
    ins_pos_ned_m, ins_cov_ned_m2 : ndarray, shapes (3,), (3, 3)
        The INS prediction [m], [m²].
    pred : PotentialPrediction
        The potential prediction at the same time.
    threshold : float
        χ²(3) gate of the disagreement.

    Returns
    -------
    pos_ned_m, cov_ned_m2, chi2 : ndarray (3,), ndarray (3, 3), float
        The combination (or the INS prediction when ``chi2 > threshold``) and the
        disagreement's χ².

    References
    ----------
    Grzegorzewski (2005), the prediction's place in the bridge; Bar-Shalom & Campo 1986 (correlated
    track fusion); the track-to-track association test, Bar-Shalom, Li & Kirubarajan §11.
    """
    shared = np.minimum(
        pred.anchor_var_ned_m2,
        np.minimum(np.diag(ins_cov_ned_m2), np.diag(pred.cov_ned_m2)),
    )
    cov_ab = np.diag(shared)
    d = pred.pos_ned_m - ins_pos_ned_m
    s = ins_cov_ned_m2 + pred.cov_ned_m2 - 2.0 * cov_ab
    try:
        chi2 = float(d @ np.linalg.solve(s, d))
    except np.linalg.LinAlgError:
        chi2 = math.inf
    if not math.isfinite(chi2) or chi2 > threshold:
        return ins_pos_ned_m, ins_cov_ned_m2, chi2
    pos, cov = combine_predictions(
        ins_pos_ned_m, ins_cov_ned_m2, pred.pos_ned_m, pred.cov_ned_m2, cov_ab
    )
    return pos, cov, chi2

"""Linear Kalman filter building blocks: discretisation, prediction, Joseph-form update.

Conventions: the state is a 1-D vector ``x`` of length n, its covariance ``P``
is (n, n); a measurement has m components: innovation ``nu`` (m,), Jacobian
``H`` (m, n), noise covariance ``R`` (m, m). The filters that use this module
are error-state filters: ``x`` is an error estimate, injected into a nominal
state and reset to zero after each update, so only the correction is returned.

Everything is pure numpy/scipy; no state lives here except in
:class:`InnovationWindow`, the moving-window statistics used by the adaptive
noise estimation of the GNSS/INS blend (:mod:`companion.nav.blend.adaptive`).

References
----------
Van Loan, "Computing integrals involving the matrix exponential", IEEE TAC 23(3), 1978.
Bucy & Joseph (1968) for the Joseph-form covariance update.
Mohamed & Schwarz, "Adaptive Kalman filtering for INS/GPS", J. Geodesy 73, 1999
(innovation-based adaptive estimation, as used by El-Mowafy 2005, RTK networks for
precision approach with an adaptive GPS/INS blend).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from scipy.linalg import lapack
from scipy.stats import chi2

from companion.types import FloatArray


def van_loan(f_mat: FloatArray, gqg_mat: FloatArray, dt_s: float) -> tuple[FloatArray, FloatArray]:
    """Discretise ``dx/dt = F x + G w`` over ``dt_s`` (F constant over the step).

    Parameters
    ----------
    f_mat : (n, n) system matrix F, 1/s.
    gqg_mat : (n, n) continuous noise intensity G Qc G^T (units of x squared per s).
    dt_s : step, s (> 0).

    Returns
    -------
    Phi : (n, n) transition matrix exp(F dt).
    Qd : (n, n) discrete process noise, integral of Phi(s) G Qc G^T Phi(s)^T ds, symmetrised.

    References
    ----------
    Van Loan (1978), eq. 1.3-1.4 (block matrix exponential).
    """
    if dt_s <= 0.0:
        raise ValueError(f"dt_s must be > 0, got {dt_s}")
    n = f_mat.shape[0]
    block = np.zeros((2 * n, 2 * n))
    block[:n, :n] = -f_mat
    block[:n, n:] = gqg_mat
    block[n:, n:] = f_mat.T
    e = expm_taylor(block * dt_s)
    phi = e[n:, n:].T
    qd = phi @ e[:n, n:]
    return phi, 0.5 * (qd + qd.T)


def discretise_second_order(
    f_mat: FloatArray, gqg_diag: FloatArray, dt_s: float
) -> tuple[FloatArray, FloatArray]:
    """Cheap discretisation for short steps: Phi = I + F dt + (F dt)^2 / 2 and the
    trapezoidal Qd = (Phi Qc Phi^T + Qc) dt / 2, for a diagonal noise intensity.

    Parameters
    ----------
    f_mat : (n, n) system matrix F, 1/s.
    gqg_diag : (n,) diagonal of G Qc G^T.
    dt_s : step, s (> 0); the error is third order in ``||F|| dt``.

    Returns
    -------
    Phi, Qd : (n, n) each.

    References
    ----------
    Groves, Principles of GNSS, inertial and multisensor navigation, 2nd ed., eq. 3.34
    (power-series transition matrix) and eq. 3.46 (trapezoidal process noise).
    """
    if dt_s <= 0.0:
        raise ValueError(f"dt_s must be > 0, got {dt_s}")
    n = f_mat.shape[0]
    fdt = f_mat * dt_s
    phi = _eye(n) + fdt
    phi += 0.5 * fdt.dot(fdt)
    return phi, trapezoid_qd(phi, gqg_diag, dt_s)


def trapezoid_qd(phi: FloatArray, gqg_diag: FloatArray, dt_s: float) -> FloatArray:
    """The trapezoidal process noise ``Qd = (Phi Qc Phi^T + Qc) dt / 2`` of
    :func:`discretise_second_order`, for a transition ``phi`` (n, n) and a diagonal noise
    intensity ``gqg_diag`` (n,); shape (n, n).

    References
    ----------
    Groves, Principles of GNSS, inertial and multisensor navigation, 2nd ed., eq. 3.46.
    """
    n = phi.shape[0]
    qd = (phi * gqg_diag).dot(phi.T) if _blas_ready(phi) else (phi * gqg_diag) @ phi.T
    diag = qd.reshape(-1)[:: n + 1]  # a view of the diagonal
    diag += gqg_diag
    qd *= 0.5 * dt_s
    return qd


def expm_taylor(a_mat: FloatArray, order: int = 10) -> FloatArray:
    """Matrix exponential by scaling and squaring of a truncated Taylor series, (n, n).

    The argument is scaled by 2^-s so its 1-norm is at most 0.5; the truncation error of
    a 10th-order series is then below 0.5^11 / 11! ~ 1e-11 relative, and s squarings
    follow. For the small, well-scaled matrices of a 0.1 s navigation step this costs a
    dozen small matrix products (scipy's Pade expm pays a large fixed overhead per call).

    References
    ----------
    Moler & Van Loan, "Nineteen dubious ways to compute the exponential of a matrix,
    twenty-five years later", SIAM Review 45(1), 2003, method 3 with scaling and squaring.
    """
    norm = float(np.max(np.sum(np.abs(a_mat), axis=0))) if a_mat.size else 0.0
    if not math.isfinite(norm):
        raise ValueError("matrix exponential of a non-finite matrix")
    squarings = max(0, math.ceil(math.log2(norm / 0.5))) if norm > 0.5 else 0
    a = a_mat / (2.0**squarings)
    n = a.shape[0]
    result = np.eye(n)
    term = np.eye(n)
    for k in range(1, order + 1):
        term = term @ a / k
        result = result + term
    for _ in range(squarings):
        result = result @ result
    return result


def predict_covariance(p_mat: FloatArray, phi: FloatArray, qd: FloatArray) -> FloatArray:
    """Covariance prediction ``Phi P Phi^T + Qd``, symmetrised, shape (n, n).

    (``ndarray.dot`` here and below: the same BLAS products as ``@``, equal values, at about
    half the call overhead, which dominates at these sizes.)
    """
    if _blas_ready(phi) and _blas_ready(p_mat):
        p_new = phi.dot(p_mat).dot(phi.T)
    else:
        p_new = phi @ p_mat @ phi.T
    p_new += qd
    return _symmetrised(p_new)


@dataclass(frozen=True, slots=True)
class Correction:
    """The outcome of one Kalman update.

    ``dx`` (n,) is the state correction, ``p_post`` (n, n) the updated covariance,
    ``gain`` (n, m) the Kalman gain, ``innov_cov`` (m, m) the predicted innovation
    covariance S = H P H^T + R, ``nis`` the normalised innovation squared
    nu^T S^-1 nu and ``std_innov`` (m,) the standardised innovation L^-1 nu
    (L the Cholesky factor of S): N(0, I) when the filter is consistent.
    """

    dx: FloatArray
    p_post: FloatArray
    gain: FloatArray
    innov_cov: FloatArray
    nis: float
    std_innov: FloatArray


def innovation_stats(
    p_mat: FloatArray, nu: FloatArray, h_mat: FloatArray, r_mat: FloatArray
) -> tuple[FloatArray, FloatArray, float, FloatArray]:
    """Innovation covariance, its Cholesky factor, the NIS and the standardised innovation.

    Returns ``(S, L, nis, std_innov)`` with S (m, m), L lower (m, m), nis scalar, std (m,).
    Raises ``ValueError`` when S is not positive definite.
    """
    s_mat = h_mat @ p_mat @ h_mat.T + r_mat
    s_mat = 0.5 * (s_mat + s_mat.T)
    try:
        chol: FloatArray = np.asarray(np.linalg.cholesky(s_mat), dtype=np.float64)
    except np.linalg.LinAlgError as exc:
        raise ValueError("innovation covariance is not positive definite") from exc
    std: FloatArray = np.asarray(np.linalg.solve(chol, nu), dtype=np.float64)
    return s_mat, chol, float(std @ std), std


def joseph_update(
    p_mat: FloatArray, nu: FloatArray, h_mat: FloatArray, r_mat: FloatArray
) -> Correction:
    """Kalman correction with the Joseph-form covariance update.

    Parameters
    ----------
    p_mat : (n, n) prior covariance.
    nu : (m,) innovation z - h(x).
    h_mat : (m, n) measurement Jacobian.
    r_mat : (m, m) measurement noise covariance.

    Returns
    -------
    Correction
        ``dx = K nu``, ``P+ = (I - K H) P (I - K H)^T + K R K^T``.

    References
    ----------
    El-Mowafy (2005) (the blend's K, update equations); Joseph form: Bucy & Joseph (1968).
    """
    return _joseph(p_mat, nu, h_mat, r_mat, None)


def joseph_update_diag_r(
    p_mat: FloatArray, nu: FloatArray, h_mat: FloatArray, r_diag: FloatArray
) -> Correction:
    """:func:`joseph_update` for a diagonal R given by its diagonal ``r_diag`` (m,).

    The same Joseph form; ``K R K^T`` is formed as ``(K * r) K^T`` (the zero
    off-diagonal products of a full R add nothing).
    """
    return _joseph(p_mat, nu, h_mat, None, r_diag)


def _joseph(
    p_mat: FloatArray,
    nu: FloatArray,
    h_mat: FloatArray,
    r_mat: FloatArray | None,
    r_diag: FloatArray | None,
) -> Correction:
    """Shared body of the Joseph-form updates (exactly one of ``r_mat``, ``r_diag``)."""
    # strided views (e.g. a block of a larger array) are copied first, so that ndarray.dot
    # below only meets contiguous operands, for which it equals @ (see _blas_ready)
    if not _blas_ready(p_mat):
        p_mat = np.ascontiguousarray(p_mat)
    if not _blas_ready(h_mat):
        h_mat = np.ascontiguousarray(h_mat)
    if not _blas_ready(nu):
        nu = np.ascontiguousarray(nu)
    if r_mat is not None and not _blas_ready(r_mat):
        r_mat = np.ascontiguousarray(r_mat)
    # ndarray.dot throughout: the same BLAS products as ``@`` (equal values) at about half
    # the call overhead, which dominates at these sizes
    pht = p_mat.dot(h_mat.T)
    s_mat = h_mat.dot(pht)
    if r_diag is not None:
        m = s_mat.shape[0]
        s_mat.ravel()[:: m + 1] += r_diag  # a view of the diagonal
    elif r_mat is not None:
        s_mat += r_mat
    else:
        raise ValueError("a measurement noise covariance is needed")
    s_mat = _symmetrised(s_mat)
    # LAPACK directly (dpotrf, dtrtri): numpy.linalg's wrappers cost several times the
    # factorisation of a matrix this small
    chol, info = _dpotrf(s_mat, lower=1, clean=1)
    if info != 0:
        raise ValueError("innovation covariance is not positive definite")
    # S^-1 = L^-T L^-1: one small triangular inverse serves the gain, the NIS and nu_std
    linv, info = _dtrtri(chol, lower=1)
    if info != 0:
        raise ValueError("innovation covariance is not positive definite")
    std = linv.dot(nu)
    gain = pht.dot(linv.T.dot(linv))
    ikh = _eye(p_mat.shape[0]) - gain.dot(h_mat)
    p_post = ikh.dot(p_mat).dot(ikh.T)
    if r_diag is not None:
        p_post += (gain * r_diag).dot(gain.T)
    elif r_mat is not None:
        p_post += gain.dot(r_mat).dot(gain.T)
    return Correction(gain.dot(nu), _symmetrised(p_post), gain, s_mat, float(std.dot(std)), std)


def _blas_ready(a: FloatArray) -> bool:
    """True when ``a`` is C- or F-contiguous. ``ndarray.dot`` and ``@`` then hand it to the
    same BLAS routine (equal values); a strided view (a sub-block) takes different routes in
    the two (a copy in one, strides or numpy's own loop in the other) and may round
    differently, so the callers keep ``@`` for those."""
    flags = a.flags
    return bool(flags.c_contiguous or flags.f_contiguous)


_dpotrf = lapack.dpotrf
_dtrtri = lapack.dtrtri

_EYES: dict[int, FloatArray] = {}


def _eye(n: int) -> FloatArray:
    """A shared, read-only identity (n, n) (building one per call costs more than using it)."""
    eye = _EYES.get(n)
    if eye is None:
        eye = np.eye(n)
        eye.flags.writeable = False
        _EYES[n] = eye
    return eye


def _symmetrised(a_mat: FloatArray) -> FloatArray:
    """``0.5 (A + A^T)``, a new array (A is left as it was)."""
    # A^T + A (the same sums) from a contiguous copy: cheaper than adding a strided view
    sym = a_mat.T.copy()
    sym += a_mat
    sym *= 0.5
    return sym


def chi2_gate(false_alarm_prob: float, dof: int) -> float:
    """NIS threshold that a consistent filter exceeds with probability ``false_alarm_prob``."""
    if not 0.0 < false_alarm_prob < 1.0:
        raise ValueError(f"false_alarm_prob must be in (0, 1), got {false_alarm_prob}")
    if dof < 1:
        raise ValueError(f"dof must be >= 1, got {dof}")
    return float(chi2.ppf(1.0 - false_alarm_prob, dof))


class InnovationWindow:
    """Moving-window means of per-component statistics (the blend's adaptive R and Q).

    Each of ``n_components`` keeps its last ``window`` values (a running sum makes
    the mean O(1); it is recomputed exactly every ``window`` additions so rounding
    cannot accumulate). The blend feeds it, per position component,
    ``(v_i^2 + (H P+ H^T)_ii) / R_rep,i`` (residual form of Mohamed & Schwarz 1999,
    relative to the reported variance) and, per NED axis, its accelerometer PSD
    estimate. Non-finite values are ignored.
    """

    def __init__(self, n_components: int, window: int) -> None:
        if n_components < 1:
            raise ValueError("n_components must be >= 1")
        if window < 2:
            raise ValueError("window must be >= 2")
        self.window = window
        self._buf: list[deque[float]] = [deque(maxlen=window) for _ in range(n_components)]
        self._sum = [0.0] * n_components
        self._adds = [0] * n_components

    def add(self, index: int, value: float) -> None:
        """Append one value for component ``index`` (non-finite values are ignored)."""
        if not math.isfinite(value):
            return
        buf = self._buf[index]
        sums = self._sum
        if len(buf) == self.window:
            sums[index] -= buf[0]
        buf.append(value)
        adds = self._adds[index] + 1
        self._adds[index] = adds
        if adds % self.window == 0:
            sums[index] = math.fsum(buf)
        else:
            sums[index] += value

    def ready_mean(self, index: int, min_count: int) -> float | None:
        """Window mean of component ``index`` when it holds at least ``min_count`` values,
        else None (:meth:`count` and :meth:`mean` in one call)."""
        n = len(self._buf[index])
        if n < min_count or n == 0:
            return None
        return self._sum[index] / n

    def count(self, index: int) -> int:
        """Number of values held for component ``index``."""
        return len(self._buf[index])

    def mean(self, index: int) -> float:
        """Window mean of component ``index`` (NaN when empty)."""
        n = len(self._buf[index])
        return self._sum[index] / n if n else float("nan")

    def clear(self) -> None:
        """Forget every value."""
        for i, buf in enumerate(self._buf):
            buf.clear()
            self._sum[i] = 0.0
            self._adds[i] = 0

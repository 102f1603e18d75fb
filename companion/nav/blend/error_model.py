"""The blend's 18-state error model: state layout, system matrix F, the diagonal noise
intensity G Qc G^T, their discretisation over a covariance segment, and the short
covariance carries between segment boundaries.

States (estimate minus truth, :mod:`companion.nav.ins`): position (0:3, m), velocity
(3:6, m/s), attitude error psi (6:9, rad), accelerometer bias (9:12, m/s^2), gyro bias
(12:15, rad/s), and the receiver's own position error (15:18, NED, m; :mod:`.receiver`).

References
----------
Titterton & Weston, Strapdown Inertial Navigation Technology, 2nd ed., eq. 12.20-12.22
(psi-angle error model); Groves, Principles of GNSS, inertial and multisensor navigation,
2nd ed., eq. 3.34 and 3.46 (second-order discretisation); Van Loan, "Computing integrals
involving the matrix exponential", IEEE TAC 23(3), 1978.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from companion.nav import ins
from companion.nav.blend.config import BlendConfig
from companion.nav.kalman import discretise_second_order, van_loan
from companion.nav.rotations import Mat3Values, Quat, Vec3, quat_to_mat_values
from companion.types import FloatArray

N_STATE = ins.N_ERR + 3
"""Blend state size: the 15 INS error states and the GNSS position error (15:18, NED, m)."""
IGB = ins.N_ERR
"""First index of the receiver's position error states."""

_HOUR_S = 3600.0


def gm_psd(sigma: float, tau_s: float) -> float:
    """White-noise PSD driving a first-order Gauss-Markov process of steady-state ``sigma``.

    For ``tau_s = inf`` the bias is a random walk reaching ``sigma`` in one hour.
    """
    if math.isfinite(tau_s):
        return 2.0 * sigma**2 / tau_s
    return sigma**2 / _HOUR_S


def _block(row: int, col: int) -> list[tuple[int, int]]:
    """The (row, col) entries of the 3x3 block at ``row``, ``col``, row-major."""
    return [(row + i, col + j) for i in range(3) for j in range(3)]


def _flat_index(entries: list[tuple[int, int]]) -> npt.NDArray[np.intp]:
    """Flat indices into an (N_STATE, N_STATE) array of (row, col) entries."""
    return np.array([r * N_STATE + c for r, c in entries], dtype=np.intp)


_F_VARIABLE_ENTRIES = [(3, 7), (3, 8), (4, 6), (4, 8), (5, 6), (5, 7)] + _block(3, 9)
"""Entries of F that change per segment: skew(f) (off-diagonal) and -C (see f_filled)."""
_F_STRAPDOWN_ENTRIES = _block(6, 12)
"""Strapdown: the C block of the attitude error's gyro-bias coupling."""
_F_UNAIDED_ENTRIES = [(ins.IA + 2, ins.IBG + j) for j in range(3)]
"""Attitude-aided, unaided (:meth:`ErrorModel.set_unaided`): the heading row of that block
(the whole block, as strapdown's, when the tilt is unaided too)."""


class ErrorModel:
    """F and G Qc G^T of the blend for one configuration, and their discretisation.

    F is kept in a preallocated template whose constant entries (the INS error model's
    correlation times, the receiver error's) are written once and whose per-segment
    entries (the specific force and the attitude) are filled in place. ``gqg`` is the
    diagonal (18,) of G Qc G^T in use: the configuration's attitude and bias noises, the
    accelerometer PSD in use and the receiver-error block.
    """

    def __init__(self, config: BlendConfig) -> None:
        cfg = config
        self._cfg = cfg
        self._strapdown = cfg.mode == "strapdown"
        self._unaided = False
        self._tilt_unaided = False
        self._van_loan = cfg.cov_discretisation == "van_loan"
        self._f_template = np.zeros((N_STATE, N_STATE))
        self._f_flat = self._f_template.reshape(-1)  # a view: writes fill the template
        self._accel_psd_ned = np.zeros(3)
        self._gyro_psd: float | None = None
        self._gb_var: FloatArray | None = None
        self._gb_tau_s = 300.0
        self._rebuild()  # F's constant entries, the static noise, ``gqg``

    gqg: FloatArray
    """Diagonal (18,) of the continuous noise intensity G Qc G^T in use."""

    def set_strapdown(self, strapdown: bool) -> None:
        """Model the attitude error as a strapdown's (gyro noise and bias, ``True``) or as
        the autopilot's attitude error (Gauss-Markov, ``False``) from now on; the
        accelerometer PSD and the receiver-error block are kept."""
        if strapdown is self._strapdown:
            return
        self._strapdown = strapdown
        self._rebuild()

    def set_unaided(self, unaided: bool, *, tilt: bool = False) -> None:
        """Attitude-aided mode: model the autopilot's heading error as unaided (``True``:
        a GNSS gap it shares) or aided (``False``). Unaided, nothing pulls the heading
        error back: no Gauss-Markov decay about down; the same white noise drives it, and
        the bias of the autopilot's body rates (the gyro-bias states) turns it, as a
        strapdown's heading. Its tilt keeps the Gauss-Markov model (an autopilot whose
        filter still has other aiding, an airspeed, keeps levelling it) unless ``tilt``:
        a filter that has lost all aiding (it holds its position still) no longer
        separates its tilt from the vehicle's accelerations, and its tilt error is
        modelled the same way. No effect in strapdown mode."""
        tilt = unaided and tilt
        if unaided is self._unaided and tilt is self._tilt_unaided:
            return
        self._unaided = unaided
        self._tilt_unaided = tilt
        self._rebuild()

    def _rebuild(self) -> None:
        """F's constant entries and the static noise for the attitude model in use."""
        cfg = self._cfg
        self._gqg_static = self._static_gqg(cfg)
        self._f_template[: ins.N_ERR, : ins.N_ERR] = ins.error_model_f(
            np.zeros(3),
            np.zeros((3, 3)),
            strapdown=self._strapdown,
            tau_att_s=cfg.att_err_tau_s,
            tau_ba_s=cfg.accel_bias_tau_s,
            tau_bg_s=cfg.gyro_bias_tau_s,
        )
        entries = list(_F_VARIABLE_ENTRIES)
        if self._strapdown:
            entries += _F_STRAPDOWN_ENTRIES
        elif self._tilt_unaided:
            for i in range(3):  # no pull back about any axis
                self._f_template[ins.IA + i, ins.IA + i] = 0.0
            entries += _F_STRAPDOWN_ENTRIES
        elif self._unaided:
            self._f_template[ins.IA + 2, ins.IA + 2] = 0.0  # no pull back about down
            entries += _F_UNAIDED_ENTRIES
        self._f_idx = _flat_index(entries)
        self.gqg = self._make_gqg()

    def _static_gqg(self, cfg: BlendConfig) -> FloatArray:
        """The configuration's part of ``gqg`` (attitude and bias noises), (18,)."""
        g = np.zeros(N_STATE)
        if self._strapdown:
            g[6:9] = cfg.gyro_arw_rad_rts**2
        else:
            sig = np.array(cfg.att_err_sigma_rad)
            g[6:9] = 2.0 * sig**2 / cfg.att_err_tau_s
        g[9:12] = gm_psd(cfg.accel_bias_sigma_mps2, cfg.accel_bias_tau_s)
        g[12:15] = gm_psd(cfg.gyro_bias_sigma_radps, cfg.gyro_bias_tau_s)
        return g

    def _make_gqg(self) -> FloatArray:
        g = self._gqg_static.copy()
        g[3:6] = self._accel_psd_ned
        if self._strapdown and self._gyro_psd is not None:
            g[6:9] = self._gyro_psd
        if self._gb_var is not None:
            g[IGB : IGB + 3] = 2.0 * self._gb_var / self._gb_tau_s
        return g

    def reset(self, accel_psd_ned: FloatArray) -> None:
        """Start again with the accelerometer PSD ``accel_psd_ned`` (3,), m^2/s^3, and no
        receiver-error noise (until :meth:`restart_receiver_error`)."""
        self._accel_psd_ned = accel_psd_ned
        self._gb_var = None
        self.gqg = self._make_gqg()

    def set_accel_psd(self, accel_psd_ned: FloatArray) -> None:
        """Use the accelerometer white-noise PSD ``accel_psd_ned`` (3,), m^2/s^3."""
        self._accel_psd_ned = accel_psd_ned
        self.gqg = self._make_gqg()

    def set_gyro_psd(self, psd_rad2ps: float | None) -> None:
        """Strapdown: drive the attitude error with the gyro white-noise PSD ``psd_rad2ps``
        (rad^2/s; None: the configured ``gyro_arw_rad_rts`` squared). Attitude-aided mode
        ignores it (its attitude noise is the autopilot's attitude error)."""
        self._gyro_psd = psd_rad2ps
        self.gqg = self._make_gqg()

    def restart_receiver_error(self, var_ned_m2: FloatArray, tau_s: float) -> None:
        """Drive the receiver-error states as Gauss-Markov processes of variance
        ``var_ned_m2`` (3,) and correlation time ``tau_s`` (a new error regime)."""
        self._f_template[IGB : IGB + 3, IGB : IGB + 3] = -np.eye(3) / tau_s
        self._gb_tau_s = tau_s
        self.set_receiver_variance(var_ned_m2)

    def set_receiver_variance(self, var_ned_m2: FloatArray) -> None:
        """A new variance (3,) of the receiver-error states, same correlation time."""
        self._gb_var = var_ned_m2
        self.gqg = self._make_gqg()

    def f_filled(self, f_ned: Vec3, mat_nb: Mat3Values) -> FloatArray:
        """F (18, 18) of :func:`companion.nav.ins.error_model_f` (and the receiver-error
        block), filled in place into the preallocated template and returned (a view that
        the next call overwrites). ``mat_nb`` is row-major (9 floats)."""
        f0, f1, f2 = f_ned
        c00, c01, c02, c10, c11, c12, c20, c21, c22 = mat_nb
        values = [-f2, f1, f2, -f0, -f1, f0, -c00, -c01, -c02, -c10, -c11, -c12, -c20, -c21, -c22]
        if self._strapdown or self._tilt_unaided:
            values += mat_nb
        elif self._unaided:
            values += (c20, c21, c22)
        # one indexed assignment instead of a dozen element writes
        self._f_flat[self._f_idx] = values
        return self._f_template

    def transition(self, dt_s: float, f_ned: Vec3, q_nb: Quat) -> tuple[FloatArray, FloatArray]:
        """Phi and Qd (18, 18) of a segment of ``dt_s`` with mean NED specific force
        ``f_ned`` and the attitude ``q_nb`` at its end."""
        f_mat = self.f_filled(f_ned, quat_to_mat_values(q_nb))
        if self._van_loan:
            return van_loan(f_mat, np.diag(self.gqg), dt_s)
        return discretise_second_order(f_mat, self.gqg, dt_s)

    def carry_open_segment(
        self, dx: FloatArray, seg_fn_sum: Sequence[float], dt_s: float, q_nb: Quat
    ) -> FloatArray:
        """A correction ``dx`` (18,) carried to first order over the open segment (shorter
        than a covariance interval): ``dx + F dx dt``, F at the segment's mean specific
        force (``seg_fn_sum / dt_s``) and attitude ``q_nb``."""
        sm = seg_fn_sum
        f_ned = (sm[0] / dt_s, sm[1] / dt_s, sm[2] / dt_s)
        f_dx = self.f_filled(f_ned, quat_to_mat_values(q_nb)).dot(dx)
        f_dx *= dt_s
        return dx + f_dx


def open_segment_cov(b: list[list[float]], psd: list[float], dt_s: float) -> tuple[float, ...]:
    """Position and velocity covariances carried ``dt_s`` through ``position += velocity dt``
    with white acceleration noise of PSD ``psd`` (3 floats, m^2/s^3) from the 6x6
    position/velocity block ``b`` (nested lists): 18 floats, the symmetrised position
    covariance then the velocity covariance, row-major.

    Per entry (i, j) of the position block: ((P_pv + P_vp) dt + P_pp) + dt^2 P_vv, plus
    psd dt^3 / 3 on the diagonal, then (A + A^T) / 2; the velocity block gains psd dt on its
    diagonal. Written out in floats (once per published state: a dozen numpy calls on 3x3
    arrays cost more than the arithmetic); the same operations as the array form.
    """
    b0, b1, b2, b3, b4, b5 = b
    q0, q1, q2 = psd
    dt2 = dt_s**2
    dt3 = dt_s**3
    a00 = ((b0[3] + b3[0]) * dt_s + b0[0]) + dt2 * b3[3] + q0 * dt3 / 3.0
    a01 = ((b0[4] + b3[1]) * dt_s + b0[1]) + dt2 * b3[4]
    a02 = ((b0[5] + b3[2]) * dt_s + b0[2]) + dt2 * b3[5]
    a10 = ((b1[3] + b4[0]) * dt_s + b1[0]) + dt2 * b4[3]
    a11 = ((b1[4] + b4[1]) * dt_s + b1[1]) + dt2 * b4[4] + q1 * dt3 / 3.0
    a12 = ((b1[5] + b4[2]) * dt_s + b1[2]) + dt2 * b4[5]
    a20 = ((b2[3] + b5[0]) * dt_s + b2[0]) + dt2 * b5[3]
    a21 = ((b2[4] + b5[1]) * dt_s + b2[1]) + dt2 * b5[4]
    a22 = ((b2[5] + b5[2]) * dt_s + b2[2]) + dt2 * b5[5] + q2 * dt3 / 3.0
    s01 = (a01 + a10) * 0.5
    s02 = (a02 + a20) * 0.5
    s12 = (a12 + a21) * 0.5
    return (
        (a00 + a00) * 0.5,
        s01,
        s02,
        s01,
        (a11 + a11) * 0.5,
        s12,
        s02,
        s12,
        (a22 + a22) * 0.5,
        b3[3] + q0 * dt_s,
        b3[4],
        b3[5],
        b4[3],
        b4[4] + q1 * dt_s,
        b4[5],
        b5[3],
        b5[4],
        b5[5] + q2 * dt_s,
    )


def carry_pos_vel(p: FloatArray, dt_s: float, accel_psd_ned: FloatArray) -> FloatArray:
    """Covariance carried ``dt_s`` forward through ``position += velocity * dt`` with white
    acceleration noise of PSD ``accel_psd_ned`` [m^2/s^3]: the dominant coupling over a
    fraction of a covariance interval. ``p`` is (N_STATE, N_STATE)."""
    carried = p.copy()
    carried[0:3, :] += dt_s * p[3:6, :]  # Phi P: position rows gain dt x velocity rows
    carried[:, 0:3] += dt_s * carried[:, 3:6]  # (Phi P) Phi^T: the same for the columns
    # the white acceleration noise on the diagonals of the four 3x3 blocks, in one indexed
    # add (the same per-element products as the array forms)
    psd = accel_psd_ned.tolist()
    q_pp = [q * dt_s**3 / 3.0 for q in psd]
    q_pv = [q * dt_s**2 / 2.0 for q in psd]
    q_vv = [q * dt_s for q in psd]
    carried.reshape(-1)[_CARRY_NOISE_IDX] += q_pp + q_pv + q_pv + q_vv
    return carried


_CARRY_NOISE_IDX = _flat_index(
    [(i, i) for i in range(3)]
    + [(i, 3 + i) for i in range(3)]
    + [(3 + i, i) for i in range(3)]
    + [(3 + i, 3 + i) for i in range(3)]
)
"""Flat indices of the diagonals of the position/velocity 3x3 blocks (see carry_pos_vel)."""

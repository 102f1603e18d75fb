"""How a GNSS fix enters the blend: its variances, the innovation and the Jacobian.

Loose coupling (El-Mowafy 2005): the receiver's position and velocity are the
measurements, with R from the accuracies it reports, else the fallback accuracy of its
fix type (:data:`companion.nav.gnss.FALLBACK_STD_M`), floored. With a lever arm the
measurement is of the antenna: position ``p + C l`` and velocity ``v + C (omega x l)``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from companion.nav import ins
from companion.nav.blend.config import BlendConfig
from companion.nav.blend.error_model import IGB, N_STATE
from companion.nav.gnss import FALLBACK_STD_M, UNKNOWN_STD_M
from companion.nav.navigator import GnssMeasurement
from companion.nav.rotations import Quat, quat_to_mat, skew
from companion.types import FloatArray


class GnssModel:
    """The measurement model of one configuration (floors, fallbacks, lever arm, whether
    the receiver error is a state), with the Jacobians of each set of velocity axes cached.
    """

    def __init__(self, config: BlendConfig) -> None:
        cfg = config
        self.lever_b_m = np.array(cfg.lever_arm_b_m, dtype=float)
        """GNSS antenna position relative to the IMU, body FRD, m, (3,)."""
        self.has_lever = bool(np.any(self.lever_b_m != 0.0))
        self._gm = cfg.gnss_error_model == "gauss_markov"
        self._white_fraction = cfg.gnss_white_fraction
        h_fl, v_fl = cfg.pos_std_floor_m
        self._pos_floor_t = (h_fl**2, h_fl**2, v_fl**2)
        # variances assumed when the receiver reports none (FALLBACK_STD_M squared)
        self._pos_fallback = {
            fix: (h_std**2, h_std**2, v_std**2) for fix, (h_std, v_std) in FALLBACK_STD_M.items()
        }
        h_un, v_un = UNKNOWN_STD_M
        self._pos_fallback_other = (h_un**2, h_un**2, v_un**2)
        self._vel_fallback_floor = (cfg.vel_std_fallback_mps**2, cfg.vel_std_floor_mps**2)
        self._h_cache: dict[tuple[bool, ...], tuple[tuple[int, ...], FloatArray]] = {}

    def reported_variances(self, meas: GnssMeasurement) -> tuple[list[float], list[float]]:
        """Position and velocity variances (3 floats each): reported, else fallback, floored."""
        fallback = self._pos_fallback.get(meas.fix_type, self._pos_fallback_other)
        r_pos = meas.pos_var_ned_m2.tolist()
        for i, (fb, fl) in enumerate(zip(fallback, self._pos_floor_t, strict=True)):
            r = r_pos[i]
            r_pos[i] = max(r if (math.isfinite(r) and r > 0.0) else fb, fl)
        vel_fb, vel_fl = self._vel_fallback_floor
        r_vel = meas.vel_var_ned_m2ps2.tolist()
        for i, r in enumerate(r_vel):
            r_vel[i] = max(r if (math.isfinite(r) and r > 0.0) else vel_fb, vel_fl)
        return r_pos, r_vel

    def white_part(self, r_pos: Sequence[float]) -> list[float]:
        """White share of the reported position variance (floored), 3 floats."""
        frac = self._white_fraction
        f0, f1, f2 = self._pos_floor_t
        return [max(frac * r_pos[0], f0), max(frac * r_pos[1], f1), max(frac * r_pos[2], f2)]

    def innovation(
        self,
        meas: GnssMeasurement,
        z_pos: list[float],
        pos: list[float],
        vel: list[float],
        q_nb: Quat,
        r_pos: list[float],
        r_vel: list[float],
        gyro_b_radps: Sequence[float],
        gyro_bias_b_radps: Sequence[float],
        receiver_error_ned_m: list[float],
    ) -> tuple[tuple[int, ...], list[float], FloatArray, list[float]]:
        """Velocity axes used, y = h(x_hat) - z (m floats: 3 position components, then the
        velocity axes), H (m, 18) (read-only), reported R diagonal (m floats).

        ``pos``, ``vel`` and ``q_nb`` are the nominal state at the fix time, ``z_pos`` the
        fix's position (3 floats), ``gyro_b_radps`` and ``gyro_bias_b_radps`` the last gyro
        reading and the gyro bias estimate (the lever arm's velocity), and
        ``receiver_error_ned_m`` the receiver-error estimate (3 floats, m).
        """
        vel_z = meas.vel_ned_mps.tolist()
        key = (math.isfinite(vel_z[0]), math.isfinite(vel_z[1]), math.isfinite(vel_z[2]))
        cached = self._h_cache.get(key)
        if cached is None:
            axes_c = tuple(i for i in range(3) if key[i])
            h_c = np.zeros((3 + len(axes_c), N_STATE))
            h_c[0:3, ins.IP : ins.IP + 3] = np.eye(3)
            if self._gm:
                h_c[0:3, IGB : IGB + 3] = np.eye(3)
            for k, axis in enumerate(axes_c):
                h_c[3 + k, ins.IV + axis] = 1.0
            h_c.flags.writeable = False  # shared between fixes
            cached = (axes_c, h_c)
            self._h_cache[key] = cached
        axes, h_mat = cached
        pos_ant: Sequence[float] = pos
        vel_ant: Sequence[float] = vel
        if self.has_lever:
            lever = self.lever_b_m
            mat_nb = quat_to_mat(q_nb)
            lever_n = mat_nb @ lever
            pos_ant = (np.array(pos) + lever_n).tolist()
            h_mat = h_mat.copy()
            h_mat[0:3, ins.IA : ins.IA + 3] = skew(lever_n)
            omega = np.array(gyro_b_radps) - np.array(gyro_bias_b_radps)
            vel_ant = (np.array(vel) + mat_nb @ np.cross(omega, lever)).tolist()
        gb = receiver_error_ned_m
        y = [(pos_ant[i] + gb[i]) - z_pos[i] for i in range(3)]
        y += [vel_ant[a] - vel_z[a] for a in axes]
        r_rep = r_pos + [r_vel[a] for a in axes]
        return axes, y, h_mat, r_rep

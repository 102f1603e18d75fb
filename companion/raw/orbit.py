"""Satellite position, velocity and clock from a broadcast ephemeris (IS-GPS-200).

Galileo I/NAV ephemerides use the same algorithm with the Galileo OS SIS ICD constants.

Position: the user algorithm of IS-GPS-200 Table 20-IV, in ECEF at the time of
transmission. Clock: the polynomial of 20.3.3.3.3.1 with the relativistic term
Δt_r = F e √A sin E_k. Velocity: the analytic time derivative of the same equations.
:func:`sat_state_at_reception` adds the Earth's rotation during the signal's flight
(the satellite's ECEF position rotated into the frame of the reception time).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from companion.raw.lnav import Ephemeris
from companion.raw.obs import C_MPS

FloatArray = npt.NDArray[np.float64]

MU_M3PS2 = 3.986005e14
"""WGS 84 gravitational parameter as IS-GPS-200 fixes it."""
OMEGA_E_RADPS = 7.2921151467e-5
"""WGS 84 Earth rotation rate."""
F_REL = -4.442807633e-10
"""Relativistic constant F = -2 √μ / c² (s/√m)."""
HALF_WEEK_S = 302_400.0
MU_GAL_M3PS2 = 3.986004418e14
"""Galileo OS SIS ICD 5.1.1 gravitational parameter."""
F_REL_GAL = -4.442807309e-10


@dataclass(frozen=True)
class SatState:
    """A satellite at one instant: ECEF position and velocity, clock offset and drift.

    ``clock_s`` includes the relativistic term and excludes the group delay T_GD (the
    caller subtracts it for single-frequency L1 C/A; it cancels in time differences).
    """

    pos_ecef_m: FloatArray
    vel_ecef_mps: FloatArray
    clock_s: float
    clock_drift_sps: float
    relativistic_s: float


def wrap_week(dt_s: float) -> float:
    """A time difference folded into ±half a week (IS-GPS-200 20.3.3.4.3.1)."""
    if dt_s > HALF_WEEK_S:
        return dt_s - 2 * HALF_WEEK_S
    if dt_s < -HALF_WEEK_S:
        return dt_s + 2 * HALF_WEEK_S
    return dt_s


def eccentric_anomaly(mean_anomaly_rad: float, e: float) -> float:
    """Kepler's equation M = E − e sin E by Newton's iteration (to 1e-14 rad)."""
    ecc = mean_anomaly_rad
    for _ in range(20):
        step = (ecc - e * math.sin(ecc) - mean_anomaly_rad) / (1.0 - e * math.cos(ecc))
        ecc -= step
        if abs(step) < 1e-14:
            break
    return ecc


def sat_state(eph: Ephemeris, t_gps_s: float) -> SatState:
    """The satellite at GPS time of week ``t_gps_s`` (transmission time), ECEF at that time."""
    galileo = eph.system == "Galileo"
    mu = MU_GAL_M3PS2 if galileo else MU_M3PS2
    f_rel = F_REL_GAL if galileo else F_REL
    a = eph.sqrt_a**2
    n0 = math.sqrt(mu / a**3)
    tk = wrap_week(t_gps_s - eph.toe_s)
    n = n0 + eph.delta_n_radps
    mk = eph.m0_rad + n * tk
    ek = eccentric_anomaly(mk, eph.e)
    sin_e, cos_e = math.sin(ek), math.cos(ek)
    root = math.sqrt(1.0 - eph.e**2)
    vk = math.atan2(root * sin_e, cos_e - eph.e)
    phi = vk + eph.w_rad
    s2, c2 = math.sin(2 * phi), math.cos(2 * phi)
    du = eph.cus_rad * s2 + eph.cuc_rad * c2
    dr = eph.crs_m * s2 + eph.crc_m * c2
    di = eph.cis_rad * s2 + eph.cic_rad * c2
    u = phi + du
    r = a * (1.0 - eph.e * cos_e) + dr
    i = eph.i0_rad + di + eph.idot_radps * tk
    xp, yp = r * math.cos(u), r * math.sin(u)
    om = eph.omega0_rad + (eph.omega_dot_radps - OMEGA_E_RADPS) * tk - OMEGA_E_RADPS * eph.toe_s
    co, so, ci, si = math.cos(om), math.sin(om), math.cos(i), math.sin(i)
    pos = np.array([xp * co - yp * ci * so, xp * so + yp * ci * co, yp * si])

    # time derivatives of the same equations
    ek_dot = n / (1.0 - eph.e * cos_e)
    vk_dot = ek_dot * root / (1.0 - eph.e * cos_e)
    di_dt = eph.idot_radps + 2 * vk_dot * (eph.cis_rad * c2 - eph.cic_rad * s2)
    u_dot = vk_dot * (1 + 2 * (eph.cus_rad * c2 - eph.cuc_rad * s2))
    r_dot = a * eph.e * sin_e * ek_dot + 2 * vk_dot * (eph.crs_m * c2 - eph.crc_m * s2)
    om_dot = eph.omega_dot_radps - OMEGA_E_RADPS
    xp_dot = r_dot * math.cos(u) - r * u_dot * math.sin(u)
    yp_dot = r_dot * math.sin(u) + r * u_dot * math.cos(u)
    vel = np.array(
        [
            xp_dot * co - yp_dot * ci * so + yp * si * so * di_dt - pos[1] * om_dot,
            xp_dot * so + yp_dot * ci * co - yp * si * co * di_dt + pos[0] * om_dot,
            yp_dot * si + yp * ci * di_dt,
        ]
    )

    dtc = wrap_week(t_gps_s - eph.toc_s)
    rel = f_rel * eph.e * eph.sqrt_a * sin_e
    clock = eph.af0_s + eph.af1_sps * dtc + eph.af2_sps2 * dtc**2 + rel
    drift = eph.af1_sps + 2 * eph.af2_sps2 * dtc + f_rel * eph.e * eph.sqrt_a * cos_e * ek_dot
    return SatState(pos, vel, clock, drift, rel)


def rotate_earth(pos_ecef_m: FloatArray, flight_s: float) -> FloatArray:
    """ECEF coordinates at transmission expressed in the ECEF frame ``flight_s`` later."""
    ang = OMEGA_E_RADPS * flight_s
    c, s = math.cos(ang), math.sin(ang)
    x, y, z = pos_ecef_m
    return np.array([c * x + s * y, -s * x + c * y, z])


def sat_state_at_reception(
    eph: Ephemeris, t_rx_s: float, pseudorange_m: float, rx_ecef_m: FloatArray | None = None
) -> tuple[SatState, float]:
    """The satellite at its transmission time, in the ECEF frame of the reception time.

    The transmission time is ``t_rx − ρ/c − dt_sat`` with ρ the pseudorange, so the
    receiver's clock error drops out of it (the pseudorange carries the same error). The
    Earth's rotation during the flight (Sagnac) is applied with the geometric flight time
    from ``rx_ecef_m`` when given, else with ρ/c. Returns the state and the transmission
    time (s of week).
    """
    t_tx = t_rx_s - pseudorange_m / C_MPS
    st = sat_state(eph, t_tx)
    t_tx -= st.clock_s
    st = sat_state(eph, t_tx)
    flight = pseudorange_m / C_MPS
    if rx_ecef_m is not None:
        for _ in range(2):
            flight = float(np.linalg.norm(rotate_earth(st.pos_ecef_m, flight) - rx_ecef_m)) / C_MPS
    pos = rotate_earth(st.pos_ecef_m, flight)
    vel = rotate_earth(st.vel_ecef_mps, flight)
    return SatState(pos, vel, st.clock_s, st.clock_drift_sps, st.relativistic_s), t_tx

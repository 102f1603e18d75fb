"""Shared pieces of the raw-observation tests: the bundled walk cut and a simulator."""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

import numpy as np

from companion.nav.frames import ecef_to_geodetic
from companion.raw.geometry import elevation_rad, saastamoinen_m
from companion.raw.lnav import Ephemeris
from companion.raw.obs import C_MPS, SIGNAL_HZ, RawEpoch, SignalObs
from companion.raw.orbit import rotate_earth, sat_state
from companion.raw.raim import FisRaim
from companion.raw.tdprp import Tdprp, TdprpConfig
from companion.ubx.session import Session, load_session

DATA = Path(__file__).resolve().parents[1] / "data" / "walk_0827"
UBX = DATA / "gnss_1730_cut.ubx"
POS = DATA / "gnss_1730_sf_cut.pos"


@lru_cache(maxsize=1)
def walk() -> Session:
    return load_session(str(UBX), str(POS))


def simulate_epoch(
    ephs: dict[tuple[str, int], Ephemeris],
    t_true_s: float,
    rx_ecef_m: np.ndarray,
    clock_m: float,
    week: int = 2381,
    faults_m: dict[tuple[str, int], float] | None = None,
    rng: np.random.Generator | None = None,
    phase_sigma_m: float = 0.0,
    rx_vel_ecef_mps: np.ndarray | None = None,
    clock_drift_mps: float = 0.0,
) -> RawEpoch:
    """L1/E1 observations of a receiver at ``rx`` (true GPS time, clock bias in m):
    geometric range with the Earth's rotation, satellite clock, the troposphere of
    Saastamoinen's model at the height of ``rx``, no ionosphere."""
    lat, _, height = ecef_to_geodetic(*rx_ecef_m)
    sigs = []
    for (system, sv), eph in sorted(ephs.items()):
        tau = 0.075
        for _ in range(5):
            st = sat_state(eph, t_true_s - tau)
            pos = rotate_earth(st.pos_ecef_m, tau)
            tau = float(np.linalg.norm(pos - rx_ecef_m)) / C_MPS
        if elevation_rad(rx_ecef_m, pos) < math.radians(15.0):
            continue
        rho = tau * C_MPS
        extra = (faults_m or {}).get((system, sv), 0.0)
        trop = saastamoinen_m(height, lat, elevation_rad(rx_ecef_m, pos))
        pr = rho + clock_m - C_MPS * st.clock_s + trop + extra
        band = "L1" if system == "GPS" else "E1"
        wl = C_MPS / SIGNAL_HZ[band]
        noise = rng.normal(0.0, phase_sigma_m) if rng is not None else 0.0
        u = (pos - rx_ecef_m) / rho
        v_rx = np.zeros(3) if rx_vel_ecef_mps is None else rx_vel_ecef_mps
        rate = float(u @ (rotate_earth(st.vel_ecef_mps, tau) - v_rx))
        rate += clock_drift_mps - C_MPS * st.clock_drift_sps
        sigs.append(
            SignalObs(
                system,
                sv,
                band,
                pr,
                (pr + noise) / wl + 1000.0,
                -rate / wl,
                64.5,
                45.0,
                True,
                True,
                True,
                False,
            )
        )
    return RawEpoch(week=week, tow_s=t_true_s + clock_m / C_MPS, signals=tuple(sigs))


def fis_raim_alerts(
    ephs: dict[tuple[str, int], Ephemeris],
    x0_ecef_m: np.ndarray,
    config: TdprpConfig,
    epochs: list[RawEpoch],
) -> tuple[list[float], FisRaim]:
    """T-D PRP from ``epochs[0]`` with FIS-RAIM on every later epoch: the receiver times
    (tow, s) of the epochs that alerted, and the monitor."""
    est = Tdprp(ephs, x0_ecef_m, config)
    est.start(epochs[0])
    fis = FisRaim()
    alerts = []
    for ep in epochs[1:]:
        tp = est.step(ep)
        assert tp is not None
        res = fis.update(tp)
        if res is not None and res.alert:
            alerts.append(ep.tow_s)
    return alerts, fis

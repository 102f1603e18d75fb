"""Raw L1/E1 observations of a simulated flight, with truth (seeded; no I/O).

Orbits and clocks from real broadcast ephemerides; the receiver clock with a drift;
per satellite a linear ionospheric drift (code delayed, carrier advanced), white code
and carrier noise, a residual of the tropospheric model (a zenith error mapped by
1/sin(elevation)), and optional cycle slips (a whole number of cycles with the lock
time reset, as a receiver reports one).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from companion.nav.frames import ecef_to_geodetic
from companion.raw.geometry import elevation_rad, saastamoinen_m
from companion.raw.lnav import Ephemeris
from companion.raw.obs import C_MPS, SIGNAL_HZ, RawEpoch, SignalObs
from companion.raw.orbit import FloatArray, rotate_earth, sat_state


@dataclass(frozen=True)
class RawSimConfig:
    rate_hz: float = 2.0
    code_sigma_m: float = 0.5
    phase_sigma_m: float = 0.005
    iono_rate_sigma_mps: float = 0.002
    """1σ of each satellite's L1 ionospheric delay rate (constant over the flight)."""
    trop_zenith_error_sigma_m: float = 0.03
    slip_probability_per_s: float = 0.0
    elevation_mask_deg: float = 10.0
    clock_drift_mps: float = -60.0


def simulate_flight(
    ephs: dict[tuple[str, int], Ephemeris],
    tow0_s: float,
    duration_s: float,
    position_ecef_m: Callable[[float], FloatArray],
    rng: np.random.Generator,
    config: RawSimConfig | None = None,
    week: int = 2381,
) -> tuple[list[RawEpoch], list[FloatArray]]:
    """Epochs and the true antenna position (ECEF) at each, from ``tow0_s``."""
    cfg = config or RawSimConfig()
    sats = sorted(ephs)
    iono_rate = {k: rng.normal(0.0, cfg.iono_rate_sigma_mps) for k in sats}
    iono0 = {k: abs(rng.normal(3.0, 1.0)) for k in sats}
    ambiguity = {k: float(rng.integers(-10_000, 10_000)) for k in sats}
    lock_start = {k: -100.0 for k in sats}
    trop_err = rng.normal(0.0, cfg.trop_zenith_error_sigma_m)
    epochs, truth = [], []
    clock0 = rng.uniform(-5e5, 5e5)
    dt = 1.0 / cfg.rate_hz
    for j in range(int(duration_s * cfg.rate_hz) + 1):
        t = j * dt
        x = position_ecef_m(t)
        v = (position_ecef_m(t + 0.05) - position_ecef_m(t - 0.05)) / 0.1
        lat, _, height = ecef_to_geodetic(*x)
        clock = clock0 + cfg.clock_drift_mps * t
        sigs = []
        for key in sats:
            eph = ephs[key]
            tau = 0.075
            for _ in range(4):
                st = sat_state(eph, tow0_s + t - tau)
                pos = rotate_earth(st.pos_ecef_m, tau)
                tau = float(np.linalg.norm(pos - x)) / C_MPS
            el = elevation_rad(x, pos)
            if el < math.radians(cfg.elevation_mask_deg):
                continue
            band = "L1" if key[0] == "GPS" else "E1"
            wl = C_MPS / SIGNAL_HZ[band]
            if cfg.slip_probability_per_s and rng.random() < cfg.slip_probability_per_s * dt:
                ambiguity[key] += float(rng.integers(1, 20))
                lock_start[key] = t
            rho = tau * C_MPS
            trop = saastamoinen_m(height, lat, el) + trop_err / max(math.sin(el), 0.1)
            iono = (iono0[key] + iono_rate[key] * t) / max(math.sin(el), 0.3)
            common = rho + clock - C_MPS * st.clock_s + trop
            pr = common + iono + rng.normal(0.0, cfg.code_sigma_m)
            phase_m = common - iono + rng.normal(0.0, cfg.phase_sigma_m)
            u = (pos - x) / rho
            rate = float(u @ (rotate_earth(st.vel_ecef_mps, tau) - v))
            rate += cfg.clock_drift_mps - C_MPS * st.clock_drift_sps
            sigs.append(
                SignalObs(
                    key[0], key[1], band, pr, phase_m / wl + ambiguity[key], -rate / wl,
                    min(t - lock_start[key], 64.5), 45.0, True, True, True, False,
                )
            )  # fmt: skip
        epochs.append(RawEpoch(week, tow0_s + t + clock / C_MPS, tuple(sigs)))
        truth.append(x)
    return epochs, truth

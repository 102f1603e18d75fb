"""Raw L1/E1 observations of a simulated flight, with truth (seeded; no I/O).

Orbits and clocks from real broadcast ephemerides; the receiver clock with a drift;
per satellite a linear ionospheric drift (code delayed, carrier advanced), white code
and carrier noise, a residual of the tropospheric model (a zenith error mapped by
1/sin(elevation)), and optional cycle slips (a whole number of cycles with the lock
time reset, as a receiver reports one).

Signal signatures, each off by default (then nothing changes: C/N0 is a constant
45 dB-Hz and no random number is drawn for them, so a seed gives the same epochs as
before). They draw from their own generator, spawned from ``rng`` without advancing
it: with the same seed, a flight with a signature has the same code, carrier and
Doppler noise as the flight without it.

* :class:`Cn0Model`: C/N0 rising with elevation (a patch antenna's gain), a fixed offset
  per satellite (transmit power, antenna pattern), white noise, whole dB-Hz as u-blox
  reports it.
* :class:`SpoofCapture`: from ``start_s`` a spoofer holds the receiver: every C/N0 jumps
  by ``jump_dbhz`` and converges to one common level (one transmitter), the receiver
  clock steps by ``clock_step_m`` (the spoofer's time), and optionally the code moves
  by ``code_drag_enu_mps`` while the carrier and Doppler keep the true motion (a spoofer
  that drags the code alone).
* :class:`Jamming`: from ``start_s`` every C/N0 falls at ``ramp_dbhz_per_s`` (the
  jammer's power rising as it nears), the code and carrier noise growing as C/N0 falls;
  a signal below ``loss_dbhz`` is lost (not reported), and tracked again with its lock
  time reset once the jamming ends and its C/N0 is back above it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from companion.nav.frames import ecef_to_geodetic
from companion.raw.geometry import elevation_rad, enu_rotation, saastamoinen_m
from companion.raw.lnav import Ephemeris
from companion.raw.obs import C_MPS, SIGNAL_HZ, RawEpoch, SignalObs
from companion.raw.orbit import FloatArray, rotate_earth, sat_state

FLAT_CN0_DBHZ = 45.0
"""C/N0 of every signal without a :class:`Cn0Model`."""


@dataclass(frozen=True)
class Cn0Model:
    """C/N0 of a clean sky (dB-Hz)."""

    zenith_dbhz: float = 48.0
    """At 90° elevation."""
    horizon_dbhz: float = 33.0
    """At 0° elevation (linear in sin(elevation) between)."""
    satellite_sigma_dbhz: float = 1.5
    """σ of each satellite's fixed offset."""
    noise_sigma_dbhz: float = 1.0
    """σ of the white noise of each epoch."""
    whole_dbhz: bool = True
    """Reported in whole dB-Hz (u-blox RXM-RAWX)."""


@dataclass(frozen=True)
class SpoofCapture:
    """A spoofer holding the receiver from ``start_s`` (s of the flight)."""

    start_s: float
    jump_dbhz: float = 8.0
    """Common C/N0 rise at the capture (the spoofer above the real signals)."""
    converge_s: float = 3.0
    """Time constant of every C/N0 going to the common level."""
    spread_dbhz: float = 0.5
    """σ about the common level (the receiver's own measurement noise)."""
    clock_step_m: float = 300.0
    """Step of the receiver clock at the capture (1 µs: the spoofer's time), m."""
    code_drag_enu_mps: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """The code's position moves at this velocity (East, North, Up) from ``start_s``;
    the carrier and Doppler keep the true motion."""


@dataclass(frozen=True)
class Jamming:
    """A jammer from ``start_s`` to ``end_s`` (s of the flight)."""

    start_s: float
    end_s: float = math.inf
    ramp_dbhz_per_s: float = 1.0
    """C/N0 loss per second of jamming (on every signal)."""
    max_loss_dbhz: float = 40.0
    """The loss stops growing here."""
    loss_dbhz: float = 25.0
    """Below this C/N0 a signal is not tracked."""


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
    cn0: Cn0Model | None = None
    """Realistic C/N0 (None: a flat 45 dB-Hz)."""
    spoof: SpoofCapture | None = None
    jam: Jamming | None = None


class _Signatures:
    """C/N0, the spoofer's and the jammer's effects, from their own generator."""

    def __init__(self, cfg: RawSimConfig, rng: np.random.Generator, sats: list[tuple[str, int]]):
        self.cfg = cfg
        self.model = cfg.cn0 or Cn0Model(
            zenith_dbhz=FLAT_CN0_DBHZ,
            horizon_dbhz=FLAT_CN0_DBHZ,
            satellite_sigma_dbhz=0.0,
            noise_sigma_dbhz=0.0,
            whole_dbhz=False,
        )
        self.rng = rng.spawn(1)[0]  # the parent's stream is not advanced
        self.offset = {k: self.rng.normal(0.0, self.model.satellite_sigma_dbhz) for k in sats}
        self.level_dbhz: float | None = None
        """The spoofer's common level, set at its first epoch."""
        self.clean_median_dbhz = FLAT_CN0_DBHZ
        self.lost: set[tuple[str, int]] = set()

    def clean(self, key: tuple[str, int], el_rad: float) -> float:
        m = self.model
        base = m.horizon_dbhz + (m.zenith_dbhz - m.horizon_dbhz) * math.sin(max(el_rad, 0.0))
        noise = self.rng.normal(0.0, m.noise_sigma_dbhz) if m.noise_sigma_dbhz else 0.0
        return base + self.offset[key] + noise

    def jam_loss_dbhz(self, t_s: float) -> float:
        jam = self.cfg.jam
        if jam is None or not jam.start_s <= t_s < jam.end_s:
            return 0.0
        return min(jam.ramp_dbhz_per_s * (t_s - jam.start_s), jam.max_loss_dbhz)

    def cn0(self, key: tuple[str, int], el_rad: float, t_s: float) -> tuple[float, float]:
        """A signal's clean C/N0 and the one reported (before quantisation), dB-Hz."""
        clean = value = self.clean(key, el_rad)
        spoof = self.cfg.spoof
        if spoof is not None and t_s >= spoof.start_s:
            if self.level_dbhz is None:
                self.level_dbhz = self.clean_median_dbhz + spoof.jump_dbhz
            k = math.exp(-(t_s - spoof.start_s) / spoof.converge_s) if spoof.converge_s > 0 else 0.0
            noise = self.rng.normal(0.0, spoof.spread_dbhz) if spoof.spread_dbhz else 0.0
            value = self.level_dbhz + (value + spoof.jump_dbhz - self.level_dbhz) * k + noise
        return clean, value - self.jam_loss_dbhz(t_s)

    def reported(self, value_dbhz: float) -> float:
        return float(round(value_dbhz)) if self.model.whole_dbhz else value_dbhz

    def noise_scale(self, t_s: float) -> float:
        """Code and carrier noise grow as 1/√(C/N0) under the jammer."""
        return 10.0 ** (self.jam_loss_dbhz(t_s) / 20.0)

    def clock_step_m(self, t_s: float) -> float:
        spoof = self.cfg.spoof
        return spoof.clock_step_m if spoof is not None and t_s >= spoof.start_s else 0.0

    def drag_ecef_m(self, t_s: float, r_enu: FloatArray) -> FloatArray:
        spoof = self.cfg.spoof
        if spoof is None or t_s < spoof.start_s:
            return np.zeros(3)
        return np.asarray(r_enu.T @ (np.asarray(spoof.code_drag_enu_mps) * (t_s - spoof.start_s)))


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
    sig = (
        _Signatures(cfg, rng, sats)
        if cfg.cn0 is not None or cfg.spoof is not None or cfg.jam is not None
        else None
    )
    r_enu: FloatArray | None = None
    dt = 1.0 / cfg.rate_hz
    for j in range(int(duration_s * cfg.rate_hz) + 1):
        t = j * dt
        x = position_ecef_m(t)
        v = (position_ecef_m(t + 0.05) - position_ecef_m(t - 0.05)) / 0.1
        lat, lon, height = ecef_to_geodetic(*x)
        clock = clock0 + cfg.clock_drift_mps * t
        noise_k = 1.0
        drag = np.zeros(3)
        if sig is not None:
            if r_enu is None:
                r_enu = enu_rotation(lat, lon)
            clock += sig.clock_step_m(t)
            noise_k = sig.noise_scale(t)
            drag = sig.drag_ecef_m(t, r_enu)
        sigs = []
        clean_cn0 = []
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
            u = (pos - x) / rho
            pr = common + iono + rng.normal(0.0, cfg.code_sigma_m) * noise_k - float(u @ drag)
            phase_m = common - iono + rng.normal(0.0, cfg.phase_sigma_m) * noise_k
            rate = float(u @ (rotate_earth(st.vel_ecef_mps, tau) - v))
            rate += cfg.clock_drift_mps - C_MPS * st.clock_drift_sps
            cn0 = FLAT_CN0_DBHZ
            if sig is not None:
                clean, cn0 = sig.cn0(key, el, t)
                clean_cn0.append(clean)
                jam = cfg.jam
                if jam is not None and cn0 < jam.loss_dbhz:
                    sig.lost.add(key)
                    continue  # not tracked
                if key in sig.lost:  # tracked again: a new lock
                    sig.lost.discard(key)
                    lock_start[key] = t
                    ambiguity[key] += float(sig.rng.integers(-50, 50))
                cn0 = sig.reported(cn0)
            sigs.append(
                SignalObs(
                    key[0], key[1], band, pr, phase_m / wl + ambiguity[key], -rate / wl,
                    min(t - lock_start[key], 64.5), cn0, True, True, True, False,
                )
            )  # fmt: skip
        if sig is not None and clean_cn0:
            sig.clean_median_dbhz = float(np.median(clean_cn0))
        epochs.append(RawEpoch(week, tow0_s + t + clock / C_MPS, tuple(sigs)))
        truth.append(x)
    return epochs, truth

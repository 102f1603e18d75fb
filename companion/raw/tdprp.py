"""Time-differenced precise relative positioning (T-D PRP) of Kim, Walter and Powell.

Carrier phase differenced between epoch 0, where the position ``x0`` is known (a
surveyed point), and epoch t, minus the change of the computed ranges:

    y_k = λΔφ_k − Δr̂_k + cΔdt_s,k + ΔI_k − ΔT_k = −1_kᵀ δx + cΔt_u + ε_k

solved for the position change δx and the receiver clock change cΔt_u by weighted
least squares, weights sin² of the elevation. ΔI_k comes from each signal's
code-minus-carrier regression ρ − λφ = β0 + 2tβ1 + M (ΔI = tβ1, ordinary least squares
on the epochs seen so far: causal); ΔT_k from Saastamoinen's model. A signal leaves the
set for good at a cycle slip (lock time not grown, tracking flags), a missing epoch, or
when its code-minus-carrier fit fails a χ² goodness-of-fit test; no signal ever joins
after epoch 0 (one set for the run: a new satellite would make the solution jump).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from companion.nav.frames import ecef_to_geodetic
from companion.raw.geometry import elevation_rad, enu_rotation, saastamoinen_m
from companion.raw.lnav import Ephemeris
from companion.raw.obs import C_MPS, L1_BANDS, SIGNAL_HZ, RawEpoch, SignalObs
from companion.raw.orbit import FloatArray, sat_state_at_reception

SignalKey = tuple[str, int, str]
"""(system, satellite, band)."""

LOCK_MAX_S = 64.5
"""u-blox RXM-RAWX lock time saturates here."""


@dataclass(frozen=True)
class TdprpConfig:
    bands: frozenset[str] = L1_BANDS
    systems: frozenset[str] = frozenset({"GPS", "Galileo"})
    elevation_mask_deg: float = 10.0
    min_cn0_dbhz: float = 28.0
    min_lock_s: float = 1.0
    iono_regression: bool = False
    """ΔI from each signal's code-minus-carrier regression (the paper); off by default:
    on the real walk the code's multipath made it far worse (docs/raw.md)."""
    cmc_sigma_m: float = 1.0
    """σ of the code-minus-carrier residual M about its line (code noise and multipath)."""
    cmc_exclusion_prob: float = 1e-3
    """Probability of a false goodness-of-fit exclusion (χ², n − 2 degrees of freedom)."""
    cmc_min_span_s: float = 10.0
    iterations: int = 3
    clock_per_band: bool = False
    """One receiver clock change per (system, band) instead of one for all signals."""
    doppler_slip_cyc: float = 1.0
    """A phase step further than this from the integrated Doppler is a cycle slip."""
    step_residual_m: float = math.inf
    """A residual of the epoch-to-epoch phase solution above this is a slip (or a jump
    of the phase's error): the signal leaves the set. Off by default; 0.04 m helped on
    the walk with every frequency and hurt with L1 alone (docs/raw.md)."""


@dataclass
class _Track:
    """One signal of the set: its epoch-0 values and its running regression sums."""

    wavelength_m: float
    phase0_m: float
    range0_m: float
    sat_clock0_m: float
    trop0_m: float
    lock_s: float
    half_subtracted: bool
    t_prev_s: float
    phase_prev_cyc: float = 0.0
    z_prev_m: float = math.nan
    doppler_prev_hz: float = 0.0
    n: int = 0
    sx: float = 0.0
    sy: float = 0.0
    sxx: float = 0.0
    sxy: float = 0.0
    syy: float = 0.0
    cmc0_m: float = 0.0

    def add_cmc(self, t_s: float, cmc_m: float) -> None:
        y = cmc_m - self.cmc0_m
        self.n += 1
        self.sx += t_s
        self.sy += y
        self.sxx += t_s * t_s
        self.sxy += t_s * y
        self.syy += y * y

    def cmc_fit(self) -> tuple[float, float]:
        """(slope of ρ − λφ in m/s, residual sum of squares about the line, m²)."""
        if self.n < 3:
            return 0.0, 0.0
        mx, my = self.sx / self.n, self.sy / self.n
        vxx = self.sxx - self.n * mx * mx
        vxy = self.sxy - self.n * mx * my
        vyy = self.syy - self.n * my * my
        if vxx <= 0.0:
            return 0.0, 0.0
        slope = vxy / vxx
        return slope, max(vyy - slope * vxy, 0.0)


@dataclass(frozen=True)
class TrackPoint:
    """The solution at one epoch, with the linear system it came from (for RAIM).

    ``g_enu`` rows are [−1_kᵀ (ENU at x0), one-hot clock column] (one clock, or one per
    (system, band) with ``clock_per_band``); ``clock_change_m`` is the first clock's.
    ``y_m`` is the observation minus the computed change at the final linearisation
    point; ``w`` the weights.
    """

    tow_s: float
    t_s: float
    delta_enu_m: FloatArray
    pos_ecef_m: FloatArray
    clock_change_m: float
    keys: tuple[SignalKey, ...]
    g_enu: FloatArray
    y_m: FloatArray
    w: FloatArray
    residual_m: FloatArray
    iono_change_m: FloatArray


def wls(g: FloatArray, y: FloatArray, w: FloatArray) -> FloatArray:
    """Weighted least squares solution of y = g x with diagonal weights w."""
    sw = np.sqrt(w)
    sol, *_ = np.linalg.lstsq(g * sw[:, None], y * sw, rcond=None)
    return np.asarray(sol, dtype=np.float64)


@dataclass
class Tdprp:
    """The T-D PRP estimator: :meth:`start` at epoch 0, then :meth:`step` per epoch."""

    ephemerides: dict[tuple[str, int], Ephemeris]
    x0_ecef_m: FloatArray
    config: TdprpConfig = field(default_factory=TdprpConfig)
    rejected: Counter[str] = field(default_factory=Counter)
    excluded: dict[SignalKey, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.x0_ecef_m = np.asarray(self.x0_ecef_m, dtype=np.float64)
        lat, lon, h = ecef_to_geodetic(*self.x0_ecef_m)
        self._lat, self._height = lat, h
        self._r_enu = enu_rotation(lat, lon)
        self._tracks: dict[SignalKey, _Track] = {}
        self._tow0 = 0.0
        self._x_lin = self.x0_ecef_m.copy()
        self._gof_limit: dict[int, float] = {}

    # ------------------------------------------------------------------ internals
    def _wavelength(self, s: SignalObs) -> float | None:
        hz = SIGNAL_HZ.get(s.band)
        return None if hz is None else C_MPS / hz

    def _geometry(
        self, eph: Ephemeris, tow_s: float, pr_m: float, rx: FloatArray
    ) -> tuple[float, float, FloatArray, float]:
        """(range m, satellite clock m, unit vector rx→sat ECEF, elevation rad)."""
        st, _ = sat_state_at_reception(eph, tow_s, pr_m, rx)
        los = st.pos_ecef_m - rx
        rng = float(np.linalg.norm(los))
        return rng, st.clock_s * C_MPS, los / rng, elevation_rad(rx, st.pos_ecef_m)

    def _usable(self, s: SignalObs) -> str | None:
        """Why a signal cannot be used, or None."""
        cfg = self.config
        if s.system not in cfg.systems or s.band not in cfg.bands:
            return "not selected"
        if not (s.pr_valid and s.phase_valid):
            return "invalid code or phase"
        if not s.half_cycle_valid:
            return "half cycle unresolved"
        if (s.system, s.sv) not in self.ephemerides:
            return "no ephemeris"
        if s.cn0_dbhz < cfg.min_cn0_dbhz:
            return "weak signal"
        return None

    # ------------------------------------------------------------------ epochs
    def start(self, epoch: RawEpoch) -> list[SignalKey]:
        """Take epoch 0 (the receiver at ``x0``): choose the set for the whole run."""
        self._tow0 = epoch.tow_s
        self._tracks.clear()
        self._x_lin = self.x0_ecef_m.copy()
        mask = math.radians(self.config.elevation_mask_deg)
        for s in epoch.signals:
            why = self._usable(s)
            if why == "not selected":
                continue
            if why is None and s.lock_time_s < self.config.min_lock_s:
                why = "lock too short"
            wl = self._wavelength(s)
            if why is None and wl is None:
                why = "unknown band"
            if why is not None or wl is None:
                self.rejected[f"epoch 0: {why}"] += 1
                continue
            eph = self.ephemerides[(s.system, s.sv)]
            rng, clk, _, el = self._geometry(eph, epoch.tow_s, s.pseudorange_m, self.x0_ecef_m)
            if el < mask:
                self.rejected["epoch 0: below the elevation mask"] += 1
                continue
            tr = _Track(
                wavelength_m=wl,
                phase0_m=wl * s.phase_cyc,
                range0_m=rng,
                sat_clock0_m=clk,
                trop0_m=saastamoinen_m(self._height, self._lat, el),
                lock_s=s.lock_time_s,
                half_subtracted=s.half_cycle_subtracted,
                t_prev_s=0.0,
                phase_prev_cyc=s.phase_cyc,
                doppler_prev_hz=s.doppler_hz,
            )
            tr.cmc0_m = s.pseudorange_m - wl * s.phase_cyc
            tr.add_cmc(0.0, tr.cmc0_m)
            self._tracks[(s.system, s.sv, s.band)] = tr
        return sorted(self._tracks)

    def _drop(self, key: SignalKey, why: str) -> None:
        self._tracks.pop(key, None)
        self.excluded[key] = why
        self.rejected[why] += 1

    def _gof_limit_m2(self, n: int) -> float:
        lim = self._gof_limit.get(n)
        if lim is None:
            lim = float(chi2.ppf(1.0 - self.config.cmc_exclusion_prob, n - 2))
            lim *= self.config.cmc_sigma_m**2
            self._gof_limit[n] = lim
        return lim

    def _step_test(self, epoch: RawEpoch, by_key: dict[SignalKey, SignalObs]) -> None:
        """Epoch-to-epoch phase: z = λφ − r̂(x0) + c·dt_s changes by −1ᵀ·(x(t) − x(t⁻)) +
        cΔt_u; solve that by least squares and drop the signal of the largest residual
        while one is above ``step_residual_m`` and four satellites remain besides it."""
        rows: dict[SignalKey, tuple[FloatArray, float]] = {}
        for key, tr in self._tracks.items():
            s = by_key[key]
            eph = self.ephemerides[key[:2]]
            rng, clk, u, _ = self._geometry(eph, epoch.tow_s, s.pseudorange_m, self.x0_ecef_m)
            z = tr.wavelength_m * s.phase_cyc - rng + clk
            if not math.isnan(tr.z_prev_m):
                rows[key] = (np.append(-u, 1.0), z - tr.z_prev_m)
            tr.z_prev_m = z
        while len({k[:2] for k in rows}) >= 5:
            keys = list(rows)
            g = np.array([rows[k][0] for k in keys])
            dz = np.array([rows[k][1] for k in keys])
            res = dz - g @ wls(g, dz, np.ones(len(keys)))
            worst = int(np.argmax(np.abs(res)))
            if abs(res[worst]) <= self.config.step_residual_m:
                break
            self._drop(keys[worst], "cycle slip (epoch-to-epoch residual)")
            del rows[keys[worst]]

    def step(self, epoch: RawEpoch) -> TrackPoint | None:
        """The position change from epoch 0 to ``epoch``; None below four satellites."""
        t = epoch.tow_s - self._tow0
        by_key = {(s.system, s.sv, s.band): s for s in epoch.signals}
        cfg = self.config
        # cycle slips, missing signals, flags
        for key in list(self._tracks):
            tr = self._tracks[key]
            s = by_key.get(key)
            if s is None or not (s.pr_valid and s.phase_valid and s.half_cycle_valid):
                self._drop(key, "lost or flagged")
                continue
            expected = min(tr.lock_s + (t - tr.t_prev_s), LOCK_MAX_S)
            if s.lock_time_s < expected - 0.5 * (t - tr.t_prev_s) - 1e-3:
                self._drop(key, "cycle slip (lock time)")
                continue
            if s.half_cycle_subtracted != tr.half_subtracted:
                self._drop(key, "cycle slip (half cycle)")
                continue
            dt = t - tr.t_prev_s
            predicted = -0.5 * (s.doppler_hz + tr.doppler_prev_hz) * dt
            if abs(s.phase_cyc - tr.phase_prev_cyc - predicted) > cfg.doppler_slip_cyc:
                self._drop(key, "cycle slip (Doppler)")
                continue
            tr.lock_s, tr.t_prev_s = s.lock_time_s, t
            tr.phase_prev_cyc, tr.doppler_prev_hz = s.phase_cyc, s.doppler_hz
            tr.add_cmc(t, s.pseudorange_m - tr.wavelength_m * s.phase_cyc)
            if t >= cfg.cmc_min_span_s:
                _, rss = tr.cmc_fit()
                if rss > self._gof_limit_m2(tr.n):
                    self._drop(key, "code-minus-carrier fit (chi-square)")
        self._step_test(epoch, by_key)
        keys = tuple(sorted(self._tracks))
        if len({k[:2] for k in keys}) < 4:
            self.rejected["epoch: fewer than four satellites"] += 1
            return None
        x_lin = self._x_lin.copy()
        n = len(keys)
        groups = sorted({(k[0], k[2]) for k in keys}) if cfg.clock_per_band else [("", "")]
        if n < 3 + len(groups):
            self.rejected["epoch: fewer signals than unknowns"] += 1
            return None
        g = np.zeros((n, 3 + len(groups)))
        y = np.empty(n)
        w = np.empty(n)
        iono = np.empty(n)
        for _ in range(cfg.iterations):
            lat_lin, _, height_lin = ecef_to_geodetic(*x_lin)
            for i, key in enumerate(keys):
                tr, s = self._tracks[key], by_key[key]
                eph = self.ephemerides[(key[0], key[1])]
                rng, clk, u, el = self._geometry(eph, epoch.tow_s, s.pseudorange_m, x_lin)
                if cfg.iono_regression:
                    iono[i] = 0.5 * tr.cmc_fit()[0] * t
                else:
                    iono[i] = 0.0
                trop = saastamoinen_m(height_lin, lat_lin, el)
                y[i] = (
                    tr.wavelength_m * s.phase_cyc
                    - tr.phase0_m
                    - (rng - tr.range0_m)
                    + (clk - tr.sat_clock0_m)
                    + iono[i]
                    - (trop - tr.trop0_m)
                )
                g[i, :3] = -(self._r_enu @ u)
                col = groups.index((key[0], key[2])) if cfg.clock_per_band else 0
                g[i, 3 + col] = 1.0
                w[i] = max(math.sin(el), 0.05) ** 2
            sol = wls(g, y, w)
            x_lin = x_lin + self._r_enu.T @ sol[:3]
            clock = sol[3]
        # the final system: y and g at x_lin before its last step, solution `sol`
        resid = y - g @ sol
        self._x_lin = x_lin
        delta = self._r_enu @ (x_lin - self.x0_ecef_m)
        return TrackPoint(
            tow_s=epoch.tow_s,
            t_s=t,
            delta_enu_m=delta,
            pos_ecef_m=x_lin,
            clock_change_m=float(clock),
            keys=keys,
            g_enu=g.copy(),
            y_m=y.copy(),
            w=w.copy(),
            residual_m=resid,
            iono_change_m=iono.copy(),
        )

"""FIS-RAIM: the separation's predicted σ, window restarts at a set change, and the
real walk cut (quiet untouched, alerts on a ramp and a dither)."""

from __future__ import annotations

import math

import numpy as np

from companion.raw.faults import dither, inject, ramp
from companion.raw.obs import ALL_BANDS
from companion.raw.raim import FisRaim, FisRaimConfig, restrict, subset_geometry
from companion.raw.tdprp import TdprpConfig, TrackPoint, wls
from tests.raw.helpers import fis_raim_alerts, walk


def _point(g: np.ndarray, y: np.ndarray, w: np.ndarray, t_s: float = 0.0) -> TrackPoint:
    n = g.shape[0]
    keys = tuple(("GPS", k + 1, "L1") for k in range(n))
    z = np.zeros(3)
    return TrackPoint(t_s, t_s, z, z, 0.0, keys, g, y, w, np.zeros(n), np.zeros(n))


def _geometry(rng: np.random.Generator, az_deg: list[float], el_deg: list[float]) -> np.ndarray:
    az, el = np.radians(az_deg), np.radians(el_deg)
    los = np.column_stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)])
    return np.hstack([-los, np.ones((len(az), 1))])


def test_predicted_separation_sigma_matches_monte_carlo() -> None:
    """sqrt(λmax(P_j − P)) is the largest σ of the separation: check it against the
    sample covariance of separations of noise-only observations (σ = 1 at unit weight)."""
    rng = np.random.default_rng(11)
    g = _geometry(rng, [0, 70, 140, 200, 260, 320, 30], [80, 30, 45, 15, 60, 25, 10])
    w = np.sin(np.radians([80, 30, 45, 15, 60, 25, 10])) ** 2
    amp = {k: a for k, (_, a) in subset_geometry(_point(g, np.zeros(7), w)).items()}
    full_s = np.linalg.pinv(g.T @ (g * w[:, None])) @ (g.T * w)
    for j, key in enumerate(sorted(amp)):
        keep = np.arange(7) != j
        sub_s = np.zeros_like(full_s)
        gs = g[keep]
        sub_s[:, keep] = np.linalg.pinv(gs.T @ (gs * w[keep, None])) @ (gs.T * w[keep])
        y = rng.normal(size=(20000, 7)) / np.sqrt(w)
        d = (y @ (sub_s - full_s).T)[:, :3]
        lam = float(np.linalg.eigvalsh(np.cov(d.T)).max())
        assert abs(math.sqrt(lam) / amp[key] - 1.0) < 0.03, (key, math.sqrt(lam), amp[key])
    # and the separation itself is the distance between the two solutions
    y = rng.normal(size=7)
    sep = subset_geometry(_point(g, y, w))[("GPS", 1)][0]
    assert math.isclose(
        sep, float(np.linalg.norm(wls(g[1:], y[1:], w[1:])[:3] - wls(g, y, w)[:3])), rel_tol=1e-9
    )


def test_weak_geometry_makes_fis_raim_unavailable_not_alerting() -> None:
    """Five satellites, four of them close together: leaving one out amplifies the phase
    noise far beyond the residual test's σ; the monitor says unavailable, never alerts."""
    rng = np.random.default_rng(2)
    good = _geometry(rng, [0, 60, 120, 180, 240, 300, 30, 200], [85, 40, 30, 50, 20, 35, 15, 65])
    weak = _geometry(rng, [0, 10, 20, 15, 190], [60, 55, 65, 50, 12])
    for g, available in ((good, True), (weak, False)):
        fis = FisRaim(FisRaimConfig(phase_sigma_m=0.05))
        n = g.shape[0]
        for k in range(80):
            y = rng.normal(0.0, 0.05, n) + 0.5 * (k % 2)  # a dither: would trip the tests
            res = fis.update(_point(g, y, np.ones(n), t_s=0.25 * k))
            assert res is not None and res.available is available
            if not available:
                assert not res.alert and res.separation_sigma_m > 0.30
        assert fis.unavailable == (0 if available else 80)


def test_a_signal_leaving_restarts_the_window() -> None:
    """A signal that leaves the set steps every separation: the window starts again and
    the slope test waits for a full one, so the step is not a ramp."""
    rng = np.random.default_rng(4)
    g = _geometry(rng, [0, 60, 120, 180, 240, 300, 30, 200], [85, 40, 30, 50, 20, 35, 15, 65])
    fis = FisRaim()
    for k in range(120):
        n = 8 if k < 40 else 7  # the last satellite leaves at 10 s
        y = rng.normal(0.0, 0.005, n) + (np.arange(n) == 0) * (0.3 if k >= 40 else 0.0)
        res = fis.update(_point(g[:n], y, np.ones(n), t_s=0.25 * k))
        assert res is not None and not res.alert, k
    assert fis.restarts == 1


def _walk_run(fault_start_s: float | None, fault=None) -> tuple[list[float], FisRaim]:
    s = walk()
    t0 = s.epochs[0].tow_s
    eps = s.epochs
    if fault is not None and fault_start_s is not None:
        eps = inject(s.epochs, "Galileo", 26, t0 + fault_start_s, fault)
    tows, fis = fis_raim_alerts(s.ephemerides, s.x0_ecef_m, TdprpConfig(bands=ALL_BANDS), eps)
    return [tow - t0 - (fault_start_s or 0.0) for tow in tows], fis


def test_fis_raim_on_the_real_walk_cut() -> None:
    """Every frequency, 40 s of the real walk: no alert untouched (twelve signals leave
    the set on the way), a 4 cm/s ramp from 15 s caught before it reaches 1 m, a 1 m
    dither from 20 s within 10 s."""
    alerts, fis = _walk_run(None)
    assert alerts == [] and fis.restarts >= 5 and fis.unavailable == 0
    alerts, _ = _walk_run(15.0, ramp(0.04))
    assert alerts and 0.0 <= alerts[0] < 25.0
    alerts, _ = _walk_run(20.0, dither(1.0, 10.0))
    assert alerts and 0.0 <= alerts[0] < 10.0


def test_restricted_epoch_is_the_system_without_those_rows() -> None:
    rng = np.random.default_rng(8)
    g = _geometry(rng, [0, 60, 120, 180, 240, 300, 30], [85, 40, 30, 50, 20, 35, 15])
    y, w = rng.normal(size=7), rng.uniform(0.2, 1.0, 7)
    full = _point(g, y, w)
    keys = full.keys[:3] + full.keys[4:]
    sub = restrict(full, keys)
    assert sub is not None and sub.keys == keys
    rows = np.array([0, 1, 2, 4, 5, 6])
    direct = subset_geometry(_point(g[rows], y[rows], w[rows]))
    mine = subset_geometry(sub)
    # the same six satellites, named by position in ``direct`` (GPS 1-6), by origin here
    assert [k[1] for k in mine] == [1, 2, 3, 5, 6, 7]
    assert np.allclose([direct[k] for k in sorted(direct)], [mine[k] for k in sorted(mine)])
    assert restrict(sub, full.keys) is None  # a signal gone from the epoch


def test_recomputed_window_keeps_the_slope_test_armed() -> None:
    """With ``recompute_window`` a set change does not blind the slope test."""
    rng = np.random.default_rng(4)
    g = _geometry(rng, [0, 60, 120, 180, 240, 300, 30, 200], [85, 40, 30, 50, 20, 35, 15, 65])
    fis = {r: FisRaim(FisRaimConfig(recompute_window=r)) for r in (False, True)}
    for k in range(80):
        n = 8 if k < 50 else 7
        y = rng.normal(0.0, 0.005, n)
        for f in fis.values():
            f.update(_point(g[:n], y, np.ones(n), t_s=0.25 * k))
    assert fis[True].restarts == fis[False].restarts == 1
    assert fis[False].slope_waiting == 40 + 30 and fis[True].slope_waiting == 40

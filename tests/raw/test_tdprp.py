"""T-D PRP: exact on simulated observations with truth, and on the real walk cut."""

from __future__ import annotations

import math

import numpy as np

from companion.raw.faults import dither, inject, ramp
from companion.raw.obs import L1_BANDS
from companion.raw.raim import chi2_raim
from companion.raw.tdprp import Tdprp, TdprpConfig
from tests.raw.helpers import fis_raim_alerts, simulate_epoch, walk

CFG = TdprpConfig(bands=L1_BANDS, iono_regression=False, step_residual_m=math.inf)


def _simulated(seconds: float = 60.0, rate_hz: float = 4.0, **kw):
    s = walk()
    r_enu = Tdprp(s.ephemerides, s.x0_ecef_m)._r_enu
    t0 = s.epochs[0].tow_s
    truth, epochs = [], []
    for k in range(int(seconds * rate_hz)):
        t = k / rate_hz
        # static 10 s, then 1.5 m/s east and 0.2 m/s up
        vel = np.array([1.5, 0.0, 0.2]) * (t > 10.0)
        enu = np.array([1.5, 0.0, 0.2]) * max(t - 10.0, 0.0)
        x = s.x0_ecef_m + r_enu.T @ enu
        clock = -462_000.0 - 60.0 * t  # the walk receiver's clock: 1.5 ms, -200 ppb
        epochs.append(
            simulate_epoch(
                s.ephemerides,
                t0 + t,
                x,
                clock,
                **kw,
                rx_vel_ecef_mps=r_enu.T @ vel,
                clock_drift_mps=-60.0,
            )
        )
        truth.append(enu)
    return s, epochs, truth


def test_exact_on_simulated_observations() -> None:
    s, epochs, truth = _simulated()
    est = Tdprp(s.ephemerides, s.x0_ecef_m, CFG)
    assert len(est.start(epochs[0])) >= 6
    worst = 0.0
    for ep, enu in zip(epochs[1:], truth[1:], strict=True):
        tp = est.step(ep)
        assert tp is not None
        worst = max(worst, float(np.linalg.norm(tp.delta_enu_m - enu)))
    assert worst < 1e-3, worst


def test_real_walk_cut_within_ten_centimetres() -> None:
    """The goal of 10 cm RMS horizontally and vertically against the RTK fixed track."""
    s = walk()
    est = Tdprp(s.ephemerides, s.x0_ecef_m, CFG)
    est.start(s.epochs[0])
    errs = []
    for ep in s.epochs[1:]:
        tp = est.step(ep)
        ref = s.reference(ep.tow_s)
        assert tp is not None and ref is not None
        if ref[1] == 1:
            errs.append(tp.delta_enu_m - ref[0])
    e = np.array(errs)
    assert len(e) > 150
    h_rms = math.sqrt(float(np.mean(e[:, 0] ** 2 + e[:, 1] ** 2)))
    v_rms = math.sqrt(float(np.mean(e[:, 2] ** 2)))
    assert h_rms < 0.10 and v_rms < 0.10, (h_rms, v_rms)
    assert est.rejected["epoch 0: no ephemeris"] > 0  # counted, not raised


def test_lost_signal_leaves_the_set_for_good() -> None:
    s, epochs, _ = _simulated(seconds=5.0)
    est = Tdprp(s.ephemerides, s.x0_ecef_m, CFG)
    keys = est.start(epochs[0])
    gone = keys[0]
    ep = epochs[3]
    cut = type(ep)(
        ep.week, ep.tow_s, tuple(x for x in ep.signals if (x.system, x.sv, x.band) != gone)
    )
    assert gone not in est.step(cut).keys  # type: ignore[union-attr]
    assert gone not in est.step(epochs[4]).keys  # type: ignore[union-attr]
    assert est.excluded[gone] == "lost or flagged"


def test_fis_raim_quiet_on_noise_and_alerts_on_a_ramp_and_a_dither() -> None:
    rng = np.random.default_rng(7)
    s, epochs, _ = _simulated(seconds=60.0, rng=rng, phase_sigma_m=0.005)
    t0 = epochs[0].tow_s
    results = {}
    for name, fault in (("none", None), ("ramp", ramp(0.04)), ("dither", dither(1.0, 10.0))):
        eps = epochs if fault is None else inject(epochs, "GPS", 10, t0 + 20.0, fault)
        tows, _ = fis_raim_alerts(s.ephemerides, s.x0_ecef_m, CFG, eps)
        results[name] = [tow - t0 - 20.0 for tow in tows]
    assert results["none"] == []
    assert results["ramp"] and 0.0 <= results["ramp"][0] < 25.0  # before the ramp is 1 m
    assert results["dither"] and 0.0 <= results["dither"][0] < 10.0


def test_standard_raim_trips_on_a_large_outlier_only() -> None:
    rng = np.random.default_rng(3)
    g = np.hstack([rng.normal(size=(8, 3)), np.ones((8, 1))])
    y = rng.normal(0.0, 1.0, 8)
    w = np.ones(8)
    assert not chi2_raim(g, y, w, sigma_m=1.0, p_fa=1e-3)[2]
    y[2] += 30.0
    assert chi2_raim(g, y, w, sigma_m=1.0, p_fa=1e-3)[2]


def test_simulated_flight_without_errors_is_recovered_exactly() -> None:
    """The raw-observation simulator and T-D PRP agree: with no noise, no ionospheric
    drift, no tropospheric error and no slips the track is exact."""
    from companion.raw.simulate import RawSimConfig, simulate_flight

    s = walk()
    r_enu = Tdprp(s.ephemerides, s.x0_ecef_m)._r_enu

    def path(t: float) -> np.ndarray:
        enu = (
            np.array([0.5 * 2.0 * t * t, 0.0, 0.0])
            if t < 20.0
            else np.array([400.0 + 40.0 * (t - 20.0), 0.0, 0.05 * (t - 20.0) ** 2])
        )
        return s.x0_ecef_m + r_enu.T @ enu  # fmt: skip

    cfg = RawSimConfig(code_sigma_m=0.0, phase_sigma_m=0.0, iono_rate_sigma_mps=0.0,
                       trop_zenith_error_sigma_m=0.0)  # fmt: skip
    eps, truth = simulate_flight(s.ephemerides, s.epochs[0].tow_s, 60.0, path,
                                 np.random.default_rng(5), cfg)  # fmt: skip
    est = Tdprp(s.ephemerides, s.x0_ecef_m, TdprpConfig(iono_regression=True))
    est.start(eps[0])
    for ep, x in zip(eps[1:], truth[1:], strict=True):
        tp = est.step(ep)
        assert tp is not None
        assert np.linalg.norm(tp.pos_ecef_m - x) < 2e-3
    assert not est.excluded

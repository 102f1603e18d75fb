"""Singer navigator: discretisation against numerical integration, consistency on simulated
Singer targets, gating, bad input, frame shift."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.integrate
import scipy.linalg
from scipy.stats import chi2

from companion.nav.frames import LocalFrame
from companion.nav.motion import SingerConfig, SingerNavigator, singer_matrices
from companion.nav.navigator import GnssMeasurement
from companion.types import FixType


def test_singer_matrices_match_numerical_integration() -> None:
    tau, sig, dt = 8.0, (1.0, 2.0, 0.5), 0.7
    phi, qd = singer_matrices(dt, tau, sig)
    alpha = 1.0 / tau
    # per-axis closed-form transition (Singer 1970)
    e = math.exp(-alpha * dt)
    phi_axis = np.array(
        [
            [1.0, dt, (alpha * dt - 1.0 + e) / alpha**2],
            [0.0, 1.0, (1.0 - e) / alpha],
            [0.0, 0.0, e],
        ]
    )
    for axis in range(3):
        idx = [axis, 3 + axis, 6 + axis]
        np.testing.assert_allclose(phi[np.ix_(idx, idx)], phi_axis, rtol=1e-10, atol=1e-14)
    f = np.zeros((9, 9))
    f[0:3, 3:6] = np.eye(3)
    f[3:6, 6:9] = np.eye(3)
    f[6:9, 6:9] = -alpha * np.eye(3)
    gqg = np.zeros((9, 9))
    gqg[6:9, 6:9] = np.diag(2 * alpha * np.array(sig) ** 2)

    def integrand(s: float) -> np.ndarray:
        ph = scipy.linalg.expm(f * s)
        return ph @ gqg @ ph.T

    q_num, _ = scipy.integrate.quad_vec(integrand, 0.0, dt, epsabs=1e-13)
    np.testing.assert_allclose(qd, q_num, rtol=1e-8, atol=1e-14)


def _singer_truth(rng: np.random.Generator, cfg: SingerConfig, t_end: float, dt: float):
    """A 3-axis Singer target sampled every ``dt``: exact discrete transitions (the
    discretisation is checked against numerical integration above), states (N, 9)."""
    n = int(round(t_end / dt))
    phi, qd = singer_matrices(dt, cfg.maneuver_tau_s, cfg.accel_sigma_mps2)
    chol = np.linalg.cholesky(qd + 1e-15 * np.eye(9))
    x = np.zeros(9)
    x[3:6] = [40.0, 5.0, -2.0]
    x[6:9] = rng.normal(0.0, 1.0, 3) * np.array(cfg.accel_sigma_mps2)
    out = np.zeros((n + 1, 9))
    out[0] = x
    for k in range(1, n + 1):
        x = phi @ x + chol @ rng.normal(0.0, 1.0, 9)
        out[k] = x
    return out


def test_singer_consistent_on_singer_targets() -> None:
    """Targets flying a Singer process: NEES (sampled 10 s apart, across runs) and NIS (every
    fix) within their two-sided 95 % chi-square intervals; through a 20 s gap the error
    stays inside the predicted covariance."""
    cfg = SingerConfig(maneuver_tau_s=10.0, accel_sigma_mps2=(1.0, 1.0, 0.3))
    dt_fine, gnss_dt, sigma_pos, sigma_vel = 0.2, 0.2, 1.0, 0.1
    nees: list[float] = []
    nis: list[float] = []
    dofs: list[int] = []
    gap_nees: list[float] = []
    for seed in range(40):
        rng = np.random.default_rng(seed)
        truth = _singer_truth(rng, cfg, 60.0, dt_fine)
        nav = SingerNavigator(cfg)
        step = int(round(gnss_dt / dt_fine))
        for k in range(step, len(truth), step):
            t = k * dt_fine
            if 40.0 <= t < 60.0:
                continue
            z_pos = truth[k, 0:3] + rng.normal(0.0, sigma_pos, 3)
            z_vel = truth[k, 3:6] + rng.normal(0.0, sigma_vel, 3)
            meas = GnssMeasurement(
                t, z_pos, np.full(3, sigma_pos**2), z_vel, np.full(3, sigma_vel**2), FixType.FIX_3D
            )
            upd = nav.on_gnss(meas, gate=False)
            if t >= 5.0:  # after the transient of the (conservative) initial covariance
                nis.append(upd.nis)
                dofs.append(upd.dof)
            if abs(t - 20.0) < 1e-9 or abs(t - 30.0) < 1e-9:
                st = nav.predict(t)
                assert st is not None
                e = np.concatenate([st.pos_ned_m - truth[k, 0:3], st.vel_ned_mps - truth[k, 3:6]])
                p = nav._p[0:6, 0:6]
                nees.append(float(e @ np.linalg.solve(p, e)))
        k_end = len(truth) - 1
        st = nav.predict(k_end * dt_fine)
        assert st is not None
        e = st.pos_ned_m - truth[k_end, 0:3]
        gap_nees.append(float(e @ np.linalg.solve(st.pos_cov_ned_m2, e)))
    n = len(nees)
    assert n == 80
    lo, hi = chi2.ppf([0.025, 0.975], 6 * n) / n
    assert lo < np.mean(nees) < hi, (lo, np.mean(nees), hi)
    lo, hi = chi2.ppf([0.025, 0.975], int(np.sum(dofs))) / len(nis)
    assert lo < np.mean(nis) < hi, (lo, np.mean(nis), hi)
    lo, hi = chi2.ppf([0.025, 0.975], 3 * len(gap_nees)) / len(gap_nees)
    assert lo < np.mean(gap_nees) < hi, (lo, np.mean(gap_nees), hi)


def _meas(t: float, pos: np.ndarray, var: float = 1.0) -> GnssMeasurement:
    return GnssMeasurement(
        t,
        pos,
        np.full(3, var),
        np.array([10.0, 0.0, np.nan]),
        np.array([0.01, 0.01, np.nan]),
        FixType.FIX_3D,
    )


def test_gate_and_bad_input() -> None:
    nav = SingerNavigator()
    assert nav.predict(0.0) is None
    assert nav.on_gnss(_meas(0.0, np.zeros(3))).reason == "init"
    for k in range(1, 20):
        assert nav.on_gnss(_meas(0.2 * k, np.array([2.0 * k, 0.0, 0.0]))).fused
    jump = nav.on_gnss(_meas(4.0, np.array([40.0 + 50.0, 0.0, 0.0])))
    assert not jump.fused and jump.reason == "gate" and jump.nis > jump.gate
    assert nav.on_gnss(_meas(4.0, np.array([np.nan, 0, 0]))).reason == "position_not_finite"
    assert nav.on_gnss(_meas(1.0, np.zeros(3))).reason == "fix_out_of_order"
    assert nav.rejected == {"position_not_finite": 1, "fix_out_of_order": 1}
    # the vertical velocity was never given: it is estimated from the heights (stays ~0)
    st = nav.predict(4.0)
    assert st is not None and abs(st.vel_ned_mps[0] - 10.0) < 0.2
    # unknown accuracies fall back to the fix-type table
    nav2 = SingerNavigator()
    nav2.on_gnss(
        GnssMeasurement(
            0.0,
            np.zeros(3),
            np.full(3, np.nan),
            np.full(3, np.nan),
            np.full(3, np.nan),
            FixType.RTK_FLOAT,
        )
    )
    st2 = nav2.predict(0.0)
    assert st2 is not None
    np.testing.assert_allclose(np.diag(st2.pos_cov_ned_m2), [0.09, 0.09, 0.45**2])


def test_config_validation() -> None:
    with pytest.raises(ValueError, match="maneuver_tau_s"):
        SingerConfig(maneuver_tau_s=0.0)
    with pytest.raises(ValueError, match="accel_sigma_mps2"):
        SingerConfig(accel_sigma_mps2=(1.0, -1.0, 1.0))


def test_shift_frame_keeps_geodetic_position() -> None:
    old = LocalFrame(math.radians(52.0), math.radians(21.0), 100.0)
    new = LocalFrame(math.radians(52.05), math.radians(21.1), 150.0)
    nav = SingerNavigator()
    nav.on_gnss(_meas(0.0, np.array([100.0, 200.0, -50.0])))
    before = nav.predict(0.0)
    nav.shift_frame(old, new)
    after = nav.predict(0.0)
    assert before is not None and after is not None
    lla0 = old.ned_to_lla(before.pos_ned_m)
    lla1 = new.ned_to_lla(after.pos_ned_m)
    np.testing.assert_allclose(lla0[:2], lla1[:2], atol=1e-11)
    assert lla0[2] == pytest.approx(lla1[2], abs=1e-4)
    assert np.trace(after.pos_cov_ned_m2) == pytest.approx(np.trace(before.pos_cov_ned_m2))

"""The realistic autopilot: switches off = the plain simulator, byte for byte; each trait
against its stated statistics (seeded KS / chi-square); same seed, same bytes."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy import stats

from companion.sim import make_scenario, simulate
from companion.sim.realism import Realism, butter2_response, imu_realism, realistic, windows
from companion.sim.writer import tlog_bytes
from companion.types import GnssFix, ImuSample

ALPHA = 1e-3
"""Significance of every seeded statistical test here."""


def _short(name: str = "approach", **over: object) -> object:
    return make_scenario(name, duration_s=60.0, **over)


def test_all_switches_off_is_the_plain_simulator_byte_for_byte() -> None:
    plain = simulate(_short(), 4)
    off = simulate(_short(realism=Realism()), 4)
    assert tlog_bytes(plain) == tlog_bytes(off)
    assert "realism" not in make_scenario("taxi").as_dict()


@pytest.mark.parametrize("vehicle", ["copter", "copter_radio", "plane", "px4"])
def test_same_seed_same_bytes(vehicle: str) -> None:
    sc = make_scenario("px4_rotorcraft", duration_s=90.0, **realistic(vehicle))
    a, b, c = (tlog_bytes(simulate(sc, s)) for s in (3, 3, 4))
    assert a == b and a != c


def test_bad_switch_is_a_value_error() -> None:
    with pytest.raises(ValueError, match="acc_bias_mps2"):
        Realism(acc_bias_mps2=-1.0)
    with pytest.raises(ValueError, match="extra_imus"):
        Realism(extra_imus=3)
    with pytest.raises(ValueError, match="unknown vehicle"):
        realistic("submarine")


def test_turn_on_biases_scale_and_misalignment_have_their_distributions() -> None:
    """Accelerometer bias uniform in +-b, gyro bias and scale factor normal (KS)."""
    rng = np.random.default_rng(11)
    rl = Realism(acc_bias_mps2=0.3, gyro_bias_radps=0.01, acc_scale_sigma=0.005)
    t = np.arange(3) * 0.02
    ab, gb, sf = [], [], []
    for _ in range(400):
        e = imu_realism(rng, rl, t, 0.0, np.zeros(3))
        ab.extend(e.acc_err_b_mps2[0])
        gb.extend(e.gyro_err_b_radps[0])
        sf.extend(np.diag(e.acc_matrix) - 1.0)
    assert stats.kstest(ab, stats.uniform(-0.3, 0.6).cdf).pvalue > ALPHA
    assert stats.kstest(gb, stats.norm(0, 0.01).cdf).pvalue > ALPHA
    assert stats.kstest(sf, stats.norm(0, 0.005).cdf).pvalue > ALPHA
    assert max(abs(x) for x in ab) <= 0.3


def test_gyro_random_walk_increments_have_the_stated_variance() -> None:
    """Increments over dt are N(0, sigma^2 dt): chi-square on their sum of squares."""
    rng = np.random.default_rng(12)
    rw, dt = 2e-4, 0.02
    t = np.arange(20001) * dt
    e = imu_realism(rng, Realism(gyro_rw_radps_rts=rw), t, 0.0, np.zeros(len(t)))
    inc = np.diff(e.gyro_err_b_radps, axis=0).ravel()
    q = float(np.sum(inc**2) / (rw**2 * dt))
    dof = len(inc)
    assert stats.chi2(dof).cdf(q) > ALPHA / 2 and stats.chi2(dof).sf(q) > ALPHA / 2


def test_white_noise_has_the_stated_sigma() -> None:
    rng = np.random.default_rng(13)
    t = np.arange(5000) * 0.02
    e = imu_realism(rng, Realism(acc_noise_mps2=0.1), t, 0.0, np.zeros(len(t)))
    x = e.acc_err_b_mps2.ravel()
    assert stats.kstest(x, stats.norm(0, 0.1).cdf).pvalue > ALPHA


def test_vibration_is_filtered_then_aliased() -> None:
    """A 140 Hz harmonic through a 20 Hz second-order low-pass, point-sampled at 50 Hz,
    shows at |140 - 3*50| = 10 Hz with the filter's gain (its 280 Hz harmonic at 20 Hz)."""
    rng = np.random.default_rng(14)
    rate = 50.0
    t = np.arange(int(200 * rate)) / rate
    rl = Realism(vibration_mps2=30.0, vibration_hz=140.0, filter_hz=20.0, vibration_wander=0.0)
    lvl = np.ones(len(t))
    e = imu_realism(rng, rl, t, 0.0, lvl)
    x = e.vibration_b_mps2[:, 2]
    spec = np.abs(np.fft.rfft(x * np.hanning(len(x))))
    f = np.fft.rfftfreq(len(x), 1.0 / rate)
    peak = f[np.argmax(spec)]
    assert abs(peak - 10.0) < 0.02, peak
    second = spec[np.argmin(np.abs(f - 20.0)) - 3 : np.argmin(np.abs(f - 20.0)) + 4].max()
    assert second > 1e-6 * spec.max()  # 280 Hz aliases to |280 - 6*50| = 20 Hz
    g1, _ = butter2_response(np.array([140.0]), 20.0)
    g2, _ = butter2_response(np.array([280.0]), 20.0)
    rms_expected = math.sqrt((30.0 * g1[0]) ** 2 / 2 + (15.0 * g2[0]) ** 2 / 2)
    assert float(np.std(x)) == pytest.approx(rms_expected, rel=0.1)
    assert 30.0 * g1[0] < 30.0 / 40  # the filter really attenuates before sampling


def test_windows_lengths_are_uniform() -> None:
    rng = np.random.default_rng(15)
    lengths = []
    for _ in range(300):
        lengths += [b - a for a, b in windows(rng, 0.0, 3600.0, 3.0, 5.0, 30.0)]
    assert stats.kstest(lengths, stats.uniform(5.0, 25.0).cdf).pvalue > ALPHA


def test_dropouts_silence_every_stream_and_the_truth_says_outage() -> None:
    rl = Realism(dropout_per_h=60.0, dropout_min_s=5.0, dropout_max_s=10.0)
    sc = make_scenario("approach", duration_s=120.0, realism=rl)
    f = simulate(sc, 5)
    drops = f.errors.realism.dropouts
    assert drops
    epoch = f.scenario.epoch0_s
    for a, b in drops:
        inside = [m for t, m in f.messages if epoch + a + 0.01 < t < epoch + b]
        assert inside == []
        assert "outage" in {
            lab for t, lab in zip(f.truth.t_s, f.truth.gnss_mode, strict=True) if a + 1 < t < b - 1
        }


def test_reboot_restarts_the_boot_clock_and_the_decoder_sees_it() -> None:
    from companion.mavlink.decode import Decoder

    rl = Realism(reboot_at_fraction=0.5)
    f = simulate(make_scenario("approach", duration_s=60.0, realism=rl), 6)
    t_r = f.errors.realism.reboot_t_s
    assert t_r is not None
    dec = Decoder()
    for t_rx, m in f.messages:
        dec.decode(m, t_rx)
    assert dec.reboots == 1
    imu = [s for s in f.samples if isinstance(s, ImuSample)]
    after = [s.t_s for s in imu if s.t_rx_s > f.scenario.epoch0_s + t_r + 1.0]
    assert after and min(after) >= 3.0 - 0.05 and max(after) < 60.0 - (t_r - 10.0) + 0.1


def test_no_fix_carries_garbage_coordinates_the_decoder_keeps() -> None:
    rl = Realism(gnss_nofix_start_s=10.0, gnss_garbage=True)
    f = simulate(make_scenario("approach", duration_s=40.0, realism=rl), 7)
    nofix = [s for s in f.samples if isinstance(s, GnssFix) and s.fix_type <= 1]
    assert len(nofix) >= 90
    assert all(s.lat_rad != 0.0 for s in nofix)
    tp = f.truth.at(nofix[-1].t_s)
    assert abs(nofix[-1].lat_rad - tp.lat_rad) * 6.4e6 > 50.0  # garbage, not the position


def test_gnss_velocity_bias_has_the_stated_sigma() -> None:
    """With white velocity noise off, the velocity error is the Gauss-Markov bias:
    fixes 5 tau apart are nearly independent N(0, sigma) (KS)."""
    rl = Realism(gnss_vel_bias_mps=0.1, gnss_vel_bias_tau_s=0.5)
    f = simulate(make_scenario("approach", duration_s=200.0, gnss_vel_noise_mps=0.0,
                               realism=rl), 8)  # fmt: skip
    v = f.errors.gnss[0].vel_err_ned_mps[::25, :2].ravel()
    assert stats.kstest(v, stats.norm(0, 0.1).cdf).pvalue > ALPHA


def test_attitude_trim_and_lag() -> None:
    rl = Realism(attitude_trim_deg=2.0)
    f = simulate(make_scenario("approach", duration_s=30.0, noise=False, realism=rl), 9)
    tilt = np.hypot(f.errors.attitude_err_rad[:, 0], f.errors.attitude_err_rad[:, 1])
    np.testing.assert_allclose(np.degrees(tilt), 2.0, rtol=1e-9)


def test_baro_noise_and_drift() -> None:
    rl = Realism(baro_rate_hz=5.0, baro_noise_hpa=0.05, baro_drift_hpa_per_h=3.6)
    f = simulate(make_scenario("approach", duration_s=200.0, realism=rl), 10)
    rz = f.errors.realism
    msgs = [m for _, m in f.messages if m.get_type() == "SCALED_PRESSURE"]
    assert len(msgs) == len(rz.baro_t_s)
    st = f.truth.sample(rz.baro_t_s)
    from companion.sim.flight import _lla

    _, _, alt = _lla(f.frame, st.pos_ned_m)
    isa = 1013.25 * (1.0 - 2.25577e-5 * alt) ** 5.25588
    p = np.array([m.press_abs for m in msgs], dtype=float)
    noise = p - isa - rz.baro_bias_hpa
    # float32 rounding of ~1000 hPa is 6e-5 hPa: negligible against 0.05
    assert stats.kstest(noise, stats.norm(0, 0.05).cdf).pvalue > ALPHA
    slope = np.polyfit(rz.baro_t_s, rz.baro_bias_hpa, 1)[0] * 3600.0
    assert abs(slope) == pytest.approx(3.6, rel=1e-6)


def test_stream_rates_and_jitter_of_the_profiles() -> None:
    sc = make_scenario("nominal", duration_s=120.0, **realistic("plane"))
    f = simulate(sc, 11)
    t = np.array([s.t_s for s in f.samples if isinstance(s, ImuSample) and s.imu_id == 0])
    d = np.diff(t)
    assert np.median(d) == pytest.approx(0.1, abs=2e-3)
    t0 = sc.t_boot0_s  # the grid; samples clipped to the flight's ends left out
    jitter = (t - (t0 + np.round((t - t0) / 0.1) * 0.1))[2:-2]
    assert stats.kstest(jitter, stats.norm(0, 0.0015).cdf).pvalue > ALPHA
    ids = {s.imu_id for s in f.samples if isinstance(s, ImuSample)}
    assert ids == {0, 1}  # RAW_IMU and a second unit (SCALED_IMU2)


def test_specific_force_closes_on_truth_with_realism_but_errors_off() -> None:
    """Realistic rates and link, IMU errors off: the decoded specific force is the truth's
    up to the message's 1 mG quantisation."""
    rl = dataclasses.replace(realistic("plane")["realism"], **{
        k: 0.0 for k in ("acc_bias_mps2", "acc_scale_sigma", "misalign_sigma_rad",
                         "gyro_bias_radps", "gyro_rw_radps_rts", "temp_rise_c",
                         "acc_noise_mps2", "gyro_noise_radps", "vibration_mps2",
                         "vibration_broadband_mps2")
    })  # fmt: skip
    over = {**realistic("plane"), "realism": rl, "noise": False}
    f = simulate(make_scenario("nominal", duration_s=120.0, **over), 12)
    imu = [s for s in f.samples if isinstance(s, ImuSample) and s.imu_id == 0]
    t = np.array([s.t_s for s in imu])
    acc = np.array([s.acc_b_mps2 for s in imu])
    truth = f.truth.sample(t).f_b_mps2
    assert np.abs(acc - truth).max() < 0.5e-3 * 9.80665 + 1e-9

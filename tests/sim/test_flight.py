"""Simulated flights: tlog read-back, samples = decoded messages, rates, events, determinism."""

from __future__ import annotations

import collections
import math
from pathlib import Path

import numpy as np
import pytest
from pymavlink import mavutil

from companion.mavlink.units import MG_PER_MPS2
from companion.sim import SCENARIO_NAMES, make_scenario, simulate, write_scenario
from companion.sim.writer import TRUTH_COLUMNS, tlog_bytes
from companion.types import AttitudeSample, BaroSample, FixType, GnssFix, ImuSample

D2R = math.pi / 180.0


def _read_tlog(path: Path) -> list:
    conn = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    out = []
    while (m := conn.recv_match()) is not None:
        if m.get_type() != "BAD_DATA":
            out.append(m)
    return out


@pytest.fixture(scope="module")
def short_ap(tmp_path_factory: pytest.TempPathFactory) -> tuple[list[Path], object]:
    out = tmp_path_factory.mktemp("sim")
    return write_scenario("ramp_fault", out, seed=7, duration_s=80.0), out


def test_tlog_reads_back_with_rates_and_ids(short_ap) -> None:
    paths, _ = short_ap
    msgs = _read_tlog(paths[0])
    c = collections.Counter(m.get_type() for m in msgs)
    dur = 80.0
    sc = make_scenario("ramp_fault")
    assert c["HIGHRES_IMU"] == pytest.approx(sc.imu_rate_hz * dur, abs=2)
    assert c["ATTITUDE"] == pytest.approx(sc.attitude_rate_hz * dur, abs=2)
    assert c["GPS_RAW_INT"] == pytest.approx(sc.gnss_rate_hz * dur, abs=2)
    assert c["GPS2_RAW"] == pytest.approx(sc.gnss_rate_hz * dur, abs=2)
    assert c["HEARTBEAT"] == pytest.approx(dur, abs=1)
    assert c["GPS_RTK"] > 0 and c["VFR_HUD"] > 0 and c["EXTENDED_SYS_STATE"] > 0
    assert c["GLOBAL_POSITION_INT"] > 0 and c["SYSTEM_TIME"] > 0
    assert all(m.get_srcSystem() == 1 and m.get_srcComponent() == 1 for m in msgs)
    hb = next(m for m in msgs if m.get_type() == "HEARTBEAT")
    assert hb.autopilot == 3
    ts = [m._timestamp for m in msgs]
    assert all(b >= a for a, b in zip(ts, ts[1:], strict=False))
    # ArduPilot: GPS_RAW_INT.time_usec is UNIX epoch of the fix
    g = next(m for m in msgs if m.get_type() == "GPS_RAW_INT")
    assert g.time_usec > 1_000_000_000_000_000 and g.time_usec / 1e6 < g._timestamp


def test_truth_csv_and_sidecar(short_ap) -> None:
    import json

    paths, _ = short_ap
    lines = paths[1].read_text().splitlines()
    assert lines[0].split(",") == list(TRUTH_COLUMNS)
    assert len(lines) - 1 == pytest.approx(80 * 10 + 1, abs=1)
    side = json.loads(paths[2].read_text())
    assert side["seed"] == 7 and side["scenario"] == "ramp_fault"
    assert side["events"][0]["kind"] == "ramp"
    assert side["events"][0]["params"]["rate_ned_mps"] == [0.0, 0.0, 0.04]


def test_samples_equal_decoded_messages() -> None:
    """Every typed sample carries exactly what its (quantised) message decodes to."""
    f = simulate(make_scenario("cruise_gnss_loss", duration_s=30.0), 3)
    by_type = {"RAW_IMU": [], "ATTITUDE": [], "GPS_RAW_INT": []}
    for t_rx, m in f.messages:
        if m.get_type() in by_type:
            by_type[m.get_type()].append((t_rx, m))
    imu = [s for s in f.samples if isinstance(s, ImuSample)]
    att = [s for s in f.samples if isinstance(s, AttitudeSample)]
    gps = [s for s in f.samples if isinstance(s, GnssFix)]
    assert len(imu) == len(by_type["RAW_IMU"]) and len(gps) == len(by_type["GPS_RAW_INT"])
    for s, (t_rx, m) in zip(imu, by_type["RAW_IMU"], strict=True):
        assert s.t_s == m.time_usec / 1e6 and s.t_rx_s == t_rx
        np.testing.assert_array_equal(
            s.acc_b_mps2, np.array([m.xacc, m.yacc, m.zacc]) * (1.0 / MG_PER_MPS2)
        )
        np.testing.assert_array_equal(
            s.gyro_b_radps, np.array([m.xgyro, m.ygyro, m.zgyro]) / 1000.0
        )
    for s, (_, m) in zip(att, by_type["ATTITUDE"], strict=True):
        assert (s.t_s, s.roll_rad, s.yaw_rad) == (m.time_boot_ms / 1e3, m.roll, m.yaw)
    sc = f.scenario
    for s, (_, m) in zip(gps, by_type["GPS_RAW_INT"], strict=True):
        assert s.t_s == pytest.approx(m.time_usec / 1e6 - sc.epoch0_s, abs=1e-6)
        assert s.lat_rad == pytest.approx(m.lat / (1e7 * 180 / math.pi), rel=1e-15)
        assert s.fix_type == m.fix_type
        assert s.ground_speed_mps == m.vel / 100.0 and s.h_acc_m == m.h_acc / 1000.0
    # fixes are close to the truth at their time of validity (DGPS: metres)
    s = gps[len(gps) // 2]
    tp = f.truth.at(s.t_s)
    assert abs(s.lat_rad - tp.lat_rad) * 6.4e6 < 6.0


def test_same_seed_same_bytes_other_seed_other_bytes() -> None:
    sc = make_scenario("taxi", duration_s=20.0)
    a, b, c = (tlog_bytes(simulate(sc, s)) for s in (5, 5, 6))
    assert a == b and a != c


def test_events_outage_stale_ramp_dither_heading() -> None:
    fast = {"imu_rate_hz": 5.0, "attitude_rate_hz": 1.0}  # the IMU plays no part here
    sc = make_scenario("cruise_gnss_loss", **fast)
    f = simulate(sc, 1)
    ev = sc.events[0]
    fixes = [s for s in f.samples if isinstance(s, GnssFix)]
    assert not any(ev.t_start_s <= s.t_s < ev.t_end_s for s in fixes)
    assert any(s.t_s >= ev.t_end_s for s in fixes)
    assert set(f.truth.gnss_mode[(f.truth.t_s >= ev.t_start_s) & (f.truth.t_s < ev.t_end_s)]) == {
        "outage"
    }
    # stale: same position repeated while the aircraft moves
    sc = make_scenario("stale_fix", **fast)
    f = simulate(sc, 1)
    st = sc.events[0]
    inside = [s for s in f.samples if isinstance(s, GnssFix) and st.t_start_s <= s.t_s < st.t_end_s]
    assert len(inside) >= 9 and len({(s.lat_rad, s.lon_rad) for s in inside}) == 1
    assert len({s.t_s for s in inside}) == len(inside)
    assert inside[0].fix_type == FixType.DGPS
    # ramp and dither offsets on receiver 0 only
    for name, check in (
        ("ramp_fault", lambda tau: 0.04 * tau),
        ("dither_fault", lambda tau: 1.0 * np.sin(2 * np.pi * tau / 20.0)),
    ):
        f = simulate(make_scenario(name, noise=False, **fast), 1)
        ev = f.scenario.events[0]
        g0, g1 = f.errors.gnss
        sel = (g0.t_fix_s >= ev.t_start_s) & (g0.t_fix_s < ev.t_end_s)
        np.testing.assert_allclose(
            g0.fault_ned_m[sel, 2], check(g0.t_fix_s[sel] - ev.t_start_s), atol=1e-12
        )
        assert np.all(g1.fault_ned_m == 0.0)
        # the reported altitude carries it (fault is down-positive: altitude drops)
        fx = {s.t_s: s for s in f.samples if isinstance(s, GnssFix) and s.receiver_id == 0}
        t_mid = float(g0.t_fix_s[sel][len(g0.t_fix_s[sel]) // 4])
        tp = f.truth.at(t_mid)
        assert fx[t_mid].alt_msl_m - tp.alt_msl_m == pytest.approx(
            -check(t_mid - ev.t_start_s), abs=2e-3
        )
    # heading error: ATTITUDE yaw = truth + 1 deg when noise is off
    f = simulate(make_scenario("taxi", noise=False, duration_s=60.0), 1)
    att = [s for s in f.samples if isinstance(s, AttitudeSample)][::50]
    for s in att:
        d = math.remainder(s.yaw_rad - f.truth.at(s.t_s).euler_rad[2], 2 * math.pi)
        assert d == pytest.approx(D2R, abs=1e-6)


def test_px4_flavour() -> None:
    f = simulate(make_scenario("px4_rotorcraft", duration_s=40.0), 1)
    types = collections.Counter(m.get_type() for _, m in f.messages)
    assert "ATTITUDE_QUATERNION" in types and "ATTITUDE" not in types and "HIGHRES_IMU" in types
    hb = next(m for _, m in f.messages if m.get_type() == "HEARTBEAT")
    assert hb.autopilot == 12 and hb.type == 2
    g = next(m for _, m in f.messages if m.get_type() == "GPS_RAW_INT")
    assert g.time_usec < 1e12  # time since boot
    att = next(s for s in f.samples if isinstance(s, AttitudeSample))
    assert att.yaw_rad == pytest.approx(f.truth.at(att.t_s).euler_rad[2], abs=0.02)


@pytest.mark.parametrize(
    "call",
    [
        lambda: make_scenario("no_such_scenario"),
        lambda: make_scenario("taxi", duration_s=-5.0),
        lambda: make_scenario("taxi", imu_rate_hz=0.0),
        lambda: make_scenario("taxi", bogus_field=1),
        lambda: make_scenario("taxi", imu_grade="navigation"),
        lambda: write_scenario("taxi", Path("/tmp"), duration_s=-1.0),
        lambda: write_scenario("taxi", Path("/tmp"), seed=-1),
        lambda: simulate(make_scenario("taxi"), -3),
    ],
)
def test_bad_input_is_a_one_line_value_error(call) -> None:
    with pytest.raises(ValueError) as info:
        call()
    assert "\n" not in str(info.value)


def test_every_named_scenario_builds() -> None:
    for name in SCENARIO_NAMES:
        sc = make_scenario(name)
        assert sc.duration_s is not None and sc.duration_s > 60.0
        assert all(sc.t_boot0_s <= e.t_start_s < sc.t_boot0_s + sc.duration_s for e in sc.events)


@pytest.mark.parametrize("name", ["px4_rotorcraft", "ramp_fault", "stale_fix", "downgrade"])
def test_samples_match_the_project_decoder(name: str) -> None:
    """companion.mavlink.decode turns the tlog's messages into exactly SimFlight.samples.

    ArduPilot stamps GPS_RAW_INT with the UNIX time of the fix; the decoder maps it
    onto the boot clock with SYSTEM_TIME's exact offset, so the fix lands on its
    time of validity up to the rounding of whole microseconds.
    """
    from pymavlink.dialects.v20 import ardupilotmega as mav

    from companion.mavlink.decode import Decoder

    sc = make_scenario(name, duration_s=40.0)
    f = simulate(sc, 2)
    dec = Decoder()
    link = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    out = []
    for t_rx, m in f.messages:
        out.extend(dec.decode(link.decode(bytearray(m.pack(link))), t_rx))
    # HIGHRES_IMU also carries the barometer (abs_pressure, flagged valid): the simulator
    # keeps one typed sample per message, its IMU sample; the decoder's barometer from it
    # is checked against the message itself
    highres_baro = [s for s in out if isinstance(s, BaroSample) and s.source == "HIGHRES_IMU"]
    for s in highres_baro:
        assert 1000.0 < s.pressure_pa < 120_000.0
    out = [s for s in out if not (isinstance(s, BaroSample) and s.source == "HIGHRES_IMU")]
    assert len(out) == len(f.samples)
    epoch_gnss = sc.flavour.value == "ardupilot"
    for a, b in zip(out, f.samples, strict=True):
        assert type(a) is type(b)
        for fld in a.__dataclass_fields__:
            x, y = getattr(a, fld), getattr(b, fld)
            if epoch_gnss and isinstance(a, GnssFix) and fld == "t_s":
                assert abs(x - y) < 1e-6
            elif isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
                np.testing.assert_array_equal(x, y)
            else:
                assert x == y, (type(a).__name__, fld, x, y)

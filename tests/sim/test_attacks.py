"""Spoofing drags, meaconing and jamming in the simulator: their truth, what the autopilot
streams of them, determinism, and the committed fixtures untouched.

Every attack draws no random number, so each flight here is compared with the same
flight (same scenario and seed) without the attack: the difference is the attack alone.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pymap3d
import pytest

from companion.sim import Event, SimFlight, make_scenario, simulate
from companion.sim.attacks import drag_offsets, event_drag, horizontal_direction
from companion.sim.writer import sidecar, tlog_bytes, truth_rows
from companion.types import AutopilotFlavour, FixType, GnssFix, GnssSignalReport, InterferenceState

FIXTURES = Path(__file__).resolve().parents[2] / "sitl_fixtures"
T_ON, T_OFF = 60.0, 140.0
"""The attack window of the plain flights below (autopilot boot time, s)."""


def _plain(events: tuple[Event, ...], **over: object) -> object:
    """A plain (no realism) 3D-fix cruise of 170 s at 10 Hz GNSS, no outage."""
    return make_scenario(
        "cruise_gnss_loss", events=events, gnss_mode="3d", duration_s=170.0, **over
    )


def _pair(event: Event, seed: int = 5, **over: object) -> tuple[SimFlight, SimFlight]:
    return simulate(_plain((event,), **over), seed), simulate(_plain((), **over), seed)


def _fixes(flight: SimFlight) -> list[GnssFix]:
    return [s for s in flight.samples if isinstance(s, GnssFix) and s.receiver_id == 0]


def _ned(flight: SimFlight, fixes: list[GnssFix]) -> np.ndarray:
    """Decoded fix positions in the simulator's local frame (the inverse of its geodesy)."""
    f = flight.frame
    n, e, d = pymap3d.geodetic2ned(
        np.array([x.lat_rad for x in fixes]), np.array([x.lon_rad for x in fixes]),
        np.array([x.alt_msl_m for x in fixes]), f.lat0_rad, f.lon0_rad, f.alt0_m, deg=False,
    )  # fmt: skip
    return np.column_stack([n, e, d])


def _same_outside(a: SimFlight, b: SimFlight, changed: object) -> None:
    """Every message equal between two flights, except the GNSS messages ``changed`` names."""
    assert len(a.messages) == len(b.messages)
    n_changed = 0
    for (ta, ma), (tb, mb) in zip(a.messages, b.messages, strict=True):
        assert ta == tb and ma.get_type() == mb.get_type()  # type: ignore[attr-defined]
        if ma.to_dict() != mb.to_dict():  # type: ignore[attr-defined]
            assert changed(ta - a.scenario.epoch0_s, ma), ma
            n_changed += 1
    assert n_changed > 0


def _gnss_in(t0: float, t1: float):  # type: ignore[no-untyped-def]
    """A GNSS message (GPS_RAW_INT, GPS_RTK) whose fix lies in [t0, t1) (arrival - latency)."""

    def changed(t_rx_boot_s: float, msg: object) -> bool:
        kind = msg.get_type()  # type: ignore[attr-defined]
        t_fix = t_rx_boot_s - 0.08
        return kind in ("GPS_RAW_INT", "GPS_RTK") and t0 - 0.01 <= t_fix < t1 + 0.02

    return changed


# --------------------------------------------------------------------------- drag


def test_drag_position_offset_is_the_integral_of_its_velocity_offset() -> None:
    ev = event_drag(T_ON, T_OFF - T_ON, 0.5, (0.6, 0.8, 0.0), max_speed_mps=5.0)
    t = np.arange(T_ON - 5.0, T_OFF + 5.0, 0.001)
    pos, vel = drag_offsets(ev, t)
    inside = (t >= T_ON) & (t < T_OFF)
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (vel[1:, 0] + vel[:-1, 0]) * np.diff(t))])
    assert np.max(np.abs(pos[inside, 0] - integral[inside])) < 1e-5
    speed = np.linalg.norm(vel, axis=1)
    assert speed.max() == pytest.approx(5.0) and np.all(speed[~inside] == 0.0)
    # a t^2 / 2 until 5 m/s (10 s), then 5 m/s: 25 m + 5 (80 - 10) = 375 m just before the end
    assert np.linalg.norm(pos[inside][-1]) == pytest.approx(375.0, abs=0.01)
    assert np.all(pos[~inside] == 0.0)  # it lets go at the end
    np.testing.assert_allclose(pos[inside][-1] / 375.0, [0.6, 0.8, 0.0], atol=1e-4)


def test_drag_as_the_autopilot_streams_it() -> None:
    """Reported position and velocity move together by the drag's offsets (decoded from the
    messages, against the same flight without the spoofer); nothing else changes."""
    u = horizontal_direction(np.random.default_rng(3))
    spoofed, clean = _pair(event_drag(T_ON, T_OFF - T_ON, 0.1, u, max_speed_mps=5.0))
    a, b = _fixes(spoofed), _fixes(clean)
    assert [x.t_s for x in a] == [x.t_s for x in b]
    t = np.array([x.t_s for x in a])
    pos_off, vel_off = drag_offsets(spoofed.events[0], t)
    d_pos = _ned(spoofed, a) - _ned(clean, b)
    np.testing.assert_allclose(d_pos, pos_off, atol=0.02)  # 1e-7 deg and mm quantisation
    d_vel = np.array([x.vel_ne_mps - y.vel_ne_mps for x, y in zip(a, b, strict=True)])
    np.testing.assert_allclose(d_vel, vel_off[:, :2], atol=0.03)  # cm/s and 0.01 deg
    # the offset speed the messages show is the derivative of the offset they show
    inside = (t > T_ON + 1.0) & (t < T_OFF - 1.0)
    rate = np.gradient(d_pos[:, :2], t, axis=0)
    np.testing.assert_allclose(rate[inside], d_vel[inside], atol=0.2)
    assert np.linalg.norm(d_pos[t < T_OFF][-1]) > 0.5 * 0.1 * 50.0**2  # 0.1 m/s^2 for 80 s
    _same_outside(spoofed, clean, _gnss_in(T_ON, T_OFF))
    truth = spoofed.errors.gnss[0]
    assert truth.attacks is not None
    np.testing.assert_allclose(truth.fault_ned_m, drag_offsets(spoofed.events[0], truth.t_fix_s)[0])


def test_vertical_drag_moves_the_altitude_only() -> None:
    spoofed, clean = _pair(event_drag(T_ON, T_OFF - T_ON, 0.1, (0.0, 0.0, -1.0)))
    a, b = _fixes(spoofed), _fixes(clean)
    t = np.array([x.t_s for x in a])
    d_alt = np.array([x.alt_msl_m - y.alt_msl_m for x, y in zip(a, b, strict=True)])
    expected = -drag_offsets(spoofed.events[0], t)[0][:, 2]
    np.testing.assert_allclose(d_alt, expected, atol=0.002)
    d_vel = np.array([x.vel_ne_mps - y.vel_ne_mps for x, y in zip(a, b, strict=True)])
    assert np.max(np.abs(d_vel)) < 0.03  # GPS_RAW_INT carries no vertical speed


# --------------------------------------------------------------------------- meaconing


@pytest.mark.parametrize("flavour", [AutopilotFlavour.ARDUPILOT, AutopilotFlavour.PX4])
def test_meaconing_is_the_truth_delayed(flavour: AutopilotFlavour) -> None:
    ev = Event("meaconing", T_ON, T_OFF, params={"delay_s": 0.7, "delay_rate": 0.02})
    meac, clean = _pair(ev, flavour=flavour)
    a, b = _fixes(meac), _fixes(clean)
    t_fix = np.array([y.t_s for y in b])  # the clean flight's stamps are the fix times
    delay = np.where((t_fix >= T_ON) & (t_fix < T_OFF), 0.7 + 0.02 * (t_fix - T_ON), 0.0)
    late = meac.truth.sample(t_fix - delay)
    now = meac.truth.sample(t_fix)
    d_pos = _ned(meac, a) - _ned(clean, b)
    np.testing.assert_allclose(d_pos, late.pos_ned_m - now.pos_ned_m, atol=0.02)
    d_vel = np.array([x.vel_ne_mps - y.vel_ne_mps for x, y in zip(a, b, strict=True)])
    np.testing.assert_allclose(d_vel, (late.vel_ned_mps - now.vel_ned_mps)[:, :2], atol=0.03)
    assert np.max(np.linalg.norm(d_pos, axis=1)) > 40.0 * 0.7  # 40 m/s for >= 0.7 s
    # the receiver's clock is late by the delay where the autopilot stamps its time
    stamps = {
        key: [m.time_usec for _, m in fl.messages if m.get_type() == "GPS_RAW_INT"]
        for key, fl in (("meac", meac), ("clean", clean))
    }
    shift_s = (np.array(stamps["meac"]) - np.array(stamps["clean"])) / 1e6
    if flavour is AutopilotFlavour.ARDUPILOT:  # UNIX time of the receiver's fix
        np.testing.assert_allclose(shift_s, -delay, atol=2e-6)
        np.testing.assert_allclose([x.t_s - y.t_s for x, y in zip(a, b, strict=True)], -delay,
                                   atol=2e-6)  # fmt: skip
    else:  # PX4 stamps boot time: the receiver's clock shows nowhere
        assert np.all(shift_s == 0.0)
    # SYSTEM_TIME, the autopilot's clock, never steps back (ArduPilot's AP_RTC)
    sys_a = [m.to_dict() for _, m in meac.messages if m.get_type() == "SYSTEM_TIME"]
    sys_b = [m.to_dict() for _, m in clean.messages if m.get_type() == "SYSTEM_TIME"]
    assert sys_a == sys_b
    _same_outside(meac, clean, _gnss_in(T_ON, T_OFF))


def test_meaconing_shifts_the_rtk_clock_too() -> None:
    ev = Event("meaconing", T_ON, T_OFF, params={"delay_s": 2.0})
    over = {"gnss_mode": "rtk_fixed"}
    meac = simulate(make_scenario("approach", events=(ev,), duration_s=150.0, **over), 2)
    clean = simulate(make_scenario("approach", events=(), duration_s=150.0, **over), 2)
    tow = {
        key: [(m.time_last_baseline_ms, m.tow) for _, m in fl.messages if m.get_type() == "GPS_RTK"]
        for key, fl in (("meac", meac), ("clean", clean))
    }
    shifts = [
        (ta - tb, ms / 1e3)
        for (ms, ta), (_, tb) in zip(tow["meac"], tow["clean"], strict=True)
    ]  # fmt: skip
    assert {s for s, t in shifts if T_ON <= t < T_OFF} == {-2000}
    assert {s for s, t in shifts if not T_ON <= t < T_OFF} == {0}


# --------------------------------------------------------------------------- jamming


def test_jamming_degrades_then_loses_the_fix_then_recovers() -> None:
    ev = Event("jamming", T_ON, T_OFF, params={"degrade_s": 20.0, "recover_s": 10.0})
    jammed, clean = _pair(ev)
    a, b = _fixes(jammed), _fixes(clean)
    t = np.array([x.t_s for x in a])
    lost = np.array([x.fix_type == FixType.NO_FIX for x in a])
    in_loss = (t >= T_ON + 20.0) & (t < T_OFF)
    assert np.array_equal(lost, in_loss)  # the loss is exactly the event's
    assert all(y.fix_type == FixType.FIX_3D for y in b)
    labels = dict(zip(jammed.truth.t_s.tolist(), jammed.truth.gnss_mode.tolist(), strict=True))
    assert {lab for tt, lab in labels.items() if T_ON + 20.0 <= tt < T_OFF} == {"none"}
    assert {lab for tt, lab in labels.items() if not T_ON + 20.0 <= tt < T_OFF} == {"3d"}
    csv = [r.split(",") for r in truth_rows(jammed)[1:]]
    assert {r[-1] for r in csv if T_ON + 20.0 <= float(r[0]) < T_OFF} == {"none"}
    # degradation: satellites down to 5, accuracies and DOP up to 8 times, monotonic
    deg = (t >= T_ON) & (t < T_ON + 20.0)
    pairs = [(x, y) for x, y, d in zip(a, b, deg, strict=True) if d]
    sats = np.array([x.satellites for x, _ in pairs])
    h_ratio = np.array([x.h_acc_m / y.h_acc_m for x, y in pairs])
    hdop = np.array([x.hdop / y.hdop for x, y in pairs])
    assert sats[0] == 10 and sats[-1] in (5, 6) and np.all(np.diff(sats) <= 0)
    assert h_ratio[0] == pytest.approx(1.0, abs=0.01) and 7.0 < h_ratio[-1] <= 8.0
    assert np.all(np.diff(h_ratio) >= -1e-3) and np.all(np.diff(hdop) >= -0.02)
    # and the errors grow with the accuracies (the receiver stays honest)
    err = jammed.errors.gnss[0]
    assert err.attacks is not None
    has_fix = err.label != "none"
    scaled = clean.errors.gnss[0].pos_err_ned_m * err.attacks.acc_factor[:, None]
    np.testing.assert_allclose(err.pos_err_ned_m[has_fix], scaled[has_fix])
    assert np.all(err.pos_err_ned_m[~has_fix] == 0.0) and np.any(~has_fix)
    # recovery: back to nominal after recover_s (the same messages as the clean flight)
    rec = (t >= T_OFF) & (t < T_OFF + 10.0)
    assert all(x.fix_type == FixType.FIX_3D for x, r in zip(a, rec, strict=True) if r)
    _same_outside(jammed, clean, _gnss_in(T_ON, T_OFF + 10.0))


# --------------------------------------------------------------------------- relay, determinism


def test_gnss_integrity_is_relayed_only_when_asked() -> None:
    jam = Event("jamming", T_ON, T_OFF, params={"degrade_s": 20.0})
    drag = event_drag(T_OFF + 5.0, 20.0, 0.5, (1.0, 0.0, 0.0), flagged=True)
    off = simulate(_plain((jam, drag), flavour=AutopilotFlavour.PX4), 1)
    assert not any(m.get_type() == "GNSS_INTEGRITY" for _, m in off.messages)
    assert "gnss_integrity_relay" not in off.scenario.as_dict()
    sc = _plain((jam, drag), flavour=AutopilotFlavour.PX4, gnss_integrity_relay=True)
    on = simulate(sc, 1)
    assert sc.as_dict()["gnss_integrity_relay"] is True
    msgs = [(t - sc.epoch0_s, m) for t, m in on.messages if m.get_type() == "GNSS_INTEGRITY"]
    assert len(msgs) == pytest.approx(170.0, abs=1)  # 1 Hz
    jam_on = {round(t) for t, m in msgs if m.jamming_state == 3}
    spoof_on = {round(t) for t, m in msgs if m.spoofing_state == 3}
    assert min(jam_on) == pytest.approx(T_ON + 10.0, abs=1) and max(jam_on) < T_OFF + 1
    assert min(spoof_on) == pytest.approx(T_OFF + 5.0, abs=1) and max(spoof_on) < T_OFF + 26
    assert all(m.jamming_state in (1, 3) and m.spoofing_state in (1, 3) for _, m in msgs)
    reports = [s for s in on.samples if isinstance(s, GnssSignalReport)]
    assert len(reports) == len(msgs)
    assert any(r.jamming is InterferenceState.DETECTED for r in reports)
    assert any(r.spoofing is InterferenceState.CLEAN for r in reports)
    # the other messages are the flight without the relay (their receive times draw their
    # jitter from the same generator as the relay's messages: they move by < 1 ms)
    rest = [(t, m.to_dict()) for t, m in on.messages if m.get_type() != "GNSS_INTEGRITY"]
    assert [m for _, m in rest] == [m.to_dict() for _, m in off.messages]
    assert max(abs(t - u) for (t, _), (u, _) in zip(rest, off.messages, strict=True)) < 1e-3
    # what a reader with the development dialect makes of the .tlog
    from pymavlink.dialects.v20 import development

    parser = development.MAVLink(None)
    parser.robust_parsing = True
    data = tlog_bytes(on)
    found = []
    pos = 0
    while pos < len(data):
        length = data[pos + 9]  # after the 8-byte stamp: STX, then the payload length
        frame = data[pos + 8 : pos + 8 + 12 + length]
        msg = parser.parse_char(bytearray(frame))
        if msg is not None and msg.get_type() == "GNSS_INTEGRITY":
            found.append(msg.jamming_state)
        pos += 8 + 12 + length
    assert found == [m.jamming_state for _, m in msgs]


@pytest.mark.parametrize("name", ["cruise_spoof_drag", "cruise_meaconing", "cruise_jamming"])
def test_attack_scenarios_are_deterministic(name: str) -> None:
    sc = make_scenario(name)
    assert [e.kind for e in sc.events] == [name.split("_")[-1].replace("spoof", "drag")]
    a, b, c = (simulate(sc, s) for s in (7, 7, 8))
    assert tlog_bytes(a) == tlog_bytes(b) != tlog_bytes(c)
    assert truth_rows(a) == truth_rows(b)
    side = sidecar(a)
    assert [e["kind"] for e in side["events"] if e["kind"] in ("drag", "meaconing", "jamming")]


@pytest.mark.parametrize(
    "params",
    [
        {"kind": "drag", "params": {"accel_mps2": -0.5}},
        {"kind": "drag", "params": {"direction_ned": (0.0, 0.0, 0.0)}},
        {"kind": "drag", "params": {"speed": 3.0}},
        {"kind": "meaconing", "params": {"delay_rate": 1.0}},
        {"kind": "meaconing", "params": {"delay_s": math.nan}},
        {"kind": "jamming", "params": {"degrade_s": 100.0}},
        {"kind": "jamming", "params": {"min_satellites": 2}},
        {"kind": "jamming", "params": {"flagged": "yes"}},
    ],
)
def test_bad_attack_parameters_are_one_line_value_errors(params: dict) -> None:
    with pytest.raises(ValueError) as info:
        Event(params["kind"], 10.0, 60.0, params=params["params"])
    assert "\n" not in str(info.value)


# --------------------------------------------------------------------------- the fixtures


@pytest.mark.slow
@pytest.mark.parametrize(
    "name",
    sorted(p.name.removesuffix(".json") for p in FIXTURES.glob("*.json")),
)
def test_committed_fixture_is_what_the_simulator_flies(name: str) -> None:
    """Every committed fixture is, byte for byte, its scenario flown with seed 1 today
    (.tlog, truth CSV, sidecar): the attacks changed none of them."""
    flight = simulate(make_scenario(name), 1)
    assert tlog_bytes(flight) == (FIXTURES / f"{name}.tlog").read_bytes()
    assert truth_rows(flight) == (FIXTURES / f"{name}.truth.csv").read_text().splitlines()
    side = json.loads((FIXTURES / f"{name}.json").read_text())
    assert json.loads(json.dumps(sidecar(flight), sort_keys=True)) == side

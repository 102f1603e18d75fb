"""Tests of the replay scorer against hand-built truth and published tlogs.

Every test builds its own truth CSV and a published tlog (MAVLink 2 frames from component
191, written with pymavlink) so that the scorer is checked against a known answer.
"""

from __future__ import annotations

import csv
import json
import math
import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pymap3d
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from companion.evaluate import (
    H95_PER_SIGMA,
    TRUTH_COLUMNS,
    Evaluation,
    EvaluationError,
    evaluate,
)
from companion.mavlink import units
from companion.mavlink.ids import MAV_COMP_ID_AUTOPILOT1, MAV_COMP_ID_ONBOARD_COMPUTER
from companion.nav.earth import radii_of_curvature_m

EPOCH0_S = 1_700_000_000.0
LATENCY_S = 0.012
LAT0_DEG, LON0_DEG, ALT0_M = 47.3977, 8.5456, 488.0
T0_S, T1_S, TRUTH_RATE_HZ = 10.0, 70.0, 50.0
PUBLISH_EVERY = 5  # 10 Hz publication at truth sample times


@dataclass
class Truth:
    """A smooth test trajectory: straight, then a steady turn; climbing at 1 m/s."""

    t_s: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    alt_m: np.ndarray
    vel_ned_mps: np.ndarray
    yaw_deg: np.ndarray


def make_truth() -> Truth:
    n = int(round((T1_S - T0_S) * TRUTH_RATE_HZ)) + 1
    t = T0_S + np.arange(n) / TRUTH_RATE_HZ
    tau = t - T0_S
    speed, turn_start, rate = 20.0, 30.0, math.radians(3.0)
    psi0 = math.radians(30.0)
    psi = np.where(tau < turn_start, psi0, psi0 + rate * (tau - turn_start))
    # Position: integral of speed * (cos psi, sin psi), closed form.
    n_m = np.where(
        tau < turn_start,
        speed * tau * math.cos(psi0),
        speed * turn_start * math.cos(psi0) + speed / rate * (np.sin(psi) - math.sin(psi0)),
    )
    e_m = np.where(
        tau < turn_start,
        speed * tau * math.sin(psi0),
        speed * turn_start * math.sin(psi0) - speed / rate * (np.cos(psi) - math.cos(psi0)),
    )
    d_m = -1.0 * tau
    lat, lon, alt = pymap3d.ned2geodetic(n_m, e_m, d_m, LAT0_DEG, LON0_DEG, ALT0_M)
    vel = np.column_stack([speed * np.cos(psi), speed * np.sin(psi), -np.ones_like(t)])
    return Truth(t, np.asarray(lat), np.asarray(lon), np.asarray(alt), vel, np.degrees(psi))


def write_truth(path: Path, truth: Truth, drop: str | None = None, dt_s: float = 0.0) -> Path:
    cols = [c for c in TRUTH_COLUMNS if c != drop]
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(cols)
        for i in range(truth.t_s.size):
            row = {
                "t_s": truth.t_s[i] + dt_s,
                "lat_deg": truth.lat_deg[i],
                "lon_deg": truth.lon_deg[i],
                "alt_m": truth.alt_m[i],
                "vn_mps": truth.vel_ned_mps[i, 0],
                "ve_mps": truth.vel_ned_mps[i, 1],
                "vd_mps": truth.vel_ned_mps[i, 2],
                "roll_deg": 0.0,
                "pitch_deg": 0.0,
                "yaw_deg": truth.yaw_deg[i],
                "phase": "cruise",
                "gnss_mode": "rtk_fixed",
            }
            w.writerow(
                [repr(float(row[c])) if c not in ("phase", "gnss_mode") else row[c] for c in cols]
            )
    return path


@dataclass
class Published:
    """Messages to write: list of (autopilot t_s, MAVLink message, component)."""

    items: list[tuple[float, object, int]] = field(default_factory=list)


OffsetFn = Callable[[float], tuple[float, float, float]]


def publish_solutions(
    truth: Truth,
    offset_ned_m: OffsetFn = lambda t: (0.0, 0.0, 0.0),
    h_acc_m: float | None = 1.0,
    v_acc_m: float = 2.0,
    every: int = PUBLISH_EVERY,
) -> list[tuple[float, object, int]]:
    """GLOBAL_POSITION_INT (+ GPS_INPUT) from comp 191 equal to truth + an NED offset."""
    out: list[tuple[float, object, int]] = []
    for i in range(0, truth.t_s.size, every):
        t = float(truth.t_s[i])
        dn, de, dd = offset_ned_m(t)
        lat, lon, alt = pymap3d.ned2geodetic(
            dn, de, dd, truth.lat_deg[i], truth.lon_deg[i], truth.alt_m[i]
        )
        lat_e7 = int(round(math.radians(float(lat)) * units.DEGE7_PER_RAD))
        lon_e7 = int(round(math.radians(float(lon)) * units.DEGE7_PER_RAD))
        v = truth.vel_ned_mps[i] * units.CM_PER_M
        hdg = int(round(math.radians(truth.yaw_deg[i] % 360.0) * units.CDEG_PER_RAD)) % 36000
        gpi = mavlink2.MAVLink_global_position_int_message(
            int(round(t * units.MS_PER_S)),
            lat_e7,
            lon_e7,
            int(round(float(alt) * units.MM_PER_M)),
            0,
            int(round(v[0])),
            int(round(v[1])),
            int(round(v[2])),
            hdg,
        )
        out.append((t, gpi, MAV_COMP_ID_ONBOARD_COMPUTER))
        if h_acc_m is not None:
            gin = mavlink2.MAVLink_gps_input_message(
                int(round(t * units.US_PER_S)), 0, 0, 0, 0, 3, lat_e7, lon_e7, float(alt),
                1.0, 1.0, *(float(x) for x in truth.vel_ned_mps[i]), 0.1, h_acc_m, v_acc_m, 12,
            )  # fmt: skip
            out.append((t, gin, MAV_COMP_ID_ONBOARD_COMPUTER))
    return out


def statustext(t_s: float, text: str, severity: int = 4) -> tuple[float, object, int]:
    msg = mavlink2.MAVLink_statustext_message(severity, text.encode("utf-8"), 0, 0)
    return (t_s, msg, MAV_COMP_ID_ONBOARD_COMPUTER)


def named_value(t_s: float, name: str, value: float) -> tuple[float, object, int]:
    msg = mavlink2.MAVLink_named_value_float_message(
        int(round(t_s * units.MS_PER_S)), name.encode(), value
    )
    return (t_s, msg, MAV_COMP_ID_ONBOARD_COMPUTER)


def write_tlog(path: Path, items: Sequence[tuple[float, object, int]]) -> Path:
    """Write items (sorted by autopilot time, stable) as a tlog stamped epoch0 + t + latency."""
    mavs = {
        comp: mavlink2.MAVLink(None, srcSystem=1, srcComponent=comp)
        for comp in {c for *_, c in items}
    }
    with path.open("wb") as fh:
        for t, msg, comp in sorted(items, key=lambda x: x[0]):
            stamp = int(round((EPOCH0_S + t + LATENCY_S) * units.US_PER_S))
            fh.write(struct.pack(">Q", stamp) + msg.pack(mavs[comp]))  # type: ignore[attr-defined]
    return path


def quantisation_bound_h_m(lat_deg: float) -> float:
    """Worst horizontal error of lat/lon rounded to 1e-7 deg: half a step on each axis."""
    m_m, n_m = radii_of_curvature_m(math.radians(lat_deg))
    half_step_rad = math.radians(0.5e-7)
    return half_step_rad * math.hypot(m_m + 600.0, (n_m + 600.0) * math.cos(math.radians(lat_deg)))


V_BOUND_M = 0.5 / units.MM_PER_M + 1e-9
"""Altitude rounded to a millimetre."""


@pytest.fixture(scope="module")
def truth() -> Truth:
    return make_truth()


def run(
    tmp_path: Path,
    truth: Truth,
    items: Sequence[tuple[float, object, int]],
    sidecar: dict | None = None,
) -> Evaluation:
    truth_csv = write_truth(tmp_path / "case.truth.csv", truth)
    if sidecar is not None:
        (tmp_path / "case.json").write_text(json.dumps(sidecar))
    out = write_tlog(tmp_path / "out.tlog", items)
    return evaluate(out, truth_csv)


# --------------------------------------------------------------------------- accuracy


def test_published_truth_gives_zero_error_to_quantisation(tmp_path: Path, truth: Truth) -> None:
    """Published = truth: the only error is MAVLink's rounding.

    Bounds: lat/lon rounded to 1e-7 deg is at most half a step on each axis, i.e.
    0.5e-7 deg x sqrt(M^2 + (N cos lat)^2) = 7.9 mm at 47 deg; altitude rounded to the mm is
    at most 0.5 mm; velocity rounded to cm/s is at most 0.5 cm/s per axis; heading rounded
    to the centidegree at most 0.005 deg.
    """
    ev = run(tmp_path, truth, publish_solutions(truth))
    bound_h = quantisation_bound_h_m(LAT0_DEG)
    assert 0.005 < bound_h < 0.01  # about 8 mm at 47 deg
    assert ev.n_published == ev.n_evaluated == (truth.t_s.size - 1) // PUBLISH_EVERY + 1
    assert ev.overall.h_max_m is not None and ev.overall.h_max_m <= bound_h
    assert ev.overall.v_max_m is not None and ev.overall.v_max_m <= V_BOUND_M
    # Velocity rounded to cm/s on each of N, E.
    assert ev.overall.vel_h_rms_mps is not None
    assert ev.overall.vel_h_rms_mps <= math.hypot(0.005, 0.005)
    # Heading rounded to a centidegree.
    assert ev.overall.yaw_rms_deg is not None and ev.overall.yaw_rms_deg <= 0.005 + 1e-9
    assert ev.normal.n == ev.overall.n and ev.windows == ()
    assert ev.accuracy_source == "GPS_INPUT"
    assert ev.overall.h95_coverage == 1.0
    assert ev.publish_rate_hz == pytest.approx(TRUTH_RATE_HZ / PUBLISH_EVERY)


def test_known_offset_is_reported(tmp_path: Path, truth: Truth) -> None:
    """3 m north and 1 m up, in the local frame of each truth point."""
    ev = run(tmp_path, truth, publish_solutions(truth, lambda t: (3.0, 0.0, -1.0)))
    bound_h = quantisation_bound_h_m(LAT0_DEG)
    s = ev.overall
    assert s.h_mean_m == pytest.approx(3.0, abs=bound_h)
    assert s.h_max_m == pytest.approx(3.0, abs=bound_h)
    assert s.h_p95_m == pytest.approx(3.0, abs=bound_h)
    assert s.v_mean_m == pytest.approx(1.0, abs=V_BOUND_M)
    assert s.v_max_m == pytest.approx(1.0, abs=V_BOUND_M)
    # 3 m is outside the published 95 % (2.45 x 1 m) everywhere; 1 m vertical is inside 1.96 x 2 m.
    assert H95_PER_SIGMA == pytest.approx(2.4477, abs=1e-4)
    assert s.h95_coverage == 0.0
    assert s.v95_coverage == 1.0


def test_offset_east_down_and_interpolated_times(tmp_path: Path, truth: Truth) -> None:
    """Published between truth samples (interpolated truth), 2 m east and 0.5 m down."""
    items = []
    for t, msg, comp in publish_solutions(truth, lambda t: (0.0, 2.0, 0.5), every=1):
        items.append((t, msg, comp))
    truth_csv = write_truth(tmp_path / "x.truth.csv", make_truth_sparse(truth))
    out = write_tlog(tmp_path / "out.tlog", items)
    ev = evaluate(out, truth_csv)
    # The sparse truth (5 Hz) is interpolated at the 50 Hz published times; the straight
    # leg and the 3 deg/s turn make the chord error below 1 cm (20 m/s, 0.2 s: r*(1-cos) ~ 2 mm).
    tol = quantisation_bound_h_m(LAT0_DEG) + 0.01
    assert ev.overall.h_mean_m == pytest.approx(2.0, abs=tol)
    assert ev.overall.h_max_m == pytest.approx(2.0, abs=tol)
    assert ev.overall.v_mean_m == pytest.approx(-0.5, abs=V_BOUND_M + 1e-6)


def make_truth_sparse(truth: Truth, every: int = 10) -> Truth:
    sl = slice(0, None, every)
    return Truth(
        truth.t_s[sl],
        truth.lat_deg[sl],
        truth.lon_deg[sl],
        truth.alt_m[sl],
        truth.vel_ned_mps[sl],
        truth.yaw_deg[sl],
    )


def test_solutions_outside_truth_are_counted_not_scored(tmp_path: Path, truth: Truth) -> None:
    items = publish_solutions(truth)
    truth_csv = write_truth(tmp_path / "a.truth.csv", truth, dt_s=30.0)  # truth 40..100 s
    out = write_tlog(tmp_path / "out.tlog", items)
    ev = evaluate(out, truth_csv)
    assert ev.n_evaluated + ev.n_outside_truth == ev.n_published
    assert ev.n_outside_truth == sum(
        1 for t, m, _ in items if m.get_type() == "GLOBAL_POSITION_INT" and t < 40.0
    )  # type: ignore[attr-defined]


# --------------------------------------------------------------------------- events


EVENTS = [
    {"kind": "outage", "t_start_s": 30.0, "t_end_s": 40.0, "receiver_id": 0, "params": {}},
    {"kind": "ramp", "t_start_s": 44.0, "t_end_s": 48.0, "receiver_id": 0,
     "params": {"rate_ned_mps": [0.0, 0.0, 0.04]}},  # the simulator's params
    {"kind": "step", "t_start_s": 50.0, "t_end_s": 55.0, "receiver_id": 0,
     "params": {"offset_ned_m": [6.0, 8.0, 0.0]}},
    {"kind": "stale", "t_start_s": 64.0, "t_end_s": 66.0, "receiver_id": 0, "params": {}},
]  # fmt: skip


def event_offset(t: float) -> tuple[float, float, float]:
    if 30.0 <= t <= 40.0:
        return (5.0, 0.0, 0.0)
    if 50.0 <= t <= 55.0:
        return (0.0, 2.0, 0.0)
    return (0.0, 0.0, 0.0)


def event_case(tmp_path: Path, truth: Truth) -> Evaluation:
    items = publish_solutions(truth, event_offset)
    items += [
        statustext(20.0, "CMP INTEGRITY HPL 40 > HAL 35"),  # no event: false
        statustext(31.2, "CMP GNSS_LOST all receivers"),  # outage detected after 1.2 s
        statustext(31.25, "CMP BRIDGING"),
        statustext(33.0, "CMP INTEGRITY HPL 50 > HAL 35"),  # explained by the outage
        statustext(41.0, "CMP GNSS_BACK"),
        statustext(43.0, "CMP FAULT rx0 rejected"),  # explained by the recovery grace (40+5)
        statustext(46.5, "CMP FAULT rx0 ramp"),  # ramp detected after 2.5 s
        statustext(51.04, "CMP FAULT rx0 step"),  # step detected after 1.04 s
        statustext(62.0, "CMP FAULT rx0 rejected"),  # after 55+5 and before 64-0.5: false
        statustext(63.0, "CMP CAT 1"),
    ]
    sidecar = {"scenario": "unit", "seed": 7, "heading_error_deg": 1.0, "crab_deg": 0.0,
               "events": EVENTS}  # fmt: skip
    return run(tmp_path, truth, items, sidecar)


def test_errors_are_split_by_event_window(tmp_path: Path, truth: Truth) -> None:
    ev = event_case(tmp_path, truth)
    bound_h = quantisation_bound_h_m(LAT0_DEG)
    assert [w.kind for w in ev.windows] == ["outage", "ramp", "step", "stale"]
    outage, ramp, step, stale = ev.windows
    assert outage.n == 101  # 30.0 .. 40.0 s at 10 Hz, both ends included
    assert outage.h_mean_m == pytest.approx(5.0, abs=bound_h)
    assert outage.h_max_m == pytest.approx(5.0, abs=bound_h)
    assert outage.h95_coverage == 0.0  # 5 m > 2.45 x 1 m
    assert step.h_mean_m == pytest.approx(2.0, abs=bound_h)
    assert step.h95_coverage == 1.0  # 2 m < 2.45 m
    assert ramp.h_max_m is not None and ramp.h_max_m <= bound_h
    assert stale.n == 21
    assert ev.normal.h_max_m is not None and ev.normal.h_max_m <= bound_h
    assert ev.normal.n == ev.overall.n - outage.n - ramp.n - step.n - stale.n
    assert ev.overall.h_max_m == pytest.approx(5.0, abs=bound_h)
    assert ev.scenario == "unit" and ev.seed == 7


def test_alerts_timed_from_window_start_and_false_alerts(tmp_path: Path, truth: Truth) -> None:
    ev = event_case(tmp_path, truth)
    res = {e.kind: e for e in ev.events}
    assert res["outage"].detected and res["outage"].alert_code == "GNSS_LOST"
    # Alert times come from the tlog stamps through the solution's time offset: exact to
    # the microsecond stamp.
    assert res["outage"].latency_s == pytest.approx(1.2, abs=1e-5)
    assert res["ramp"].alert_code == "FAULT"
    assert res["ramp"].latency_s == pytest.approx(2.5, abs=1e-5)
    assert res["ramp"].fault_size_at_detection == pytest.approx(0.04 * 2.5, abs=1e-6)
    assert res["step"].latency_s == pytest.approx(1.04, abs=1e-5)
    assert res["step"].fault_size_at_detection == pytest.approx(10.0)
    assert not res["stale"].detected and res["stale"].latency_s is None
    false = [(round(a.t_s, 3), a.code) for a in ev.alerts if a.false_alert]
    assert false == [(20.0, "INTEGRITY"), (62.0, "FAULT")]
    assert ev.n_false_alerts == 2
    codes = [a.code for a in ev.alerts]
    assert codes.count("BRIDGING") == 1 and "CAT" in codes and "GNSS_BACK" in codes
    text = ev.to_text()
    assert "MISSED" in text and "GNSS_LOST" in text and "FALSE" in text
    doc = ev.to_dict()
    json.dumps(doc, allow_nan=False)
    assert doc["n_false_alerts"] == 2
    assert doc["events"][0]["latency_s"] == pytest.approx(1.2, abs=1e-5)


def test_alert_time_uses_the_preceding_solution_offset(tmp_path: Path, truth: Truth) -> None:
    """The tlog clock runs 100 s ahead of the boot clock after t=40: alert times follow it."""
    items = publish_solutions(truth) + [
        statustext(35.03, "CMP GNSS_LOST"),
        statustext(45.07, "CMP FAULT x"),
    ]
    truth_csv = write_truth(tmp_path / "c.truth.csv", truth)
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=191)
    path = tmp_path / "out.tlog"
    with path.open("wb") as fh:
        for t, msg, _ in sorted(items, key=lambda x: x[0]):
            jump = 100.0 if t >= 40.0 else 0.0
            stamp = int(round((EPOCH0_S + t + jump) * units.US_PER_S))
            fh.write(struct.pack(">Q", stamp) + msg.pack(mav))  # type: ignore[attr-defined]
    ev = evaluate(path, truth_csv)
    assert [round(a.t_s, 4) for a in ev.alerts] == [35.03, 45.07]


@pytest.mark.parametrize("pm", ["\u00b1", "?", "+-"])
def test_heading_correction_against_sidecar(tmp_path: Path, truth: Truth, pm: str) -> None:
    """The +- sign survives UTF-8 (decoded as two U+FFFD), ASCII "?" replacement and "+-"."""
    items = publish_solutions(truth, every=25)
    items += [
        named_value(15.0, "CMP_HDGC", 0.7),
        named_value(15.0, "CMP_HDGE", 0.5),
        named_value(24.0, "CMP_HDGC", 1.02),
        named_value(24.0, "CMP_HDGE", 0.05),
        statustext(24.0, f"CMP HDG_READY 1.02 {pm}0.05 n=412"),
        statustext(25.0, "CMP HDG_APPLIED"),
    ]
    params = {"heading_error_deg": 1.0, "crab_deg": -0.5}
    # At the top level (as specified) or under "parameters" (as the simulator writes it).
    sidecar = {"scenario": "taxi", "seed": 1, "events": []}
    sidecar.update(params if pm != "+-" else {"parameters": params})
    ev = run(tmp_path, truth, items, sidecar)
    h = ev.heading
    assert h.ready_value_deg == pytest.approx(1.02)
    assert h.ready_eps_deg == pytest.approx(0.05)
    assert h.ready_cycles == 412
    assert h.ready_t_s == pytest.approx(24.0, abs=1e-5)
    assert h.expected_deg == pytest.approx(0.5)  # heading error + crab
    assert h.error_deg == pytest.approx(0.52)
    assert h.hdgc_last_deg == pytest.approx(1.02, abs=1e-6)
    assert h.hdge_last_deg == pytest.approx(0.05, abs=1e-6)
    assert h.accumulation_s == pytest.approx(9.0, abs=1e-5)
    assert h.applied
    assert ev.n_false_alerts == 0
    assert "HDG_READY +1.020" in ev.to_text()
    if pm == "?":  # undone after: not applied
        undone = run(tmp_path, truth, [*items, statustext(26.0, "CMP HDG_UNDONE 1.02")], sidecar)
        assert not undone.heading.applied


def test_px4_accuracy_from_named_values(tmp_path: Path, truth: Truth) -> None:
    items = publish_solutions(truth, lambda t: (0.0, 3.0, 0.0), h_acc_m=None)
    items += [named_value(float(t), "CMP_HACC", 1.5) for t in np.arange(T0_S, T1_S, 0.5)]
    ev = run(tmp_path, truth, items)
    assert ev.accuracy_source == "CMP_HACC"
    assert ev.overall.h95_coverage == 1.0  # 3 m < 2.45 x 1.5 m
    assert ev.overall.v95_coverage is None


def test_corrupt_records_are_skipped_and_counted(tmp_path: Path, truth: Truth) -> None:
    items = publish_solutions(truth, h_acc_m=None)
    path = write_tlog(tmp_path / "out.tlog", items)
    data = bytearray(path.read_bytes())
    rec_len = len(data) // len(items)  # every GLOBAL_POSITION_INT record has the same length
    data[10 * rec_len + 20] ^= 0xFF  # corrupt the 11th record's payload (CRC fails)
    garbage = bytes(np.random.default_rng(3).integers(0, 256, 37, dtype=np.uint8))
    data[20 * rec_len : 20 * rec_len] = garbage  # garbage between records 20 and 21
    path.write_bytes(bytes(data) + data[:13])  # and a truncated last record
    truth_csv = write_truth(tmp_path / "t.truth.csv", truth)
    ev = evaluate(path, truth_csv)
    assert ev.n_published == len(items) - 1
    assert ev.tlog.bad_records == 2
    assert ev.tlog.truncated_records == 1  # the 13-byte cut-short last record
    assert ev.overall.h_max_m is not None and ev.overall.h_max_m <= quantisation_bound_h_m(LAT0_DEG)


def test_only_component_191_is_scored(tmp_path: Path, truth: Truth) -> None:
    ours = publish_solutions(truth, h_acc_m=None)
    theirs = [
        (t, m, MAV_COMP_ID_AUTOPILOT1)
        for t, m, _ in publish_solutions(truth, lambda t: (50.0, 0.0, 0.0), h_acc_m=None)
    ]
    ev = run(tmp_path, truth, ours + theirs + [(20.0, statustext(20.0, "CMP FAULT x")[1], 1)])
    assert ev.n_published == len(ours)
    assert ev.overall.h_max_m is not None and ev.overall.h_max_m < 0.01
    assert ev.alerts == ()


# --------------------------------------------------------------------------- bad input


def test_missing_files_raise(tmp_path: Path, truth: Truth) -> None:
    truth_csv = write_truth(tmp_path / "t.truth.csv", truth)
    out = write_tlog(tmp_path / "out.tlog", publish_solutions(truth))
    with pytest.raises(EvaluationError, match="no such file"):
        evaluate(tmp_path / "nope.tlog", truth_csv)
    with pytest.raises(EvaluationError, match="no such file"):
        evaluate(out, tmp_path / "nope.csv")
    with pytest.raises(EvaluationError, match="no such events file"):
        evaluate(out, truth_csv, tmp_path / "nope.json")


def test_missing_column_raises(tmp_path: Path, truth: Truth) -> None:
    truth_csv = write_truth(tmp_path / "t.truth.csv", truth, drop="alt_m")
    out = write_tlog(tmp_path / "out.tlog", publish_solutions(truth))
    with pytest.raises(EvaluationError, match="alt_m"):
        evaluate(out, truth_csv)


def test_non_overlapping_truth_raises(tmp_path: Path, truth: Truth) -> None:
    truth_csv = write_truth(tmp_path / "t.truth.csv", truth, dt_s=1000.0)
    out = write_tlog(tmp_path / "out.tlog", publish_solutions(truth))
    with pytest.raises(EvaluationError, match="mismatched truth"):
        evaluate(out, truth_csv)


def test_truth_of_another_place_raises(tmp_path: Path, truth: Truth) -> None:
    truth_csv = write_truth(tmp_path / "t.truth.csv", truth)
    far = publish_solutions(truth, lambda t: (200_000.0, 0.0, 0.0))
    out = write_tlog(tmp_path / "out.tlog", far)
    with pytest.raises(EvaluationError, match="mismatched truth"):
        evaluate(out, truth_csv)


def test_unreadable_tlog_and_bad_sidecar_raise(tmp_path: Path, truth: Truth) -> None:
    truth_csv = write_truth(tmp_path / "t.truth.csv", truth)
    junk = tmp_path / "junk.tlog"
    junk.write_bytes(bytes(np.random.default_rng(5).integers(0, 256, 5000, dtype=np.uint8)))
    with pytest.raises(EvaluationError):
        evaluate(junk, truth_csv)
    text = tmp_path / "text.tlog"
    text.write_text("this is not a tlog\n" * 50)
    with pytest.raises(EvaluationError):
        evaluate(text, truth_csv)
    only_autopilot = [(t, m, 1) for t, m, _ in publish_solutions(truth)]
    out = write_tlog(tmp_path / "ap.tlog", only_autopilot)
    with pytest.raises(EvaluationError, match="no published solution"):
        evaluate(out, truth_csv)
    good = write_tlog(tmp_path / "out.tlog", publish_solutions(truth))
    bad_json = tmp_path / "bad.json"
    bad_json.write_text("{not json")
    with pytest.raises(EvaluationError, match="not valid JSON"):
        evaluate(good, truth_csv, bad_json)
    bad_window = tmp_path / "bw.json"
    bad_window.write_text(
        json.dumps({"events": [{"kind": "outage", "t_start_s": 5, "t_end_s": 1}]})
    )
    with pytest.raises(EvaluationError, match="invalid window"):
        evaluate(good, truth_csv, bad_window)
    empty_truth = tmp_path / "e.truth.csv"
    empty_truth.write_text(",".join(TRUTH_COLUMNS) + "\n")
    with pytest.raises(EvaluationError, match="fewer than 2"):
        evaluate(good, empty_truth)


def test_an_autopilot_reboot_is_undone_by_the_tlog_time_of_its_silence():
    # the simulator's truth stays on the first boot's clock: published times after a
    # reboot continue the first boot's by the silence's tlog time, not from zero
    from companion.evaluate.published import _BootClock

    boot = _BootClock()
    epoch = 1.7e9
    times = [boot.continuous(t, epoch + t) for t in (10.0, 10.1, 10.2)]
    # 3 s of silence, then the new boot's clock starts at 4.0 s
    after = [boot.continuous(t, epoch + 10.2 + 3.0 + (t - 4.0)) for t in (4.0, 4.1)]
    assert times == [10.0, 10.1, 10.2]
    assert after == pytest.approx([13.2, 13.3])
    # jitter of the clock (a few ms back) is no reboot
    assert boot.continuous(4.095, epoch + 13.31) == pytest.approx(13.295)

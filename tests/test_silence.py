"""Silence is an event, no GNSS is an alert: constructed streams and logs with known answers.

A whole-stream dropout cut out of a simulated flight (its truth known) and the same
flight without GNSS, replayed: what is due during the silence comes at its log time,
nothing is published across it, the first position after it is the first fix's; without
GNSS the service says so within 5 s and again every 30 s. The engine-level tests drive the
same through :meth:`Engine.on_clock`, as a driver's timer does.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import struct
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from companion.engine import Engine, EngineConfig
from companion.mavlink.tlog import TlogReader
from companion.pipeline import NAV_NO_GNSS, NAV_SILENT
from companion.replay import replay
from companion.types import (
    Alert,
    AlertCode,
    GnssFix,
    NavSolution,
    Output,
    RebootEvent,
    Sample,
)
from tests.helpers import FIXTURES, ORIGIN, Line, line_stream

CRUISE = FIXTURES / "cruise_gnss_loss.tlog"
"""A simulated cruise with turns (its GNSS loss at 130 s is after the part used here)."""
EPOCH0_S = json.loads((FIXTURES / "cruise_gnss_loss.json").read_text())["epoch0_s"]
"""UNIX time of the simulation's boot-clock zero."""
MSG_GPS_RAW_INT = 24
MSG_HEARTBEAT = 0
SILENCE_TIMEOUT_S = EngineConfig().silence_timeout_s
DATA_IDS = frozenset({24, 27, 30})
"""GPS_RAW_INT, RAW_IMU, ATTITUDE: the fixture's navigation data."""
CHI_2D_99 = math.sqrt(-2.0 * math.log(0.01))
"""Radius of the 99 % circle in units of the 1-sigma of the worst axis (3.03)."""


# ---------------------------------------------------------------------- tlog surgery


def tlog_records(path: Path) -> Iterator[tuple[float, int, bytes]]:
    """(time s, message id, the whole record) of every record of a MAVLink 1/2 tlog."""
    data = path.read_bytes()
    i = 0
    while i + 8 < len(data):
        (t_us,) = struct.unpack(">Q", data[i : i + 8])
        magic = data[i + 8]
        length = data[i + 9]
        if magic == 0xFD:
            signed = data[i + 10] & 0x01
            size = 10 + length + 2 + (13 if signed else 0)
            msgid = int.from_bytes(data[i + 15 : i + 18], "little")
        elif magic == 0xFE:
            size = 8 + length
            msgid = data[i + 13]
        else:
            raise ValueError(f"not a frame at {i}")
        yield t_us / 1e6, msgid, data[i : i + 8 + size]
        i += 8 + size


def cut(path: Path, out: Path, keep) -> Path:
    """Write the records of ``path`` for which ``keep(t_rel_s, msgid)`` holds to ``out``."""
    records = list(tlog_records(path))
    t0 = records[0][0]
    out.write_bytes(b"".join(rec for t, mid, rec in records if keep(t - t0, mid)))
    return out


def truth_at(t_boot_s: float) -> tuple[float, float]:
    """The simulator's true (lat, lon) in degrees at ``t_boot_s`` (linear interpolation)."""
    rows = _truth()
    times = [r[0] for r in rows]
    k = int(np.searchsorted(times, t_boot_s))
    (ta, la, oa), (tb, lb, ob) = rows[k - 1], rows[k]
    w = (t_boot_s - ta) / (tb - ta)
    return la + w * (lb - la), oa + w * (ob - oa)


_TRUTH: list[tuple[float, float, float]] = []


def _truth() -> list[tuple[float, float, float]]:
    if not _TRUTH:
        with open(FIXTURES / "cruise_gnss_loss.truth.csv") as fh:
            for row in csv.DictReader(fh):
                _TRUTH.append((float(row["t_s"]), float(row["lat_deg"]), float(row["lon_deg"])))
    return _TRUTH


def fix_boot_s(fix) -> float:
    """A simulated GPS_RAW_INT's time of validity on the boot clock (its time_usec is UNIX
    time: the simulation's epoch is in the fixture's description)."""
    return fix.time_usec / 1e6 - EPOCH0_S


def dist_m(a: tuple[float, float], b: tuple[float, float]) -> float:
    lat = math.radians(a[0])
    dn = math.radians(b[0] - a[0]) * 6_371_000.0
    de = math.radians(b[1] - a[1]) * 6_371_000.0 * math.cos(lat)
    return math.hypot(dn, de)


# ---------------------------------------------------------------------- replays


SILENCE = (40.0, 55.0)
"""The dropout cut out of the cruise (s after its first record): every record, heartbeats too."""


@pytest.fixture(scope="module")
def silence_replay(tmp_path_factory):
    d = tmp_path_factory.mktemp("silence")
    src = cut(CRUISE, d / "in.tlog", lambda t, mid: t < 80.0 and not SILENCE[0] <= t < SILENCE[1])
    out_a, out_b = d / "a.tlog", d / "b.tlog"
    replay(src, out_a)
    replay(src, out_b)
    return src, out_a, out_b


def test_a_silence_in_a_replayed_log_gives_its_alerts_at_their_log_times(silence_replay):
    src, out, again = silence_replay
    assert out.read_bytes() == again.read_bytes()  # deterministic
    records = list(tlog_records(src))
    t0 = records[0][0]
    last_data = max(t for t, mid, _ in records if t - t0 < SILENCE[0] and mid != MSG_HEARTBEAT)
    last_fix = max(t for t, mid, _ in records if t - t0 < SILENCE[0] and mid == MSG_GPS_RAW_INT)
    back = min(t for t, mid, _ in records if t - t0 >= SILENCE[1] and mid in DATA_IDS)
    texts = [(t, m.text) for t, m in TlogReader(out) if m.get_type() == "STATUSTEXT"]
    during = [(t, text.split()[1]) for t, text in texts if last_fix < t < back]
    # one alert for the dropout, in log time: NO_DATA at the GNSS timeout (the fixes
    # stopped with every other stream), within 1.5 s of the last fix and before the
    # silence timeout; no GNSS_LOST beside it
    assert [code for _, code in during] == ["NO_DATA"]
    no_data = during[0][0]
    assert no_data - last_fix <= 1.5
    assert no_data - last_data < SILENCE_TIMEOUT_S
    data_back = [t for t, text in texts if text.startswith("CMP DATA_BACK")]
    assert data_back == [pytest.approx(back, abs=1e-6)]
    # the heartbeat goes on in the silence, once a second, saying so after NO_DATA
    beats = [(t, m) for t, m in TlogReader(out) if m.get_type() == "HEARTBEAT"]
    in_gap = [(t, m) for t, m in beats if no_data < t < back]
    assert len(in_gap) >= 10
    assert all(m.custom_mode == NAV_SILENT and m.system_status == 5 for _, m in in_gap)
    gaps = np.diff([t for t, _ in beats])
    assert np.allclose(gaps, 1.0, atol=1e-6)


def test_after_a_silence_the_first_position_is_the_first_fix_within_its_bound(silence_replay):
    src, out, _ = silence_replay
    records = list(tlog_records(src))
    t0 = records[0][0]
    last_data = max(t for t, mid, _ in records if t - t0 < SILENCE[0] and mid != MSG_HEARTBEAT)
    fixes = [
        (t, m) for t, m in TlogReader(src) if m.get_type() == "GPS_RAW_INT" and t - t0 >= SILENCE[1]
    ]
    first_fix_t, first_fix = fixes[0]
    published = [(t, m) for t, m in TlogReader(out) if m.get_type() == "GPS_INPUT"]
    # nothing published from the silence's start to the first fix after it
    assert not [t for t, _ in published if last_data + 0.2 < t < first_fix_t]
    after = [(t, m) for t, m in published if t >= first_fix_t]
    t_pub, first = after[0]
    assert t_pub - first_fix_t < 0.5
    pos = (first.lat * 1e-7, first.lon * 1e-7)
    bound_m = CHI_2D_99 * first.horiz_accuracy
    # the first fix, carried by its own velocity to the solution's time of validity (the
    # simulated receiver reports at the same time as its validity: GPS_RAW_INT and GPS_INPUT
    # times are both on the boot clock here)
    lag_s = first.time_usec / 1e6 - fix_boot_s(first_fix)
    assert 0.0 <= lag_s < 0.2
    course = math.radians(first_fix.cog / 100.0)
    speed = first_fix.vel / 100.0
    north, east = speed * math.cos(course) * lag_s, speed * math.sin(course) * lag_s
    fix_then = (
        first_fix.lat * 1e-7 + math.degrees(north / 6_371_000.0),
        first_fix.lon * 1e-7
        + math.degrees(east / 6_371_000.0 / math.cos(math.radians(first_fix.lat * 1e-7))),
    )
    assert dist_m(pos, fix_then) <= bound_m
    # and against the truth, at the published time of validity
    assert dist_m(pos, truth_at(first.time_usec / 1e6)) <= bound_m
    # nothing jumps in the first 5 s: every published position within its own 99 % bound
    for _, m in after[:50]:
        truth = truth_at(m.time_usec / 1e6)
        assert dist_m((m.lat * 1e-7, m.lon * 1e-7), truth) <= CHI_2D_99 * m.horiz_accuracy


def test_a_log_without_gnss_alerts_within_5_s_and_every_30_s(tmp_path):
    src = cut(CRUISE, tmp_path / "in.tlog", lambda t, mid: t < 70.0 and mid != MSG_GPS_RAW_INT)
    out = replay(src, tmp_path / "out.tlog")
    assert out.out_by_type.get("GPS_INPUT", 0) == 0
    t0 = next(tlog_records(src))[0]
    no_gnss = [
        t - t0
        for t, m in TlogReader(tmp_path / "out.tlog")
        if m.get_type() == "STATUSTEXT" and m.text.startswith("CMP NO_GNSS")
    ]
    assert no_gnss and no_gnss[0] <= 5.0
    assert np.allclose(np.diff(no_gnss), 30.0, atol=0.05) and len(no_gnss) == 3
    beats = [m for t, m in TlogReader(tmp_path / "out.tlog") if m.get_type() == "HEARTBEAT"]
    late = beats[6:]
    assert all(m.custom_mode == NAV_NO_GNSS and m.system_status == 5 for m in late)


# ---------------------------------------------------------------------- the engine


GNSS_AND_DATA = frozenset(
    {
        AlertCode.NO_GNSS,
        AlertCode.GNSS_LOST,
        AlertCode.GNSS_BACK,
        AlertCode.NO_DATA,
        AlertCode.DATA_BACK,
    }
)
"""The alerts of the GNSS and the data streams (the others, CAT ..., are not at stake)."""


def alerts(outputs: list[Output], code: AlertCode) -> list[Alert]:
    return [o for o in outputs if isinstance(o, Alert) and o.code is code]


def drive(engine: Engine, samples: list[Sample]) -> list[Output]:
    """Feed ``samples`` as a driver does: before each, what the engine has due on its clock."""
    outputs: list[Output] = []
    for sample in samples:
        while (due := engine.next_due_s()) <= sample.t_s:
            outputs += engine.on_clock(due)
        outputs += engine.handle(sample)
    return outputs


def shifted(sample: Sample, north_m: float) -> Sample:
    """A fix moved ``north_m`` north (the vehicle went elsewhere during a silence)."""
    if not isinstance(sample, GnssFix):
        return sample
    pos = ORIGIN.lla_to_ned(sample.lat_rad, sample.lon_rad, sample.alt_msl_m)
    lat, lon, _ = ORIGIN.ned_to_lla(np.asarray(pos) + np.array([north_m, 0.0, 0.0]))
    return dataclasses.replace(sample, lat_rad=lat, lon_rad=lon)


def test_the_engine_restarts_from_the_first_fix_after_a_silence_nothing_jumps():
    """15 s of silence, after which the vehicle is 300 m north of where constant velocity
    would put it: the first solution after is the first fix, within its 99 % bound."""
    line = Line()
    samples = list(line_stream(50.0, line=line))
    t_cut = (30.0, 45.0)  # absolute (line_stream starts at 10 s)
    before = [s for s in samples if s.t_s < t_cut[0]]
    after = [shifted(s, 300.0) for s in samples if s.t_s >= t_cut[1]]
    engine = Engine()
    out = drive(engine, before)
    out_gap: list[Output] = []
    while (due := engine.next_due_s()) < t_cut[1]:
        out_gap += engine.on_clock(due)
    last_fix = max(s.t_s for s in before if isinstance(s, GnssFix))
    # one alert, at the GNSS timeout: NO_DATA (every stream stopped), not GNSS_LOST
    said = [(a.code, a.t_s - last_fix) for a in out_gap if isinstance(a, Alert)]
    assert said == [(AlertCode.NO_DATA, pytest.approx(1.0, abs=1e-3))]
    assert not [o for o in out_gap if isinstance(o, NavSolution)]
    assert engine.watch.silent and out
    out_after = drive(engine, after)
    assert alerts(out_after, AlertCode.DATA_BACK)[0].t_s == after[0].t_s
    assert engine.stats.silences == 1
    solutions = [o for o in out_after if isinstance(o, NavSolution)]
    assert solutions
    for sol in solutions[:50]:
        truth = line.pos_ned_m(sol.t_s) + np.array([300.0, 0.0, 0.0])
        lat, lon, _ = ORIGIN.ned_to_lla(truth)
        err = dist_m(
            (math.degrees(sol.lat_rad), math.degrees(sol.lon_rad)),
            (math.degrees(lat), math.degrees(lon)),
        )
        assert err <= CHI_2D_99 * sol.h_acc_m, sol.t_s


def test_no_gnss_is_raised_at_3_s_repeated_every_30_s_and_ended_by_the_first_fix():
    line = Line()
    imu_only = [s for s in line_stream(70.0, line=line) if not isinstance(s, GnssFix)]
    engine = Engine()
    out = drive(engine, imu_only)
    no_gnss = alerts(out, AlertCode.NO_GNSS)
    assert [a.t_s - 10.0 for a in no_gnss] == pytest.approx([3.0, 33.0, 63.0], abs=0.03)
    assert not [o for o in out if isinstance(o, NavSolution)]
    later = [s for s in line_stream(10.0, line=line, t0_s=80.0)]
    out = drive(engine, later)
    back = alerts(out, AlertCode.GNSS_BACK)
    assert len(back) == 1 and "navigating" in back[0].text
    assert [o for o in out if isinstance(o, NavSolution)]
    assert not engine.watch.waiting


def test_an_autopilot_reboot_during_a_silence_ends_it_and_restarts_everything():
    line = Line()
    engine = Engine()
    drive(engine, list(line_stream(20.0, line=line)))
    engine.on_clock(40.0)
    assert engine.watch.silent
    reboot = RebootEvent(t_s=1.0, t_rx_s=41.0, previous_t_s=30.0)
    out = engine.handle(reboot)
    assert [a.text for a in alerts(out, AlertCode.DATA_BACK)] == ["reboot: restart from next fix"]
    assert engine.stats.reboots == 1 and not engine.watch.silent
    out = drive(engine, list(line_stream(10.0, line=line, t0_s=1.5)))
    assert [o for o in out if isinstance(o, NavSolution)]
    assert not alerts(out, AlertCode.DATA_BACK)


def test_a_stall_shorter_than_the_silence_timeout_is_said_once_and_restarts() -> None:
    """Every stream stops 1.5 s (under the 2 s silence timeout): the GNSS loss, due while
    everything is quiet, is said as NO_DATA; the first sample after ends it with DATA_BACK
    and the navigation restarts from the next fix (nothing is carried across an announced
    silence): one alert and one return, no GNSS_LOST nor GNSS_BACK."""
    line = Line()
    samples = list(line_stream(40.0, line=line))
    cut_s = (30.0, 31.5)
    engine = Engine()
    out = drive(engine, [s for s in samples if not cut_s[0] < s.t_s < cut_s[1]])
    codes = [a.code for a in out if isinstance(a, Alert) and a.t_s > cut_s[0]]
    assert [c for c in codes if c in GNSS_AND_DATA] == [AlertCode.NO_DATA, AlertCode.DATA_BACK]
    assert engine.stats.silences == 1 and engine.stats.gnss["loss_in_silence"] == 1
    assert [o for o in out if isinstance(o, NavSolution) and o.t_s > cut_s[1]]


def gnss_stops(last_fix_s: float, drop: Callable[[Sample], bool]) -> list[Alert]:
    """Drive a straight flight (IMU 50 Hz, fixes 5 Hz, from 10 s to 10 s after
    ``last_fix_s``) whose receiver stops after ``last_fix_s`` while the other streams
    run on, but for the samples ``drop`` takes out; the alerts after the last fix."""
    samples = [
        s
        for s in line_stream(last_fix_s, line=Line(), gnss_hz=5.0)
        if not (isinstance(s, GnssFix) and s.t_s > last_fix_s) and not drop(s)
    ]
    return [
        a
        for a in drive(Engine(), samples)
        if isinstance(a, Alert) and a.t_s > last_fix_s and a.code in GNSS_AND_DATA
    ]


def test_a_gnss_loss_with_the_other_streams_running_is_gnss_lost() -> None:
    """The receiver (5 Hz) stops, the IMU and attitude run on, and a pause of theirs
    straddles the loss's due time, 1 s later: the loss is the receiver's, GNSS_LOST, no
    NO_DATA, both when the pause is longer than any before it but not than the
    receiver's interval between fixes (0.1 s of a 0.16 s pause, fixes 0.2 s apart), and
    when it is longer than that interval but not than the link's own pauses (0.26 s of
    IMU samples sent 0.34 s apart)."""
    paused = gnss_stops(60.0, lambda s: 60.9 < s.t_s < 61.06)
    assert [(a.code, a.t_s) for a in paused] == [
        (AlertCode.GNSS_LOST, pytest.approx(61.0, abs=1e-3))
    ]
    sparse = gnss_stops(
        60.6, lambda s: not isinstance(s, GnssFix) and round((s.t_s - 10.0) * 50.0) % 17 != 0
    )
    assert [(a.code, a.t_s) for a in sparse] == [
        (AlertCode.GNSS_LOST, pytest.approx(61.6, abs=1e-3))
    ]


def test_before_the_links_pauses_are_known_a_stall_is_not_called() -> None:
    """Every stream stops 1.5 s after the first sample (fewer pauses seen than the window
    of the link's usual ones): the loss is said as GNSS_LOST at its timeout, the silence
    as NO_DATA at the silence timeout (a radio's first delivery burst is not a dropout)."""
    samples = [s for s in line_stream(20.0, line=Line()) if s.t_s <= 11.5]
    engine = Engine()
    out = drive(engine, samples)
    while (due := engine.next_due_s()) < 20.0:
        out += engine.on_clock(due)
    said = [(a.code, a.t_s) for a in out if isinstance(a, Alert) and a.code in GNSS_AND_DATA]
    assert said == [
        (AlertCode.GNSS_LOST, pytest.approx(12.5, abs=1e-3)),
        (AlertCode.NO_DATA, pytest.approx(11.5 + SILENCE_TIMEOUT_S, abs=1e-3)),
    ]

"""The raw link's interference reports (companion.raw.interference): the receiver's own
indicators mapped onto MAVLink's states, the signal tests' verdicts as reports on the
autopilot clock; a simulated jamming through the link raises JAM once and ends it."""

from __future__ import annotations

import io
import math

import numpy as np
from pyubx2 import UBXMessage, UBXReader

from companion.integrity.signal import SignalMonitor
from companion.nav.frames import ecef_to_geodetic
from companion.raw.interference import InterferenceReports, receiver_states
from companion.raw.link import RawConfig, RawLink
from companion.raw.obs import PvtFix, ReceiverStatus
from companion.raw.simulate import Cn0Model, Jamming, RawSimConfig, simulate_flight
from companion.replay import timed_raw_items
from companion.types import AlertCode, FixType, GnssFix, GnssSignalReport, InterferenceState
from companion.ubx.reader import UbxSource, enable_raw_output

from .helpers import walk
from .test_signal import _path

S = InterferenceState
OFFSET_S = -408_600.0
"""The autopilot clock of these tests: GPS time of week plus this."""


def test_the_receivers_own_indicators_map_onto_mavlinks_states() -> None:
    nav = receiver_states(ReceiverStatus("NAV-STATUS", 1.0, spoof_det_state=3))
    assert nav[:2] == (S.UNKNOWN, S.DETECTED)
    assert nav[3] == ("receiver multiple spoofing indications (NAV-STATUS)",) and nav[2] == ()
    assert receiver_states(ReceiverStatus("NAV-STATUS", 1.0, spoof_det_state=2))[1] is S.MITIGATED
    assert receiver_states(ReceiverStatus("NAV-STATUS", 1.0, spoof_det_state=1))[1] is S.CLEAN
    assert receiver_states(ReceiverStatus("NAV-STATUS", 1.0, spoof_det_state=0))[1] is S.UNKNOWN
    rf = receiver_states(ReceiverStatus("MON-RF", None, jamming_state=3, jam_indicator=200))
    assert rf[0] is S.DETECTED and rf[2] == ("receiver jamming critical (no fix) (MON-RF)",)
    assert receiver_states(ReceiverStatus("MON-HW", None, jamming_state=2))[0] is S.MITIGATED
    assert receiver_states(ReceiverStatus("MON-HW", None, jamming_state=7))[0] is S.UNKNOWN


def test_ubx_status_messages_are_read_and_asked_for() -> None:
    frames = (
        UBXMessage("NAV", "NAV-STATUS", 0, iTOW=408640000, gpsFix=3, spoofDetState=3).serialize()
        + UBXMessage(
            "MON", "MON-RF", 0, version=0, nBlocks=2,
            jammingState_01=1, jamInd_01=40, jammingState_02=2, jamInd_02=90,
        ).serialize()
        + UBXMessage("MON", "MON-HW", 0, jammingState=1, jamInd=12).serialize()
    )  # fmt: skip
    src = UbxSource(io.BytesIO(frames))
    assert list(src) == [
        ReceiverStatus("NAV-STATUS", itow_s=408640.0, spoof_det_state=3),
        ReceiverStatus("MON-RF", jamming_state=2, jam_indicator=90),  # the worst RF block
        ReceiverStatus("MON-HW", jamming_state=1, jam_indicator=12),
    ]
    assert not src.rejected
    text = str(UBXReader.parse(enable_raw_output("UART2"), msgmode=1))
    assert "NAV_STATUS_UART2" in text and "MON_RF_UART2" in text


def test_a_status_without_time_replays_at_the_newest_epochs() -> None:
    s = walk()
    epoch = s.epochs[0]
    items = [
        ReceiverStatus("MON-RF", jamming_state=1),  # before any epoch: no week, dropped
        epoch,
        ReceiverStatus("MON-RF", jamming_state=1),
        ReceiverStatus("NAV-STATUS", itow_s=epoch.tow_s + 0.25, spoof_det_state=1),
    ]
    timed = timed_raw_items(items)
    assert [type(i).__name__ for _, i in timed] == ["RawEpoch", "ReceiverStatus", "ReceiverStatus"]
    assert timed[1][0] == timed[0][0] and math.isclose(timed[2][0] - timed[0][0], 0.25)


def test_reports_go_out_on_change_and_once_a_second_otherwise() -> None:
    rep = InterferenceReports(receiver_id=1)
    clean = ReceiverStatus("MON-RF", jamming_state=1, jam_indicator=30)
    assert rep.on_status(clean, 10.0) == []  # no epoch yet: no receiver time
    rep._tow_s = 100.0
    first = rep.on_status(clean, 10.0)
    assert len(first) == 1 and first[0].source == "receiver" and first[0].receiver_id == 1
    assert first[0].jamming is S.CLEAN and math.isclose(first[0].jam_indicator or 0, 30 / 255)
    assert rep.on_status(clean, 10.1) == []  # unchanged, within the interval
    bad = ReceiverStatus("MON-RF", jamming_state=3, jam_indicator=200)
    assert [r.jamming for r in rep.on_status(bad, 10.2)] == [S.DETECTED]  # at once
    rep._tow_s = 101.5
    assert len(rep.on_status(bad, 11.5)) == 1  # unchanged, but a second later
    assert rep.on_status(ReceiverStatus("MON-RF", jamming_state=1), None) == []
    assert rep.rejected["signal report: time not mapped"] == 1


def _pvt(tow_s: float, x: np.ndarray) -> PvtFix:
    lat, lon, h = ecef_to_geodetic(*x)
    return PvtFix(
        itow_s=tow_s, lat_deg=math.degrees(lat), lon_deg=math.degrees(lon), height_m=h,
        height_msl_m=h, fix_type=3, carrier_solution=0, num_sv=10, h_acc_m=1.0, v_acc_m=1.5,
    )  # fmt: skip


def _fix(pvt: PvtFix) -> GnssFix:
    return GnssFix(
        pvt.itow_s + OFFSET_S, 0.0, 0, FixType.FIX_3D, math.radians(pvt.lat_deg),
        math.radians(pvt.lon_deg), pvt.height_msl_m, None, None, 0.0, None, 1.0, 1.5,
        None, None, None, 10,
    )  # fmt: skip


def test_a_simulated_jamming_through_the_link_raises_jam_once_then_its_end() -> None:
    """Epochs, NAV-PVTs and the autopilot's fixes of a flight jammed from 40 to 70 s: the
    link's reports, on the autopilot clock, make the monitor raise JAM once, cite the
    C/N0 and the lost lock, and end it once the signals are back."""
    s = walk()
    tow0 = s.epochs[0].tow_s
    cfg = RawSimConfig(rate_hz=4.0, cn0=Cn0Model(), jam=Jamming(start_s=40.0, end_s=70.0))
    epochs, truth = simulate_flight(
        s.ephemerides, tow0, 100.0, _path, np.random.default_rng(11), cfg
    )
    link = RawLink(RawConfig(file="sim"))
    link.ephemerides = dict(s.ephemerides)
    monitor = SignalMonitor()
    reports: list[GnssSignalReport] = []
    alerts = []
    for k, (epoch, x) in enumerate(zip(epochs, truth, strict=True)):
        pvt = _pvt(tow0 + k / 4.0, x)
        out = link.on_item(epoch, 0.0) + link.on_item(pvt, 0.0) + link.on_fix(_fix(pvt))
        for o in out:
            if isinstance(o, GnssSignalReport):
                reports.append(o)
                alerts += monitor.on_report(o)
    assert link.clock.offset_s is not None and math.isclose(link.clock.offset_s, OFFSET_S)
    assert reports and all(r.source == "raw" for r in reports)
    t0 = tow0 + OFFSET_S
    assert all(r.jamming is S.CLEAN for r in reports if r.t_s < t0 + 40.0)
    assert [a.code for a in alerts] == [AlertCode.JAM, AlertCode.JAM_END]
    jam, end = alerts
    assert t0 + 40.0 < jam.t_s < t0 + 52.0 and "below its baseline" in jam.text
    assert any("lock lost" in e for r in reports for e in r.evidence)
    assert t0 + 70.0 < end.t_s < t0 + 85.0
    # at most one report a second while nothing changes (4 Hz epochs)
    assert len(reports) < 0.5 * len(epochs)


def test_the_bundled_walk_through_the_link_reports_clean_and_raises_nothing() -> None:
    from .test_link import _fix as walk_fix
    from .test_link import _items

    link = RawLink(RawConfig(file="cut"))
    monitor = SignalMonitor()
    reports = []
    for item in _items():
        out = link.on_item(item, 0.0)
        if isinstance(item, PvtFix):
            out += link.on_fix(walk_fix(item))
        for o in out:
            if isinstance(o, GnssSignalReport):
                reports.append(o)
                assert monitor.on_report(o) == []
    assert len(reports) > 20  # from the time mapping on, about one a second
    assert all(r.jamming is S.CLEAN and r.spoofing is S.CLEAN for r in reports)
    assert monitor.spoof_evidence(0, reports[-1].t_s) == ()

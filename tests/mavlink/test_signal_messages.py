"""GNSS_INTEGRITY in and out: the autopilot's relay of the receiver's flags decoded into a
report (receiver, states, rejections), the engine raising JAM from it and publishing its
verdicts in our own GNSS_INTEGRITY, a PX4 log's flags carried as GNSS_INTEGRITY, and the
console showing the alert."""

from __future__ import annotations

import collections
import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pymavlink.dialects.v20 import all as mav_all

from companion.config import Config
from companion.console.model import ConsoleModel
from companion.engine import Engine
from companion.mavlink.decode import Decoder
from companion.mavlink.encode import Encoder, EncoderConfig
from companion.mavlink.logs import open_flight_log
from companion.mavlink.logs.ulog import _events
from companion.pipeline import Pipeline
from companion.types import (
    Alert,
    AlertCode,
    AutopilotFlavour,
    GnssSignalReport,
    IntegrityReport,
    InterferenceState,
    Severity,
)
from tests.helpers import line_stream
from tests.mavlink._util import attitude, heartbeat

S = InterferenceState
ROOT = Path(__file__).resolve().parents[2]
SMALL_ULG = ROOT / "tests" / "data" / "logs" / "sample_log_small.ulg"


class _Autopilot:
    """Packs messages as system 1 component 1 with the ``all`` dialect (which has 441)."""

    def __init__(self) -> None:
        self.mav = mav_all.MAVLink(None, 1, 1)
        self.rx = mav_all.MAVLink(None)

    def __call__(self, msg: Any) -> Any:
        data = bytearray(msg.pack(self.mav))
        self.mav.seq = (self.mav.seq + 1) % 256
        return self.rx.decode(data)


def _integrity(rx_id: int, jamming: int, spoofing: int) -> Any:
    return mav_all.MAVLink_gnss_integrity_message(
        rx_id, 0, 0, jamming, spoofing, 0, 65535, 65535, 255, 255, 255, 255
    )


def _decoder(autopilot: int) -> tuple[Decoder, _Autopilot]:
    ap = _Autopilot()
    d = Decoder()
    d.decode(ap(heartbeat(autopilot)), 0.0)
    d.decode(ap(attitude(10_000)), 0.0)
    return d, ap


def test_gnss_integrity_becomes_a_report_of_the_receiver_it_names() -> None:
    d, ap = _decoder(3)
    (rep,) = d.decode(ap(_integrity(1, 3, 2)), 1.0)
    assert rep == GnssSignalReport(
        10.0, 1, "autopilot", S.DETECTED, S.MITIGATED, None,
        ("receiver jamming detected (GNSS_INTEGRITY)",
         "receiver spoofing mitigated (GNSS_INTEGRITY)"),
        ("receiver spoofing mitigated (GNSS_INTEGRITY)",),
    )  # fmt: skip
    (clean,) = d.decode(ap(_integrity(0, 1, 1)), 1.0)
    assert (clean.receiver_id, clean.jamming, clean.spoofing) == (0, S.CLEAN, S.CLEAN)
    assert clean.evidence == ()
    assert d.decode(ap(_integrity(7, 1, 1)), 1.0) == []
    assert d.decode(ap(_integrity(0, 4, 1)), 1.0) == []
    assert d.rejections["unknown_receiver"] == 1 and d.rejections["bad_enum"] == 1
    assert d.accepted["GNSS_INTEGRITY"] == 2


def test_px4s_gnss_integrity_carries_a_device_id_and_is_its_first_receiver() -> None:
    d, ap = _decoder(12)
    (rep,) = d.decode(ap(_integrity(0xA7, 1, 3)), 1.0)
    assert rep.receiver_id == 0 and rep.spoofing is S.DETECTED


def test_the_service_reads_gnss_integrity_only_with_a_dialect_that_knows_it() -> None:
    """ArduPilot's dialect (the default) has no message 441: such a frame is an unknown
    message; with ``all`` it is decoded and raises JAM."""
    ap = _Autopilot()
    frames = b"".join(
        bytes(m.pack(ap.mav))
        for m in (heartbeat(12), attitude(10_000), _integrity(3, 3, 1), attitude(10_100))
    )
    from companion.mavlink.framing import FrameParser

    for dialect, jam in (("ardupilotmega", False), ("all", True)):
        cfg = Config()
        cfg = dataclasses.replace(cfg, encoder=dataclasses.replace(cfg.encoder, dialect=dialect))
        pipeline = Pipeline(cfg)
        parser = FrameParser(dialect)
        for msg in parser.feed(frames):
            pipeline.on_message(msg, 0.0)
        pipeline.unknown_frames(parser.unknown_frames)
        assert (pipeline.engine.stats.alerts["JAM"] == 1) is jam
        assert (pipeline.decoder.rejections["unknown_message"] == 1) is not jam


def test_the_engine_raises_jam_without_moving_its_clock_and_stamps_its_reports() -> None:
    engine = Engine()
    reports = []
    jammed = GnssSignalReport(
        25.0, 0, "raw", S.DETECTED, S.CLEAN, None, ("C/N0 9 dB-Hz below its baseline",)
    )
    for sample in line_stream(40.0):
        if sample.t_s >= 25.0 and jammed is not None:
            before = engine.now_s
            (alert,) = engine.handle(dataclasses.replace(jammed, t_s=1e6))  # a far clock
            assert engine.now_s == before  # a report moves no clock
            assert alert.code is AlertCode.JAM and alert.severity is Severity.WARNING
            jammed = None
        reports += [o for o in engine.handle(sample) if isinstance(o, IntegrityReport)]
    assert engine.stats.alerts["JAM"] == 1
    # spoofing: the service's own monitor tests the receiver against the IMU once in the
    # air; nothing says spoofed, and after 40 s its prior of the attitude's wander is not
    # yet measured down: it cannot vouch for a fast drag within 10 s, so it does not say
    # clean (tests/integrity/test_spoof.py: clean once it can)
    assert reports and all(r.spoofing in (S.UNKNOWN, S.CLEAN) for r in reports)
    spoof = engine.integrity.spoof
    assert spoof.stats["tested"] > 0
    assert reports[-1].spoofing is (S.CLEAN if spoof.verified_mps2() <= 0.5 else S.UNKNOWN)
    # before the report nothing was monitored; after it, jamming stands (the report's own
    # time was far ahead: it is current for the monitor only at that time, the episode is)
    assert [r.jamming for r in reports if r.t_s < 25.0] == [S.UNKNOWN] * len(
        [r for r in reports if r.t_s < 25.0]
    )
    assert all(r.jamming is S.DETECTED for r in reports if r.t_s > 25.0)


def test_our_gnss_integrity_carries_the_services_verdicts() -> None:
    enc = Encoder(EncoderConfig(dialect="development"))
    assert enc.has_gnss_integrity
    rep = IntegrityReport(1.0, 2.5, 3.5, True, False, spoofing=S.MITIGATED, jamming=S.DETECTED)
    (msg,) = enc.encode(rep, AutopilotFlavour.PX4)
    assert (msg.jamming_state, msg.spoofing_state) == (3, 2)
    assert (msg.raim_hfom, msg.raim_vfom, msg.raim_state) == (250, 350, 2)
    (none,) = enc.encode(IntegrityReport(1.0, 2.5, 3.5, True, False), AutopilotFlavour.PX4)
    assert (none.jamming_state, none.spoofing_state) == (0, 0)
    clean = IntegrityReport(1.0, 2.5, 3.5, True, False, spoofing=S.CLEAN, jamming=S.CLEAN)
    (msg,) = enc.encode(clean, AutopilotFlavour.PX4)
    assert (msg.jamming_state, msg.spoofing_state) == (1, 1)
    assert Encoder().encode(rep, AutopilotFlavour.ARDUPILOT) == []  # ardupilotmega: none


def test_the_console_shows_jam_and_spoof_like_every_alert() -> None:
    enc = Encoder()
    enc.system_id = 1
    rx = mav_all.MAVLink(None)
    model = ConsoleModel()
    for alert in (
        Alert(12.0, AlertCode.JAM, Severity.WARNING, "rx0 raw: C/N0 9.0 dB-Hz below its baseline"),
        Alert(30.0, AlertCode.SPOOF, Severity.CRITICAL, "rx0: receiver spoofing detected"),
        Alert(40.0, AlertCode.JAM_END, Severity.NOTICE, "clean for 10 s after 28 s"),
    ):
        for msg in enc.encode(alert, AutopilotFlavour.ARDUPILOT):
            assert model.take(rx.decode(bytearray(enc.pack(msg))), alert.t_s)
    codes = [(a.text.split()[1], a.severity_name) for a in model.alerts]
    assert codes == [("JAM", "WARN"), ("SPOOF", "CRIT"), ("JAM_END", "NOTICE")]
    assert "CMP JAM rx0 raw: C/N0 9.0" in model.render(41.0)


# --------------------------------------------------------------------------- PX4 logs


def test_a_real_px4_logs_gps_has_an_indicator_but_no_states_so_no_gnss_integrity() -> None:
    """PX4 1.11's vehicle_gps_position has jamming_indicator and noise_per_ms (no MAVLink
    field carries them) and no jamming_state / spoofing_state."""
    from pyulog import ULog

    gps = [d for d in ULog(str(SMALL_ULG)).data_list if d.name == "vehicle_gps_position"][0]
    assert {"jamming_indicator", "noise_per_ms"} <= set(gps.data)
    assert "jamming_state" not in gps.data and "spoofing_state" not in gps.data
    ind = gps.data["jamming_indicator"]
    assert 45 <= ind.min() and ind.max() <= 60  # clean: well under the 84 of the limit
    names = {msg.get_type() for _, msg in open_flight_log(SMALL_ULG)}
    assert "GPS_RAW_INT" in names and "GNSS_INTEGRITY" not in names


def _gps_topic(jam: list[int], spoof: list[int]) -> dict[str, np.ndarray]:
    n = len(jam)
    t = 1_000_000 + np.arange(n) * 200_000  # 5 Hz
    cols = {
        "timestamp": t,
        "latitude_deg": np.full(n, 47.39),
        "longitude_deg": np.full(n, 8.54),
        "altitude_msl_m": np.full(n, 500.0),
        "altitude_ellipsoid_m": np.full(n, 548.0),
        "fix_type": np.full(n, 3),
        "eph": np.full(n, 1.0),
        "epv": np.full(n, 1.5),
        "s_variance_m_s": np.full(n, 0.2),
        "vel_m_s": np.full(n, 0.0),
        "cog_rad": np.full(n, 0.0),
        "satellites_used": np.full(n, 12),
        "device_id": np.full(n, 0x00AB12A7),
        "jamming_state": np.array(jam),
        "spoofing_state": np.array(spoof),
    }
    return cols


def test_a_px4_logs_gps_flags_become_gnss_integrity_on_change_and_at_1_hz() -> None:
    jam = [1] * 10 + [3] * 3 + [1] * 7
    spoof = [1] * 15 + [2] * 5
    events, _ = _events({"sensor_gps": _gps_topic(jam, spoof)}, collections.Counter())
    got = [(e.t_us, e.args) for e in events if e.name == "gnss_integrity"]
    times = [t for t, _ in got]
    # the first sample, a second later, jamming at 3.0 s and back at 3.6 s, spoofing at 4 s
    assert times == [1_000_000, 2_000_000, 3_000_000, 3_600_000, 4_000_000]
    assert [a[3:5] for _, a in got] == [[1, 1], [1, 1], [3, 1], [1, 1], [1, 2]]
    assert all(a[0] == 0xA7 for _, a in got)  # the device id's low byte, as PX4 sends it
    # the whole chain: packed, decoded, a report of receiver 0 with PX4's meaning
    d, ap = _decoder(12)
    args = got[2][1]
    (rep,) = d.decode(ap(mav_all.MAVLink_gnss_integrity_message(*args)), 1.0)
    assert (rep.receiver_id, rep.jamming, rep.spoofing) == (0, S.DETECTED, S.CLEAN)


@pytest.mark.parametrize("name", ["sensor_gps", "vehicle_gps_position"])
def test_only_a_topic_with_the_flags_gives_gnss_integrity(name: str) -> None:
    cols = _gps_topic([1] * 5, [1] * 5)
    del cols["jamming_state"]
    events, _ = _events({name: cols}, collections.Counter())
    assert [e for e in events if e.name == "gnss_integrity"] == []
    assert any(e.name == "gps_raw_int" for e in events)


def test_a_telemetry_log_is_replayed_with_the_services_dialect(tmp_path: Path) -> None:
    """A PX4 telemetry log holding GNSS_INTEGRITY: replayed with the default dialect the
    frame is an unknown one (as on a link), with ``all`` it raises JAM."""
    from companion.mavlink.tlog import TlogWriter
    from companion.replay import replay

    ap = _Autopilot()
    path = tmp_path / "px4.tlog"
    with TlogWriter(path) as w:
        for k, msg in enumerate(
            (heartbeat(12), attitude(10_000), _integrity(0, 3, 1), attitude(10_100))
        ):
            w.write(1_700_000_000.0 + 0.1 * k, bytes(msg.pack(ap.mav)))
    for dialect, jam in (("ardupilotmega", False), ("all", True)):
        cfg = Config()
        cfg = dataclasses.replace(cfg, encoder=dataclasses.replace(cfg.encoder, dialect=dialect))
        summary = replay(path, tmp_path / f"out_{dialect}.tlog", cfg)
        assert (summary.alerts.get("JAM", 0) == 1) is jam
        assert ("tlog_unknown_frame" in summary.rejections) is not jam

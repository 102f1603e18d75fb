"""Autopilot logs (.bin, .ulg) read as the MAVLink streams of a telemetry log.

The bundled originals (tests/data/logs, README there) give the streams the
converted telemetry logs of the same flights hold, message for message; where the
real-data folder is present, a replay of each original is byte-identical to the
replay of its converted .tlog.
"""

from __future__ import annotations

import logging
from collections import Counter
from pathlib import Path

import pytest

from companion.mavlink.logs import log_format, open_flight_log
from companion.mavlink.logs.dataflash import read_dataflash
from companion.mavlink.logs.ulog import SYNTHETIC_EPOCH_US, read_ulog
from companion.mavlink.tlog import TlogError
from companion.replay import replay

ROOT = Path(__file__).resolve().parents[2]
LOGS = ROOT / "tests" / "data" / "logs"
LOG171 = LOGS / "log171.bin"
PX4_SMALL = LOGS / "sample_log_small.ulg"
PX4_NOGPS = LOGS / "sample.ulg"
FLIGHTS = ROOT.parent / "shared" / "realdata" / "flights"


def counts(reader) -> Counter[str]:
    return Counter(msg.get_type() for _t, msg in reader)


def test_formats_are_told_by_content_not_name(tmp_path):
    renamed = tmp_path / "flight.tlog"
    renamed.write_bytes(PX4_SMALL.read_bytes()[:4096])
    assert log_format(LOG171) == "dataflash"
    assert log_format(renamed) == "ulog"
    assert log_format(ROOT / "sitl_fixtures" / "approach_rtk20.tlog") == "tlog"


def test_dataflash_streams_are_those_of_the_converted_tlog():
    reader = read_dataflash(LOG171)
    # the converted tlog of this flight (its meta.json written_counts)
    assert counts(reader) == {
        "HIGHRES_IMU": 11916,
        "SCALED_IMU": 11916,
        "ATTITUDE": 2383,
        "GPS_RAW_INT": 1199,
        "HEARTBEAT": 243,
        "SYSTEM_TIME": 243,
        "GLOBAL_POSITION_INT": 2051,
    }
    assert not any(reader.stats.values())


def test_dataflash_time_conventions_and_values():
    first = {}
    for t_rx_s, msg in read_dataflash(LOG171):
        first.setdefault(msg.get_type(), (t_rx_s, msg))
    # receive time = the log's UTC (DFReader's GNSS-week time base) of the boot time
    t_imu, imu = first["HIGHRES_IMU"]
    assert imu.time_usec == 11_460_000 and t_imu == pytest.approx(1448149430.724, abs=1e-6)
    assert imu.xacc == pytest.approx(-0.07167863845825195, rel=1e-6)
    t_gps, gps = first["GPS_RAW_INT"]
    # the older format's GPS TimeMS is GPS time of week; its boot time is T
    assert gps.time_usec == 11_737_000 and gps.fix_type == 1  # a no-fix sample kept
    assert gps.eph == 9999 and gps.epv == 65535
    _, sys_time = first["SYSTEM_TIME"]
    assert sys_time.time_unix_usec == 1448149431264000 and sys_time.time_boot_ms == 12000
    _, hb = first["HEARTBEAT"]
    assert (hb.type, hb.autopilot, hb.custom_mode, hb.base_mode) == (2, 3, 5, 1)
    _, att = first["ATTITUDE"]
    # ATT is logged before the IMU sample of its time: the rates of that sample
    assert att.rollspeed == pytest.approx(0.00014373366138897836, rel=1e-6)


def test_ulog_streams_and_utc_offset():
    reader = read_ulog(PX4_SMALL)
    assert counts(reader) == {
        "HIGHRES_IMU": 1298,
        "SCALED_IMU": 326,
        "ATTITUDE": 1298,
        "GPS_RAW_INT": 32,
        "HEARTBEAT": 6,
        "SYSTEM_TIME": 6,
    }
    assert reader.utc_offset_us == 1618986638141670  # median of the GNSS samples' UTC
    gps = next(m for _t, m in read_ulog(PX4_SMALL) if m.get_type() == "GPS_RAW_INT")
    assert (gps.time_usec, gps.fix_type, gps.lat, gps.h_acc, gps.vel_acc) == (
        20471648, 3, 634170622, 3260, 651,
    )  # fmt: skip
    nogps = read_ulog(PX4_NOGPS)
    assert nogps.utc_offset_us == SYNTHETIC_EPOCH_US
    assert "GPS_RAW_INT" not in counts(nogps)


def test_replay_of_the_originals_publishes(tmp_path):
    summary = replay(PX4_SMALL, tmp_path / "px4.tlog")
    assert summary.out_by_type.get("GLOBAL_POSITION_INT", 0) > 0
    # PX4's aux position id is asked for; the log holds no answer: nothing goes to PX4
    # until the service gives up asking (companion.mavlink.px4_agp), then it does
    assert summary.out_by_type.get("PARAM_REQUEST_READ", 0) >= 2  # with each stream request
    sent = summary.out_by_type.get("GLOBAL_POSITION_SENSOR", 0)
    assert 0 < sent < summary.out_by_type["GLOBAL_POSITION_INT"]
    assert summary.rejections.get("no_system_yet", 0) > 0  # before the first HEARTBEAT


@pytest.mark.parametrize("cut", [0.3, 0.7])
def test_a_truncated_or_corrupt_dataflash_log_replays_what_is_left(tmp_path, cut):
    data = bytearray(LOG171.read_bytes())
    data = data[: int(len(data) * cut)]
    for at in range(100_000, len(data) - 1000, 150_000):
        data[at : at + 200] = bytes(range(200))  # garbage in the middle
    path = tmp_path / "corrupt.bin"
    path.write_bytes(bytes(data))
    summary = replay(path, tmp_path / "out.tlog")
    assert summary.rejections.get("dataflash_bad_region", 0) >= 1
    assert summary.out_by_type.get("GPS_INPUT", 0) > 0


def test_a_truncated_ulog_replays_what_is_left(tmp_path):
    data = PX4_SMALL.read_bytes()
    path = tmp_path / "cut.ulg"
    path.write_bytes(data[: len(data) // 2])
    summary = replay(path, tmp_path / "out.tlog")
    assert summary.messages_in > 0


def test_a_ulog_header_alone_is_one_error(tmp_path):
    path = tmp_path / "empty.ulg"
    path.write_bytes(PX4_SMALL.read_bytes()[:16])
    with pytest.raises(TlogError, match="a PX4 ULog"):
        replay(path, tmp_path / "out.tlog")


FLIGHT_ORIGINALS = sorted(
    p for p in FLIGHTS.glob("*/*") if p.suffix.lower() in (".bin", ".ulg")
) if FLIGHTS.is_dir() else []  # fmt: skip


@pytest.mark.skipif(not FLIGHTS.is_dir(), reason="no ../shared/realdata/flights beside the clone")
@pytest.mark.parametrize("original", FLIGHT_ORIGINALS, ids=lambda p: p.parent.name)
def test_replay_of_an_original_equals_the_replay_of_its_converted_tlog(tmp_path, original):
    logging.disable(logging.WARNING)
    try:
        tlog = original.parent / f"{original.parent.name}.tlog"
        a = replay(original, tmp_path / "a.tlog")
        b = replay(tlog, tmp_path / "b.tlog")
    finally:
        logging.disable(logging.NOTSET)
    assert (tmp_path / "a.tlog").read_bytes() == (tmp_path / "b.tlog").read_bytes()
    assert a.messages_in == b.messages_in
    assert {k: v for k, v in a.rejections.items() if not k.startswith("dataflash_")} == (
        b.rejections
    )


def test_open_flight_log_of_a_missing_file_is_an_error(tmp_path):
    with pytest.raises(TlogError, match="cannot open"):
        open_flight_log(tmp_path / "absent.bin")

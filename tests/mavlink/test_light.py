"""Light messages carry exactly what pymavlink's objects carry for their consumers.

Every message of every fixture is decoded both ways (light and pymavlink's
``MAVLink.decode``) and compared field by field; the :class:`Decoder` must give the
same samples and counters from both; odd frames, every message class of the dialect
and corrupted streams (tlog reader, frame parser) behave as the pymavlink path.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as apm

from companion.mavlink.decode import LIGHT_MESSAGE_IDS, Decoder
from companion.mavlink.framing import FrameParser
from companion.mavlink.messages import FastDecoder, LightMessage
from companion.mavlink.tlog import TlogError, TlogReader
from tests.mavlink._util import Packer, attitude, heartbeat, raw_imu

FIXTURES = Path(__file__).resolve().parents[2] / "sitl_fixtures"
TLOGS = sorted(FIXTURES.glob("*.tlog"))
ALL_IDS = frozenset(apm.mavlink_map)


def _same(a: Any, b: Any) -> bool:
    """Equal values of the same type (NaN equal to NaN)."""
    if type(a) is not type(b):
        return False
    if isinstance(a, float) and math.isnan(a):
        return math.isnan(b)
    return bool(a == b)


def _assert_same_message(light: Any, want: Any, where: str = "") -> None:
    """What a consumer can read of a received message is the same on both."""
    name = want.get_type()
    for field in want.get_fieldnames():
        assert _same(getattr(light, field), getattr(want, field)), f"{where} {name}.{field}"
    assert light._type == want._type == light.get_type() == name
    assert light.get_fieldnames() == want.get_fieldnames()
    hdr, whdr = light._header, want._header
    assert (hdr.msgId, hdr.srcSystem, hdr.srcComponent, hdr.seq) == (
        whdr.msgId,
        whdr.srcSystem,
        whdr.srcComponent,
        whdr.seq,
    ), f"{where} {name} header"
    assert light.get_msgId() == want.get_msgId()
    assert light.get_srcSystem() == want.get_srcSystem()
    assert light.get_srcComponent() == want.get_srcComponent()
    assert light.get_seq() == want.get_seq()
    assert type(light.get_msgbuf()) is bytearray
    assert bytes(light.get_msgbuf()) == bytes(want.get_msgbuf())
    assert str(light.to_dict()) == str(want.to_dict())  # str: NaN-safe, types visible


def _records(path: Path) -> list[tuple[float, bytearray]]:
    """(time, frame) of every record of a clean fixture tlog."""
    data = path.read_bytes()
    out = []
    pos = 0
    while pos < len(data):
        p = pos + 8
        n = 10 + data[p + 1] + 2 + (13 if data[p + 2] & 1 else 0)
        out.append((int.from_bytes(data[pos:p], "big") / 1e6, bytearray(data[p : p + n])))
        pos = p + n
    return out


def _samples_equal(a: Any, b: Any) -> bool:
    if type(a) is not type(b):
        return False
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            if not (
                isinstance(x, np.ndarray)
                and isinstance(y, np.ndarray)
                and x.dtype == y.dtype
                and np.array_equal(x, y, equal_nan=True)
            ):
                return False
        elif not _same(x, y):
            return False
    return True


@pytest.mark.parametrize("tlog", TLOGS, ids=lambda p: p.stem)
def test_every_fixture_message_light_equals_pymavlink_and_decodes_alike(tlog: Path) -> None:
    fast = FastDecoder(apm, LIGHT_MESSAGE_IDS)
    mav = apm.MAVLink(None)
    dec_light, dec_slow = Decoder(), Decoder()
    light_types = set()
    samples = 0
    records = _records(tlog)
    for t_s, frame in records:
        found = fast.light_decode_at(bytearray(frame), 0)
        want = mav.decode(bytearray(frame))
        assert found is not None and found[1] == len(frame)
        got = found[0]
        if isinstance(got, LightMessage):
            light_types.add(got.get_type())
            assert got.get_msgId() in LIGHT_MESSAGE_IDS
            _assert_same_message(got, want, tlog.stem)
        else:  # not a light id, or one with arrays: pymavlink's own object
            assert type(got) is type(want)
            assert got.get_msgId() not in LIGHT_MESSAGE_IDS or got.get_type() in {
                "ATTITUDE_QUATERNION"
            }
        a, b = dec_light.decode(got, t_s), dec_slow.decode(want, t_s)
        assert len(a) == len(b) and all(_samples_equal(x, y) for x, y in zip(a, b, strict=True))
        samples += len(a)
    assert dec_light.accepted == dec_slow.accepted
    assert dec_light.rejections == dec_slow.rejections
    assert samples > len(records) // 2  # the comparison covered the samples of the flight
    assert {"GPS_RAW_INT", "GLOBAL_POSITION_INT", "SYSTEM_TIME"} <= light_types
    assert light_types & {"RAW_IMU", "HIGHRES_IMU", "SCALED_IMU2"}


def _raw_frame(msg_id: int, payload: bytes, crc_extra: int, seq: int = 7) -> bytearray:
    """A MAVLink 2 frame around a raw payload (system 3, component 1)."""
    head = bytes((0xFD, len(payload), 0, 0, seq, 3, 1, msg_id & 0xFF, (msg_id >> 8) & 0xFF))
    head += bytes((msg_id >> 16,))
    crc = apm.x25crc(head[1:] + payload + bytes((crc_extra,))).crc
    return bytearray(head + payload + bytes((crc & 0xFF, crc >> 8)))


@pytest.mark.parametrize("fill", [0x00, 0x41, 0xFF])
def test_every_message_class_light_equals_pymavlink_or_is_pymavlinks(fill: int) -> None:
    # every message of the dialect made light where it can be, from a payload of one
    # repeated byte (0xFF: NaN floats, negative ints), full length, truncated by a
    # third (zero-extended) and with 3 bytes more than the dialect knows
    fast = FastDecoder(apm, ALL_IDS)
    plain = FastDecoder(apm)
    mav = apm.MAVLink(None)
    light = 0
    for msg_id, cls in sorted(apm.mavlink_map.items()):
        size = cls.unpacker.size
        for n in (size, (2 * size) // 3, min(size + 3, 255)):
            frame = _raw_frame(msg_id, bytes((fill,)) * n, cls.crc_extra, seq=n)
            got = fast.light_at(bytearray(frame), 0)
            try:
                want = mav.decode(bytearray(frame))
            except Exception:  # noqa: BLE001 - pymavlink refuses it: so must the light path
                assert got is None or not isinstance(got, LightMessage), cls.msgname
                continue
            if isinstance(got, LightMessage):
                light += 1
                _assert_same_message(got, want, f"fill {fill:#x} len {n}")
            else:  # arrays, strings or a clashing name: as the pymavlink fast path
                assert str(got) == str(plain.message_at(bytearray(frame), 0)), cls.msgname
    assert light > 3 * 150


def test_odd_frames_are_declined_as_by_the_pymavlink_path() -> None:
    pack = Packer()
    good = bytearray(pack(raw_imu(1000)))
    fast = FastDecoder(apm, LIGHT_MESSAGE_IDS)
    assert isinstance(fast.light_at(good, 0), LightMessage)
    bad_crc = bytearray(good)
    bad_crc[-1] ^= 0xFF
    signed = bytearray(good)
    signed[2] |= 0x01
    v1 = apm.MAVLink(None, 1, 1)
    v1.WIRE_PROTOCOL_VERSION = "1.0"
    frame_v1 = bytearray(raw_imu(1000).pack(v1, force_mavlink1=True))
    for odd in (bad_crc, signed + bytearray(13), frame_v1):
        assert fast.light_at(odd, 0) is None
        assert fast.light_decode_at(odd, 0) is None
    # every prefix of a good frame at an offset: None, never an IndexError
    for cut in range(len(good)):
        assert fast.light_at(bytearray(b"\x00" * 5) + good[:cut], 5) is None
    found = fast.light_decode_at(bytearray(b"\x00" * 5) + good + bytearray(3), 5)
    assert found is not None and found[1] == len(good)
    assert bytes(found[0].get_msgbuf()) == bytes(good)


def test_decode_keeps_returning_pymavlink_objects() -> None:
    frame = bytearray(Packer()(raw_imu(1000)))
    fast = FastDecoder(apm, ALL_IDS)
    assert type(fast.decode(frame)) is apm.MAVLink_raw_imu_message
    found = fast.decode_at(frame, 0)
    assert found is not None and type(found[0]) is apm.MAVLink_raw_imu_message
    assert type(fast.message_at(frame, 0)) is apm.MAVLink_raw_imu_message


def test_light_ids_are_the_decoders_handlers() -> None:
    assert set(Decoder()._handlers) == LIGHT_MESSAGE_IDS


def _frames() -> list[bytes]:
    pack = Packer()
    msgs = [heartbeat()] + [m for i in range(12) for m in (attitude(10 * i), raw_imu(10_000 * i))]
    return [pack(m) for m in msgs]


FRAMES = _frames()
STREAM = b"".join(FRAMES)
TLOG = b"".join(
    (1_700_000_000_000_000 + 20_000 * k).to_bytes(8, "big") + f for k, f in enumerate(FRAMES)
)


def _view(m: Any) -> str:
    return f"{m.get_type()} {m.get_srcSystem()} {m.get_seq()} {m.to_dict()}"


def _damage(data: st.DataObject, clean: bytes) -> bytes:
    blob = bytearray(clean)
    for _ in range(data.draw(st.integers(0, 8))):
        blob[data.draw(st.integers(0, len(blob) - 1))] = data.draw(st.integers(0, 255))
    return bytes(blob[: data.draw(st.integers(0, len(blob)))]) + data.draw(st.binary(max_size=30))


@settings(max_examples=80, deadline=None)
@given(st.data())
def test_corrupted_link_stream_gives_the_same_messages_light_or_not(data: st.DataObject) -> None:
    blob = _damage(data, STREAM)
    light_parser, parser = FrameParser(light_ids=LIGHT_MESSAGE_IDS), FrameParser()
    split = data.draw(st.integers(0, len(blob)))
    got = light_parser.feed(blob[:split]) + light_parser.feed(blob[split:]) + light_parser.flush()
    want = parser.feed(blob[:split]) + parser.feed(blob[split:]) + parser.flush()
    assert [_view(m) for m in got] == [_view(m) for m in want]
    assert (light_parser.bad_frames, light_parser.bad_bytes) == (
        parser.bad_frames,
        parser.bad_bytes,
    )


@settings(
    max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(st.data())
def test_corrupted_tlog_gives_the_same_records_light_or_not(
    tmp_path: Path, data: st.DataObject
) -> None:
    path = tmp_path / "f.tlog"
    path.write_bytes(_damage(data, TLOG))
    got, light_stats = _records_or_refusal(path, light_ids=LIGHT_MESSAGE_IDS)
    want, stats = _records_or_refusal(path)
    assert got == want
    assert light_stats == stats


def _records_or_refusal(path: Path, **kwargs: Any) -> tuple[object, object]:
    """The records and the reader's counts, or the refusal of a damaged file that now
    starts like another format (a PDF's or a gzip's magic number): both readers must
    agree either way."""
    try:
        reader = TlogReader(path, **kwargs)
        return [(t, _view(m)) for t, m in reader], reader.stats
    except TlogError as exc:
        return f"refused: {exc}", None


def test_a_damaged_tlog_that_starts_like_a_pdf_is_refused_by_both(tmp_path: Path) -> None:
    path = tmp_path / "f.tlog"
    path.write_bytes(b"%PDF" + TLOG[4:])
    refused, _ = _records_or_refusal(path)
    assert isinstance(refused, str) and "PDF" in refused
    assert _records_or_refusal(path, light_ids=LIGHT_MESSAGE_IDS) == (refused, None)

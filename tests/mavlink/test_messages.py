"""The fast decode path builds exactly what pymavlink's MAVLink.decode builds."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import ardupilotmega as apm

from companion.mavlink.dialect import load_dialect
from companion.mavlink.framing import FrameParser
from companion.mavlink.messages import FastDecoder
from tests.mavlink._util import Packer, attitude, heartbeat, raw_imu

FIXTURES = Path(__file__).resolve().parents[2] / "sitl_fixtures"


def _state(msg: Any) -> dict[str, Any]:
    """Everything a message object holds, its header's fields included."""
    d = dict(vars(msg))
    d["_header"] = dict(vars(d["_header"]))
    for k, v in d.items():  # NaN != NaN: compare NaN floats by their repr
        if isinstance(v, float) and math.isnan(v):
            d[k] = "nan"
    return d


def _frames(path: Path) -> list[bytearray]:
    """The frames of a clean fixture tlog (8-byte time stamp, then one MAVLink 2 frame)."""
    data = path.read_bytes()
    out = []
    pos = 0
    while pos < len(data):
        p = pos + 8
        if data[p] != 0xFD:
            raise ValueError(f"{path.name}: not a MAVLink 2 frame at {p}")
        n = 10 + data[p + 1] + 2 + (13 if data[p + 2] & 1 else 0)
        out.append(bytearray(data[p : p + n]))
        pos = p + n
    return out


def _both(frame: bytearray) -> tuple[Any, Any]:
    fast = FastDecoder(apm).decode(bytearray(frame))
    slow = apm.MAVLink(None).decode(bytearray(frame))
    return fast, slow


@pytest.fixture(scope="module")
def fast() -> FastDecoder:
    dec = FastDecoder(load_dialect("ardupilotmega"))
    assert dec.enabled
    return dec


@pytest.mark.parametrize("tlog", sorted(FIXTURES.glob("*.tlog")), ids=lambda p: p.stem)
def test_every_fixture_message_decodes_identically(fast: FastDecoder, tlog: Path) -> None:
    mav = apm.MAVLink(None)
    frames = _frames(tlog)
    types = set()
    for frame in frames:
        got = fast.decode(bytearray(frame))
        want = mav.decode(bytearray(frame))
        assert got is not None, f"{tlog.name}: fast path declined a plain frame"
        assert type(got) is type(want)
        assert _state(got) == _state(want)
        assert got.to_dict() == want.to_dict()
        assert bytes(got.get_msgbuf()) == bytes(frame)
        types.add(want.get_type())
    assert {"HEARTBEAT", "SYSTEM_TIME", "GLOBAL_POSITION_INT"} <= types
    assert types & {"RAW_IMU", "HIGHRES_IMU", "SCALED_IMU2"}


def test_truncated_payload_is_zero_extended_like_pymavlink() -> None:
    # MAVLink 2 senders drop trailing zero bytes of the payload: zeros at the end
    # (RAW_IMU's id and temperature, ATTITUDE's rates) give a short frame
    pack = Packer()
    for msg in (
        apm.MAVLink_raw_imu_message(123456, 1, 2, 3, 4, 5, 6, 0, 0, 0, 0, 0),
        apm.MAVLink_attitude_message(1000, 0.1, 0.2, 0.3, 0.0, 0.0, 0.0),
        apm.MAVLink_gps_raw_int_message(0, 0, 0, 0, 0, 0, 0, 0, 0, 0),
    ):
        frame = bytearray(pack(msg))
        assert frame[1] < msg.unpacker.size  # really truncated
        got, want = _both(frame)
        assert got is not None
        assert _state(got) == _state(want)


def test_arrays_decode_like_pymavlink_and_strings_go_to_pymavlink() -> None:
    pack = Packer()
    for msg in (
        apm.MAVLink_attitude_quaternion_message(
            5, 0.9, 0.1, 0.2, 0.3, 0.01, 0.02, 0.03, [1, 0, 0, 0]
        ),
        apm.MAVLink_gps_input_message(1, 0, 0, 0, 0, 3, 1, 2, 3.0, 1, 1, 0, 0, 0, 1, 1, 1, 9, 0),
    ):
        got, want = _both(bytearray(pack(msg)))
        assert got is not None
        assert _state(got) == _state(want)
    for msg in (
        apm.MAVLink_statustext_message(4, b"CMP GNSS_LOST rx0", 0, 0),
        apm.MAVLink_named_value_float_message(7, b"CMP_HPL", 12.5),
    ):  # string fields: pymavlink's classes decode them in __init__
        got, want = _both(bytearray(pack(msg)))
        assert got is None


def _raw_frame(msg_id: int, payload: bytes, crc_extra: int) -> bytearray:
    """A MAVLink 2 frame around a raw payload (system 1, component 1, sequence 7)."""
    head = bytes((0xFD, len(payload), 0, 0, 7, 1, 1, msg_id & 0xFF, (msg_id >> 8) & 0xFF))
    head += bytes((msg_id >> 16,))
    crc = apm.x25crc(head[1:] + payload + bytes((crc_extra,))).crc
    return bytearray(head + payload + bytes((crc & 0xFF, crc >> 8)))


@pytest.mark.parametrize("fill", [0x00, 0x41])
def test_every_message_class_decodes_like_pymavlink_or_is_declined(fill: int) -> None:
    # every message of the dialect, from a payload of one repeated byte, full length and
    # truncated by a third (zero-extended by both): what the fast path takes, it builds
    # as pymavlink does; string messages are declined
    dec = FastDecoder(apm)
    mav = apm.MAVLink(None)
    taken = 0
    for msg_id, cls in sorted(apm.mavlink_map.items()):
        size = cls.unpacker.size
        for n in (size, (2 * size) // 3):
            frame = _raw_frame(msg_id, bytes((fill,)) * n, cls.crc_extra)
            got = dec.decode(bytearray(frame))
            want = mav.decode(bytearray(frame))
            if got is None:
                assert "s" in cls.unpacker.format or "c" in cls.unpacker.format, cls.msgname
                continue
            taken += 1
            assert _state(got) == _state(want), cls.msgname
    assert taken > 200


def test_odd_frames_are_left_to_pymavlink() -> None:
    pack = Packer()
    good = bytearray(pack(raw_imu(1000)))
    dec = FastDecoder(apm)
    bad_crc = bytearray(good)
    bad_crc[-1] ^= 0xFF
    assert dec.decode(bad_crc) is None  # pymavlink then raises its CRC error
    signed = bytearray(good)
    signed[2] |= 0x01
    assert dec.decode(signed + bytearray(13)) is None
    v1 = apm.MAVLink(None, 1, 1)
    v1.WIRE_PROTOCOL_VERSION = "1.0"
    frame_v1 = bytearray(heartbeat().pack(v1, force_mavlink1=True))
    assert frame_v1[0] == 0xFE
    assert dec.decode(frame_v1) is None
    unknown = bytearray(good)
    unknown[7:10] = bytes((0xFF, 0xFF, 0x00))  # an id the dialect does not know
    assert dec.decode(unknown) is None


def test_frame_parser_with_fast_path_matches_pymavlink() -> None:
    pack = Packer()
    data = b"".join(pack(m) for m in (heartbeat(), attitude(10), raw_imu(10_000), attitude(30)))
    parser = FrameParser()
    # a heartbeat frame is 21 bytes: split inside it, garbage between it and the next
    got = parser.feed(data[:17]) + parser.feed(data[17:21] + b"\x00garbage" + data[21:])
    mav = apm.MAVLink(None)
    want = [mav.parse_char(data[i : i + 1]) for i in range(len(data))]
    want = [m for m in want if m is not None]
    assert [_state(m) for m in got] == [_state(m) for m in want]
    assert parser.bad_frames == 1


def test_incomplete_frames_are_declined_without_error() -> None:
    # every prefix of a good frame (a reader's buffer cut anywhere): None, never an
    # IndexError, and the full frame at any offset decodes to its length
    frame = bytearray(Packer()(raw_imu(1000)))
    dec = FastDecoder(apm)
    for cut in range(len(frame)):
        assert dec.decode_at(frame[:cut] if cut else bytearray(b"\xfd"), 0) is None
        assert dec.message_at(bytearray(b"\x00" * 5) + frame[:cut], 5) is None
    found = dec.decode_at(bytearray(b"\x00" * 5) + frame + bytearray(3), 5)
    assert found is not None and found[1] == len(frame)
    assert bytes(found[0].get_msgbuf()) == bytes(frame)

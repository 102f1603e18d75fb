"""Encoder.pack packs what pymavlink's msg.pack packs, byte for byte."""

from __future__ import annotations

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as apm

from companion.mavlink.encode import Encoder, _pack_plan
from tests.mavlink.test_fastdecode import _raw_frame


def test_every_plain_message_packs_like_pymavlink() -> None:
    # every message class of the dialect, with field values decoded from random payloads
    # (and an all-zero one: the trailing-zero truncation down to one byte)
    rng = np.random.default_rng(7)
    enc = Encoder(system_id=42)
    ref = apm.MAVLink(None, srcSystem=42, srcComponent=191)
    rx = apm.MAVLink(None)
    packed_here = 0
    for msg_id, cls in sorted(apm.mavlink_map.items()):
        for k in range(3):
            size = cls.unpacker.size
            payload = bytes(size) if k == 0 else rng.integers(0, 256, size, dtype=np.uint8)
            frame = _raw_frame(msg_id, bytes(payload), cls.crc_extra)
            msg_a = rx.decode(bytearray(frame))
            msg_b = rx.decode(bytearray(frame))
            ref.seq = enc._mav.seq
            got = enc.pack(msg_a)
            want = bytes(msg_b.pack(ref))
            assert got == want, cls.msgname
            assert bytes(msg_a.get_msgbuf()) == bytes(msg_b.get_msgbuf())
            assert msg_a.get_crc() == msg_b.get_crc()
            assert bytes(msg_a.get_payload()) == bytes(msg_b.get_payload())
            assert vars(msg_a.get_header()) == vars(msg_b.get_header())
            packed_here += _pack_plan(apm, cls) is not False
    assert packed_here > 300


def test_sequence_wraps_and_decodes() -> None:
    enc = Encoder(system_id=7)
    rx = apm.MAVLink(None)
    for i in range(300):
        data = enc.pack(apm.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3))
        msg = rx.decode(bytearray(data))
        assert msg.get_header().seq == i % 256
        assert msg.get_srcSystem() == 7 and msg.get_srcComponent() == 191

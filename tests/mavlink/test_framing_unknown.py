"""Valid frames of message ids the dialect does not know are counted unknown, not bad."""

from __future__ import annotations

import struct

from pymavlink.dialects.v20 import ardupilotmega as apm
from pymavlink.mavutil import x25crc

from companion.mavlink.framing import FrameParser
from companion.mavlink.tlog import TlogReader
from companion.pipeline import Pipeline
from tests.mavlink._util import Packer, attitude, heartbeat

ESC_STATUS_ID = 291
ESC_STATUS_CRC_EXTRA = 10  # common.xml's ESC_STATUS (PX4 sends it; pymavlink 2.4 lacks it)


def _unknown_frame(
    seq: int = 0, msg_id: int = ESC_STATUS_ID, extra: int = ESC_STATUS_CRC_EXTRA
) -> bytes:
    payload = bytes(range(57))
    header = struct.pack(
        "<BBBBBBBHB", 0xFD, len(payload), 0, 0, seq, 1, 1, msg_id & 0xFFFF, msg_id >> 16
    )
    crc = x25crc(header[1:] + payload)
    crc.accumulate(bytes((extra,)))
    return header + payload + struct.pack("<H", crc.crc)


def test_unknown_but_valid_frames_are_unknown_not_bad() -> None:
    assert ESC_STATUS_ID not in apm.mavlink_map
    pk = Packer()
    good = [pk(heartbeat()), pk(attitude(1000)), pk(attitude(1020))]
    stream = good[0] + _unknown_frame(1) + good[1] + _unknown_frame(2) + _unknown_frame(3) + good[2]
    p = FrameParser()
    msgs = p.feed(stream)
    assert len(msgs) == 3
    assert p.unknown_frames == 3
    assert p.bad_frames == 0 and p.bad_bytes == 0
    # one datagram, one frame: valid at the end of the data too
    p2 = FrameParser()
    assert p2.feed(_unknown_frame()) == [] and p2.unknown_frames == 1 and p2.bad_frames == 0


def test_unknown_frame_with_bad_crc_is_bad() -> None:
    pk = Packer()
    frame = bytearray(_unknown_frame())
    frame[20] ^= 0x10
    stream = pk(heartbeat()) + bytes(frame) + pk(attitude(1000))
    p = FrameParser()
    msgs = p.feed(stream)
    assert len(msgs) == 2  # the good neighbours are kept
    assert p.unknown_frames == 0
    assert p.bad_frames == 1


def test_unknown_frame_not_followed_by_a_frame_is_bad() -> None:
    """A valid-looking unknown frame must be followed by the next STX (or the data's end):
    a false STX in garbage then cannot swallow the good frames behind it."""
    pk = Packer()
    stream = pk(heartbeat()) + _unknown_frame() + b"\x00\x11" + pk(attitude(1000))
    p = FrameParser()
    msgs = p.feed(stream)
    assert len(msgs) == 2
    assert p.unknown_frames == 0 and p.bad_frames == 1


def test_pipeline_counts_unknown_message(tmp_path) -> None:  # type: ignore[no-untyped-def]
    pipeline = Pipeline()
    pipeline.unknown_frames(4)
    assert pipeline.decoder.rejections["unknown_message"] == 4
    assert pipeline.decoder.rejections.get("corrupt_frame", 0) == 0


def test_tlog_unknown_record_is_unknown_frame(tmp_path) -> None:  # type: ignore[no-untyped-def]
    pk = Packer()
    path = tmp_path / "x.tlog"
    t_us = 1_700_000_000_000_000
    frames = [pk(heartbeat()), _unknown_frame(1), pk(attitude(1000)), _unknown_frame(2)]
    with path.open("wb") as fh:
        for i, f in enumerate(frames):
            fh.write(struct.pack(">Q", t_us + 1000 * i) + f)
    reader = TlogReader(path)
    msgs = list(reader)
    assert [m.get_type() for _, m in msgs] == ["HEARTBEAT", "ATTITUDE"]
    assert reader.stats["unknown_frame"] == 2
    assert reader.stats.get("bad_region", 0) == 0

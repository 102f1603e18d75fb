"""FrameParser: exact agreement with pymavlink on clean streams, robustness on bad ones."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as apm

from companion.mavlink.framing import FrameParser
from tests.mavlink._util import Packer, attitude, gps_raw, heartbeat, raw_imu


def _frames(n: int = 60) -> list[bytes]:
    pk = Packer()
    out = [pk(heartbeat())]
    for i in range(n):
        out.append(pk(raw_imu(1_000_000 + 20_000 * i)))
        out.append(pk(attitude(1000 + 20 * i)))
        if i % 5 == 0:
            out.append(pk(gps_raw(1_000_000 + 20_000 * i)))
    return out


FRAMES = _frames()
STREAM = b"".join(FRAMES)


def _key(m: object) -> tuple:
    return (m.get_type(), tuple(m.to_dict().items()))  # type: ignore[attr-defined]


def test_clean_stream_matches_pymavlink() -> None:
    p = FrameParser()
    ours = p.feed(STREAM)
    ref = apm.MAVLink(None)
    ref.robust_parsing = True
    theirs = ref.parse_buffer(STREAM) or []
    assert [_key(m) for m in ours] == [_key(m) for m in theirs]
    assert len(ours) == len(FRAMES)
    assert p.bad_frames == 0 and p.bad_bytes == 0 and p.pending_bytes == 0


def test_byte_by_byte_feed_gives_same_messages() -> None:
    p = FrameParser()
    got = []
    for b in STREAM:
        got.extend(p.feed(bytes([b])))
    assert [_key(m) for m in got] == [_key(m) for m in FrameParser().feed(STREAM)]


def test_mavlink1_frames_are_parsed() -> None:
    mav = apm.MAVLink(None, 1, 1)
    data = b"".join(bytes(attitude(10 * i).pack(mav, force_mavlink1=True)) for i in range(5))
    msgs = FrameParser().feed(data)
    assert [m.time_boot_ms for m in msgs] == [0, 10, 20, 30, 40]


def test_every_single_bit_flip_loses_only_its_frame() -> None:
    rng = np.random.default_rng(7)
    starts = np.cumsum([0] + [len(f) for f in FRAMES])
    for _ in range(200):
        k = int(rng.integers(1, len(FRAMES) - 1))
        bit = int(rng.integers(0, 8 * len(FRAMES[k])))
        bad = bytearray(STREAM)
        bad[starts[k] + bit // 8] ^= 1 << (bit % 8)
        p = FrameParser()
        msgs = p.feed(bytes(bad)) + p.flush()
        assert len(msgs) == len(FRAMES) - 1, (k, bit)
        assert p.bad_frames == 1
        assert p.bad_bytes == len(FRAMES[k])


def test_corrupted_length_byte_does_not_swallow_neighbours() -> None:
    """pymavlink's own robust parser drops the frames a bad length covers; ours does not."""
    k = 10
    starts = np.cumsum([0] + [len(f) for f in FRAMES])
    bad = bytearray(STREAM)
    bad[starts[k] + 1] = 255  # claims a 255-byte payload
    p = FrameParser()
    msgs = p.feed(bytes(bad)) + p.flush()
    assert len(msgs) == len(FRAMES) - 1
    ref = apm.MAVLink(None)
    ref.robust_parsing = True
    theirs = [m for m in (ref.parse_buffer(bytes(bad)) or []) if m.get_type() != "BAD_DATA"]
    assert len(theirs) < len(FRAMES) - 1


def test_truncated_frames_and_garbage_between_frames() -> None:
    rng = np.random.default_rng(11)
    pieces: list[bytes] = []
    n_good = 0
    n_bad_regions = 0
    for i, f in enumerate(FRAMES):
        if i % 7 == 3:
            pieces.append(f[: int(rng.integers(1, len(f)))])  # cut short
            n_bad_regions += 1
        elif i % 7 == 5:
            pieces.append(rng.integers(0, 256, int(rng.integers(1, 40))).astype(np.uint8).tobytes())
            pieces.append(f)
            n_good += 1
            n_bad_regions += 1
        else:
            pieces.append(f)
            n_good += 1
    p = FrameParser()
    data = b"".join(pieces)
    msgs = []
    for i in range(0, len(data), 97):  # arbitrary chunking
        msgs.extend(p.feed(data[i : i + 97]))
    msgs.extend(p.flush())
    assert len(msgs) == n_good
    assert p.bad_frames == n_bad_regions


def test_random_bytes_never_crash_seeded() -> None:
    rng = np.random.default_rng(3)
    p = FrameParser()
    total = 0
    for _ in range(50):
        total += len(p.feed(rng.integers(0, 256, 1000).astype(np.uint8).tobytes()))
    total += len(p.flush())
    assert total == 0
    assert p.bad_bytes == 50_000
    # and it still parses a good frame afterwards
    assert len(p.feed(FRAMES[1]) + p.flush()) == 1


@settings(max_examples=150, deadline=None)
@given(st.binary(max_size=600))
def test_arbitrary_bytes_never_raise(data: bytes) -> None:
    p = FrameParser()
    msgs = p.feed(data) + p.flush()
    assert p.good_frames == len(msgs)
    assert p.bad_bytes + sum(len(m.get_msgbuf()) for m in msgs) == len(data)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(st.integers(0, len(FRAMES)), st.binary(min_size=1, max_size=30)), max_size=5
    ),
    st.integers(1, 300),
)
def test_garbage_inserted_between_frames_keeps_every_frame(
    inserts: list[tuple[int, bytes]], chunk: int
) -> None:
    where = dict(inserts)
    data = b"".join(where.get(i, b"") + f for i, f in enumerate(FRAMES)) + where.get(
        len(FRAMES), b""
    )
    p = FrameParser()
    msgs = []
    for i in range(0, len(data), chunk):
        msgs.extend(p.feed(data[i : i + chunk]))
    msgs.extend(p.flush())
    assert [_key(m) for m in msgs] == [_key(m) for m in FrameParser().feed(STREAM)]

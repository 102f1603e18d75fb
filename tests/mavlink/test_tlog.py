"""Tlog reader/writer: round trip, and robustness to every kind of damage."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from companion.mavlink.tlog import TlogError, TlogReader, TlogWriter, foreign_format, read_tlog
from tests.mavlink._util import Packer, attitude, gps_raw, raw_imu

T0 = 1_700_000_000.0


def _records(n: int = 80) -> list[tuple[float, bytes]]:
    pk = Packer()
    out = []
    for i in range(n):
        t = T0 + 0.02 * i
        if i % 4 == 0:
            out.append((t, pk(gps_raw(1_000_000 + 20_000 * i))))
        elif i % 2:
            out.append((t, pk(raw_imu(1_000_000 + 20_000 * i))))
        else:
            out.append((t, pk(attitude(1000 + 20 * i))))
    return out


RECORDS = _records()


def _blob(records: list[tuple[float, bytes]]) -> list[bytes]:
    return [struct.pack(">Q", int(round(t * 1e6))) + f for t, f in records]


def _write(path: Path, parts: list[bytes]) -> Path:
    path.write_bytes(b"".join(parts))
    return path


def test_writer_reader_round_trip(tmp_path: Path) -> None:
    path = tmp_path / "a.tlog"
    pk = Packer()
    with TlogWriter(path) as w:
        for t, f in RECORDS[:10]:
            w.write(t, f)
        w.write(T0 + 1.0, attitude(5000))  # an unpacked message object
        w.write(T0 + 1.1, pk.parsed(attitude(5020)))  # a received message, written as received
    got = list(read_tlog(path))
    assert len(got) == 12
    for (t, f), (t2, m) in zip(RECORDS[:10], got[:10], strict=True):
        assert t2 == pytest.approx(t, abs=1e-6)
        assert bytes(m.get_msgbuf()) == f
    assert got[10][1].time_boot_ms == 5000 and got[11][1].time_boot_ms == 5020
    assert got[11][0] == pytest.approx(T0 + 1.1, abs=1e-6)


def test_missing_or_unreadable_file_raises_tlog_error(tmp_path: Path) -> None:
    with pytest.raises(TlogError, match="cannot open"):
        read_tlog(tmp_path / "nope.tlog")
    with pytest.raises(TlogError):
        read_tlog(tmp_path)  # a directory
    with pytest.raises(TlogError):
        TlogWriter(tmp_path / "no_dir" / "x.tlog")


def test_writer_rejects_bad_time(tmp_path: Path) -> None:
    with TlogWriter(tmp_path / "w.tlog") as w, pytest.raises(ValueError):
        w.write(float("nan"), RECORDS[0][1])


def test_truncated_last_record(tmp_path: Path) -> None:
    parts = _blob(RECORDS)
    for cut in (1, 5, 9, 12, len(parts[-1]) - 1):
        p = _write(tmp_path / f"t{cut}.tlog", parts[:-1] + [parts[-1][:cut]])
        r = TlogReader(p)
        assert len(list(r)) == len(RECORDS) - 1
        assert r.stats["truncated_record"] == 1
        assert r.stats["bad_region"] == 0


def test_corrupt_frames_and_garbage_between_records(tmp_path: Path) -> None:
    rng = np.random.default_rng(5)
    parts = _blob(RECORDS)
    out: list[bytes] = []
    good = 0
    regions = 0
    for i, rec in enumerate(parts):
        if i % 9 == 4:  # flip one bit in the frame (not the timestamp)
            b = bytearray(rec)
            j = 8 + int(rng.integers(0, len(rec) - 8))
            b[j] ^= 1 << int(rng.integers(0, 8))
            out.append(bytes(b))
            regions += 1
        elif i % 9 == 7:  # garbage before a good record
            out.append(rng.integers(0, 256, int(rng.integers(1, 50))).astype(np.uint8).tobytes())
            out.append(rec)
            good += 1
            regions += 1
        else:
            out.append(rec)
            good += 1
    r = TlogReader(_write(tmp_path / "c.tlog", out))
    got = list(r)
    assert len(got) == good
    assert r.stats["bad_region"] == regions
    assert r.stats["truncated_record"] == 0
    ts = [t for t, _ in got]
    assert ts == sorted(ts)


def test_timestamp_going_backwards_or_jumping_is_skipped(tmp_path: Path) -> None:
    recs = list(RECORDS)
    recs[10] = (recs[10][0] - 5.0, recs[10][1])  # backwards
    recs[20] = (recs[20][0] + 1e6, recs[20][1])  # a flipped high bit: far future
    r = TlogReader(_write(tmp_path / "b.tlog", _blob(recs)))
    got = list(r)
    assert len(got) == len(RECORDS) - 2
    assert r.stats["time_backwards"] == 1
    assert r.stats["time_jump"] == 1
    assert r.stats["clock_rebased"] == 0


def test_recording_clock_step_is_followed(tmp_path: Path) -> None:
    recs = [(t - 100.0 if i >= 40 else t, f) for i, (t, f) in enumerate(RECORDS)]
    r = TlogReader(_write(tmp_path / "s.tlog", _blob(recs)), resync_records=5)
    got = list(r)
    # the first four of the new clock are skipped, the fifth re-bases it
    assert len(got) == len(RECORDS) - 4
    assert r.stats["clock_rebased"] == 1
    assert got[-1][0] == pytest.approx(RECORDS[-1][0] - 100.0, abs=1e-6)


@settings(
    max_examples=40,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(st.data())
def test_fuzzed_tlogs_never_crash(tmp_path: Path, data: st.DataObject) -> None:
    blob = bytearray(b"".join(_blob(RECORDS[:20])))
    for _ in range(data.draw(st.integers(0, 10))):
        i = data.draw(st.integers(0, len(blob) - 1))
        blob[i] = data.draw(st.integers(0, 255))
    cut = data.draw(st.integers(0, len(blob)))
    path = tmp_path / "f.tlog"
    path.write_bytes(bytes(blob[:cut]) + data.draw(st.binary(max_size=40)))
    try:
        got = list(TlogReader(path))
    except TlogError:
        # only a file that starts like another format (a zip, a gzip...) is refused whole
        assert foreign_format(path.read_bytes()[:16]) is not None
        return
    assert len(got) <= 20 + 2
    assert all(isinstance(t, float) for t, _ in got)


def test_corrupt_tlog_through_the_decoder_gives_every_good_sample(tmp_path: Path) -> None:
    """Reader + decoder: bit flips, garbage and a cut tail; every good record becomes a sample."""
    from companion.mavlink.decode import Decoder
    from tests.mavlink._util import heartbeat

    pk = Packer()
    recs = [(T0, pk(heartbeat()))] + [
        (T0 + 0.02 * (i + 1), pk(attitude(1000 + 20 * i))) for i in range(300)
    ]
    rng = np.random.default_rng(99)
    parts = _blob(recs)
    damaged = set(int(k) for k in rng.choice(np.arange(2, len(parts) - 2), 30, replace=False))
    out = []
    for i, rec in enumerate(parts):
        if i in damaged:
            b = bytearray(rec)
            b[8 + int(rng.integers(0, len(rec) - 8))] ^= 1 << int(rng.integers(0, 8))
            out.append(bytes(b) + rng.integers(0, 256, 7).astype(np.uint8).tobytes())
        else:
            out.append(rec)
    out[-1] = out[-1][:-3]  # the last record is cut short
    reader = TlogReader(_write(tmp_path / "d.tlog", out))
    dec = Decoder()
    samples = [s for t, m in reader for s in dec.decode(m, t)]
    assert len(samples) == 300 - 30 - 1  # heartbeat precedes the clock: no sample
    # adjacent damaged records form one bad region
    regions = sum(1 for k in damaged if k - 1 not in damaged)
    assert reader.stats["bad_region"] == regions and reader.stats["truncated_record"] == 1
    dec.bad_frame(reader.stats["bad_region"])
    assert dec.rejections["corrupt_frame"] == regions
    assert all(b.t_s > a.t_s for a, b in zip(samples, samples[1:], strict=False))


def test_write_frames_is_write_per_frame(tmp_path: Path) -> None:
    frames = [f for _, f in RECORDS[:7]]
    with TlogWriter(tmp_path / "one.tlog") as a, TlogWriter(tmp_path / "many.tlog") as b:
        for i in range(3):
            t = T0 + 0.5 * i
            for f in frames[i:]:
                a.write(t, f)
            b.write_frames(t, frames[i:])
        b.write_frames(T0 + 2.0, [])
        assert a.records == b.records == 7 + 6 + 5
    assert (tmp_path / "one.tlog").read_bytes() == (tmp_path / "many.tlog").read_bytes()
    with TlogWriter(tmp_path / "w.tlog") as w, pytest.raises(ValueError):
        w.write_frames(-1.0, frames)
    assert (tmp_path / "w.tlog").read_bytes() == b""

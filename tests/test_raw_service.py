"""The live service's raw receiver reader: UBX read in a worker thread, fed to the pipeline
while the loop keeps its timer; a port that cannot open is a logged retry, not a crash."""

from __future__ import annotations

import asyncio
import contextlib
from pathlib import Path

from companion.config import Config, LinkConfig
from companion.raw.link import RawConfig
from companion.service import Service, _read_raw

CUT = Path(__file__).resolve().parent / "data" / "walk_0827" / "gnss_1730_cut.ubx"


def test_the_raw_file_is_read_at_its_pace_off_the_loop(tmp_path: Path) -> None:
    data = bytearray(CUT.read_bytes())
    data[5000] ^= 0xFF  # inside the first RXM-RAWX frame: its checksum fails
    ubx = tmp_path / "cut.ubx"
    ubx.write_bytes(bytes(data))
    link = LinkConfig(heartbeat_rate_hz=10.0, state_file="", record_dir="")
    service = Service(Config(link=link, raw=RawConfig(file=str(ubx))))

    async def run() -> None:
        tasks = [asyncio.create_task(service._timer()), asyncio.create_task(service._raw_reader())]
        await asyncio.sleep(1.6)
        for task in tasks:
            task.cancel()
        for task in tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await task

    asyncio.run(run())
    raw = service.pipeline.raw
    assert raw is not None
    # 4 Hz epochs at their own pace: about six in 1.6 s, not the file's 161 at once;
    # the cut's navigation words come at its end, so none is an epoch 0 yet (counted)
    rejected = raw.rejections()
    epochs = rejected.get("epoch 0: fewer than 5 satellites", 0)
    assert 3 <= epochs <= 9
    assert rejected["bad frame"] == 1  # counted by the reader thread, not raised
    # the loop was never held: the 10 Hz heartbeat kept its rate
    assert service.pipeline.stats.out_by_type["HEARTBEAT"] >= 12


def test_a_device_that_cannot_open_is_reported_not_raised() -> None:
    got: list[object] = []
    import threading

    why = _read_raw(RawConfig(device="/nonexistent/ttyRAW"), got.append, threading.Event())
    assert why.startswith("cannot open") and got == [None]

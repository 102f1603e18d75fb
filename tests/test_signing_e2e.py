"""MAVLink 2 signing on a live ground-station link, end to end over UDP on 127.0.0.1.

The service runs (in a thread, so that its counters can be read) with the autopilot link
unsigned and the ground-station link requiring signatures. A pymavlink "autopilot" plays
the bundled taxi until the heading correction is READY; a pymavlink ground station with
``mav.signing`` set up (the key from the passphrase, as MAVProxy's ``signing setup``
makes it) confirms it and the correction is applied. An unsigned ground station, a
ground station with another key and a replayed signed confirmation are refused and
counted, and never answered; everything the service sends on the ground-station link
verifies with pymavlink. The signing timestamp is stored and a restart starts above it.
"""

from __future__ import annotations

import asyncio
import json
import math
import socket
import threading
import time
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import ardupilotmega as apm

from companion.config import Config, LinkConfig
from companion.mavlink.ids import MAV_CMD_USER_1, MAV_COMP_ID_ONBOARD_COMPUTER
from companion.mavlink.signing import (
    BAD_SIGNATURE,
    REPLAYED,
    UNSIGNED,
    LinkSigningConfig,
    SigningConfig,
    passphrase_key,
    timestamp_at,
)
from companion.mavlink.tlog import TlogReader
from companion.service import SIGNING_STATE_FILE, Service
from tests.helpers import TAXI, TAXI_HEADING_ERROR_DEG

PASSPHRASE = "companion signing test"
GCS_LINK_ID = 0
OUR_LINK_ID = 1
TIMEOUT_S = 60.0


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def udp_socket() -> socket.socket:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.setblocking(False)
    return sock


class ServiceThread:
    """The service's asyncio loop in a thread; :meth:`stop` stops it as SIGTERM does."""

    def __init__(self, config: Config) -> None:
        self.service = Service(config)
        self.loop: asyncio.AbstractEventLoop | None = None
        self.exit_status: int | None = None
        self.thread = threading.Thread(target=self._main, daemon=True)
        self.thread.start()

    def _main(self) -> None:
        async def run() -> None:
            self.loop = asyncio.get_running_loop()
            self.exit_status = await self.service.run()

        asyncio.run(run())

    def wait_links(self, n: int) -> None:
        deadline = time.monotonic() + TIMEOUT_S
        while self.service.links_opened < n:
            assert time.monotonic() < deadline, "links never opened"
            time.sleep(0.01)

    def stop(self) -> None:
        assert self.loop is not None
        self.loop.call_soon_threadsafe(self.service.stop)
        self.thread.join(15.0)
        assert not self.thread.is_alive(), "service did not stop"
        assert self.exit_status == 0


class GroundStation:
    """A pymavlink ground station on its own UDP socket, signing with ``key`` (or not)."""

    def __init__(self, port: int, key: bytes | None, sysid: int = 255, compid: int = 190):
        self.sock = udp_socket()
        self.port = port
        self.mav = apm.MAVLink(None, sysid, compid)
        self.mav.robust_parsing = True  # a frame failing its signature becomes bad data
        if key is not None:
            self.mav.signing.secret_key = key
            self.mav.signing.link_id = GCS_LINK_ID
            self.mav.signing.timestamp = timestamp_at(time.time())
            self.mav.signing.sign_outgoing = True
        self.received: list = []
        self.raw: list[bytes] = []

    def send(self, msg) -> bytes:
        frame = bytes(msg.pack(self.mav))
        self.mav.seq = (self.mav.seq + 1) % 256
        self.sock.sendto(frame, ("127.0.0.1", self.port))
        return frame

    def heartbeat(self) -> bytes:
        return self.send(apm.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))  # GCS, not autopilot

    def confirm(self, apply: float = 1.0) -> bytes:
        return self.send(
            apm.MAVLink_command_long_message(0, 191, MAV_CMD_USER_1, 0, apply, 0, 0, 0, 0, 0, 0)
        )

    def drain(self) -> None:
        while True:
            try:
                data = self.sock.recv(65536)
            except BlockingIOError:
                return
            self.raw.append(data)
            self.received += self.mav.parse_buffer(data) or []

    def ours(self, kind: str) -> list:
        return [
            m
            for m in self.received
            if m.get_type() == kind and m.get_srcComponent() == MAV_COMP_ID_ONBOARD_COMPUTER
        ]

    def texts(self, prefix: str) -> list[str]:
        return [m.text for m in self.ours("STATUSTEXT") if m.text.startswith(prefix)]

    def wait_for(self, what, timeout_s: float = 10.0) -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            self.drain()
            if what():
                return
            time.sleep(0.01)
        self.drain()


def taxi_frames() -> list[bytes]:
    return [bytes(msg.get_msgbuf()) for _, msg in TlogReader(TAXI)]


def signing_config(tmp_path: Path, master_port: int, gcs_port: int) -> Config:
    link = LinkConfig(
        master=f"udpin:127.0.0.1:{master_port}",
        gcs=f"udpin:127.0.0.1:{gcs_port}",
        state_file=str(tmp_path / "state" / "state.json"),
        record_dir="",
    )
    gcs = LinkSigningConfig(mode="require", passphrase=PASSPHRASE, link_id=OUR_LINK_ID)
    return Config(link=link, signing=SigningConfig(gcs=gcs))


def play_taxi_until_ready(
    running: ServiceThread,
    autopilot: socket.socket,
    port: int,
    gcs: GroundStation,
    heard: list[bytes],
) -> None:
    """Stream the taxi to the autopilot link, paced by what the service has taken in,
    until the ground station hears HDG_READY; what the autopilot hears goes to ``heard``."""
    frames = taxi_frames()
    pipeline = running.service.pipeline
    sent = 0
    deadline = time.monotonic() + TIMEOUT_S
    while not gcs.texts("CMP HDG_READY"):
        assert sent < len(frames), "the taxi ended before HDG_READY"
        assert time.monotonic() < deadline, "HDG_READY never heard"
        chunk = frames[sent : sent + 20]
        autopilot.sendto(b"".join(chunk), ("127.0.0.1", port))
        sent += len(chunk)
        while pipeline.stats.messages_in < sent - 200 and time.monotonic() < deadline:
            time.sleep(0.001)
        if sent % 1000 < 20:
            gcs.heartbeat()  # a ground station beats at 1 Hz; it also makes it the peer
        gcs.drain()
        heard += _drain_raw(autopilot)


@pytest.fixture(scope="module")
def signed_run(tmp_path_factory):
    """One service run: the taxi to READY, then the ground stations' attempts."""
    tmp_path = tmp_path_factory.mktemp("signing")
    master_port, gcs_port = free_udp_port(), free_udp_port()
    running = ServiceThread(signing_config(tmp_path, master_port, gcs_port))
    autopilot = udp_socket()
    key = passphrase_key(PASSPHRASE)
    gcs = GroundStation(gcs_port, key)
    intruder = GroundStation(gcs_port, None, sysid=254)
    stranger = GroundStation(gcs_port, passphrase_key("another passphrase"), sysid=253)
    result: dict = {"tmp_path": tmp_path, "gcs": gcs, "intruder": intruder}
    try:
        running.wait_links(2)
        gcs.heartbeat()
        heard: list[bytes] = []
        play_taxi_until_ready(running, autopilot, master_port, gcs, heard)
        heading = running.service.pipeline.engine.heading
        verifier = running.service.signing["gcs"].verifier
        result["correction_when_ready_rad"] = heading.correction_rad

        # an unsigned confirmation, then one signed with another key: refused
        intruder.confirm()
        stranger.confirm()
        gcs.wait_for(lambda: verifier.rejections[UNSIGNED] and verifier.rejections[BAD_SIGNATURE])
        gcs.heartbeat()
        time.sleep(0.5)
        gcs.drain()
        result["correction_after_refused_rad"] = heading.correction_rad
        result["acks_after_refused"] = len(gcs.ours("COMMAND_ACK"))

        # the signed confirmation: applied and acknowledged
        confirmation = gcs.confirm()
        gcs.wait_for(lambda: gcs.texts("CMP HDG_APPLIED") and gcs.ours("COMMAND_ACK"))
        result["correction_applied_rad"] = heading.correction_rad

        # the same signed frame replayed, by the ground station's socket and another
        gcs.sock.sendto(confirmation, ("127.0.0.1", gcs_port))
        intruder.sock.sendto(confirmation, ("127.0.0.1", gcs_port))
        gcs.wait_for(lambda: verifier.rejections[REPLAYED] >= 2)
        gcs.heartbeat()
        time.sleep(0.5)
        gcs.drain()
        for peer in (intruder, stranger):
            peer.drain()
        result["rejections"] = dict(verifier.rejections)
        result["accepted_signed"] = verifier.accepted_signed
        result["acks"] = gcs.ours("COMMAND_ACK")
        result["applied_texts"] = gcs.texts("CMP HDG_APPLIED")
        result["strangers_heard"] = len(intruder.raw) + len(stranger.raw)
        result["autopilot_frames"] = heard + _drain_raw(autopilot)
        result["our_last_timestamp"] = running.service.signing["gcs"].timestamp
    finally:
        running.stop()
        for sock in (autopilot, gcs.sock, intruder.sock, stranger.sock):
            sock.close()
    return result


def _drain_raw(sock: socket.socket) -> list[bytes]:
    out = []
    while True:
        try:
            out.append(sock.recv(65536))
        except BlockingIOError:
            return out


def test_a_signed_ground_station_confirms_the_heading_correction(signed_run):
    assert signed_run["correction_when_ready_rad"] == 0.0
    applied = signed_run["correction_applied_rad"]
    assert applied == pytest.approx(math.radians(TAXI_HEADING_ERROR_DEG), abs=math.radians(0.1))
    acks = signed_run["acks"]
    assert len(acks) == 1
    assert acks[0].command == MAV_CMD_USER_1 and acks[0].result == 0
    assert acks[0].target_system == 255 and acks[0].target_component == 190
    assert len(signed_run["applied_texts"]) == 1
    gcs = signed_run["gcs"]
    print(
        f"applied {math.degrees(applied):.3f} deg (injected {TAXI_HEADING_ERROR_DEG} deg); "
        f"refused {signed_run['rejections']}; signed frames accepted "
        f"{signed_run['accepted_signed']}; ours verified by pymavlink "
        f"{gcs.mav.signing.goodsig_count}, bad {gcs.mav.signing.badsig_count}"
    )


def test_unsigned_and_wrong_key_confirmations_are_refused_and_counted(signed_run):
    assert signed_run["correction_after_refused_rad"] == 0.0
    assert signed_run["acks_after_refused"] == 0
    assert signed_run["rejections"][UNSIGNED] == 1
    assert signed_run["rejections"][BAD_SIGNATURE] == 1


def test_a_replayed_signed_confirmation_is_refused_and_counted(signed_run):
    assert signed_run["rejections"][REPLAYED] == 2
    assert len(signed_run["acks"]) == 1  # the replays got no answer


def test_strangers_do_not_divert_the_ground_station_link(signed_run):
    """On a signing udpin link only senders of accepted frames become the peer."""
    assert signed_run["strangers_heard"] == 0


def test_everything_sent_to_the_ground_station_verifies_with_pymavlink(signed_run):
    gcs = signed_run["gcs"]
    ours = [m for m in gcs.received if m.get_srcComponent() == MAV_COMP_ID_ONBOARD_COMPUTER]
    assert len(ours) > 100
    assert all(m._signed and m._link_id == OUR_LINK_ID for m in ours)
    assert not [m for m in gcs.received if m.get_type() == "BAD_DATA"]
    assert gcs.mav.signing.badsig_count == 0
    assert gcs.mav.signing.goodsig_count >= len(ours)
    # one stream, strictly increasing timestamps (pymavlink refuses any that is not)
    stamps = [int.from_bytes(m.get_msgbuf()[-12:-6], "little") for m in ours]
    assert all(b > a for a, b in zip(stamps, stamps[1:], strict=False))


def test_the_unsigned_autopilot_link_is_unchanged(signed_run):
    """Signing off on the autopilot link: it receives unsigned frames, as without signing."""
    data = b"".join(signed_run["autopilot_frames"])
    msgs = apm.MAVLink(None).parse_buffer(data) or []
    types = {m.get_type() for m in msgs}
    assert {"HEARTBEAT", "GPS_INPUT", "GLOBAL_POSITION_INT"} <= types
    assert all(m.get_msgbuf()[2] == 0 for m in msgs)  # no SIGNED flag


def test_the_signing_timestamp_is_stored_and_a_restart_starts_above_it(signed_run, tmp_path):
    state_dir = signed_run["tmp_path"] / "state"
    stored = json.loads((state_dir / SIGNING_STATE_FILE).read_text())["timestamp_10us"]
    assert stored >= signed_run["our_last_timestamp"]
    # a restart, even with a wall clock behind the stored timestamp, starts above it
    path = state_dir / SIGNING_STATE_FILE
    ahead = timestamp_at(time.time()) + 3600 * 100_000
    path.write_text(json.dumps({"timestamp_10us": ahead}))
    config = signing_config(signed_run["tmp_path"], free_udp_port(), free_udp_port())
    assert Service(config).signing["gcs"].timestamp >= ahead
    # and with a stored timestamp behind the wall clock, from the wall clock
    path.write_text(json.dumps({"timestamp_10us": 5}))
    before = timestamp_at(time.time())
    assert Service(config).signing["gcs"].timestamp >= before
    # an unreadable file: from the wall clock, with a warning
    path.write_text("{")
    assert Service(config).signing["gcs"].timestamp >= before


def test_a_missing_key_file_stops_the_start_naming_the_block(tmp_path):
    link = LinkConfig(state_file="", record_dir="")
    gcs = LinkSigningConfig(mode="require", key_file=str(tmp_path / "absent.key"))
    with pytest.raises(ValueError, match=r"\[signing.gcs\] signing key_file .*absent.key"):
        Service(Config(link=link, signing=SigningConfig(gcs=gcs)))

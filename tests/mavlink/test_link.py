"""Links on loopback and on a real pseudo-terminal, including unplug/replug."""

from __future__ import annotations

import asyncio
import os
import socket
import tty
from collections.abc import Awaitable
from pathlib import Path
from typing import TypeVar

import pytest

from companion.mavlink.link import (
    LinkError,
    LinkUrlError,
    ReconnectingLink,
    TcpServerLink,
    UdpLink,
    open_link,
    parse_url,
    reconnecting,
)

T = TypeVar("T")
TIMEOUT_S = 5.0


def run(coro: Awaitable[T]) -> T:
    async def bounded() -> T:
        return await asyncio.wait_for(coro, 20.0)

    return asyncio.run(bounded())


async def recv_exactly(link, n: int) -> bytes:  # type: ignore[no-untyped-def]
    buf = b""
    while len(buf) < n:
        buf += await asyncio.wait_for(link.recv(), TIMEOUT_S)
    return buf


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_parse_url() -> None:
    assert parse_url("serial:/dev/ttyUSB0:921600") == ("serial", "/dev/ttyUSB0", 921600)
    assert parse_url("serial:/dev/ttyUSB0", 57600) == ("serial", "/dev/ttyUSB0", 57600)
    assert parse_url("/dev/ttyACM0", 115200) == ("serial", "/dev/ttyACM0", 115200)
    assert parse_url("udpin:0.0.0.0:14550") == ("udpin", "0.0.0.0", 14550)
    assert parse_url("udp:0.0.0.0:14550") == ("udpin", "0.0.0.0", 14550)
    assert parse_url("tcpin:127.0.0.1:5760") == ("tcpin", "127.0.0.1", 5760)
    assert parse_url("udpin:127.0.0.1:0") == ("udpin", "127.0.0.1", 0)  # any free port
    # a by-path device name has colons of its own
    by_path = "/dev/serial/by-path/pci-0000:00:14.0-usb-0:1:1.0-port0"
    assert parse_url(f"serial:{by_path}", 9600) == ("serial", by_path, 9600)
    for bad, why in (
        ("bogus:1:2", "unknown scheme 'bogus'"),
        ("udpot:127.0.0.1:14550", "unknown scheme 'udpot'"),
        ("tcp:localhost", "expected tcp:HOST:PORT"),
        ("udpin:127.0.0.1", "expected udpin:HOST:PORT"),
        ("udpout:127.0.0.1:x", "port 'x' is not a number"),
        ("udpout:127.0.0.1:-1", "port '-1' is not a number"),
        ("tcp:127.0.0.1:70000", "out of range"),
        ("tcp:127.0.0.1:0", "port 0 can only listen"),
        ("udpout:127.0.0.300:14550", "not an IPv4 address"),
        ("serial:/dev/ttyUSB0:0", "baud rate 0"),
        ("", "expected serial:DEVICE"),
    ):
        with pytest.raises(LinkUrlError, match=why):
            parse_url(bad)


def test_a_well_formed_url_that_cannot_open_is_not_malformed() -> None:
    """Device absent, port busy: a plain LinkError (the service retries), not LinkUrlError."""

    async def main() -> None:
        with pytest.raises(LinkError) as absent:
            await open_link("serial:/dev/companion-test-no-such-device:57600")
        assert not isinstance(absent.value, LinkUrlError)
        holder = await open_link("udpin:127.0.0.1:0")
        try:
            with pytest.raises(LinkError) as busy:
                await open_link(f"udpin:127.0.0.1:{holder.local_port}")
            assert not isinstance(busy.value, LinkUrlError)
        finally:
            await holder.close()

    run(main())


def test_udp_in_out_round_trip() -> None:
    async def main() -> None:
        server = await open_link("udpin:127.0.0.1:0")
        assert isinstance(server, UdpLink)
        await server.send(b"nobody yet")  # no peer: dropped and counted, no exception
        assert server.send_failures == 1
        client = await open_link(f"udpout:127.0.0.1:{server.local_port}")
        await client.send(b"\xfd hello")
        assert await recv_exactly(server, 7) == b"\xfd hello"
        await server.send(b"reply")  # to the last sender
        assert await recv_exactly(client, 5) == b"reply"
        await client.close()
        await server.close()
        with pytest.raises(LinkError):
            await server.recv()

    run(main())


def test_udp_datagrams_waiting_come_together_one_sender_at_a_time() -> None:
    async def main() -> None:
        server = await open_link("udpin:127.0.0.1:0")
        assert isinstance(server, UdpLink)
        a = await open_link(f"udpout:127.0.0.1:{server.local_port}")
        b = await open_link(f"udpout:127.0.0.1:{server.local_port}")
        for link, data in ((a, b"a1"), (a, b"a2"), (b, b"b1"), (a, b"a3")):
            await link.send(data)
        await asyncio.sleep(0.2)  # all four waiting before the first recv
        chunks = []
        while sum(len(c) for c in chunks) < 8:
            chunks.append(await asyncio.wait_for(server.recv(), TIMEOUT_S))
            if chunks[-1] == b"b1":
                sender_b = server.last_sender
            else:
                sender_a = server.last_sender
        assert chunks == [b"a1a2", b"b1", b"a3"]
        assert sender_a != sender_b and server.bytes_in == 8
        for link in (a, b, server):
            await link.close()

    run(main())


def test_tcp_client_server_round_trip_and_broadcast() -> None:
    async def main() -> None:
        srv = await open_link("tcpin:127.0.0.1:0")
        assert isinstance(srv, TcpServerLink)
        port = srv.local_port
        c1 = await open_link(f"tcp:127.0.0.1:{port}")
        c2 = await open_link(f"tcp:127.0.0.1:{port}")
        await c1.send(b"from c1")
        assert await recv_exactly(srv, 7) == b"from c1"
        for _ in range(50):
            if srv.n_clients == 2:
                break
            await asyncio.sleep(0.01)
        await srv.send(b"to all")
        assert await recv_exactly(c1, 6) == b"to all"
        assert await recv_exactly(c2, 6) == b"to all"
        await c2.close()
        await c1.send(b"still")  # a client leaving is not an error for the server
        assert await recv_exactly(srv, 5) == b"still"
        await srv.close()
        with pytest.raises(LinkError):
            await asyncio.wait_for(c1.recv(), TIMEOUT_S)  # server gone
        await c1.send(b"x")  # never raises
        await c1.close()

    run(main())


def test_tcp_connect_refused_is_link_error() -> None:
    async def main() -> None:
        with pytest.raises(LinkError):
            await open_link(f"tcp:127.0.0.1:{_free_port()}")
        with pytest.raises(LinkError):
            await reconnecting(f"tcp:127.0.0.1:{_free_port()}", backoff_min_s=0.01, max_attempts=3)

    run(main())


def test_tcp_client_reconnects_after_server_restart() -> None:
    async def main() -> None:
        port = _free_port()
        srv = await open_link(f"tcpin:127.0.0.1:{port}")
        cli = await reconnecting(f"tcp:127.0.0.1:{port}", backoff_min_s=0.02, backoff_max_s=0.1)
        await cli.send(b"one")
        assert await recv_exactly(srv, 3) == b"one"
        await srv.close()
        pending = asyncio.ensure_future(cli.recv())  # waits across the outage
        await asyncio.sleep(0.2)
        await cli.send(b"lost")  # while disconnected: dropped, counted
        srv2 = await open_link(f"tcpin:127.0.0.1:{port}")
        assert isinstance(srv2, TcpServerLink)
        for _ in range(200):
            if srv2.n_clients:
                break
            await asyncio.sleep(0.01)
        assert srv2.n_clients == 1
        await srv2.send(b"two")
        assert await asyncio.wait_for(pending, TIMEOUT_S) == b"two"
        assert isinstance(cli, ReconnectingLink)
        assert cli.connects == 2 and cli.drops == 1 and cli.send_failures >= 1
        await cli.send(b"three")
        assert await recv_exactly(srv2, 5) == b"three"
        await cli.close()
        await srv2.close()

    run(main())


class FakeDevice:
    """A serial device: a pty whose slave is reached through a symlink that can vanish."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.master = -1
        self.slave = -1

    def plug(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.master)
        os.set_blocking(self.master, False)
        self.path.symlink_to(os.ttyname(self.slave))

    def unplug(self) -> None:
        self.path.unlink()
        os.close(self.master)
        os.close(self.slave)

    async def read(self, n: int) -> bytes:
        buf = b""
        for _ in range(500):
            try:
                buf += os.read(self.master, 4096)
            except BlockingIOError:
                await asyncio.sleep(0.01)
            if len(buf) >= n:
                break
        return buf


def test_serial_over_pty_with_unplug_and_replug(tmp_path: Path) -> None:
    dev = FakeDevice(tmp_path / "ttyFAKE")

    async def main() -> None:
        with pytest.raises(LinkError):
            await open_link(str(dev.path))  # not plugged yet
        dev.plug()
        plain = await open_link(f"serial:{dev.path}:921600")
        os.write(dev.master, b"\xfdabc")
        assert await recv_exactly(plain, 4) == b"\xfdabc"
        await plain.send(b"out")
        assert await dev.read(3) == b"out"
        await plain.close()

        link = await reconnecting(
            f"serial:{dev.path}:921600", backoff_min_s=0.02, backoff_max_s=0.1
        )
        os.write(dev.master, b"first")
        assert await recv_exactly(link, 5) == b"first"
        pending = asyncio.ensure_future(link.recv())
        await asyncio.sleep(0.05)
        dev.unplug()  # the device disappears
        await asyncio.sleep(0.3)
        assert not pending.done()
        await link.send(b"into the void")  # never raises
        dev.plug()  # ... and comes back (a new pty behind the same path)
        for _ in range(300):
            if link.connects == 2:
                break
            await asyncio.sleep(0.01)
        assert link.connects == 2 and link.drops == 1
        os.write(dev.master, b"second")
        assert await asyncio.wait_for(pending, TIMEOUT_S) == b"second"
        await link.send(b"back")
        assert await dev.read(4) == b"back"
        await link.close()
        dev.unplug()

    run(main())

"""Asyncio byte transports to the autopilot: serial, UDP and TCP behind one interface.

URLs
----
``serial:/dev/ttyUSB0:921600``, ``serial:/dev/ttyUSB0`` or a bare device path
``/dev/ttyACM0`` (baud from the argument)
    a serial device (pyserial opens it; the non-blocking fd is watched with
    ``loop.add_reader``). When the device disappears, :meth:`Link.recv` raises
    :class:`LinkError`.
``udpin:0.0.0.0:14550`` (alias ``udp:``)
    listen; sends go to the last sender (dropped, counted, before anyone spoke);
    with ``reply_to_any_sender`` off, only to a sender the caller adopts (the
    service adopts the sender of frames a signing link accepted).
``udpout:127.0.0.1:14550``
    send to that address; replies are received on the same socket.
``tcp:127.0.0.1:5760``
    client; :meth:`Link.recv` raises :class:`LinkError` when the server closes.
``tcpin:0.0.0.0:5760``
    server; accepts any number of clients, receives from all, sends to all.
    A client leaving is not an error.

A malformed URL (unknown scheme, no port, a port or baud rate that is not a
number, a dotted address that is not IPv4) raises :class:`LinkUrlError` from
:func:`parse_url`: no retry can fix it, so the service refuses to start. A
well-formed URL that cannot be opened now (device absent, port busy, peer not
listening) raises the plain :class:`LinkError`: worth retrying.

Reconnection policy: :func:`open_link` opens once (``LinkError`` if it
cannot). :func:`reconnecting` returns a :class:`ReconnectingLink` that re-opens
the URL with exponential backoff whenever it drops (a serial device unplugged
and plugged back, a TCP server restarted) and whose ``recv`` only returns bytes;
the service uses that one for live links.

``send`` is best effort everywhere: it never raises because the peer went away;
failures are counted in :attr:`Link.send_failures` and logged (rate-limited).
"""

from __future__ import annotations

import abc
import asyncio
import collections
import contextlib
import ipaddress
import logging
import os
import socket
from typing import Any

logger = logging.getLogger(__name__)

RECV_CHUNK = 65536
_SEND_TIMEOUT_S = 0.5


class LinkError(Exception):
    """The link cannot be opened, or it dropped."""


class LinkUrlError(LinkError):
    """The link URL is malformed: fatal, never retried (a :class:`LinkError`, so that
    callers catching that still catch it)."""


_LISTENING = ("udpin", "tcpin")
"""Kinds for which port 0 (any free port) makes sense."""


def _split_host_port(rest: str, url: str, kind: str) -> tuple[str, int]:
    host, sep, port_s = rest.rpartition(":")
    if not sep or not host:
        scheme = url.partition(":")[0]
        raise LinkUrlError(f"bad link URL {url!r}: expected {scheme}:HOST:PORT")
    if not port_s.isdigit():
        raise LinkUrlError(f"bad link URL {url!r}: port {port_s!r} is not a number")
    port = int(port_s)
    if not 0 <= port <= 65535:
        raise LinkUrlError(f"bad link URL {url!r}: port {port} out of range 0-65535")
    if port == 0 and kind not in _LISTENING:
        raise LinkUrlError(f"bad link URL {url!r}: port 0 can only listen (udpin, tcpin)")
    if host.replace(".", "").isdigit():
        try:
            ipaddress.IPv4Address(host)
        except ValueError:
            raise LinkUrlError(f"bad link URL {url!r}: {host!r} is not an IPv4 address") from None
    elif any(c.isspace() for c in host):
        raise LinkUrlError(f"bad link URL {url!r}: blank in host {host!r}")
    return host, port


def parse_url(url: str, baud: int = 57600) -> tuple[str, Any, Any]:
    """Split a link URL into ``(kind, address, option)``.

    ``kind`` is one of ``serial, udpin, udpout, tcp, tcpin``; for serial the
    address is the device path and the option the baud rate, otherwise the
    address is the host and the option the port.

    Raises
    ------
    LinkUrlError
        On a malformed URL (the message says what is wrong and what was expected).
    """
    if url.startswith("/"):
        return "serial", url, _check_baud(baud, url)
    scheme, sep, rest = url.partition(":")
    if not sep or not rest:
        raise LinkUrlError(
            f"bad link URL {url!r}: expected serial:DEVICE[:BAUD], a device path, "
            "udpin:, udpout:, tcp: or tcpin:HOST:PORT"
        )
    if scheme == "serial":
        path, sep2, baud_s = rest.rpartition(":")
        if sep2 and baud_s.isdigit() and path:
            return "serial", path, _check_baud(int(baud_s), url)
        return "serial", rest, _check_baud(baud, url)
    if scheme == "udp":
        scheme = "udpin"
    if scheme in ("udpin", "udpout", "tcp", "tcpin"):
        host, port = _split_host_port(rest, url, scheme)
        return scheme, host, port
    raise LinkUrlError(
        f"bad link URL {url!r}: unknown scheme {scheme!r} (serial, udpin, udp, udpout, tcp, tcpin)"
    )


def _check_baud(baud: int, url: str) -> int:
    if baud <= 0:
        raise LinkUrlError(f"bad link URL {url!r}: baud rate {baud} must be > 0")
    return baud


class Link(abc.ABC):
    """Common interface of every transport.

    Attributes
    ----------
    url : str
        The URL it was opened with.
    send_failures : int
        Sends dropped (peer gone, no peer yet, buffer full).
    bytes_in, bytes_out : int
        Traffic counters.
    """

    def __init__(self, url: str) -> None:
        self.url = url
        self.send_failures = 0
        self.bytes_in = 0
        self.bytes_out = 0
        self._closed = False

    @property
    def closed(self) -> bool:
        """True once :meth:`close` was called."""
        return self._closed

    @abc.abstractmethod
    async def recv(self) -> bytes:
        """Next chunk of bytes (never empty). Raises LinkError when the link drops."""

    @abc.abstractmethod
    async def send(self, data: bytes) -> None:
        """Send bytes, best effort (never raises on a dropped peer)."""

    async def close(self) -> None:
        """Release the transport; idempotent."""
        self._closed = True

    async def _recv_queued(self, queue: asyncio.Queue[bytes | None]) -> bytes:
        """Next chunk from a transport that queues what it receives (None: closed)."""
        if self._closed:
            raise LinkError(f"{self.url}: closed")
        data = await queue.get()
        if data is None:
            raise LinkError(f"{self.url}: closed")
        self.bytes_in += len(data)
        return data

    def _send_failed(self, why: object) -> None:
        self.send_failures += 1
        n = self.send_failures
        if n == 1 or len(str(n)) != len(str(n - 1)):
            logger.warning("%s: send failed (%s); %d so far", self.url, why, n)


# ---------------------------------------------------------------------- serial


def _wake(fut: asyncio.Future[None]) -> None:
    if not fut.done():
        fut.set_result(None)


class SerialLink(Link):
    """A serial device through pyserial, read with ``loop.add_reader``."""

    def __init__(self, url: str, path: str, baud: int) -> None:
        super().__init__(url)
        import serial  # pyserial; imported here so the other links do not need it

        try:
            self._ser = serial.Serial(port=path, baudrate=baud, timeout=0, write_timeout=0)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise LinkError(f"cannot open serial {path}: {exc}") from exc
        self._fd = self._ser.fileno()
        os.set_blocking(self._fd, False)
        self.path = path

    async def recv(self) -> bytes:
        if self._closed:
            raise LinkError(f"{self.url}: closed")
        loop = asyncio.get_running_loop()
        woken = False
        while True:
            try:
                data = os.read(self._fd, RECV_CHUNK)
            except BlockingIOError:
                data = b""
            except OSError as exc:
                raise LinkError(f"{self.url}: device lost ({exc.strerror})") from exc
            if data:
                self.bytes_in += len(data)
                return data
            if woken:
                # readable but nothing to read: the device is gone (pyserial's rule; a
                # tty in raw mode with VMIN=0 returns 0 bytes instead of EAGAIN)
                raise LinkError(f"{self.url}: device lost (no data though readable)")
            fut: asyncio.Future[None] = loop.create_future()
            loop.add_reader(self._fd, _wake, fut)
            try:
                await fut
            finally:
                loop.remove_reader(self._fd)
            if self._closed:
                raise LinkError(f"{self.url}: closed")
            woken = True

    async def send(self, data: bytes) -> None:
        if self._closed:
            self._send_failed("closed")
            return
        view = memoryview(data)
        loop = asyncio.get_running_loop()
        deadline = loop.time() + _SEND_TIMEOUT_S
        while view:
            try:
                n = os.write(self._fd, view)
                self.bytes_out += n
                view = view[n:]
                continue
            except BlockingIOError:
                pass
            except OSError as exc:
                self._send_failed(exc.strerror)
                return
            remaining = deadline - loop.time()
            if remaining <= 0:
                self._send_failed("timeout")
                return
            fut: asyncio.Future[None] = loop.create_future()
            loop.add_writer(self._fd, _wake, fut)
            try:
                await asyncio.wait_for(fut, remaining)
            except asyncio.TimeoutError:
                self._send_failed("timeout")
                return
            finally:
                loop.remove_writer(self._fd)

    async def close(self) -> None:
        if not self._closed:
            self._closed = True
            with contextlib.suppress(OSError):
                self._ser.close()


# ---------------------------------------------------------------------- UDP


class _DatagramQueue(asyncio.DatagramProtocol):
    def __init__(self, link: UdpLink) -> None:
        self._link = link

    def datagram_received(self, data: bytes, addr: Any) -> None:
        self._link._on_datagram(data, addr)

    def error_received(self, exc: Exception) -> None:
        # ICMP port unreachable etc.: the peer is not there yet
        logger.debug("%s: %s", self._link.url, exc)

    def connection_lost(self, exc: Exception | None) -> None:
        self._link._wake()


class UdpLink(Link):
    """``udpin`` (listen, reply to the last sender) or ``udpout`` (send to a fixed peer).

    Attributes
    ----------
    reply_to_any_sender : bool
        ``udpin``: every datagram makes its sender the peer (the default). Off, the peer
        changes only by :meth:`adopt_sender`, so that a stranger's datagrams cannot
        divert what is sent.
    last_sender : Any
        ``udpin``: the sender of the chunk :meth:`recv` returned last.

    The datagrams waiting when :meth:`recv` is called are returned together (joined, as
    a stream link would deliver them), those of one sender at a time: one wake-up of the
    reader for all of them. They wait in a deque with one waiter, not an
    ``asyncio.Queue``: the live path's cost is per datagram.
    """

    def __init__(self, url: str, listen: bool, host: str, port: int) -> None:
        super().__init__(url)
        self.listen = listen
        self.reply_to_any_sender = True
        self.last_sender: Any = None
        self._addr = (host, port)
        self._peer: Any = None if listen else (host, port)
        self._datagrams: collections.deque[tuple[bytes, Any]] = collections.deque()
        self._waiter: asyncio.Future[None] | None = None
        self._transport: asyncio.DatagramTransport | None = None

    async def _open(self) -> None:
        loop = asyncio.get_running_loop()
        try:
            if self.listen:
                transport, _ = await loop.create_datagram_endpoint(
                    lambda: _DatagramQueue(self), local_addr=self._addr, family=socket.AF_INET
                )
            else:
                transport, _ = await loop.create_datagram_endpoint(
                    lambda: _DatagramQueue(self), local_addr=("0.0.0.0", 0), family=socket.AF_INET
                )
        except OSError as exc:
            raise LinkError(f"cannot open {self.url}: {exc.strerror or exc}") from exc
        self._transport = transport

    @property
    def local_port(self) -> int:
        """The bound UDP port (useful with port 0)."""
        if self._transport is None:
            return 0
        return int(self._transport.get_extra_info("sockname")[1])

    def _on_datagram(self, data: bytes, addr: Any) -> None:
        if self.listen and self.reply_to_any_sender:
            self._peer = addr
        self._datagrams.append((data, addr))
        self._wake()

    def _wake(self) -> None:
        waiter = self._waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    async def recv(self) -> bytes:
        datagrams = self._datagrams
        while not datagrams:
            if self._closed:
                raise LinkError(f"{self.url}: closed")
            waiter = self._waiter = asyncio.get_running_loop().create_future()
            try:
                await waiter
            finally:
                self._waiter = None
        if self._closed:
            raise LinkError(f"{self.url}: closed")
        data, sender = datagrams.popleft()
        if datagrams and datagrams[0][1] == sender:  # more from the same sender: together
            chunks = [data]
            while datagrams and datagrams[0][1] == sender:
                chunks.append(datagrams.popleft()[0])
            data = b"".join(chunks)
        if self.listen:
            self.last_sender = sender
        self.bytes_in += len(data)
        return data

    def adopt_sender(self) -> None:
        """``udpin``: send to the sender of the chunk :meth:`recv` returned last."""
        if self.listen and self.last_sender is not None:
            self._peer = self.last_sender

    async def send(self, data: bytes) -> None:
        if self._transport is None or self._closed:
            self._send_failed("closed")
            return
        if self._peer is None:
            self._send_failed("no peer yet")
            return
        try:
            self._transport.sendto(data, self._peer)
            self.bytes_out += len(data)
        except OSError as exc:
            self._send_failed(exc.strerror)

    async def close(self) -> None:
        if not self._closed:
            self._closed = True
            if self._transport is not None:
                self._transport.close()
            self._wake()


# ---------------------------------------------------------------------- TCP


class TcpClientLink(Link):
    """A TCP client; ``recv`` raises LinkError when the server closes."""

    def __init__(self, url: str, host: str, port: int) -> None:
        super().__init__(url)
        self._host, self._port = host, port
        self._reader: asyncio.StreamReader | None = None
        self._writer: asyncio.StreamWriter | None = None

    async def _open(self, timeout_s: float = 5.0) -> None:
        try:
            self._reader, self._writer = await asyncio.wait_for(
                asyncio.open_connection(self._host, self._port), timeout_s
            )
        except (OSError, asyncio.TimeoutError) as exc:
            raise LinkError(f"cannot connect {self.url}: {exc}") from exc

    async def recv(self) -> bytes:
        if self._reader is None or self._closed:
            raise LinkError(f"{self.url}: closed")
        try:
            data = await self._reader.read(RECV_CHUNK)
        except OSError as exc:
            raise LinkError(f"{self.url}: {exc.strerror or exc}") from exc
        if not data:
            raise LinkError(f"{self.url}: connection closed by peer")
        self.bytes_in += len(data)
        return data

    async def send(self, data: bytes) -> None:
        w = self._writer
        if w is None or self._closed or w.is_closing():
            self._send_failed("not connected")
            return
        try:
            w.write(data)
            await asyncio.wait_for(w.drain(), _SEND_TIMEOUT_S)
            self.bytes_out += len(data)
        except (OSError, asyncio.TimeoutError) as exc:
            self._send_failed(exc)

    async def close(self) -> None:
        if not self._closed:
            self._closed = True
            if self._writer is not None:
                self._writer.close()
                with contextlib.suppress(OSError, asyncio.TimeoutError):
                    await asyncio.wait_for(self._writer.wait_closed(), 1.0)


class TcpServerLink(Link):
    """A TCP server: receives from every client, sends to every client."""

    def __init__(self, url: str, host: str, port: int) -> None:
        super().__init__(url)
        self._host, self._port = host, port
        self._server: asyncio.Server | None = None
        self._clients: set[asyncio.StreamWriter] = set()
        self._queue: asyncio.Queue[bytes | None] = asyncio.Queue()
        self.clients_seen = 0

    async def _open(self) -> None:
        try:
            self._server = await asyncio.start_server(self._on_client, self._host, self._port)
        except OSError as exc:
            raise LinkError(f"cannot listen on {self.url}: {exc.strerror or exc}") from exc

    @property
    def local_port(self) -> int:
        """The bound TCP port (useful with port 0)."""
        if self._server is None or not self._server.sockets:
            return 0
        return int(self._server.sockets[0].getsockname()[1])

    @property
    def n_clients(self) -> int:
        """Connected clients."""
        return len(self._clients)

    async def _on_client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self._clients.add(writer)
        self.clients_seen += 1
        peer = writer.get_extra_info("peername")
        logger.info("%s: client %s connected", self.url, peer)
        try:
            while True:
                data = await reader.read(RECV_CHUNK)
                if not data:
                    break
                self._queue.put_nowait(data)
        except OSError as exc:
            logger.info("%s: client %s: %s", self.url, peer, exc)
        finally:
            self._clients.discard(writer)
            writer.close()
            logger.info("%s: client %s left", self.url, peer)

    async def recv(self) -> bytes:
        return await self._recv_queued(self._queue)

    async def send(self, data: bytes) -> None:
        if self._closed or not self._clients:
            self._send_failed("no client")
            return
        for w in list(self._clients):
            if w.is_closing():
                self._clients.discard(w)
                continue
            try:
                w.write(data)
                self.bytes_out += len(data)
            except OSError as exc:
                self._send_failed(exc)
                self._clients.discard(w)
        for w in list(self._clients):
            try:
                await asyncio.wait_for(w.drain(), _SEND_TIMEOUT_S)
            except (OSError, asyncio.TimeoutError) as exc:
                self._send_failed(exc)
                self._clients.discard(w)
                w.close()

    async def close(self) -> None:
        if not self._closed:
            self._closed = True
            if self._server is not None:
                self._server.close()
            for w in list(self._clients):
                w.close()
            self._clients.clear()
            self._queue.put_nowait(None)
            if self._server is not None:
                with contextlib.suppress(asyncio.TimeoutError):
                    await asyncio.wait_for(self._server.wait_closed(), 1.0)


# ---------------------------------------------------------------------- factory


async def open_link(url: str, baud: int = 57600) -> Link:
    """Open ``url`` once.

    Raises
    ------
    LinkError
        On a malformed URL or when the transport cannot be opened.
    """
    kind, addr, opt = parse_url(url, baud)
    if kind == "serial":
        return SerialLink(url, addr, opt)
    if kind in ("udpin", "udpout"):
        udp = UdpLink(url, kind == "udpin", addr, opt)
        await udp._open()
        return udp
    if kind == "tcp":
        tcp = TcpClientLink(url, addr, opt)
        await tcp._open()
        return tcp
    srv = TcpServerLink(url, addr, opt)
    await srv._open()
    return srv


class ReconnectingLink(Link):
    """A link that re-opens its URL with exponential backoff whenever it drops.

    ``recv`` waits (re-opening as needed) and returns bytes; it raises
    :class:`LinkError` only after :meth:`close` or when ``max_attempts``
    consecutive opens failed. ``send`` while disconnected is dropped and counted.

    Attributes
    ----------
    connects : int
        Successful opens (the first one included).
    drops : int
        Times the open link dropped.
    """

    def __init__(
        self,
        url: str,
        baud: int = 57600,
        backoff_min_s: float = 0.1,
        backoff_max_s: float = 5.0,
        max_attempts: int | None = None,
    ) -> None:
        super().__init__(url)
        parse_url(url, baud)  # raise early on a malformed URL
        if not 0.0 < backoff_min_s <= backoff_max_s:
            raise ValueError("need 0 < backoff_min_s <= backoff_max_s")
        self._baud = baud
        self._min = backoff_min_s
        self._max = backoff_max_s
        self._max_attempts = max_attempts
        self._inner: Link | None = None
        self.connects = 0
        self.drops = 0

    @property
    def connected(self) -> bool:
        """True while an underlying link is open."""
        return self._inner is not None

    async def connect(self) -> None:
        """Open the underlying link now if needed (with backoff)."""
        delay = self._min
        attempts = 0
        while self._inner is None:
            if self._closed:
                raise LinkError(f"{self.url}: closed")
            try:
                self._inner = await open_link(self.url, self._baud)
            except LinkError as exc:
                attempts += 1
                if self._max_attempts is not None and attempts >= self._max_attempts:
                    raise
                if attempts == 1 or attempts % 10 == 0:
                    logger.warning("%s: %s; retrying (attempt %d)", self.url, exc, attempts)
                await asyncio.sleep(delay)
                delay = min(2.0 * delay, self._max)
                continue
            self.connects += 1
            logger.info("%s: connected (%d)", self.url, self.connects)

    async def recv(self) -> bytes:
        while True:
            await self.connect()
            inner = self._inner
            if inner is None:
                continue
            try:
                data = await inner.recv()
            except LinkError as exc:
                if self._closed:
                    raise
                self.drops += 1
                logger.warning("%s: link dropped (%s); reconnecting", self.url, exc)
                self._inner = None
                await inner.close()
                continue
            self.bytes_in += len(data)
            return data

    async def send(self, data: bytes) -> None:
        inner = self._inner
        if inner is None:
            self._send_failed("disconnected")
            return
        before = inner.send_failures
        await inner.send(data)
        if inner.send_failures != before:
            self.send_failures += inner.send_failures - before
        else:
            self.bytes_out += len(data)

    async def close(self) -> None:
        if not self._closed:
            self._closed = True
            if self._inner is not None:
                await self._inner.close()
                self._inner = None


async def reconnecting(
    url: str,
    baud: int = 57600,
    backoff_min_s: float = 0.1,
    backoff_max_s: float = 5.0,
    max_attempts: int | None = None,
) -> ReconnectingLink:
    """A :class:`ReconnectingLink` on ``url``, connected once before returning.

    Raises
    ------
    LinkError
        On a malformed URL, or if ``max_attempts`` opens in a row fail.
    """
    link = ReconnectingLink(url, baud, backoff_min_s, backoff_max_s, max_attempts)
    await link.connect()
    return link


__all__ = [
    "Link",
    "LinkError",
    "LinkUrlError",
    "ReconnectingLink",
    "SerialLink",
    "TcpClientLink",
    "TcpServerLink",
    "UdpLink",
    "open_link",
    "parse_url",
    "reconnecting",
]

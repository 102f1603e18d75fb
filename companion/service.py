"""The live service: asyncio tasks around one :class:`~companion.pipeline.Pipeline`.

Tasks:

* one reader per link (the autopilot, and the ground station if configured):
  bytes -> :class:`~companion.mavlink.framing.FrameParser` -> pipeline -> frames
  sent to every open link and to the flight recorder. A link that drops is
  re-opened every ``reconnect_s`` until it comes back (a serial adapter
  unplugged and plugged in again, a TCP peer restarting); the failed opens are
  logged with backoff (the 1st, 2nd, 4th, 8th ... and then every 64th, or when the
  reason changes). A malformed URL is no such failure: :meth:`Service.run` raises
  :class:`~companion.mavlink.link.LinkUrlError` before starting anything. The
  autopilot link's reader counts what it delivers (bytes, frames, bad frames) and
  its autopilot HEARTBEATs in a :class:`~companion.mavlink.watch.HeartbeatWatch`.
* the timer: sleeps until the pipeline's, the watch's or the flight recorder's next
  due time; sends the pipeline's periodic output (our HEARTBEAT at
  ``heartbeat_rate_hz``), logs the watch's warning (no autopilot HEARTBEAT for
  ``no_autopilot_warn_s``, then every ``no_autopilot_repeat_s``) and flushes the
  recorder (at least every ``[recorder] flush_interval_s``); the systemd watchdog is
  fed from the same loop, at least twice per watchdog timeout, only while every
  reader task is alive.

* the raw receiver (``[raw] device`` or ``file``): its UBX read by pyubx2 in a worker
  thread (a blocking read never holds the loop), each decoded message handed to the
  loop with its receive time and fed to the pipeline (:meth:`Pipeline.on_raw`); a
  file is read at the pace of its epochs. A receiver that stops sending ends the read
  (the serial read times out), which is logged and counted, and the port is opened
  again every ``link.reconnect_s``; the CFG-VALSET turning its raw output on is sent
  at each opening.

SIGTERM and SIGINT stop it cleanly: readers cancelled, links closed, the
recorder flushed, exit status 0.

Everything goes to every link: the autopilot consumes GPS_INPUT and routes the
rest to its own ground stations; a direct ground-station link sees all of it.

MAVLink 2 signing (``[signing.autopilot]``, ``[signing.gcs]``) is applied per link at
this edge (:mod:`companion.mavlink.signing`): frames are signed as they are sent on a
signing link (the flight recorder keeps them as the pipeline packed them), and a
signing link's parser drops the frames its verifier refuses. The signing timestamp is
stored in ``signing.json`` beside ``link.state_file`` every ``SIGNING_SAVE_PERIOD_S``
and on stop, and starts from the larger of the stored one and the wall clock.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import os
import signal
import threading
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import IO

from companion.config import Config
from companion.mavlink.decode import LIGHT_MESSAGE_IDS
from companion.mavlink.framing import FrameParser
from companion.mavlink.link import Link, LinkError, UdpLink, open_link, parse_url
from companion.mavlink.signing import LinkSigning, load_key, timestamp_at
from companion.mavlink.watch import HeartbeatWatch
from companion.notify import SystemdNotifier
from companion.params import load_overrides, saved_form
from companion.pipeline import Pipeline
from companion.raw.link import RawConfig
from companion.raw.obs import NavWords, PvtFix, RawEpoch, ReceiverStatus
from companion.recorder import Recorder
from companion.ubx.reader import UbxSource

log = logging.getLogger(__name__)

SIGNING_STATE_FILE = "signing.json"
"""The signing timestamp's file, in the folder of ``link.state_file``."""
SIGNING_SAVE_PERIOD_S = 10.0
"""How often the signing timestamp is stored (MAVLink asks for at least once a minute)."""
RETRY_LOG_EVERY_MAX = 64
"""Failed opens of a link between two of its warnings, at most (once a minute or so)."""


def _log_retry(failures: int) -> bool:
    """Whether the ``failures``-th failed open in a row is logged: 1, 2, 4, ... 64, then
    every 64th."""
    return failures & (failures - 1) == 0 or failures % RETRY_LOG_EVERY_MAX == 0


PARAMS_FILE = "params.json"
"""The parameters set over MAVLink, kept beside ``link.state_file``."""


def params_path(config: Config) -> Path | None:
    """Where the parameters set over MAVLink are kept (None: no state file, not kept)."""
    state_file = config.link.state_file
    return Path(state_file).with_name(PARAMS_FILE) if state_file else None


def load_params(config: Config) -> tuple[Config, dict[str, object]]:
    """``config`` with the parameters saved in :func:`params_path` applied over it (each
    validated as when it was set; one that no longer is is dropped, with a warning), and
    the values applied."""
    path = params_path(config)
    if path is None or not path.exists():
        return config, {}
    try:
        saved = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        log.warning("parameter file %s unreadable (%s): TOML configuration only", path, exc)
        return config, {}
    config, applied, problems = load_overrides(config, saved)
    for problem in problems:
        log.warning("parameter file %s: %s: dropped", path, problem)
    if applied:
        log.info("%d parameters set over MAVLink loaded from %s", len(applied), path)
    return config, applied


def _write_json(path: Path, value: object, what: str, indent: int | None = None) -> bool:
    """Write ``value`` to ``path`` atomically (write, fsync, rename); False, logged, when
    it cannot be written."""
    tmp = path.with_suffix(path.suffix + ".tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(tmp, "w") as fh:
            json.dump(value, fh, indent=indent)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        log.error("cannot save %s to %s: %s", what, path, exc)
        return False
    return True


WRITE_MAX_BYTES = 1400
"""Frames are sent together up to this many bytes a write (below the Ethernet MTU: a
UDP datagram that is never fragmented)."""


def _pack_writes(frames: list[bytes]) -> list[bytes]:
    """``frames`` joined into writes of at most :data:`WRITE_MAX_BYTES` (a longer frame
    alone), in order."""
    if len(frames) == 1:
        return frames
    writes: list[bytes] = []
    batch: list[bytes] = []
    size = 0
    for frame in frames:
        if batch and size + len(frame) > WRITE_MAX_BYTES:
            writes.append(b"".join(batch))
            batch, size = [], 0
        batch.append(frame)
        size += len(frame)
    if batch:
        writes.append(b"".join(batch))
    return writes


class Service:
    """Run the pipeline on live links until stopped."""

    def __init__(self, config: Config) -> None:
        config, param_overrides = load_params(config)
        self.config = config
        self.pipeline = Pipeline(config)
        self.pipeline.params.overrides.update(param_overrides)
        self._saved_params = 0
        self.notifier = SystemdNotifier()
        self._links: dict[str, Link] = {}
        self._stop = asyncio.Event()
        self._readers: list[asyncio.Task[None]] = []
        self.recorder: Recorder | None = None
        self.links_opened = 0
        self._saved_changes = 0
        link_cfg = config.link
        self.watch = HeartbeatWatch(
            f"master {link_cfg.master}",
            link_cfg.no_autopilot_warn_s,
            link_cfg.no_autopilot_repeat_s,
        )
        """The autopilot link's HEARTBEAT watch (docs/mavlink.md, link health)."""
        self._load_state()
        self._signing_saved_at_s = -math.inf
        """When the signing timestamp was last stored (wall clock, s)."""
        self._signing_saved = -1
        """The signing timestamp last stored."""
        self.signing: dict[str, LinkSigning] = self._setup_signing()
        """Signing per link name ("autopilot", "gcs"), for the links that sign."""

    def stop(self) -> None:
        """Ask the service to stop (signal handlers call this)."""
        self._stop.set()

    async def run(self) -> int:
        """Run until stopped; returns the process exit status."""
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGTERM, signal.SIGINT):
            with contextlib.suppress(NotImplementedError, RuntimeError):
                loop.add_signal_handler(sig, self.stop)
        link_cfg = self.config.link
        urls = {"autopilot": link_cfg.master}
        if link_cfg.gcs:
            urls["gcs"] = link_cfg.gcs
        for url in urls.values():
            parse_url(url, link_cfg.baud)  # malformed: LinkUrlError, fatal (never retried)
        if link_cfg.record_dir:
            try:
                self.recorder = Recorder(
                    Path(link_cfg.record_dir), time.time(), self.config.recorder
                )
            except OSError as exc:
                log.error("flight recorder disabled: cannot write %s: %s", link_cfg.record_dir, exc)
        self._readers = [
            asyncio.create_task(self._reader(name, url), name=f"reader-{name}")
            for name, url in urls.items()
        ]
        if self.config.raw.enabled:
            self._readers.append(asyncio.create_task(self._raw_reader(), name="reader-raw"))
        timer = asyncio.create_task(self._timer(), name="timer")
        self.notifier.notify("READY=1")
        log.info(
            "companion running: autopilot %s%s",
            link_cfg.master,
            f", gcs {link_cfg.gcs}" if link_cfg.gcs else "",
        )
        await self._stop.wait()
        self.notifier.notify("STOPPING=1")
        for task in (*self._readers, timer):
            task.cancel()
        for task in (*self._readers, timer):
            with contextlib.suppress(asyncio.CancelledError):
                await task
        for link in list(self._links.values()):
            await link.close()
        self._links.clear()
        if self.recorder is not None:
            self.recorder.close()
        self._save_state()
        self._save_signing(time.time())
        for name, signing in self.signing.items():
            verifier = signing.verifier
            log.info(
                "%s link signing: %d frames signed, %d signed frames accepted, refused %s",
                name,
                signing.signer.signed,
                verifier.accepted_signed,
                dict(verifier.rejections) or "none",
            )
        log.info("companion stopped")
        return 0

    async def _reader(self, name: str, url: str) -> None:
        # the pipeline's decoder and the recorder (get_msgbuf) are the only consumers
        signing = self.signing.get(name)
        parser = FrameParser(
            self.config.encoder.dialect,
            light_ids=LIGHT_MESSAGE_IDS,
            frame_check=signing.accept if signing is not None else None,
        )
        watch = self.watch if name == "autopilot" else None
        failures = 0
        last_reason = ""
        while not self._stop.is_set():
            try:
                link = await open_link(url, self.config.link.baud)
            except LinkError as exc:
                failures += 1
                if _log_retry(failures) or str(exc) != last_reason:
                    log.warning(
                        "%s link %s: %s; retrying every %.1f s (%d failed)",
                        name,
                        url,
                        exc,
                        self.config.link.reconnect_s,
                        failures,
                    )
                last_reason = str(exc)
                await asyncio.sleep(self.config.link.reconnect_s)
                continue
            self._links[name] = link
            self.links_opened += 1
            log.info(
                "%s link open: %s%s", name, url, f" after {failures} failed" if failures else ""
            )
            failures, last_reason = 0, ""
            if watch is not None:
                watch.start(time.time())
            # a signing udpin link replies only to senders of frames it accepted
            adopt = None
            if signing is not None and isinstance(link, UdpLink) and link.listen:
                link.reply_to_any_sender = False
                adopt = link.adopt_sender
            try:
                while True:
                    data = await link.recv()
                    good_before = parser.good_frames
                    await self._on_bytes(parser, data, watch)
                    if adopt is not None and parser.good_frames > good_before:
                        adopt()
            except LinkError as exc:
                log.warning("%s link %s dropped: %s", name, url, exc)
            finally:
                self._links.pop(name, None)
                await link.close()
            await asyncio.sleep(self.config.link.reconnect_s)

    async def _raw_reader(self) -> None:
        """The raw receiver's messages, read in a worker thread, fed to the pipeline."""
        cfg = self.config.raw
        loop = asyncio.get_running_loop()
        what = cfg.device or cfg.file
        failures = 0
        while not self._stop.is_set():
            queue: asyncio.Queue[RawEntry] = asyncio.Queue()
            stop_reading = threading.Event()

            put = _ThreadSafePut(loop, queue)
            link = self.pipeline.enable_raw()
            worker = loop.run_in_executor(
                None, _read_raw, cfg, put, stop_reading, link.reader_rejected
            )
            delivered = 0
            try:
                while True:
                    entry = await queue.get()
                    if entry is None:
                        break
                    delivered += 1
                    t_rx_s, item = entry
                    frames = self.pipeline.on_raw(item, t_rx_s)
                    if frames:
                        await self._send(frames, t_rx_s)
            finally:
                stop_reading.set()
                error = await worker
            if error:
                failures += 1
                if _log_retry(failures):
                    log.warning("raw receiver %s: %s; retrying (%d failed)", what, error, failures)
            else:
                failures = 0
                link.rejected["receiver read ended"] += 1
                log.warning(
                    "raw receiver %s: nothing more to read after %d messages; opened again "
                    "in %.1f s",
                    what,
                    delivered,
                    self.config.link.reconnect_s,
                )
            await asyncio.sleep(self.config.link.reconnect_s)

    def _load_state(self) -> None:
        path = Path(self.config.link.state_file) if self.config.link.state_file else None
        if path is None or not path.exists():
            return
        try:
            state = json.loads(path.read_text())
        except (OSError, ValueError) as exc:
            log.warning("state file %s unreadable (%s): starting afresh", path, exc)
            return
        if isinstance(state, dict):
            self.pipeline.engine.restore(state)
            log.info("state loaded from %s (applied if the autopilot has not rebooted)", path)

    def _save_state(self) -> None:
        """Write the engine's persistent state atomically."""
        if self.config.link.state_file:
            _write_json(
                Path(self.config.link.state_file), self.pipeline.engine.persistent_state(), "state"
            )

    def _signing_path(self) -> Path | None:
        state_file = self.config.link.state_file
        return Path(state_file).with_name(SIGNING_STATE_FILE) if state_file else None

    def _setup_signing(self) -> dict[str, LinkSigning]:
        """Keys read and timestamps started for the links that sign (``ValueError`` naming
        the block when a key cannot be read)."""
        cfg = self.config.signing
        links = (("autopilot", cfg.autopilot), ("gcs", cfg.gcs))
        wanted = {name: c for name, c in links if c.enabled}
        if not wanted:
            return {}
        start = max(self._load_signing_timestamp(), timestamp_at(time.time()))
        out: dict[str, LinkSigning] = {}
        for name, link_cfg in wanted.items():
            try:
                key = load_key(link_cfg)
            except ValueError as exc:
                raise ValueError(f"[signing.{name}] {exc}") from None
            out[name] = LinkSigning(link_cfg, key, start, name)
            log.info(
                "%s link: MAVLink 2 signing, %s, link id %d", name, link_cfg.mode, link_cfg.link_id
            )
        if self._signing_path() is None:
            log.warning("no link.state_file: the signing timestamp is not kept across restarts")
        return out

    def _load_signing_timestamp(self) -> int:
        """The stored signing timestamp (0 when none or unreadable)."""
        path = self._signing_path()
        if path is None or not path.exists():
            return 0
        try:
            value = json.loads(path.read_text())["timestamp_10us"]
        except (OSError, ValueError, KeyError, TypeError) as exc:
            log.warning("signing timestamp %s unreadable (%s): from the wall clock", path, exc)
            return 0
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            log.warning("signing timestamp %s is not a count: from the wall clock", path)
            return 0
        return value

    def _save_signing(self, now_s: float) -> None:
        """Store the largest signing timestamp of the links, when it moved (atomically)."""
        path = self._signing_path()
        if not self.signing or path is None:
            return
        self._signing_saved_at_s = now_s
        timestamp = max(s.timestamp for s in self.signing.values())
        if timestamp == self._signing_saved:
            return
        if _write_json(path, {"timestamp_10us": timestamp}, "the signing timestamp"):
            self._signing_saved = timestamp

    def _save_params(self) -> None:
        """Write the parameters set over MAVLink atomically."""
        path = params_path(self.config)
        if path is None:
            log.warning("no link.state_file: parameters set over MAVLink are not kept")
            return
        _write_json(path, saved_form(self.pipeline.params.overrides), "parameters", indent=1)

    async def _on_bytes(
        self, parser: FrameParser, data: bytes, watch: HeartbeatWatch | None = None
    ) -> None:
        t_rx_s = time.time()
        bad_before = parser.bad_frames
        bad_bytes_before = parser.bad_bytes
        unknown_before = parser.unknown_frames
        messages = parser.feed(data)
        self.pipeline.bad_frames(parser.bad_frames - bad_before)
        self.pipeline.unknown_frames(parser.unknown_frames - unknown_before)
        if watch is not None:
            watch.received(
                len(data),
                len(messages),
                parser.bad_frames - bad_before,
                parser.bad_bytes - bad_bytes_before,
            )
        pipeline = self.pipeline
        decoder = pipeline.decoder
        engine = pipeline.engine
        recorder = self.recorder
        out: list[bytes] = []
        for msg in messages:
            if recorder is not None:
                recorder.record(t_rx_s, bytes(msg.get_msgbuf()))
            beats = decoder.autopilot_heartbeats
            frames = pipeline.on_message(msg, t_rx_s)
            if watch is not None and decoder.autopilot_heartbeats != beats:
                line = watch.heartbeat(t_rx_s)
                if line:
                    log.info("%s", line)
            if frames:
                if recorder is not None:
                    for frame in frames:
                        recorder.record(t_rx_s, frame)
                out += frames
            if engine.state_changes != self._saved_changes:
                self._saved_changes = engine.state_changes
                self._save_state()
            if pipeline.params.changes != self._saved_params:
                self._saved_params = pipeline.params.changes
                self._save_params()
        if out:  # what one read made, in one write per link
            await self._send_links(out, t_rx_s)

    async def _send(self, frames: list[bytes], t_s: float) -> None:
        """Record ``frames`` and send them on every open link."""
        if self.recorder is not None:
            for frame in frames:
                self.recorder.record(t_s, frame)
        await self._send_links(frames, t_s)

    async def _send_links(self, frames: list[bytes], t_s: float) -> None:
        """``frames`` on every open link, in one write each (one UDP datagram: MAVLink
        frames follow each other in a datagram as on a byte stream), signed on a link
        that signs."""
        now = timestamp_at(t_s) if self.signing else 0
        plain: list[bytes] | None = None
        for name, link in list(self._links.items()):
            signing = self.signing.get(name)
            if signing is not None:
                writes = _pack_writes([signing.sign(frame, now) for frame in frames])
            else:
                if plain is None:
                    plain = _pack_writes(frames)
                writes = plain
            for data in writes:
                await link.send(data)

    async def _timer(self) -> None:
        """Send the pipeline's periodic output when due, flush the recorder when due and
        feed the watchdog.

        The pipeline's clock is the wall clock the readers stamp messages with
        (``time.time()``): its next due time is mapped to a sleep from now. The sleep
        is at most half the watchdog timeout systemd set, so that the watchdog is fed
        whatever the heartbeat rate.
        """
        watchdog_s = self.notifier.watchdog_period_s
        max_sleep_s = watchdog_s / 2.0 if watchdog_s else math.inf
        while True:
            now_s = time.time()
            frames = self.pipeline.on_timer(now_s)
            if frames:
                await self._send(frames, now_s)
            if now_s - self._signing_saved_at_s >= SIGNING_SAVE_PERIOD_S:
                self._save_signing(now_s)
            warning = self.watch.check(now_s)
            if warning:
                log.warning("%s", warning)
            due_s = min(self.pipeline.next_due_s(), self.watch.next_due_s())
            if self.recorder is not None:  # flushes what the readers recorded meanwhile
                self.recorder.tick(time.time())
                due_s = min(due_s, self.recorder.next_due_s())
            if all(not task.done() for task in self._readers):
                self.notifier.notify("WATCHDOG=1")
            else:
                log.error("a link reader has died: not feeding the watchdog")
            sleep_s = min(due_s - time.time(), max_sleep_s)
            await asyncio.sleep(max(sleep_s, 0.0))


RawEntry = tuple[float, RawEpoch | NavWords | PvtFix | ReceiverStatus] | None
"""A raw receiver's message with its receive time; None when the reading ended."""


class _ThreadSafePut:
    """Puts a worker thread's entries on an asyncio queue from outside the loop."""

    def __init__(self, loop: asyncio.AbstractEventLoop, queue: asyncio.Queue[RawEntry]) -> None:
        self._loop = loop
        self._queue = queue

    def __call__(self, entry: RawEntry) -> None:
        self._loop.call_soon_threadsafe(self._queue.put_nowait, entry)


RAW_READ_TIMEOUT_S = 2.0
"""A serial read of the raw receiver that gets nothing for this long ends the reading."""


def _read_raw(
    cfg: RawConfig,
    put: Callable[[RawEntry], None],
    stop: threading.Event,
    rejected: Counter[str] | None = None,
) -> str:
    """Read the raw receiver until it stops (a worker thread): each message ``put`` with its
    receive time, then None; bad frames counted in ``rejected`` (this thread alone writes
    it). Returns why it could not be read ('' when it just ended)."""
    from companion.ubx.reader import enable_raw_output

    try:
        if cfg.device:
            import serial  # the edge only: pyserial

            try:
                port = serial.Serial(cfg.device, cfg.baud, timeout=RAW_READ_TIMEOUT_S)
            except (OSError, ValueError, serial.SerialException) as exc:
                return f"cannot open: {exc}"
            with port:
                if cfg.configure_receiver:
                    port.write(enable_raw_output(cfg.receiver_port))
                for item in _source(port, rejected):
                    if stop.is_set():
                        break
                    put((time.time(), item))
            return ""
        try:
            fh = open(cfg.file, "rb")
        except OSError as exc:
            return f"cannot open: {exc}"
        with fh:
            last_tow_s: float | None = None
            for item in _source(fh, rejected):
                if stop.is_set():
                    break
                if isinstance(item, RawEpoch):
                    if last_tow_s is not None and 0.0 < item.tow_s - last_tow_s < 60.0:
                        time.sleep(item.tow_s - last_tow_s)  # the recording's own pace
                    last_tow_s = item.tow_s
                put((time.time(), item))
        return ""
    except OSError as exc:
        return f"read failed: {exc}"
    finally:
        put(None)


def _source(stream: IO[bytes], rejected: Counter[str] | None) -> UbxSource:
    source = UbxSource(stream)
    if rejected is not None:
        source.rejected = rejected
    return source


def run_service(config: Config) -> int:
    """Entry point of ``companion run``."""
    return asyncio.run(Service(config).run())

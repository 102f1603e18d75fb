"""The live service: asyncio tasks around one :class:`~companion.pipeline.Pipeline`.

Tasks:

* one reader per link (the autopilot, and the ground station if configured):
  bytes -> :class:`~companion.mavlink.framing.FrameParser` -> pipeline -> frames
  sent to every open link and to the flight recorder. A link that drops is
  re-opened every ``reconnect_s`` until it comes back (a serial adapter
  unplugged and plugged in again, a TCP peer restarting).
* the timer: sleeps until the pipeline's next due time and sends its periodic
  output (our HEARTBEAT at ``heartbeat_rate_hz``); the systemd watchdog is fed
  from the same loop, at least twice per watchdog timeout, only while every
  reader task is alive.

SIGTERM and SIGINT stop it cleanly: readers cancelled, links closed, the
recorder flushed, exit status 0.

Everything goes to every link: the autopilot consumes GPS_INPUT and routes the
rest to its own ground stations; a direct ground-station link sees all of it.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import os
import signal
import time
from pathlib import Path

from companion.config import Config
from companion.mavlink.decode import LIGHT_MESSAGE_IDS
from companion.mavlink.framing import FrameParser
from companion.mavlink.link import Link, LinkError, open_link
from companion.notify import SystemdNotifier
from companion.params import load_overrides, saved_form
from companion.pipeline import Pipeline
from companion.recorder import Recorder

log = logging.getLogger(__name__)

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
        self._load_state()

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
        if link_cfg.record_dir:
            try:
                self.recorder = Recorder(Path(link_cfg.record_dir), time.time())
            except OSError as exc:
                log.error("flight recorder disabled: cannot write %s: %s", link_cfg.record_dir, exc)
        urls = {"autopilot": link_cfg.master}
        if link_cfg.gcs:
            urls["gcs"] = link_cfg.gcs
        self._readers = [
            asyncio.create_task(self._reader(name, url), name=f"reader-{name}")
            for name, url in urls.items()
        ]
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
        log.info("companion stopped")
        return 0

    async def _reader(self, name: str, url: str) -> None:
        # the pipeline's decoder and the recorder (get_msgbuf) are the only consumers
        parser = FrameParser(self.config.encoder.dialect, light_ids=LIGHT_MESSAGE_IDS)
        while not self._stop.is_set():
            try:
                link = await open_link(url, self.config.link.baud)
            except LinkError as exc:
                log.warning(
                    "%s link %s: %s; retrying in %.1f s",
                    name,
                    url,
                    exc,
                    self.config.link.reconnect_s,
                )
                await asyncio.sleep(self.config.link.reconnect_s)
                continue
            self._links[name] = link
            self.links_opened += 1
            log.info("%s link open: %s", name, url)
            try:
                while True:
                    data = await link.recv()
                    await self._on_bytes(parser, data)
            except LinkError as exc:
                log.warning("%s link %s dropped: %s", name, url, exc)
            finally:
                self._links.pop(name, None)
                await link.close()
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
        """Write the engine's persistent state atomically (write, fsync, rename)."""
        if not self.config.link.state_file:
            return
        path = Path(self.config.link.state_file)
        tmp = path.with_suffix(path.suffix + ".tmp")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with open(tmp, "w") as fh:
                json.dump(self.pipeline.engine.persistent_state(), fh)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, path)
        except OSError as exc:
            log.error("cannot save state to %s: %s", path, exc)

    def _save_params(self) -> None:
        """Write the parameters set over MAVLink atomically (write, fsync, rename)."""
        path = params_path(self.config)
        if path is None:
            log.warning("no link.state_file: parameters set over MAVLink are not kept")
            return
        tmp = path.with_suffix(path.suffix + ".tmp")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with open(tmp, "w") as fh:
                json.dump(saved_form(self.pipeline.params.overrides), fh, indent=1)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, path)
        except OSError as exc:
            log.error("cannot save parameters to %s: %s", path, exc)

    async def _on_bytes(self, parser: FrameParser, data: bytes) -> None:
        t_rx_s = time.time()
        bad_before = parser.bad_frames
        messages = parser.feed(data)
        self.pipeline.bad_frames(parser.bad_frames - bad_before)
        for msg in messages:
            if self.recorder is not None:
                self.recorder.record(t_rx_s, bytes(msg.get_msgbuf()))
            frames = self.pipeline.on_message(msg, t_rx_s)
            if frames:
                await self._send(frames, t_rx_s)
            if self.pipeline.engine.state_changes != self._saved_changes:
                self._saved_changes = self.pipeline.engine.state_changes
                self._save_state()
            if self.pipeline.params.changes != self._saved_params:
                self._saved_params = self.pipeline.params.changes
                self._save_params()

    async def _send(self, frames: list[bytes], t_s: float) -> None:
        for frame in frames:
            if self.recorder is not None:
                self.recorder.record(t_s, frame)
            for link in list(self._links.values()):
                await link.send(frame)

    async def _timer(self) -> None:
        """Send the pipeline's periodic output when due and feed the watchdog.

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
            if all(not task.done() for task in self._readers):
                self.notifier.notify("WATCHDOG=1")
            else:
                log.error("a link reader has died: not feeding the watchdog")
            sleep_s = min(self.pipeline.next_due_s() - time.time(), max_sleep_s)
            await asyncio.sleep(max(sleep_s, 0.0))


def run_service(config: Config) -> int:
    """Entry point of ``companion run``."""
    return asyncio.run(Service(config).run())

"""One clock for every sample: the autopilot's time since boot, seconds.

:class:`BootClock` maps each message's own time field onto that clock, detects
reboots and rejects messages that step back in time.

* ``time_boot_ms`` and a boot-based ``time_usec`` map directly. ``time_boot_ms``
  is uint32 and wraps after 49.7 days: a value below :data:`WRAP_WINDOW_MS`
  after one above ``2**32 - WRAP_WINDOW_MS`` adds one wrap of 2**32 ms.
* A ``time_usec`` above ``units.EPOCH_USEC_THRESHOLD`` is UNIX-epoch time
  (ArduPilot stamps GPS_RAW_INT so). It is mapped onto the boot clock with
  ``t_s = epoch_s - offset_s``, where ``offset_s`` is the running maximum,
  over all epoch-stamped messages, of ``epoch_s - latest_boot_t_s``. Each
  difference equals the true offset minus the message's latency behind the
  latest boot-clock message, so the maximum converges to the true offset minus
  the smallest latency seen: mapped times are late by that smallest latency
  (tens of ms at most with a 50 Hz IMU stream). Before any boot-clock time has
  been seen, such messages are rejected ``no_time_yet``. Once SYSTEM_TIME
  (``time_unix_usec`` with its ``time_boot_ms``, sent at 1 Hz by ArduPilot and
  PX4) has given the offset exactly, that offset is used instead, and GNSS
  fixes land on their time of validity. Epoch-stamped messages are held back
  (rejected ``awaiting_system_time``) for up to ``system_time_wait_s`` of boot
  clock after the first of them, so that the offset does not step by the
  latency once SYSTEM_TIME arrives; without SYSTEM_TIME the estimate is used.
* ``time_usec == 0`` (ArduPilot's GPS_RAW_INT before the receiver has time)
  and messages without a time (HEARTBEAT, VFR_HUD, EXTENDED_SYS_STATE, GPS_RTK,
  the heading command) take the latest boot-clock time (:meth:`BootClock.now`).
* Reboot: a boot-clock time more than ``reboot_backjump_s`` before the latest
  one queues a :class:`~companion.types.RebootEvent` (reported before the
  message's own sample) and resets the clock state (wraps, epoch offset,
  per-stream times). Only the "now" streams (IMU, attitude,
  GLOBAL_POSITION_INT) detect reboots: a GNSS ``time_usec`` is the time of the
  last fix and stays put through a GNSS outage (equal stamps are accepted; the
  engine sees the fix is stale). A smaller backward step on one stream (a
  message type, per instance) rejects that message ``time_backwards``; equal
  times are accepted.
"""

from __future__ import annotations

import logging
import math
from typing import Any

from companion.mavlink import units
from companion.mavlink.decode.config import DecoderConfig
from companion.mavlink.decode.rejections import Rejected
from companion.types import RebootEvent, Sample

logger = logging.getLogger(__name__)

UINT32_WRAP_MS = 1 << 32
WRAP_WINDOW_MS = 600_000
"""A time_boot_ms below this after one above 2**32 minus this is a wrap (10 min)."""
_WRAP_HI_MS = UINT32_WRAP_MS - WRAP_WINDOW_MS
_MS_PER_S = units.MS_PER_S
_US_PER_S = units.US_PER_S
_EPOCH_USEC = units.EPOCH_USEC_THRESHOLD
_NO_TIME = -math.inf
"""A stream's previous time before it has one (compares below every time)."""


class BootClock:
    """The autopilot's boot clock as reconstructed from the messages' time fields.

    Parameters
    ----------
    config
        ``reboot_backjump_s`` and ``system_time_wait_s`` are used.

    Attributes
    ----------
    last_t_s : float | None
        Latest boot-clock time seen, s.
    epoch_offset_s : float | None
        Current UNIX-epoch minus boot-clock offset (estimate or exact), s.
    reboots : int
        Reboots detected.
    pending : list
        RebootEvents queued by a reboot, for the decoder to report (and clear).
    """

    def __init__(self, config: DecoderConfig) -> None:
        self.last_t_s: float | None = None
        self.epoch_offset_s: float | None = None
        self.reboots = 0
        self.pending: list[Sample] = []
        self._offset_exact = False
        self._first_epoch_boot_s: float | None = None
        self._wraps = 0
        self._last_ms_raw: int | None = None
        self._stream_t: dict[Any, float] = {}
        self._backjump_s = config.reboot_backjump_s
        self._system_time_wait_s = config.system_time_wait_s

    def reset(self) -> None:
        """Forget everything about the clock (after a reboot)."""
        self._wraps = 0
        self._last_ms_raw = None
        self._stream_t.clear()
        self.epoch_offset_s = None
        self._offset_exact = False
        self._first_epoch_boot_s = None
        self.last_t_s = None

    def now(self) -> float:
        """The latest boot-clock time; rejects ``no_time_yet`` before there is one."""
        t = self.last_t_s
        if t is None:
            raise Rejected("no_time_yet")
        return t

    def boot_time(
        self, t_s: float, stream: Any, t_rx_s: float, t_after_reboot_s: float | None = None
    ) -> float:
        """Register a boot-clock time on ``stream``; detects reboots and backward steps.

        ``t_after_reboot_s`` is the message's time on a freshly reset clock (it
        differs from ``t_s`` only for wrapped ``time_boot_ms``).
        """
        last = self.last_t_s
        if last is not None and t_s < last - self._backjump_s:
            if t_after_reboot_s is not None:
                t_s = t_after_reboot_s
            self._reboot(last, t_s, t_rx_s)
            last = None
        stream_t = self._stream_t
        if t_s < stream_t.get(stream, _NO_TIME):
            raise Rejected("time_backwards")
        stream_t[stream] = t_s
        if last is None or t_s > last:
            self.last_t_s = t_s
        return t_s

    def _reboot(self, last_t_s: float, t_s: float, t_rx_s: float) -> None:
        """The boot clock restarted: reset the clock state and queue the RebootEvent."""
        self.reboots += 1
        logger.warning(
            "autopilot reboot detected: boot clock went from %.3f s to %.3f s", last_t_s, t_s
        )
        self.reset()
        self.pending.append(RebootEvent(t_s=t_s, t_rx_s=t_rx_s, previous_t_s=last_t_s))

    def time_ms(self, raw_ms: int, stream: Any, t_rx_s: float) -> float:
        """Map a ``time_boot_ms`` onto the boot clock (unwrapping the uint32)."""
        last_raw = self._last_ms_raw
        wraps = self._wraps
        if last_raw is not None and WRAP_WINDOW_MS <= raw_ms <= _WRAP_HI_MS:
            # the common case, far from a wrap: the general steps below with nothing to do
            t_s = (raw_ms + wraps * UINT32_WRAP_MS) / _MS_PER_S
            t_s = self.boot_time(t_s, stream, t_rx_s, raw_ms / _MS_PER_S)
            self._last_ms_raw = raw_ms  # (a reboot inside reset the wraps to 0 already)
            return t_s
        straggler = False
        if last_raw is not None:
            if last_raw > _WRAP_HI_MS and raw_ms < WRAP_WINDOW_MS:
                wraps += 1  # the uint32 wrapped
            elif raw_ms > _WRAP_HI_MS and last_raw < WRAP_WINDOW_MS and wraps > 0:
                wraps -= 1  # a late message from before the wrap
                straggler = True
        t_s = (raw_ms + wraps * UINT32_WRAP_MS) / _MS_PER_S
        t_s = self.boot_time(t_s, stream, t_rx_s, raw_ms / _MS_PER_S)
        if self._last_ms_raw is None:  # first, or just reset by a reboot
            self._wraps = 0
            self._last_ms_raw = raw_ms
        elif not straggler:
            self._wraps = wraps
            self._last_ms_raw = raw_ms
        return t_s

    def time_us(self, raw_us: int, stream: Any, t_rx_s: float, clock: bool = True) -> float:
        """Map a ``time_usec`` onto the boot clock.

        ``clock=False`` (GNSS fix times) never detects a reboot: a GNSS stamp is
        the time of the last fix, which stays put while the receiver has no fix
        and would otherwise look like the boot clock jumping back.
        """
        if raw_us > _EPOCH_USEC:
            epoch_s = raw_us / _US_PER_S
            off = self.epoch_offset_s
            if not self._offset_exact or off is None:
                last = self.last_t_s
                if last is None:
                    raise Rejected("no_time_yet")
                if self._first_epoch_boot_s is None:
                    self._first_epoch_boot_s = last
                if last - self._first_epoch_boot_s < self._system_time_wait_s:
                    raise Rejected("awaiting_system_time")
                d = epoch_s - last
                if off is None or d > off:
                    self.epoch_offset_s = off = d
            t_s = epoch_s - off
            if t_s < self._stream_t.get(stream, _NO_TIME):
                raise Rejected("time_backwards")
            self._stream_t[stream] = t_s
            return t_s
        if raw_us == 0:
            return self.now()
        t_s = raw_us / _US_PER_S
        if clock:
            return self.boot_time(t_s, stream, t_rx_s)
        if t_s < self._stream_t.get(stream, _NO_TIME):
            raise Rejected("time_backwards")
        self._stream_t[stream] = t_s
        if self.last_t_s is None or t_s > self.last_t_s:
            self.last_t_s = t_s
        return t_s

    def system_time(self, msg: Any, t_rx_s: float) -> None:
        """SYSTEM_TIME: when the autopilot has UNIX time, the exact epoch-to-boot offset."""
        if msg.time_unix_usec > units.EPOCH_USEC_THRESHOLD:
            # the pair gives the offset; the boot clock itself is left to the "now" streams
            t_boot_s = (msg.time_boot_ms + self._wraps * UINT32_WRAP_MS) / units.MS_PER_S
            self.epoch_offset_s = msg.time_unix_usec / units.US_PER_S - t_boot_s
            self._offset_exact = True
        return None

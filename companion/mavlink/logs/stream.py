"""What the autopilot-log readers share: events in log order, made into MAVLink messages.

A reader of a DataFlash ``.bin`` or a PX4 ``.ulg`` turns the log's records into
:class:`Event` s (a boot-clock time and the arguments of a MAVLink message), the
same streams a telemetry log of the flight holds, and :class:`LogStream` hands
them out as ``(t_rx_s, message)``, as :class:`~companion.mavlink.tlog.TlogReader`
does: each message is packed (system 1, component 1, MAVLink 2) and decoded back
with the tlog reader's decoder, so that the pipeline sees the very values a
telemetry log would carry (float32 fields, integer scalings) and the decoder
validates and counts them unchanged. The receive time is the log's UNIX time
(the boot time plus the log's UTC offset).

Streams (the conventions of a telemetry log):

* ``HIGHRES_IMU`` every sample of the primary IMU (m/s², rad/s; the latest
  magnetometer and barometer beside it), ``SCALED_IMU`` the same samples
  decimated to at most 50 Hz (mG, mrad/s);
* ``ATTITUDE`` the autopilot's attitude, its rates the latest gyro sample;
* ``GPS_RAW_INT`` / ``GPS2_RAW`` every GNSS sample as logged (no-fix samples too);
* ``GLOBAL_POSITION_INT`` the autopilot's own position estimate;
* ``HEARTBEAT`` and ``SYSTEM_TIME`` once a second of boot time;
* ``GNSS_INTEGRITY`` the receiver's own jamming and spoofing flags, where a PX4 log has
  them (packed with the ``all`` dialect, which carries ArduPilot's messages and this one
  of the development set).

A value a message field cannot hold (not finite where an integer goes, or beyond the
field's range) drops that message, counted ``bad_value`` in :attr:`LogStream.stats`.
"""

from __future__ import annotations

import collections
import logging
import math
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

from companion.mavlink.decode import LIGHT_MESSAGE_IDS
from companion.mavlink.dialect import load_dialect
from companion.mavlink.messages import FastDecoder
from companion.mavlink.units import US_PER_S

_US_PER_S_INT = int(US_PER_S)

logger = logging.getLogger(__name__)

LOG_SYSTEM_ID = 1
LOG_COMPONENT_ID = 1
"""The autopilot's identity in the messages made from a log (a log names neither)."""

SCALED_IMU_MIN_INTERVAL_US = 18_000
"""SCALED_IMU is written when at least this long (µs) after the previous one: ≤ 50 Hz
(0.9 of the 20 ms period, so that a 50 Hz IMU's jitter keeps every sample)."""

HIGHRES_ACC_GYRO = 0b111111
HIGHRES_MAG = 0b111 << 6
HIGHRES_ABS_PRESSURE = 1 << 9
HIGHRES_PRESSURE_ALT = 1 << 11
HIGHRES_TEMPERATURE = 1 << 12
"""HIGHRES_IMU ``fields_updated`` bits."""

UINT16_UNKNOWN = 65535
MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = 1
MAV_MODE_FLAG_SAFETY_ARMED = 128
MAV_STATE_STANDBY = 3
MAV_STATE_ACTIVE = 4
G0_MPS2 = 9.80665
"""Standard gravity: SCALED_IMU's milli-g."""


_TIE_RANK = {
    name: rank
    for rank, name in enumerate(
        ("heartbeat", "system_time", "highres_imu", "scaled_imu", "gps_raw_int", "gps2_raw",
         "attitude", "global_position_int")
    )
}  # fmt: skip
"""Order of the streams at the same time: the heartbeat first, the IMU sample before
the attitude made with it, the estimates last."""


@dataclass(slots=True)
class Event:
    """One message to make: at ``t_us`` of the boot clock, ``name`` with ``args``
    (the arguments of pymavlink's ``<name>_encode``, in order). ``order`` breaks ties
    of time (the log's own order)."""

    t_us: int
    order: int
    name: str
    args: list[Any]


def to_int(value: float, scale: float = 1.0) -> int:
    """``round(value * scale)``; ValueError when it is not finite."""
    scaled = value * scale
    if not math.isfinite(scaled):
        raise ValueError("not finite")
    return int(round(scaled))


def _int16(value: float, scale: float) -> int:
    """SCALED_IMU's int16 fields saturate, as the autopilot's own message does."""
    return max(-32768, min(32767, to_int(value, scale)))


def wrap_cdeg(deg: float) -> int:
    """An angle in degrees as centidegrees in [0, 36000)."""
    return to_int(deg % 360.0, 100.0) % 36000


def wrap_pi(rad: float) -> float:
    """An angle wrapped to [-pi, pi)."""
    return (rad + math.pi) % (2.0 * math.pi) - math.pi


class ImuStreams:
    """HIGHRES_IMU for every IMU sample and SCALED_IMU at most at 50 Hz, with the
    latest magnetometer (gauss) and barometer (hPa, m, °C) beside them."""

    def __init__(self) -> None:
        self.mag_gauss: tuple[float, float, float] | None = None
        self.baro: tuple[float, float, float] | None = None
        """abs_pressure hPa, pressure_alt m, temperature °C."""
        self.gyro_radps = (0.0, 0.0, 0.0)
        self._last_scaled_us: int | None = None

    def events(
        self,
        t_us: int,
        order: int,
        acc_mps2: tuple[float, float, float],
        gyro_radps: tuple[float, float, float],
        temperature_c: float | None,
    ) -> list[Event]:
        """The HIGHRES_IMU (and, when due, SCALED_IMU) of one IMU sample."""
        self.gyro_radps = gyro_radps
        fields = HIGHRES_ACC_GYRO
        mag = (0.0, 0.0, 0.0)
        if self.mag_gauss is not None:
            mag = self.mag_gauss
            fields |= HIGHRES_MAG
        press_hpa = alt_m = 0.0
        if self.baro is not None:
            press_hpa, alt_m, baro_temp = self.baro
            fields |= HIGHRES_ABS_PRESSURE | HIGHRES_PRESSURE_ALT
            if temperature_c is None:
                temperature_c = baro_temp
        temp = 0.0
        if temperature_c is not None:
            temp = temperature_c
            fields |= HIGHRES_TEMPERATURE
        out = [
            Event(
                t_us, order, "highres_imu",
                [t_us, *acc_mps2, *gyro_radps, *mag, press_hpa, 0.0, alt_m, temp, fields, 0],
            )
        ]  # fmt: skip
        last = self._last_scaled_us
        if last is None or t_us - last >= SCALED_IMU_MIN_INTERVAL_US or t_us < last:
            self._last_scaled_us = t_us
            k_acc = 1000.0 / G0_MPS2
            out.append(
                Event(
                    t_us, order, "scaled_imu",
                    [
                        to_int(t_us / 1000.0),
                        *(_int16(a, k_acc) for a in acc_mps2),
                        *(_int16(g, 1000.0) for g in gyro_radps),
                        *(_int16(m, 1000.0) for m in mag),
                        _int16(temp, 100.0),
                    ],
                )
            )  # fmt: skip
        return out


def heartbeat_events(
    first_us: int,
    last_us: int,
    status: list[tuple[int, bool, int]],
    mav_type: int,
    autopilot: int,
) -> list[Event]:
    """HEARTBEAT and SYSTEM_TIME (its UTC filled by :class:`LogStream`) at every whole
    second of boot time from the first event to the last, with the vehicle's state
    then: ``status`` is ``(t_us, armed, custom_mode)`` in time order."""
    out: list[Event] = []
    t_us = -(-first_us // _US_PER_S_INT) * _US_PER_S_INT
    k = 0
    armed, mode = False, 0
    while t_us <= last_us:
        while k < len(status) and status[k][0] <= t_us:
            _, armed, mode = status[k]
            k += 1
        base = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
        state = MAV_STATE_ACTIVE if armed else MAV_STATE_STANDBY
        out.append(Event(t_us, -1, "heartbeat", [mav_type, autopilot, base, mode, state, 3]))
        out.append(Event(t_us, -1, "system_time", [0, t_us // 1000]))
        t_us += _US_PER_S_INT
    return out


class LogStream:
    """Iterate ``(t_rx_s, message)`` over events made into MAVLink messages.

    Parameters
    ----------
    events
        Every event of the log (sorted here by time, ties in the log's order).
    utc_offset_us
        UNIX time minus boot time, µs (the receive time is boot time plus it).
    stats
        The reader's counts so far (what it skipped in the log); ``bad_value`` is added.
    stats_prefix
        The format's name, for the counts among the replay's rejections.
    what
        What the file is ("an ArduPilot DataFlash log (.bin)").
    light_ids
        As :class:`~companion.mavlink.tlog.TlogReader`'s.
    """

    def __init__(
        self,
        events: list[Event],
        utc_offset_us: int,
        stats: collections.Counter[str],
        light_ids: frozenset[int] = LIGHT_MESSAGE_IDS,
        stats_prefix: str = "log_",
        what: str = "an autopilot log",
    ) -> None:
        events.sort(key=lambda e: (e.t_us, _TIE_RANK.get(e.name, len(_TIE_RANK)), e.order))
        self._events = events
        self.utc_offset_us = utc_offset_us
        self.stats = stats
        self.messages = 0
        # "all": ArduPilot's messages and the development set's (GNSS_INTEGRITY from a
        # PX4 log), the same definitions of every message they share
        self._mod = load_dialect("all")
        self._light_ids = light_ids
        self.stats_prefix = stats_prefix
        self.what = what
        """What the file is, for the error when it holds nothing the replay uses."""
        """How the replay names these counts among its rejections (``dataflash_``...)."""

    def __len__(self) -> int:
        return len(self._events)

    def __iter__(self) -> Iterator[tuple[float, Any]]:
        mod = self._mod
        mav = mod.MAVLink(None, srcSystem=LOG_SYSTEM_ID, srcComponent=LOG_COMPONENT_ID)
        fast = FastDecoder(mod, self._light_ids)
        decode = fast.light_at if self._light_ids else fast.message_at
        offset = self.utc_offset_us
        encoders: dict[str, Any] = {}
        for ev in self._events:
            if ev.name == "system_time":
                ev.args[0] = ev.t_us + offset
            encode = encoders.get(ev.name)
            if encode is None:
                encode = encoders[ev.name] = getattr(mav, ev.name + "_encode")
            try:
                frame = bytearray(encode(*ev.args).pack(mav))
            except (struct.error, ValueError, TypeError, OverflowError):
                self.stats["bad_value"] += 1
                continue
            mav.seq = (mav.seq + 1) % 256
            msg = decode(frame, 0)
            if msg is None:  # no fast path for it: pymavlink's own decoding
                msg = mav.decode(frame)
            t_rx_us = ev.t_us + offset
            if t_rx_us < 0:
                self.stats["bad_time"] += 1
                continue
            self.messages += 1
            yield t_rx_us / US_PER_S, msg
        if any(self.stats.values()) and self.messages:  # with none, the caller says
            logger.info("log: %d messages; skipped %s", self.messages, dict(self.stats))

"""Asking the autopilot for the streams we need, and checking what we get.

:func:`stream_requests` builds one ``COMMAND_LONG MAV_CMD_SET_MESSAGE_INTERVAL``
per message (param1 = message id, param2 = interval in microseconds, -1 to
stop the message when its rate is 0) and, for unknown autopilots only,
``REQUEST_DATA_STREAM`` fallbacks for firmware older than SET_MESSAGE_INTERVAL
support: a group request raises every message of the group, also those nobody asked
for, so ArduPilot (which has taken SET_MESSAGE_INTERVAL for years) and PX4 (which
ignores groups) get none. The data-stream groups follow ArduPilot's; a group's rate is
the highest requested rate of its members, rounded up to whole Hz.

:func:`select_streams` turns the configured rates into what an autopilot can honour:
one IMU stream (ArduPilot RAW_IMU, PX4 HIGHRES_IMU, at the highest IMU rate asked
for; the decoder uses one anyway) and no rate above the autopilot's loop rate
(ArduPlane's 50 Hz loop delivers ~40 Hz of a 50 Hz request and refuses faster).

:class:`RateMonitor` measures the received rate of each requested message over
a sliding window and reports those below ``min_fraction`` (70 %) of the
requested rate — e.g. ArduPlane's default 1 Hz RAW_IMU when 50 Hz was asked.
"""

from __future__ import annotations

import collections
import math
from collections.abc import Mapping
from typing import Any

from companion.mavlink.dialect import load_dialect
from companion.mavlink.ids import (
    MAV_CMD_SET_MESSAGE_INTERVAL,
    MAV_DATA_STREAM_EXTENDED_STATUS,
    MAV_DATA_STREAM_EXTRA1,
    MAV_DATA_STREAM_EXTRA2,
    MAV_DATA_STREAM_EXTRA3,
    MAV_DATA_STREAM_POSITION,
    MAV_DATA_STREAM_RAW_SENSORS,
)
from companion.mavlink.units import US_PER_S
from companion.types import AutopilotFlavour

DATA_STREAM_OF: dict[str, int] = {
    "RAW_IMU": MAV_DATA_STREAM_RAW_SENSORS,
    "SCALED_IMU2": MAV_DATA_STREAM_RAW_SENSORS,
    "SCALED_IMU3": MAV_DATA_STREAM_RAW_SENSORS,
    "GPS_RAW_INT": MAV_DATA_STREAM_EXTENDED_STATUS,
    "GPS_RTK": MAV_DATA_STREAM_EXTENDED_STATUS,
    "GPS2_RAW": MAV_DATA_STREAM_EXTENDED_STATUS,
    "GPS2_RTK": MAV_DATA_STREAM_EXTENDED_STATUS,
    "GLOBAL_POSITION_INT": MAV_DATA_STREAM_POSITION,
    "ATTITUDE": MAV_DATA_STREAM_EXTRA1,
    "VFR_HUD": MAV_DATA_STREAM_EXTRA2,
    "EXTENDED_SYS_STATE": MAV_DATA_STREAM_EXTRA3,
}
"""ArduPilot's REQUEST_DATA_STREAM group of each message we use."""


IMU_STREAMS = ("HIGHRES_IMU", "RAW_IMU", "SCALED_IMU", "SCALED_IMU2", "SCALED_IMU3")
"""The IMU messages; one of them is requested."""
IMU_STREAM_OF: dict[AutopilotFlavour, str] = {
    AutopilotFlavour.ARDUPILOT: "RAW_IMU",
    AutopilotFlavour.PX4: "HIGHRES_IMU",
}
"""The IMU message each autopilot sends best (ArduPilot: its primary IMU, unscaled)."""


def select_streams(
    flavour: AutopilotFlavour, rates_hz: Mapping[str, float], max_rate_hz: float | None = None
) -> dict[str, float]:
    """The rates to request of ``flavour`` from the configured ``rates_hz``: one IMU
    stream (:data:`IMU_STREAM_OF`, all of them for an unknown autopilot) at the highest
    configured IMU rate, every rate capped at ``max_rate_hz`` (the autopilot's loop
    rate, when known). Messages configured at 0 are left out (left alone)."""
    out: dict[str, float] = {}
    imu = IMU_STREAM_OF.get(flavour)
    imu_rate = max((rates_hz.get(n, 0.0) for n in IMU_STREAMS), default=0.0)
    for name, rate in rates_hz.items():
        if rate <= 0.0:
            continue
        if imu is not None and name in IMU_STREAMS:
            if name != imu:
                continue
            rate = imu_rate
        if max_rate_hz is not None and max_rate_hz > 0.0:
            rate = min(rate, max_rate_hz)
        out[name] = rate
    if imu is not None and imu_rate > 0.0 and imu not in out:
        out[imu] = imu_rate if max_rate_hz is None else min(imu_rate, max_rate_hz)
    return out


def _message_ids(dialect: str) -> dict[str, int]:
    mod = load_dialect(dialect)
    return {cls.msgname: msg_id for msg_id, cls in mod.mavlink_map.items()}


def stream_requests(
    target_system: int,
    target_component: int,
    flavour: AutopilotFlavour,
    rates_hz: Mapping[str, float],
    dialect: str = "ardupilotmega",
) -> list[Any]:
    """Messages that ask the autopilot for ``rates_hz`` (message name -> Hz).

    Parameters
    ----------
    target_system, target_component
        The autopilot.
    flavour
        ArduPilot / unknown also get REQUEST_DATA_STREAM fallbacks; PX4 does not.
    rates_hz
        Requested rate of each message by MAVLink name, Hz (0 stops it).
    dialect
        pymavlink dialect that names the messages.

    Returns
    -------
    list
        SET_MESSAGE_INTERVAL COMMAND_LONGs in the order of ``rates_hz``, then
        REQUEST_DATA_STREAMs in ascending stream id.

    Raises
    ------
    ValueError
        On an unknown message name or a negative or non-finite rate.
    """
    mod = load_dialect(dialect)
    ids = _message_ids(dialect)
    out: list[Any] = []
    groups: dict[int, float] = {}
    for name, rate in rates_hz.items():
        if name not in ids:
            raise ValueError(f"unknown MAVLink message {name!r}")
        if not (math.isfinite(rate) and rate >= 0.0):
            raise ValueError(f"rate for {name} must be finite and >= 0, got {rate!r}")
        interval_us = -1.0 if rate == 0.0 else float(round(US_PER_S / rate))
        out.append(
            mod.MAVLink_command_long_message(
                target_system,
                target_component,
                MAV_CMD_SET_MESSAGE_INTERVAL,
                0,
                float(ids[name]),
                interval_us,
                0.0,
                0.0,
                0.0,
                0.0,
                0.0,
            )
        )
        group = DATA_STREAM_OF.get(name)
        if group is not None:
            groups[group] = max(groups.get(group, 0.0), rate)
    if flavour == AutopilotFlavour.UNKNOWN:
        for group in sorted(groups):
            rate = groups[group]
            out.append(
                mod.MAVLink_request_data_stream_message(
                    target_system,
                    target_component,
                    group,
                    int(math.ceil(rate)),
                    1 if rate > 0.0 else 0,
                )
            )
    return out


class RateMonitor:
    """Measured vs requested message rates over a sliding window.

    Parameters
    ----------
    rates_hz
        Requested rate of each message name, Hz (0 = not monitored).
    window_s
        Length of the measurement window, s.
    min_fraction
        A stream is short when its measured rate is below this fraction of the request.
    """

    def __init__(
        self, rates_hz: Mapping[str, float], window_s: float = 5.0, min_fraction: float = 0.7
    ) -> None:
        if not window_s > 0.0:
            raise ValueError("window_s must be > 0")
        if not 0.0 < min_fraction <= 1.0:
            raise ValueError("min_fraction must be in (0, 1]")
        self.rates_hz = {k: float(v) for k, v in rates_hz.items() if v > 0.0}
        self.window_s = float(window_s)
        self.min_fraction = float(min_fraction)
        self._times: dict[str, collections.deque[float]] = {
            k: collections.deque() for k in self.rates_hz
        }
        self._queue_of: dict[str, collections.deque[float] | None] = dict(self._times)
        """Any name seen -> its window (pymavlink class names too), None if not monitored."""
        self._start_s: float | None = None

    def reset(self, t_s: float | None = None) -> None:
        """Forget all observations (after a reboot or a new request); optionally restart at t_s."""
        for q in self._times.values():
            q.clear()
        self._start_s = t_s

    def observe(self, msg_type: str, t_s: float) -> None:
        """Record one received ``msg_type`` at ``t_s`` (s, any monotonic clock).

        ``msg_type`` is the MAVLink name (``msg.get_type()``, e.g. ``RAW_IMU``);
        a pymavlink class name (``MAVLink_raw_imu_message``) is accepted too.
        """
        if self._start_s is None:
            self._start_s = t_s
        try:
            q = self._queue_of[msg_type]
        except KeyError:
            q = self._queue_of[msg_type] = self._window_of(msg_type)
        if q is None:
            return
        q.append(t_s)
        lo = t_s - self.window_s
        while q and q[0] < lo:
            q.popleft()

    def _window_of(self, msg_type: str) -> collections.deque[float] | None:
        """The window of a MAVLink name or pymavlink class name; None if not monitored."""
        q = self._times.get(msg_type)
        if q is None and msg_type.startswith("MAVLink_"):
            q = self._times.get(msg_type[8:].removesuffix("_message").upper())
        return q

    def measured_hz(self, msg_type: str, t_s: float) -> float:
        """Rate of ``msg_type`` over the window ending at ``t_s``, Hz."""
        q = self._times.get(msg_type)
        if q is None:
            return 0.0
        lo = t_s - self.window_s
        n = sum(1 for t in q if lo < t <= t_s)
        return n / self.window_s

    def shortfalls(self, t_s: float) -> list[str]:
        """Warnings for the streams below ``min_fraction`` of their request at ``t_s``.

        Nothing is reported before one full window has been observed.
        """
        if self._start_s is None or t_s - self._start_s < self.window_s:
            return []
        out = []
        for name, want in self.rates_hz.items():
            got = self.measured_hz(name, t_s)
            if got < self.min_fraction * want:
                out.append(f"{name} at {got:.1f} Hz, requested {want:g} Hz")
        return out

"""The autopilot's own parameters the service adapts to, read over the parameter protocol.

ArduPilot: which GPS instance takes MAVLink GPS_INPUT (``GPS1_TYPE``/``GPS2_TYPE``, or
``GPS_TYPE`` before 4.6, equal to 14, MAV: AP_GPS_MAV.cpp takes a GPS_INPUT only when
its ``gps_id`` is that instance), each instance's lag (``GPS1_DELAY_MS``/
``GPS2_DELAY_MS``, ``GPS_DELAY_MS``/``GPS_DELAY_MS2`` before 4.6: the time from a fix's
validity to its arrival; 0 means the driver's default, not known here), the loop
rate (``SCHED_LOOP_RATE``: no stream goes faster) and the first receiver's fix period
(``GPS1_RATE_MS``, ``GPS_RATE_MS`` before 4.6: no more distinct fixes than that, however
often GPS_RAW_INT is sent).

:class:`AutopilotParams` asks for each name by PARAM_REQUEST_READ (again every
``retry_s`` of autopilot time, ``max_tries`` times: a name the firmware does not have
is never answered) and keeps the values of the PARAM_VALUEs that come back from the
autopilot, whoever asked (a ground station's parameter download counts too). The
derived settings are properties: None while unknown.
"""

from __future__ import annotations

import math
from typing import Any

from companion.mavlink.dialect import load_dialect

GPS_TYPE_MAV = 14
"""ArduPilot GPSn_TYPE of a GPS instance fed by MAVLink GPS_INPUT."""

ARDUPILOT_NAMES: tuple[str, ...] = (
    "GPS1_TYPE",
    "GPS2_TYPE",
    "GPS_TYPE",
    "GPS1_DELAY_MS",
    "GPS2_DELAY_MS",
    "GPS_DELAY_MS",
    "GPS_DELAY_MS2",
    "SCHED_LOOP_RATE",
    "GPS1_RATE_MS",
    "GPS_RATE_MS",
)
_TYPE_NAMES = (("GPS1_TYPE", "GPS_TYPE"), ("GPS2_TYPE",))
"""Per GPS instance, the names of its type (new name first)."""
_DELAY_NAMES = (("GPS1_DELAY_MS", "GPS_DELAY_MS"), ("GPS2_DELAY_MS", "GPS_DELAY_MS2"))
_RATE_NAMES = ("GPS1_RATE_MS", "GPS_RATE_MS")


class AutopilotParams:
    """Requests for and values of the autopilot's parameters in :data:`ARDUPILOT_NAMES`.

    Parameters
    ----------
    names
        Parameter names to read.
    retry_s, max_tries
        A name without an answer is asked again after ``retry_s`` (autopilot time, s),
        at most ``max_tries`` times in all.
    """

    def __init__(
        self, names: tuple[str, ...] = ARDUPILOT_NAMES, retry_s: float = 5.0, max_tries: int = 3
    ) -> None:
        self.names = names
        self.retry_s = retry_s
        self.max_tries = max_tries
        self.values: dict[str, float] = {}
        self._tries: dict[str, int] = {}
        self._next_s: float | None = None

    def reset(self) -> None:
        """The autopilot rebooted: its parameters may have changed; ask again."""
        self.values.clear()
        self._tries.clear()
        self._next_s = None

    @property
    def next_s(self) -> float:
        """When :meth:`requests` next has something to send (autopilot time, s)."""
        return -math.inf if self._next_s is None else self._next_s

    def requests(self, t_s: float, target: tuple[int, int], dialect: str) -> list[Any]:
        """The PARAM_REQUEST_READs due at ``t_s`` (autopilot time, s)."""
        if self._next_s is not None and t_s < self._next_s:
            return []
        mod = load_dialect(dialect)
        out = []
        for name in self.names:
            if name in self.values or self._tries.get(name, 0) >= self.max_tries:
                continue
            self._tries[name] = self._tries.get(name, 0) + 1
            out.append(
                mod.MAVLink_param_request_read_message(target[0], target[1], name.encode(), -1)
            )
        self._next_s = t_s + self.retry_s if out else math.inf
        return out

    def on_value(self, name: str, value: float) -> bool:
        """A PARAM_VALUE from the autopilot; True when it is one of ours and changed."""
        if name not in self.names or not math.isfinite(value):
            return False
        changed = self.values.get(name) != value
        self.values[name] = value
        return changed

    def _first(self, names: tuple[str, ...]) -> float | None:
        for name in names:
            if name in self.values:
                return self.values[name]
        return None

    @property
    def mav_gps_instance(self) -> int | None:
        """The first GPS instance (0, 1) fed by GPS_INPUT (type 14); None if none is known."""
        for instance, names in enumerate(_TYPE_NAMES):
            if self._first(names) == GPS_TYPE_MAV:
                return instance
        return None

    @property
    def types_known(self) -> bool:
        """Every instance's type has been read (or given up on)."""
        return all(
            any(n in self.values for n in names)
            or all(self._tries.get(n, 0) >= self.max_tries for n in names)
            for names in _TYPE_NAMES
        )

    def gps_delay_s(self, instance: int) -> float | None:
        """The lag the autopilot is set to for GPS ``instance``, s; None when unknown or
        0 (the driver's default, which is not a parameter)."""
        if not 0 <= instance < len(_DELAY_NAMES):
            return None
        ms = self._first(_DELAY_NAMES[instance])
        return ms / 1000.0 if ms is not None and ms > 0 else None

    @property
    def loop_rate_hz(self) -> float | None:
        rate = self.values.get("SCHED_LOOP_RATE")
        return rate if rate is not None and rate > 0 else None

    @property
    def gnss_rate_hz(self) -> float | None:
        """The first GPS's fix rate (``GPS1_RATE_MS``), Hz; None when unknown."""
        ms = self._first(_RATE_NAMES)
        return 1000.0 / ms if ms is not None and ms > 0 else None

"""The published side of an evaluation: the service's solutions, accuracies, alerts and
named values over the flight, read back from the output tlog.

Each message is read with :mod:`companion.mavlink.readback`. Times:

* a solution is at ``GLOBAL_POSITION_INT.time_boot_ms / 1000`` (autopilot time of validity),
  made continuous across an autopilot reboot by the tlog time of the silence
  (:class:`_BootClock`), as the truth is on the first boot's clock;
* STATUSTEXT and GPS_INPUT carry no time: an alert's (or accuracy's) autopilot time is
  its tlog time minus the offset ``tlog_time - time_boot_ms/1000`` of the nearest
  *preceding* published GLOBAL_POSITION_INT in the log (the first one for records before
  any solution);
* a solution takes the latest accuracy at or before its time (GPS_INPUT, else
  ``CMP_HACC`` / ``CMP_VACC``), no older than :data:`ACCURACY_MAX_AGE_S`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from companion.evaluate.results import EvaluationError
from companion.mavlink.ids import MAV_COMP_ID_ONBOARD_COMPUTER
from companion.mavlink.readback import (
    PublishedFix,
    PublishedPosition,
    PublishedText,
    TextJoiner,
    from_service,
    parse_alert,
    read_message,
)
from companion.types import FloatArray, NamedValue

ACCURACY_MAX_AGE_S = 1.0
"""A published accuracy older than this no longer applies to a solution, s."""
REBOOT_STEP_S = 1.0
"""A published time going back by more than this is an autopilot reboot."""


@dataclass(frozen=True, slots=True, eq=False)
class Publications:
    """What the service published, solutions sorted by time: arrays of shape (n,) or (n, 3).

    ``alerts`` are ``(t_s, t_rx_s, code, rest, severity)`` sorted by autopilot time;
    ``named`` maps each NAMED_VALUE_FLOAT name to its ``(t_s, value)`` in log order.
    """

    t_s: FloatArray
    lat_rad: FloatArray
    lon_rad: FloatArray
    alt_msl_m: FloatArray
    vel_ned_mps: FloatArray  # (n, 3)
    yaw_rad: FloatArray  # NaN when unknown
    acc_h_m: FloatArray  # 1-sigma, NaN when none
    acc_v_m: FloatArray
    accuracy_source: str | None
    alerts: list[tuple[float, float, str, str, int]]  # (t_s, t_rx_s, code, rest, severity)
    named: dict[str, list[tuple[float, float]]]


def _nan_if_none(x: float | None) -> float:
    return math.nan if x is None else x


class _BootClock:
    """The autopilot's time made continuous across its reboots: when the published time
    goes back by more than :data:`REBOOT_STEP_S`, the new boot's times are moved on by
    the tlog time elapsed since the last publication before it (the truth stays on the
    first boot's clock)."""

    def __init__(self) -> None:
        self.offset_s = 0.0
        self._last: tuple[float, float] | None = None  # (continuous t_s, t_rx)

    def continuous(self, t_s: float, t_rx: float) -> float:
        if self._last is not None and t_s + self.offset_s < self._last[0] - REBOOT_STEP_S:
            self.offset_s = self._last[0] + max(t_rx - self._last[1], 0.0) - t_s
        t_c = t_s + self.offset_s
        self._last = (t_c, t_rx)
        return t_c


def extract_publications(records: Sequence[tuple[float, Any]], path: Path) -> Publications:
    """Pull the service's publications (component 191) out of the tlog records."""
    gpi_rows: list[tuple[float, ...]] = []
    gpi_stream_idx: list[int] = []
    gpi_offsets: list[float] = []
    gps_input: list[tuple[int, float, float, float]] = []  # (stream idx, t_rx, h, v)
    texts: list[tuple[int, float, str, int]] = []
    named: dict[str, list[tuple[float, float]]] = {}
    joiner = TextJoiner()
    boot = _BootClock()
    for k, (t_rx, msg) in enumerate(records):
        if not from_service(msg):
            continue
        item = read_message(msg)
        if isinstance(item, PublishedPosition):
            t_s = boot.continuous(item.t_s, t_rx)
            vn, ve, vd = item.vel_ned_mps
            yaw = _nan_if_none(item.yaw_rad)
            gpi_rows.append((t_s, item.lat_rad, item.lon_rad, item.alt_msl_m, vn, ve, vd, yaw))
            gpi_stream_idx.append(k)
            gpi_offsets.append(t_rx - t_s)
        elif isinstance(item, PublishedFix):
            gps_input.append((k, t_rx, _nan_if_none(item.h_acc_m), _nan_if_none(item.v_acc_m)))
        elif isinstance(item, PublishedText):
            done = joiner.add((k, t_rx), item)
            if done is not None:
                (k0, t0), text, sev = done
                texts.append((k0, t0, text, sev))
        elif isinstance(item, NamedValue):
            named.setdefault(item.name, []).append((boot.continuous(item.t_s, t_rx), item.value))
    for (k0, t0), text, sev in joiner.unfinished():
        texts.append((k0, t0, text, sev))
    if not gpi_rows:
        raise EvaluationError(
            f"{path}: no published solution (GLOBAL_POSITION_INT from component "
            f"{MAV_COMP_ID_ONBOARD_COMPUTER})"
        )
    gpi = np.asarray(gpi_rows, dtype=np.float64)
    idx_arr = np.asarray(gpi_stream_idx)
    off_arr = np.asarray(gpi_offsets)

    def to_autopilot_time(stream_idx: int, t_rx: float) -> float:
        j = int(np.searchsorted(idx_arr, stream_idx, side="right")) - 1
        return t_rx - float(off_arr[max(j, 0)])

    alerts: list[tuple[float, float, str, str, int]] = []
    for k, t_rx, text, sev in sorted(texts):
        alert = parse_alert(text)
        if alert is None:
            continue
        code, rest = alert
        alerts.append((to_autopilot_time(k, t_rx), t_rx, code, rest, sev))
    alerts.sort(key=lambda a: a[0])

    order = np.argsort(gpi[:, 0], kind="stable")
    gpi = gpi[order]
    acc_h = np.full(gpi.shape[0], np.nan)
    acc_v = np.full(gpi.shape[0], np.nan)
    source: str | None = None
    if gps_input:
        t_acc = np.asarray([to_autopilot_time(k, t_rx) for k, t_rx, _, _ in gps_input])
        acc_h = hold(t_acc, np.asarray([g[2] for g in gps_input]), gpi[:, 0])
        acc_v = hold(t_acc, np.asarray([g[3] for g in gps_input]), gpi[:, 0])
        source = "GPS_INPUT"
    elif "CMP_HACC" in named:
        h_series = np.asarray(named["CMP_HACC"], dtype=np.float64)
        acc_h = hold(h_series[:, 0], h_series[:, 1], gpi[:, 0])
        if "CMP_VACC" in named:
            v_series = np.asarray(named["CMP_VACC"], dtype=np.float64)
            acc_v = hold(v_series[:, 0], v_series[:, 1], gpi[:, 0])
        source = "CMP_HACC"
    return Publications(
        t_s=gpi[:, 0],
        lat_rad=gpi[:, 1],
        lon_rad=gpi[:, 2],
        alt_msl_m=gpi[:, 3],
        vel_ned_mps=gpi[:, 4:7],
        yaw_rad=gpi[:, 7],
        acc_h_m=acc_h,
        acc_v_m=acc_v,
        accuracy_source=source,
        alerts=alerts,
        named=named,
    )


def hold(t_src: FloatArray, values: FloatArray, t_query: FloatArray) -> FloatArray:
    """Zero-order hold: latest value at or before each query time, NaN if older than allowed."""
    order = np.argsort(t_src, kind="stable")
    t_sorted = t_src[order]
    v_sorted = values[order]
    j = np.searchsorted(t_sorted, t_query, side="right") - 1
    out = np.full(t_query.shape, np.nan)
    ok = j >= 0
    jj = np.where(ok, j, 0)
    fresh = ok & (t_query - t_sorted[jj] <= ACCURACY_MAX_AGE_S)
    out[fresh] = v_sorted[jj[fresh]]
    return out

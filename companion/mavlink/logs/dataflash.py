"""ArduPilot DataFlash logs (.bin) read with pymavlink's DFReader, as MAVLink streams.

Records used (field names of both the older ``TimeMS`` and the newer ``TimeUS``
formats; instance 0 of multi-instance records):

* ``IMU`` (``IMU2`` when the log has no ``IMU``) -> HIGHRES_IMU, SCALED_IMU, with
  ``MAG`` (mGauss) and ``BARO`` (Pa, m) beside them;
* ``ATT`` (deg) -> ATTITUDE, its rates the latest IMU gyro;
* ``GPS`` -> GPS_RAW_INT, ``GPS2`` (or ``GPS`` instance 1) -> GPS2_RAW, their
  accuracies from ``GPA`` / ``GPA2`` when the log has them; the boot time of a
  GNSS sample is ``TimeUS`` or, in the older format whose ``TimeMS`` is GPS time
  of week, ``T``;
* ``POS`` or, without it, ``AHR2`` (only where it has a position) ->
  GLOBAL_POSITION_INT, velocity from ``NKF1`` / ``XKF1`` / ``EKF1`` (core 0),
  relative altitude against the first 3D-fix GNSS altitude, heading from ``ATT``;
* ``MODE``, ``EV`` (armed 10, disarmed 11), ``ARM`` and the firmware ``MSG`` ->
  HEARTBEAT once a second.

The UTC offset is DFReader's (from the GNSS week and time of week); a log without
GNSS time gets boot time as its receive time. Corrupt regions DFReader skips are
counted ``bad_region``; a record whose values cannot be read, ``bad_record``.
"""

from __future__ import annotations

import bisect
import collections
import contextlib
import io
import math
import os
import re
import struct
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from companion.mavlink.logs.stream import (
    Event,
    ImuStreams,
    LogStream,
    heartbeat_events,
    to_int,
    wrap_cdeg,
    wrap_pi,
)

MAV_AUTOPILOT_ARDUPILOTMEGA = 3
_VEHICLE_TYPES = (
    ("Copter", 2),
    ("Plane", 1),
    ("Rover", 10),
    ("Sub", 12),
    ("Tracker", 5),
    ("Blimp", 7),
)
"""Firmware name in the log's MSG -> MAV_TYPE (a helicopter or a hexacopter logs as
Copter: quadrotor is said)."""
EV_ARMED = 10
EV_DISARMED = 11
WANTED = [
    "IMU", "IMU2", "MAG", "BARO", "ATT", "GPS", "GPS2", "GPA", "GPA2", "POS", "AHR2",
    "EKF1", "NKF1", "XKF1", "MODE", "EV", "ARM", "MSG",
]  # fmt: skip


WHAT = "an ArduPilot DataFlash log (.bin)"


class DataFlashError(Exception):
    """The file cannot be read as a DataFlash log at all."""


def _regions(offsets: list[str]) -> int:
    """Runs of consecutive byte offsets (the indexer says each bad byte)."""
    runs = 0
    previous = -2
    for text in offsets:
        at = int(text)
        if at != previous + 1:
            runs += 1
        previous = at
    return runs


@contextlib.contextmanager
def _fd2_captured() -> Iterator[io.StringIO]:
    """What is written to file descriptor 2 meanwhile (DFReader's native indexer writes
    there what it skips), kept rather than printed; read it after the block."""
    out = io.StringIO()
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):  # no descriptor 2 (an embedded interpreter): as it is
        yield out
        return
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield out
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            out.write(tmp.read().decode("utf-8", "replace"))
            out.seek(0)


def _boot_us(m: Any) -> int | None:
    """The boot time of a record, µs (None when it carries none)."""
    t = getattr(m, "TimeUS", None)
    if t is not None:
        return int(t)
    if m.get_type() in ("GPS", "GPS2"):
        t = getattr(m, "T", None)  # older format: TimeMS is GPS time of week
        return None if t is None else int(t) * 1000
    t = getattr(m, "TimeMS", None)
    return None if t is None else int(t) * 1000


def _instance(m: Any) -> int:
    i = getattr(m, "I", None)
    if i is None:
        i = getattr(m, "C", None)
    return int(i) if isinstance(i, (int, float)) else 0


def read_dataflash(path: Path | str, light_ids: frozenset[int] | None = None) -> LogStream:
    """The MAVLink streams of a DataFlash log (see the module's docstring).

    Raises
    ------
    DataFlashError
        When DFReader cannot open or parse the file at all.
    """
    from pymavlink import DFReader

    stats: collections.Counter[str] = collections.Counter()
    noise = io.StringIO()  # DFReader prints what it skips: counted, not printed
    with (
        _fd2_captured() as native,
        contextlib.redirect_stdout(noise),
        contextlib.redirect_stderr(noise),
    ):
        try:
            reader = DFReader.DFReader_binary(str(path), zero_time_base=False)
        except (OSError, ValueError, IndexError, KeyError, TypeError, struct.error) as exc:
            raise DataFlashError(f"{path}: not a readable DataFlash log: {exc}") from exc
    with contextlib.redirect_stdout(noise), contextlib.redirect_stderr(noise):
        events, offset_us = _events(reader, stats)
    said = noise.getvalue() + native.read()
    skipped = said.count("Skipped") + _regions(re.findall(r"bad header.* at (\d+)", said))
    if skipped:
        stats["bad_region"] += skipped
    if light_ids is None:
        return LogStream(events, offset_us, stats, stats_prefix="dataflash_", what=WHAT)
    return LogStream(events, offset_us, stats, light_ids, stats_prefix="dataflash_", what=WHAT)


def _events(reader: Any, stats: collections.Counter[str]) -> tuple[list[Event], int]:
    events: list[Event] = []
    imu = {"IMU": ImuStreams(), "IMU2": ImuStreams()}
    imu_events: dict[str, list[Event]] = {"IMU": [], "IMU2": []}
    gps_last: dict[int, Event] = {}
    positions: list[tuple[int, int, Any]] = []
    velocities: tuple[float, float, float] | None = None
    yaw_deg: float | None = None
    first_fix_alt_m: float | None = None
    status: list[tuple[int, bool, int]] = []
    armed, mode = False, 0
    mav_type = 0
    offset_us: int | None = None
    order = 0
    have_pos = False
    saw_arming = False
    last_t_us = 0
    attitudes: list[Event] = []
    while True:
        try:
            m = reader.recv_match(type=WANTED)
        except (ValueError, IndexError, KeyError, TypeError, UnicodeDecodeError):
            stats["bad_record"] += 1
            continue
        if m is None:
            break
        order += 1
        kind = m.get_type()
        try:
            if kind == "MSG":
                text = str(getattr(m, "Message", ""))
                for word, code in _VEHICLE_TYPES:
                    if word in text and mav_type == 0:
                        mav_type = code
                continue
            t_us = _boot_us(m)
            if t_us is None:
                if kind not in ("EV", "MODE"):
                    continue
                t_us = last_t_us  # an untimed event: when the latest timed record was
            else:
                last_t_us = max(last_t_us, t_us)
            if offset_us is None and kind not in ("EV", "MODE"):
                offset_us = int(round(m._timestamp * 1e6)) - t_us
            if kind in ("IMU", "IMU2"):
                if _instance(m) != 0:
                    continue
                streams = imu[kind]
                temp = getattr(m, "Temp", getattr(m, "T", None))
                imu_events[kind] += streams.events(
                    t_us, order,
                    (float(m.AccX), float(m.AccY), float(m.AccZ)),
                    (float(m.GyrX), float(m.GyrY), float(m.GyrZ)),
                    None if temp is None else float(temp),
                )  # fmt: skip
            elif kind == "MAG":
                if _instance(m) == 0:
                    mag = (m.MagX / 1000.0, m.MagY / 1000.0, m.MagZ / 1000.0)
                    for s in imu.values():
                        s.mag_gauss = mag
            elif kind == "BARO":
                if _instance(m) == 0:
                    baro = (m.Press / 100.0, float(m.Alt), float(m.Temp))
                    for s in imu.values():
                        s.baro = baro
            elif kind == "ATT":
                yaw_deg = float(m.Yaw)
                ev_att = Event(
                    t_us, order, "attitude",
                    [
                        to_int(t_us / 1000.0),
                        math.radians(m.Roll), math.radians(m.Pitch),
                        wrap_pi(math.radians(m.Yaw)), 0.0, 0.0, 0.0,
                    ],
                )  # fmt: skip
                events.append(ev_att)
                attitudes.append(ev_att)
            elif kind in ("GPS", "GPS2"):
                receiver = 1 if kind == "GPS2" else _instance(m)
                if receiver > 1:
                    continue
                fix = int(m.Status)
                if fix >= 3 and first_fix_alt_m is None:
                    first_fix_alt_m = float(m.Alt)
                args: list[Any] = [
                    t_us, fix, to_int(m.Lat, 1e7), to_int(m.Lng, 1e7), to_int(m.Alt, 1e3),
                    to_int(m.HDop, 100.0), to_int(getattr(m, "VDop", 655.35), 100.0),
                    to_int(m.Spd, 100.0), wrap_cdeg(m.GCrs), int(m.NSats),
                ]  # fmt: skip
                if receiver == 0:
                    ev = Event(t_us, order, "gps_raw_int", [*args, 0, 0, 0, 0, 0, 0])
                else:
                    ev = Event(t_us, order, "gps2_raw", [*args, 0, 0, 0, 0, 0, 0, 0, 0])
                events.append(ev)
                gps_last[receiver] = ev
            elif kind in ("GPA", "GPA2"):
                receiver = 1 if kind == "GPA2" else _instance(m)
                ev_gps = gps_last.get(receiver)
                if ev_gps is not None and abs(t_us - ev_gps.t_us) <= 250_000:
                    ev_gps.args[6] = to_int(m.VDop, 100.0)
                    base = 14 if ev_gps.name == "gps2_raw" else 11  # h_acc's index
                    ev_gps.args[base] = to_int(m.HAcc, 1e3)
                    ev_gps.args[base + 1] = to_int(m.VAcc, 1e3)
                    ev_gps.args[base + 2] = to_int(m.SAcc, 1e3)
            elif kind in ("EKF1", "NKF1", "XKF1"):
                if _instance(m) == 0:
                    velocities = (float(m.VN), float(m.VE), float(m.VD))
            elif kind in ("POS", "AHR2"):
                if kind == "POS":
                    have_pos = True
                if m.Lat == 0 and m.Lng == 0:
                    continue
                positions.append((t_us, order, (kind, m.Lat, m.Lng, m.Alt, velocities, yaw_deg)))
            elif kind == "MODE":
                mode = int(getattr(m, "ModeNum", m.Mode))
                status.append((t_us, armed, mode))
            elif kind == "ARM":
                armed = bool(m.ArmState)
                saw_arming = True
                status.append((t_us, armed, mode))
            elif kind == "EV":
                if m.Id in (EV_ARMED, EV_DISARMED):
                    armed = m.Id == EV_ARMED
                    saw_arming = True
                    status.append((t_us, armed, mode))
        except (ValueError, TypeError, AttributeError, OverflowError):
            stats["bad_record"] += 1
    # the primary IMU: IMU, or IMU2 in a log without IMU
    primary = imu_events["IMU"] if imu_events["IMU"] else imu_events["IMU2"]
    events += primary
    _attitude_rates(attitudes, [e for e in primary if e.name == "highres_imu"])
    want = "POS" if have_pos else "AHR2"
    for t_us, order_, (kind, lat, lon, alt, vel, yaw) in positions:
        if kind != want:
            continue
        vn, ve, vd = vel if vel is not None else (0.0, 0.0, 0.0)
        rel = 0 if first_fix_alt_m is None else to_int(alt - first_fix_alt_m, 1e3)
        try:
            events.append(
                Event(
                    t_us, order_, "global_position_int",
                    [
                        to_int(t_us / 1000.0), to_int(lat, 1e7), to_int(lon, 1e7),
                        to_int(alt, 1e3), rel, to_int(vn, 100.0), to_int(ve, 100.0),
                        to_int(vd, 100.0), 65535 if yaw is None else wrap_cdeg(yaw),
                    ],
                )
            )  # fmt: skip
        except ValueError:
            stats["bad_record"] += 1
    if not events:
        return events, offset_us or 0
    status.sort(key=lambda s: s[0])
    if not saw_arming:  # no arming records (ArduPlane 3.1 needs no arming): armed throughout
        status = [(t, True, mode_) for t, _, mode_ in status] or [(0, True, 0)]
    first = min(e.t_us for e in events)
    last = max(e.t_us for e in events)
    events += heartbeat_events(first, last, status, mav_type, MAV_AUTOPILOT_ARDUPILOTMEGA)
    return events, offset_us or 0


def _attitude_rates(attitudes: list[Event], imu: list[Event]) -> None:
    """ATTITUDE's rates: the gyro of the latest IMU sample at or before it (the IMU
    sample of the same time is logged after ATT)."""
    times = [e.t_us for e in imu]
    for ev in attitudes:
        k = bisect.bisect_right(times, ev.t_us) - 1
        if k >= 0:
            ev.args[4:7] = imu[k].args[4:7]

"""Truth and the autopilot's own solution from SITL's DataFlash log.

ArduPilot SITL logs the simulator's true state (``SIM``: Lat, Lng, Alt) and the
autopilot's AHRS/EKF3 position (``POS``) on its own clock (``TimeUS``), and every
parameter change (``PARM``): the service's outputs (GLOBAL_POSITION_INT ``time_boot_ms``,
the same clock) are scored against the truth interpolated to their time.
"""

from __future__ import annotations

import bisect
import statistics
from dataclasses import dataclass, field
from pathlib import Path

from pymavlink import DFReader, mavutil

from tests.sitl.harness import horizontal_m


@dataclass
class Track:
    """Positions on the autopilot's clock."""

    t_s: list[float] = field(default_factory=list)
    lat_deg: list[float] = field(default_factory=list)
    lon_deg: list[float] = field(default_factory=list)

    def append(self, t_s: float, lat: float, lon: float) -> None:
        self.t_s.append(t_s)
        self.lat_deg.append(lat)
        self.lon_deg.append(lon)

    def at(self, t_s: float) -> tuple[float, float] | None:
        """Linear interpolation at ``t_s`` (None outside the track or across a gap > 0.2 s)."""
        i = bisect.bisect_left(self.t_s, t_s)
        if i == 0 or i >= len(self.t_s):
            return None
        t0, t1 = self.t_s[i - 1], self.t_s[i]
        if t1 - t0 > 0.2:
            return None
        w = (t_s - t0) / (t1 - t0) if t1 > t0 else 0.0
        return (
            self.lat_deg[i - 1] + w * (self.lat_deg[i] - self.lat_deg[i - 1]),
            self.lon_deg[i - 1] + w * (self.lon_deg[i] - self.lon_deg[i - 1]),
        )


@dataclass
class SitlLog:
    truth: Track
    autopilot: Track
    params: list[tuple[float, str, float]]
    """(t_s, name, value) of each logged parameter change."""

    def errors(self, track: Track, t0: float, t1: float) -> list[float]:
        """Horizontal errors against the truth of the points of ``track`` in [t0, t1], m."""
        out = []
        for t, lat, lon in zip(track.t_s, track.lat_deg, track.lon_deg, strict=True):
            if t0 <= t <= t1:
                ref = self.truth.at(t)
                if ref is not None:
                    out.append(horizontal_m(ref[0], ref[1], lat, lon))
        return out

    def lag_s(self, fixes: Track, t0: float, t1: float) -> float | None:
        """The lag (s, 0 to 0.2 by 1 ms) that best places ``fixes`` (positions at their
        stamps) on the truth: the truth at ``stamp - lag`` nearest them on average."""
        best: tuple[float, float] | None = None
        for lag_ms in range(0, 201):
            lag = lag_ms / 1000.0
            err = [
                horizontal_m(ref[0], ref[1], lat, lon)
                for t, lat, lon in zip(fixes.t_s, fixes.lat_deg, fixes.lon_deg, strict=True)
                if t0 <= t <= t1 and (ref := self.truth.at(t - lag)) is not None
            ]
            if err and (best is None or statistics.fmean(err) < best[1]):
                best = (lag, statistics.fmean(err))
        return None if best is None else best[0]

    def param_changes(self, name: str) -> list[tuple[float, float]]:
        return [(t, v) for t, n, v in self.params if n == name]


def newest_log(workdir: Path) -> Path:
    logs = sorted((workdir / "logs").glob("*.BIN"), key=lambda p: p.stat().st_mtime)
    if not logs:
        raise FileNotFoundError(f"no DataFlash log in {workdir / 'logs'}")
    return logs[-1]


def read_gps_raw(tlog: Path) -> Track:
    """The distinct GPS_RAW_INT fixes the service received (its own recording), each at
    its ``time_usec`` (the autopilot's clock)."""
    conn = mavutil.mavlink_connection(str(tlog))
    track, seen = Track(), set()
    try:
        while (m := conn.recv_match(type="GPS_RAW_INT")) is not None:
            if m.fix_type >= 3 and m.time_usec not in seen:
                seen.add(m.time_usec)
                track.append(m.time_usec * 1e-6, m.lat * 1e-7, m.lon * 1e-7)
    finally:
        conn.close()
    return track


def read_gps_instance(path: Path, instance: int) -> Track:
    """The distinct 3-D fixes of the autopilot's GPS ``instance`` (0, 1) from its DataFlash
    ``GPS`` records, each at the time it was logged (just after the autopilot took it)."""
    reader = DFReader.DFReader_binary(str(path), zero_time_base=True)
    track, last = Track(), None
    while (m := reader.recv_match(type="GPS")) is not None:
        if m.I != instance or m.Status < 3:
            continue
        key = (m.GMS, m.Lat, m.Lng)
        if key != last:
            last = key
            track.append(m.TimeUS * 1e-6, m.Lat, m.Lng)
    return track


def read_log(path: Path) -> SitlLog:
    reader = DFReader.DFReader_binary(str(path), zero_time_base=True)
    truth, ap = Track(), Track()
    params: list[tuple[float, str, float]] = []
    while True:
        m = reader.recv_match(type=["SIM", "POS", "PARM"])
        if m is None:
            break
        t_s = m.TimeUS * 1e-6
        kind = m.get_type()
        if kind == "SIM":
            truth.append(t_s, m.Lat, m.Lng)
        elif kind == "POS":
            ap.append(t_s, m.Lat, m.Lng)
        else:
            params.append((t_s, m.Name, float(m.Value)))
    return SitlLog(truth, ap, params)

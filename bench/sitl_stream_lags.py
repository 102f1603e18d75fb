"""How late each stream the service reads is, against ArduPilot SITL's truth.

Reads a flight kept by the SITL runner (``python -m tests.sitl.ardupilot_runner flight
... --keep DIR``, run inside ``private-net`` like every SITL run): the truth from the
DataFlash log (``SIM``: position and attitude on the autopilot's clock), the streams from
the service's own recording (``companion-logs/*.tlog``). For each stream, over the
scoring window [T0, T1] (the result's ``healthy`` ``t0_s``/``t1_s``), the shift of its
stamps that best lays it on the truth (1 ms grid, 0.5 ms for the attitude):

* GPS_RAW_INT (distinct fixes at ``time_usec``), the autopilot's GLOBAL_POSITION_INT and
  DataFlash ``POS``, the service's GLOBAL_POSITION_INT: horizontal position;
* ATTITUDE: roll and pitch against the truth's;
* RAW_IMU: the gyro's x against the truth's roll rate (differenced ``SIM`` roll; pitch
  stays small in cruise).

A positive lag: the stream shows the truth of that long before its stamp.

Run: ``python bench/sitl_stream_lags.py DIR T0 T1``.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
from pymavlink import DFReader, mavutil

EARTH_RADIUS_M = 6378137.0


def _truth(binlog: Path) -> tuple[np.ndarray, np.ndarray]:
    """``SIM`` (t, lat, lon, roll, pitch) and ``POS`` (t, lat, lon) rows."""
    reader = DFReader.DFReader_binary(str(binlog), zero_time_base=True)
    sim, pos = [], []
    while (m := reader.recv_match(type=["SIM", "POS"])) is not None:
        if m.get_type() == "SIM":
            sim.append((m.TimeUS * 1e-6, m.Lat, m.Lng, m.Roll, m.Pitch))
        else:
            pos.append((m.TimeUS * 1e-6, m.Lat, m.Lng))
    return np.array(sim), np.array(pos)


def _streams(tlog: Path) -> dict[str, list[tuple[float, ...]]]:
    out: dict[str, list[tuple[float, ...]]] = {
        "GPS_RAW_INT": [],
        "GLOBAL_POSITION_INT (autopilot)": [],
        "GLOBAL_POSITION_INT (service)": [],
        "ATTITUDE": [],
        "RAW_IMU": [],
    }
    conn = mavutil.mavlink_connection(str(tlog))
    seen: set[int] = set()
    while (m := conn.recv_match()) is not None:
        kind, src = m.get_type(), (m.get_srcSystem(), m.get_srcComponent())
        if kind == "GPS_RAW_INT" and m.fix_type >= 3 and m.time_usec not in seen:
            seen.add(m.time_usec)
            out[kind].append((m.time_usec * 1e-6, m.lat * 1e-7, m.lon * 1e-7))
        elif kind == "GLOBAL_POSITION_INT":
            who = "autopilot" if src == (1, 1) else "service"
            row = (m.time_boot_ms * 1e-3, m.lat * 1e-7, m.lon * 1e-7)
            out[f"GLOBAL_POSITION_INT ({who})"].append(row)
        elif kind == "ATTITUDE" and src == (1, 1):
            out[kind].append((m.time_boot_ms * 1e-3, m.roll, m.pitch))
        elif kind == "RAW_IMU" and src == (1, 1):
            out[kind].append((m.time_usec * 1e-6, m.xgyro * 1e-3))
    conn.close()
    return out


def _best(lags: np.ndarray, cost: np.ndarray) -> float:
    return float(lags[int(np.argmin(cost))])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("dir", type=Path)
    p.add_argument("t0", type=float)
    p.add_argument("t1", type=float)
    args = p.parse_args()
    binlog = sorted((args.dir / "logs").glob("*.BIN"))[-1]
    tlog = sorted((args.dir / "companion-logs").glob("*.tlog"))[0]
    sim, pos = _truth(binlog)
    lat0, lon0 = sim[0, 1], sim[0, 2]
    coslat = math.cos(math.radians(lat0))

    def ne(lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
        return np.stack(
            [
                np.radians(lat - lat0) * EARTH_RADIUS_M,
                np.radians(lon - lon0) * EARTH_RADIUS_M * coslat,
            ],
            -1,
        )

    truth_ne = ne(sim[:, 1], sim[:, 2])

    def truth_at(t: np.ndarray) -> np.ndarray:
        return np.stack([np.interp(t, sim[:, 0], truth_ne[:, a]) for a in (0, 1)], -1)

    def window(rows: list[tuple[float, ...]] | np.ndarray) -> np.ndarray:
        a = np.array(rows)
        return a[(a[:, 0] >= args.t0) & (a[:, 0] <= args.t1)]

    streams = _streams(tlog)
    print(f"{'stream':34s} {'n':>6s} {'lag ms':>7s}  error at that lag / at 0")
    lags = np.arange(-0.1, 0.25, 0.001)
    positions = [(k, streams[k]) for k in streams if k in ("GPS_RAW_INT",) or "POSITION" in k]
    positions.insert(2, ("DataFlash POS (autopilot)", list(map(tuple, pos))))
    for name, rows in positions:
        a = window(rows)
        p_ne = ne(a[:, 1], a[:, 2])
        cost = np.array(
            [np.linalg.norm(p_ne - truth_at(a[:, 0] - lag), axis=1).mean() for lag in lags]
        )
        e0 = np.linalg.norm(p_ne - truth_at(a[:, 0]), axis=1).mean()
        print(
            f"{name:34s} {len(a):6d} {_best(lags, cost) * 1e3:7.1f}  "
            f"{cost.min():.3f} / {e0:.3f} m mean"
        )
    fine = np.arange(-0.1, 0.1, 0.0005)
    att = window(streams["ATTITUDE"])
    for col, name in ((1, "roll"), (2, "pitch")):
        deg = np.degrees(att[:, col])
        cost = np.array(
            [
                np.mean((deg - np.interp(att[:, 0] - lag, sim[:, 0], sim[:, 2 + col])) ** 2)
                for lag in fine
            ]
        )
        print(
            f"{'ATTITUDE ' + name:34s} {len(att):6d} {_best(fine, cost) * 1e3:7.1f}  "
            f"{math.sqrt(cost.min()):.3f} deg rms"
        )
    imu = window(streams["RAW_IMU"])
    t_mid = 0.5 * (sim[1:, 0] + sim[:-1, 0])
    roll_rate = np.diff(sim[:, 3]) / np.diff(sim[:, 0])
    gx = np.degrees(imu[:, 1])
    cost = np.array(
        [np.mean((gx - np.interp(imu[:, 0] - lag, t_mid, roll_rate)) ** 2) for lag in fine]
    )
    print(
        f"{'RAW_IMU gyro x (truth roll rate)':34s} {len(imu):6d} "
        f"{_best(fine, cost) * 1e3:7.1f}  {math.sqrt(cost.min()):.3f} deg/s rms"
    )


if __name__ == "__main__":
    main()

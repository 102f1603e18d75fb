"""Writing a simulated flight: the .tlog, the truth CSV and the JSON sidecar.

* .tlog: for each message an 8-byte big-endian uint64 of UNIX-epoch
  microseconds (the receive time), then the packed MAVLink 2 frame (system 1,
  component 1, sequence numbers counting from 0). Readable with
  ``pymavlink.mavutil.mavlink_connection``.
* truth CSV (``docs/replay.md``): ``t_s, lat_deg, lon_deg, alt_m, vn_mps, ve_mps, vd_mps,
  roll_deg, pitch_deg, yaw_deg, phase, gnss_mode`` at ``truth_rate_hz`` on the
  autopilot clock, ``alt_m`` MSL, evaluated exactly on the path.
* JSON: scenario (every field), seed, sensor grades, message rates, phases and
  every scheduled event window with its kind and parameters.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import struct
from pathlib import Path
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mav

from companion.mavlink import units
from companion.mavlink.ids import MAV_COMP_ID_AUTOPILOT1
from companion.nav.grades import IMU_GRADES
from companion.sim.flight import SimFlight, _lla
from companion.sim.scenarios import describe
from companion.sim.sensors import GNSS_MODE_SPECS, gnss_state

logger = logging.getLogger(__name__)

TRUTH_COLUMNS = (
    "t_s", "lat_deg", "lon_deg", "alt_m", "vn_mps", "ve_mps", "vd_mps",
    "roll_deg", "pitch_deg", "yaw_deg", "phase", "gnss_mode",
)  # fmt: skip


def tlog_bytes(flight: SimFlight) -> bytes:
    """The .tlog image of a flight's messages (deterministic)."""
    link = mav.MAVLink(None, srcSystem=1, srcComponent=MAV_COMP_ID_AUTOPILOT1)
    link.robust_parsing = True
    chunks: list[bytes] = []
    pack_q = struct.Struct(">Q").pack
    for t_rx, msg in flight.messages:
        frame = msg.pack(link)  # type: ignore[attr-defined]
        link.seq = (link.seq + 1) % 256
        chunks.append(pack_q(round(t_rx * units.US_PER_S)))
        chunks.append(bytes(frame))
    return b"".join(chunks)


def write_tlog(flight: SimFlight, path: Path) -> Path:
    """Write the .tlog; returns its path."""
    path.write_bytes(tlog_bytes(flight))
    return path


def truth_rows(flight: SimFlight) -> list[str]:
    """Truth CSV lines (header first)."""
    sc = flight.scenario
    t0 = float(flight.truth.t_s[0])
    t1 = float(flight.truth.t_s[-1])
    n = int(math.floor((t1 - t0) * sc.truth_rate_hz + 1e-9)) + 1
    t = np.rint((t0 + np.arange(n) / sc.truth_rate_hz) * 1e6) / 1e6
    t = t[t <= t1]
    st = flight.truth.sample(t)
    lat, lon, alt = _lla(flight.frame, st.pos_ned_m)
    eul = np.degrees(st.euler_rad)
    phase = flight.truth.path.phase_at(t)
    rows = [",".join(TRUTH_COLUMNS)]
    for k in range(len(t)):
        v = st.vel_ned_mps[k]
        rows.append(
            f"{t[k]:.6f},{math.degrees(lat[k]):.10f},{math.degrees(lon[k]):.10f},{alt[k]:.4f},"
            f"{v[0]:.5f},{v[1]:.5f},{v[2]:.5f},{eul[k, 0]:.5f},{eul[k, 1]:.5f},{eul[k, 2]:.5f},"
            f"{phase[k]},{gnss_state(flight.truth.scenario, 0, float(t[k])).label}"
        )
    return rows


def write_truth_csv(flight: SimFlight, path: Path) -> Path:
    """Write the truth CSV; returns its path."""
    path.write_text("\n".join(truth_rows(flight)) + "\n", encoding="ascii")
    return path


def sidecar(flight: SimFlight) -> dict[str, Any]:
    """The JSON sidecar's content."""
    sc = flight.scenario
    counts: dict[str, int] = {}
    for _, msg in flight.messages:
        name = msg.get_type()  # type: ignore[attr-defined]
        counts[name] = counts.get(name, 0) + 1
    duration = float(flight.truth.t_s[-1] - flight.truth.t_s[0])
    return {
        "scenario": sc.name,
        "description": describe(sc.name),
        "seed": flight.seed,
        "duration_s": duration,
        "t_start_s": float(flight.truth.t_s[0]),
        "t_end_s": float(flight.truth.t_s[-1]),
        "epoch0_s": sc.epoch0_s,
        "frame_origin": {"lat_deg": sc.lat0_deg, "lon_deg": sc.lon0_deg, "alt_msl_m": sc.alt0_m},
        "imu_grade": dataclasses.asdict(IMU_GRADES[sc.imu_grade]),
        "gnss_modes": {
            k: {**dataclasses.asdict(v), "fix_type": int(v.fix_type)}
            for k, v in GNSS_MODE_SPECS.items()
        },
        "message_counts": counts,
        "message_rates_hz": {k: v / duration for k, v in counts.items()} if duration else {},
        "phases": [{"phase": p, "t_start_s": a, "t_end_s": b} for p, a, b in flight.phases],
        "events": [e.as_dict() for e in flight.events],
        "parameters": sc.as_dict(),
        "notes": (
            "t_s is autopilot time since boot; tlog times are UNIX epoch = epoch0_s + t_s "
            "+ transport latency. GNSS h_acc/v_acc are per-axis 1-sigma. Flat non-rotating "
            "local NED model: gyros carry no Earth rate."
        ),
    }


def write_sidecar(flight: SimFlight, path: Path) -> Path:
    """Write the JSON sidecar; returns its path."""
    path.write_text(json.dumps(sidecar(flight), indent=1, sort_keys=True) + "\n", encoding="ascii")
    return path


def write_flight(flight: SimFlight, out_dir: Path) -> list[Path]:
    """Write <name>.tlog, <name>.truth.csv and <name>.json into ``out_dir``."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    name = flight.scenario.name
    paths = [
        write_tlog(flight, out_dir / f"{name}.tlog"),
        write_truth_csv(flight, out_dir / f"{name}.truth.csv"),
        write_sidecar(flight, out_dir / f"{name}.json"),
    ]
    logger.info("wrote %s", ", ".join(str(p) for p in paths))
    return paths

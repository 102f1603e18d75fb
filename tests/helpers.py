"""Small synthetic sample streams with known truth, for tests that must not
depend on the full simulator (straight constant-velocity flight)."""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from companion.nav.earth import gravity_mps2
from companion.nav.frames import LocalFrame
from companion.types import AttitudeSample, FixType, GnssFix, ImuSample, Sample

FIXTURES = Path(__file__).resolve().parent.parent / "sitl_fixtures"
TAXI = FIXTURES / "taxi.tlog"
"""The bundled taxi: parked, straight legs, a heading correction READY at about 82 s."""
TAXI_HEADING_ERROR_DEG: float = json.loads((FIXTURES / "taxi.json").read_text())["parameters"][
    "heading_error_deg"
]
"""The heading error the simulator injected into the taxi's ATTITUDE (deg)."""

ORIGIN = LocalFrame(math.radians(52.2), math.radians(20.9), 110.0)


@dataclass(frozen=True)
class Line:
    """Straight flight at constant NED velocity from the origin."""

    vel_ned_mps: tuple[float, float, float] = (40.0, 30.0, -2.0)

    def pos_ned_m(self, t_s: float, t0_s: float = 10.0) -> np.ndarray:
        return np.array(self.vel_ned_mps) * (t_s - t0_s)


def fix_at(
    t_s: float,
    pos_ned_m: np.ndarray,
    vel_ned_mps: np.ndarray,
    fix_type: FixType = FixType.RTK_FIXED,
    h_acc_m: float = 0.02,
    v_acc_m: float = 0.03,
    vel_acc_mps: float = 0.05,
    receiver_id: int = 0,
) -> GnssFix:
    lat, lon, alt = ORIGIN.ned_to_lla(pos_ned_m)
    return GnssFix(
        t_s=t_s,
        t_rx_s=t_s,
        receiver_id=receiver_id,
        fix_type=fix_type,
        lat_rad=lat,
        lon_rad=lon,
        alt_msl_m=alt,
        alt_hae_m=None,
        vel_ne_mps=np.array(vel_ned_mps[:2], dtype=float),
        ground_speed_mps=float(np.hypot(vel_ned_mps[0], vel_ned_mps[1])),
        course_rad=math.atan2(vel_ned_mps[1], vel_ned_mps[0]),
        h_acc_m=h_acc_m,
        v_acc_m=v_acc_m,
        vel_acc_mps=vel_acc_mps,
        hdop=0.8,
        vdop=1.2,
        satellites=14,
    )


def line_stream(
    duration_s: float,
    *,
    line: Line = Line(),
    gnss_hz: float = 10.0,
    imu_hz: float = 50.0,
    t0_s: float = 10.0,
    gaps: tuple[tuple[float, float], ...] = (),
    fix_type_at=lambda t: FixType.RTK_FIXED,
    noise_m: float = 0.0,
    seed: int = 0,
) -> Iterator[Sample]:
    """IMU (level, 1 g), attitude and GNSS samples of a straight flight, in time order.

    ``gaps`` are (start, end) windows, relative to ``t0_s``, with no GNSS.
    """
    rng = np.random.default_rng(seed)
    vel = np.array(line.vel_ned_mps)
    # level, unaccelerated: the accelerometer reads minus the local normal gravity
    f_b = np.array([0.0, 0.0, -gravity_mps2(ORIGIN.lat0_rad, ORIGIN.alt0_m)])
    yaw = math.atan2(vel[1], vel[0])
    n_imu = int(duration_s * imu_hz)
    gnss_every = int(round(imu_hz / gnss_hz))
    for k in range(n_imu + 1):
        t = t0_s + k / imu_hz
        yield ImuSample(t, t, f_b, np.zeros(3), 0, "TEST")
        if k % 5 == 0:
            yield AttitudeSample(t, t, 0.0, 0.0, yaw, np.zeros(3))
        if k % gnss_every == 0:
            rel = t - t0_s
            if any(a <= rel < b for a, b in gaps):
                continue
            pos = line.pos_ned_m(t, t0_s) + noise_m * rng.standard_normal(3)
            yield fix_at(t, pos, vel, fix_type=fix_type_at(rel))

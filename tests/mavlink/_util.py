"""Shared helpers for the MAVLink edge tests: an 'autopilot' that packs messages."""

from __future__ import annotations

from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as apm

AP_SYS = 1
AP_COMP = 1


class Packer:
    """Packs messages as a given (system, component), with a running sequence."""

    def __init__(self, sysid: int = AP_SYS, compid: int = AP_COMP, module: Any = apm) -> None:
        self.mav = module.MAVLink(None, sysid, compid)

    def __call__(self, msg: Any) -> bytes:
        data = bytes(msg.pack(self.mav))
        self.mav.seq = (self.mav.seq + 1) % 256
        return data

    def parsed(self, msg: Any) -> Any:
        """The message as a receiver would see it (packed then decoded: header filled)."""
        rx = apm.MAVLink(None)
        return rx.decode(bytearray(self(msg)))


def heartbeat(autopilot: int = 3, base_mode: int = 0, status: int = 4) -> Any:
    return apm.MAVLink_heartbeat_message(1, autopilot, base_mode, 0, status, 3)


def attitude(t_ms: int, roll: float = 0.1, pitch: float = -0.2, yaw: float = 0.3) -> Any:
    return apm.MAVLink_attitude_message(t_ms, roll, pitch, yaw, 0.01, -0.02, 0.03)


def raw_imu(t_us: int, zacc: int = -1000, imu_id: int = 0) -> Any:
    return apm.MAVLink_raw_imu_message(t_us, 10, -20, zacc, 1, -2, 3, 0, 0, 0, imu_id, 2500)


def gps_raw(
    t_us: int,
    fix: int = 3,
    lat: int = 473977420,
    lon: int = 85455940,
    alt: int = 500_000,
    eph: int = 120,
    epv: int = 200,
    vel: int = 1500,
    cog: int = 9000,
    sats: int = 12,
    alt_ell: int = 548_000,
    h_acc: int = 800,
    v_acc: int = 1200,
    vel_acc: int = 150,
) -> Any:
    return apm.MAVLink_gps_raw_int_message(
        t_us, fix, lat, lon, alt, eph, epv, vel, cog, sats, alt_ell, h_acc, v_acc, vel_acc, 0, 0
    )

"""The encoder's settings: which solution message, accuracy floors, alert rate limits, dialect."""

from __future__ import annotations

from dataclasses import dataclass

from companion.mavlink.dialect import load_dialect
from companion.ranges import check_ranges, ranged
from companion.types import AlertCode

OUTPUTS = ("auto", "gps_input", "global_position_sensor")
"""Choices of ``EncoderConfig.output``."""

LIVE_KEYS = frozenset(
    {
        "output",
        "gps_id",
        "gps_id_from_autopilot",
        "min_h_acc_m",
        "min_v_acc_m",
        "min_vel_acc_mps",
        "uere_m",
        "gps_input_yaw",
        "px4_agp_lead_s",
        "statustext_min_interval_s",
    }
)
"""The keys :meth:`Encoder.reconfigure <companion.mavlink.encode.Encoder.reconfigure>`
applies to a running encoder: read from the configuration at each message. The dialect
and the per-code STATUSTEXT intervals are built into it."""


@dataclass(frozen=True, slots=True)
class EncoderConfig:
    """Encoder settings."""

    output: str = ranged("auto", choices=OUTPUTS)
    """``"auto"`` (by autopilot flavour), ``"gps_input"`` or
    ``"global_position_sensor"``."""
    gps_id: int = ranged(0, ge=0, le=255)
    """GPS_INPUT ``gps_id`` / GLOBAL_POSITION_SENSOR ``id``."""
    gps_id_from_autopilot: bool = True
    """ArduPilot: send GPS_INPUT with the ``gps_id`` of the autopilot's GPS instance that
    takes it (``GPS1_TYPE``/``GPS2_TYPE`` = 14, MAV, read over the parameter protocol)
    instead of ``gps_id``; ``gps_id`` until the parameters are read, and when no instance
    is of that type (the autopilot then ignores GPS_INPUT: a warning says so)."""
    min_h_acc_m: float = ranged(0.01, gt=0.0)
    """Floors of the published 1-sigma horizontal / vertical accuracy, m."""
    min_v_acc_m: float = ranged(0.01, gt=0.0)
    """Floors of the published 1-sigma horizontal / vertical accuracy, m."""
    min_vel_acc_mps: float = ranged(0.01, gt=0.0)
    """Floor of the published speed accuracy, m/s."""
    uere_m: float = ranged(1.0, gt=0.0)
    """Nominal user-equivalent range error used to derive HDOP/VDOP, m."""
    gps_input_yaw: bool = False
    """Send the solution's (taxi-corrected) yaw in GPS_INPUT.yaw. Off by default: the
    autopilot then fuses it as a GNSS heading (ArduPilot EK3_SRC1_YAW = 2), which must
    be a deliberate choice."""
    px4_agp_lead_s: float = ranged(0.0, ge=0.0, le=0.5)
    """GLOBAL_POSITION_SENSOR (PX4): the position is carried forward by the solution's
    velocity this long (and stamped that much later), s. PX4 stamps an aux global
    position on arrival and, with ``EKF2_AGP0_DELAY`` = EKF2's fusion horizon, compares
    it with its newest position then: set this to the time from the solution to its
    arrival at PX4 (the link's lag) when that is not small; more puts PX4 ahead
    (docs/mavlink.md, PX4 aux global position)."""
    statustext_min_interval_s: float = ranged(5.0, ge=0.0)
    """Least time between two STATUSTEXTs of the same alert code, s (a change of state
    within a family, e.g. GNSS_BACK then GNSS_LOST, INTEGRITY restored then lost, is
    always sent)."""
    statustext_interval_overrides: tuple[tuple[str, float], ...] = ()
    """``((code, interval_s), ...)`` per-code exceptions."""
    dialect: str = "ardupilotmega"
    """pymavlink v2.0 dialect module used to build and pack messages."""

    def __post_init__(self) -> None:
        check_ranges(self)
        codes = {c.value for c in AlertCode}
        for code, interval in self.statustext_interval_overrides:
            if code not in codes:
                raise ValueError(f"unknown alert code {code!r} in statustext_interval_overrides")
            if not interval >= 0.0:
                raise ValueError(f"interval for {code} must be >= 0")
        load_dialect(self.dialect)

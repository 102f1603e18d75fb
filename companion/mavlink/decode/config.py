"""The decoder's settings: system id policy, plausibility limits, GNSS time corrections."""

from __future__ import annotations

from dataclasses import dataclass

from companion.mavlink import units
from companion.mavlink.ids import MAV_COMP_ID_ONBOARD_COMPUTER
from companion.ranges import check_ranges, ranged


@dataclass(frozen=True, slots=True)
class DecoderConfig:
    """Decoder settings."""

    system_id: int | None = ranged(None, ge=1, le=255, optional=True)
    """The autopilot's MAVLink system id; ``None`` locks onto the first HEARTBEAT whose
    autopilot is not MAV_AUTOPILOT_INVALID."""
    own_component: int = MAV_COMP_ID_ONBOARD_COMPUTER
    """Our component id (messages from it are ignored)."""
    max_speed_mps: float = ranged(600.0, gt=0.0)
    """Largest plausible speed (GNSS, VFR_HUD, GLOBAL_POSITION_INT), m/s."""
    max_accuracy_m: float = ranged(1e5, gt=0.0)
    """Largest plausible 1-sigma accuracy, m (also m/s for speed accuracy)."""
    alt_min_m: float = -1000.0
    """Plausible altitude range, m."""
    alt_max_m: float = 50_000.0
    """Plausible altitude range, m."""
    max_acc_mps2: float = ranged(50.0 * units.STANDARD_GRAVITY_MPS2, gt=0.0)
    """Largest plausible specific-force magnitude, m/s^2 (50 g)."""
    max_gyro_radps: float = ranged(50.0, gt=0.0)
    """Largest plausible angular-rate magnitude, rad/s."""
    reboot_backjump_s: float = ranged(2.0, gt=0.0)
    """A boot-clock step backwards larger than this is a reboot, s."""
    gnss_delay_s: float = ranged(0.0, ge=0.0, le=1.0)
    """Subtracted from GNSS fix times (receiver lag not in the stamp), s."""
    gnss_delay_measure: bool = True
    """Measure the first receiver's lag in flight (its velocity against the IMU): used
    where neither the autopilot's lag parameter nor ``gnss_delay_s`` gives one, announced
    (``AP_CONFIG``) where the autopilot's parameter disagrees with it."""
    system_time_wait_s: float = ranged(3.0, ge=0.0, le=60.0)
    """How long epoch-stamped messages wait for SYSTEM_TIME's exact offset, s."""

    def __post_init__(self) -> None:
        check_ranges(self)
        if not self.alt_min_m < self.alt_max_m:
            raise ValueError("alt_min_m must be < alt_max_m")

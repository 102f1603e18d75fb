"""The contract between the engine and a navigator (the thing that carries position).

The engine owns the local NED frame, the outage logic and publication; a
navigator only estimates. Every navigator — the first GNSS pass-through with
constant-velocity extrapolation, the Singer model without IMU, the adaptive
GNSS/INS blend — implements :class:`Navigator`, so the engine swaps them
without other changes.

GNSS enters as a :class:`GnssMeasurement` already in the engine's local NED
frame, at its own time of validity ``t_s`` (older than the newest IMU sample:
a navigator that buffers history fuses it at that time and carries the result
forward).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

from companion.nav.frames import LocalFrame
from companion.types import AttitudeSample, FixType, FloatArray, ImuSample


@dataclass(frozen=True, slots=True)
class GnssMeasurement:
    """A GNSS fix in the local NED frame.

    ``vel_ned_mps`` has NaN in components the receiver did not give (GPS_RAW_INT
    has no vertical velocity); ``*_var_*`` are per-axis 1-sigma squared, shape (3,),
    NaN where unknown. ``fix_type`` is the receiver's, for the R model.
    """

    t_s: float
    pos_ned_m: FloatArray
    pos_var_ned_m2: FloatArray
    vel_ned_mps: FloatArray
    vel_var_ned_m2ps2: FloatArray
    fix_type: FixType
    receiver_id: int = 0


@dataclass(frozen=True, slots=True)
class GnssUpdate:
    """What a navigator did with a GNSS measurement.

    ``nis`` is the normalised innovation squared of the position (and velocity,
    when used) innovation against its predicted covariance, with ``dof``
    degrees of freedom; ``gate`` the threshold it was tested against.
    ``innovation`` and ``innovation_cov`` are the position part (3,), (3, 3).
    """

    t_s: float
    fused: bool
    nis: float
    dof: int
    gate: float
    innovation: FloatArray
    innovation_cov: FloatArray
    reason: str = ""


@dataclass(frozen=True, slots=True)
class NavState:
    """A navigator's estimate at ``t_s`` in the local NED frame.

    ``pos_cov_ned_m2`` and ``vel_cov_ned_m2ps2`` are (3, 3).
    ``yaw_rad`` is the navigator's heading if it has one.
    """

    t_s: float
    pos_ned_m: FloatArray
    vel_ned_mps: FloatArray
    pos_cov_ned_m2: FloatArray
    vel_cov_ned_m2ps2: FloatArray
    yaw_rad: float | None = None


@dataclass(frozen=True, slots=True)
class AnchoredState(NavState):
    """A reference solution whose error is a constant between anchors plus white noise
    (a carrier-phase position from its epoch 0): ``anchor_t_s`` changes when it is
    anchored again, and a separation series against it restarts there."""

    anchor_t_s: float = math.nan


class Navigator(Protocol):
    """What the engine asks of a navigator. Pure: no I/O, no clock."""

    @property
    def initialised(self) -> bool:
        """True once a state exists (usually after the first accepted fix)."""
        ...

    def on_imu(self, sample: ImuSample) -> None:
        """Propagate with one IMU sample (navigators without IMU ignore it)."""
        ...

    def on_attitude(self, sample: AttitudeSample, yaw_correction_rad: float) -> None:
        """Take the autopilot's attitude; ``yaw_correction_rad`` (taxi heading
        correction, Markelov et al.) is subtracted from its yaw before use."""
        ...

    def on_gnss(self, meas: GnssMeasurement, *, gate: bool = True) -> GnssUpdate:
        """Test (innovation chi-square gate when ``gate``) and fuse one fix."""
        ...

    def predict(self, t_s: float) -> NavState | None:
        """The state carried to ``t_s`` (>= the last input) without changing it."""
        ...

    def reset(self) -> None:
        """Forget everything (autopilot reboot, re-initialisation)."""
        ...

    def reset_heading(self, yaw_sigma_rad: float) -> None:
        """A taxi heading correction (Markelov et al.) was applied to the attitude input:
        restart the navigator's own heading error from it, with 1-sigma ``yaw_sigma_rad``
        (navigators without an attitude ignore it)."""
        ...

    def shift_frame(self, old: LocalFrame, new: LocalFrame) -> None:
        """Re-express the state in a new local frame (re-anchoring on long legs)."""
        ...

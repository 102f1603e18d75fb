"""What the blend's last GNSS update saw, its counters, and the adaptive noise in use."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from companion.types import FloatArray


@dataclass(slots=True)
class BlendDiagnostics:
    """What the last GNSS update saw and the adaptive estimates now in use."""

    r_scale: FloatArray = field(default_factory=lambda: np.ones(6))
    """Adaptive scale on the reported variance per component (pos N, E, D, vel N, E, D);
    the velocity components stay at 1 (see :mod:`companion.nav.blend.adaptive`)."""
    r_used: FloatArray = field(default_factory=lambda: np.full(6, np.nan))
    """Measurement variances used at the last update, (6,), NaN for absent components."""
    accel_psd_ned: FloatArray = field(default_factory=lambda: np.zeros(3))
    """Accelerometer white-noise PSD in use per NED axis, m^2/s^3."""
    gyro_psd: float = math.nan
    """Strapdown: the gyro white-noise PSD driving the attitude error, rad^2/s (NaN until
    the blend runs strapdown; the configured one unless the IMU measured noisier)."""
    last_nis: float = math.nan
    """Normalised innovation squared of the last fix tested."""
    last_dof: int = 0
    """Its degrees of freedom (3 position components and the velocity axes given)."""
    fused: int = 0
    """Fixes fused."""
    gated: int = 0
    heights_fused: int = 0
    receiver_error_returned: int = 0
    """Times the receiver-error estimate went beyond what its model allows and the
    position was returned to the receiver (:meth:`BlendNavigator._receiver_error_check`)."""
    """Independent heights (the barometer through a GNSS gap) fused."""
    """Fixes refused by the innovation gate."""
    rejected: dict[str, int] = field(default_factory=dict)
    """Inputs refused, by reason."""

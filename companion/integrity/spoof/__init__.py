"""Spoofing: receivers that lie consistently, found against the IMU and held out.

:mod:`.inertial` (the IMU's increments), :mod:`.drag` (one receiver's velocity against
them), :mod:`.episode` (the frozen reference a spoofed receiver is held against),
:mod:`.monitor` (detection, hold and re-admission), :mod:`.config` (``[spoof]``).
"""

from companion.integrity.spoof.config import SpoofConfig
from companion.integrity.spoof.monitor import SpoofMonitor, SpoofStep

__all__ = ["SpoofConfig", "SpoofMonitor", "SpoofStep"]

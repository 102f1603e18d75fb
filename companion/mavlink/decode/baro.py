"""Barometer messages: SCALED_PRESSURE, SCALED_PRESSURE2, HIGHRES_IMU's ``abs_pressure``.

* SCALED_PRESSURE / SCALED_PRESSURE2 (``press_abs`` hPa, ``temperature`` cdegC,
  ``time_boot_ms``) -> :class:`BaroSample` (``baro_id`` 0 / 1).
* HIGHRES_IMU (PX4, and the DataFlash/ULog readers) carries the barometer beside the
  IMU: ``abs_pressure`` (hPa) is taken when ``fields_updated`` has its bit
  (:data:`HIGHRES_ABS_PRESSURE_BIT`), at the IMU sample's time.

Checks: non-finite values (``nan_field``); a pressure outside
[:data:`MIN_PRESSURE_PA`, :data:`MAX_PRESSURE_PA`] (``baro_out_of_range``).
"""

from __future__ import annotations

import math
from typing import Any

from companion.mavlink.decode.clock import BootClock
from companion.mavlink.decode.rejections import Rejected
from companion.types import BaroSample

PA_PER_HPA = 100.0
MIN_PRESSURE_PA = 1_000.0
"""Lowest plausible static pressure (about 31 km in the standard atmosphere), Pa."""
MAX_PRESSURE_PA = 120_000.0
"""Highest plausible static pressure (below sea level, a deep valley, a storm's margin), Pa."""
HIGHRES_ABS_PRESSURE_BIT = 1 << 9
"""HIGHRES_IMU ``fields_updated``: ``abs_pressure`` is valid (HIGHRES_IMU_UPDATED_ABS_PRESSURE)."""


def _check(pressure_pa: float) -> None:
    if not math.isfinite(pressure_pa):
        raise Rejected("nan_field")
    if not MIN_PRESSURE_PA <= pressure_pa <= MAX_PRESSURE_PA:
        raise Rejected("baro_out_of_range")


class BaroDecoder:
    """The barometer handlers (``(msg, t_rx_s) -> sample``, raising :class:`Rejected`)."""

    def __init__(self, clock: BootClock) -> None:
        self._time_ms = clock.time_ms

    def scaled_pressure(self, msg: Any, t_rx_s: float) -> BaroSample:
        """SCALED_PRESSURE (baro 0), SCALED_PRESSURE2 (baro 1)."""
        name = msg.get_type()
        p_pa = float(msg.press_abs) * PA_PER_HPA
        _check(p_pa)
        temp_c = float(msg.temperature) / 100.0
        t_s = self._time_ms(msg.time_boot_ms, name, t_rx_s)
        return BaroSample(t_s, t_rx_s, p_pa, temp_c, 0 if name == "SCALED_PRESSURE" else 1, name)

    @staticmethod
    def from_highres(msg: Any, t_s: float, t_rx_s: float) -> BaroSample | None:
        """The barometer of a HIGHRES_IMU already decoded at ``t_s``; None when its
        ``abs_pressure`` is not flagged valid. Raises :class:`Rejected` when it is flagged
        but implausible."""
        if not int(msg.fields_updated) & HIGHRES_ABS_PRESSURE_BIT:
            return None
        p_pa = float(msg.abs_pressure) * PA_PER_HPA
        _check(p_pa)
        temp = float(msg.temperature)
        return BaroSample(
            t_s, t_rx_s, p_pa, temp if math.isfinite(temp) else None, 0, "HIGHRES_IMU"
        )

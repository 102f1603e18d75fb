"""Raw observation records: what the receiver measured, in SI units, before any model."""

from __future__ import annotations

import math
from dataclasses import dataclass

C_MPS = 299_792_458.0
"""Speed of light (IS-GPS-200)."""

GPS_L1_HZ = 1_575.42e6
GPS_L2_HZ = 1_227.60e6
GPS_L5_HZ = 1_176.45e6

SIGNAL_HZ: dict[str, float] = {
    "L1": GPS_L1_HZ,
    "L2": GPS_L2_HZ,
    "L5": GPS_L5_HZ,
    "E1": GPS_L1_HZ,
    "E5a": GPS_L5_HZ,
    "E5b": 1_207.14e6,
    "E6": 1_278.75e6,
}
"""Carrier frequency of each band this package uses (GPS and Galileo), by band name."""

L1_BANDS = frozenset({"L1", "E1"})
"""The single frequency of Kim, Walter and Powell: GPS L1 and Galileo E1 (1575.42 MHz)."""
ALL_BANDS = frozenset(SIGNAL_HZ)


@dataclass(frozen=True)
class SignalObs:
    """One signal of one satellite at one epoch (u-blox RXM-RAWX fields, SI units).

    ``band`` is ``"L1"``, ``"L2"`` or ``"L5"`` for GPS, the receiver's signal name
    otherwise. Carrier phase is in cycles, with the sign of the pseudorange
    (``wavelength * phase_cyc`` grows with the range).
    """

    system: str
    sv: int
    band: str
    pseudorange_m: float
    phase_cyc: float
    doppler_hz: float
    lock_time_s: float
    cn0_dbhz: float
    pr_valid: bool
    phase_valid: bool
    half_cycle_valid: bool
    half_cycle_subtracted: bool


@dataclass(frozen=True)
class RawEpoch:
    """Every signal measured at one receiver epoch; ``tow_s`` in the receiver's GPS time."""

    week: int
    tow_s: float
    signals: tuple[SignalObs, ...]
    clock_reset: bool = False


@dataclass(frozen=True)
class NavWords:
    """One broadcast navigation subframe as the receiver delivers it (u-blox RXM-SFRBX).

    For GPS L1 C/A: ten 32-bit words, the 30-bit navigation word in bits 29..0 with its
    six parity bits in 5..0 (already checked and with the data bits un-inverted).
    """

    system: str
    sv: int
    words: tuple[int, ...]
    signal: str = "L1"


@dataclass(frozen=True)
class PvtFix:
    """The receiver's own solution (u-blox NAV-PVT): ellipsoidal and MSL heights, the
    carrier-solution state, its accuracy estimates (m; NaN when not decoded)."""

    itow_s: float
    lat_deg: float
    lon_deg: float
    height_m: float
    height_msl_m: float
    fix_type: int
    carrier_solution: int
    num_sv: int
    h_acc_m: float = math.nan
    v_acc_m: float = math.nan
    vel_ned_mps: tuple[float, float, float] = (math.nan, math.nan, math.nan)


@dataclass(frozen=True)
class ReceiverStatus:
    """The receiver's own interference indicators (u-blox NAV-STATUS, MON-RF, MON-HW).

    ``itow_s`` is NAV-STATUS's time of week; MON-RF and MON-HW carry none (None: the
    stream's latest). ``spoof_det_state``: NAV-STATUS ``spoofDetState`` (0 unknown or
    off, 1 no spoofing indicated, 2 spoofing indicated, 3 multiple indications);
    ``jamming_state``: ``jammingState`` (0 unknown or off, 1 ok, 2 warning: interference
    visible but fix ok, 3 critical: interference visible and no fix); ``jam_indicator``:
    ``jamInd``, 0 (no CW jamming) to 255 (strong). None where the message has no such
    field; MON-RF's worst block.
    """

    source: str
    itow_s: float | None = None
    spoof_det_state: int | None = None
    jamming_state: int | None = None
    jam_indicator: int | None = None

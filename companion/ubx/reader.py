"""Read UBX RXM-RAWX, RXM-SFRBX, NAV-PVT and the receiver's interference indicators
(NAV-STATUS, MON-RF, MON-HW) from a file or a serial port (pyubx2).

Every frame that does not parse, and every measurement the receiver flags as unusable,
is a counted rejection in :attr:`UbxSource.rejected`, never an exception.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Iterator
from typing import IO, Any

from pyubx2 import ERR_LOG, SET_LAYER_RAM, TXN_NONE, UBX_PROTOCOL, UBXMessage, UBXReader

from companion.raw.obs import NavWords, PvtFix, RawEpoch, ReceiverStatus, SignalObs

log = logging.getLogger(__name__)


SYSTEMS = {0: "GPS", 1: "SBAS", 2: "Galileo", 3: "BeiDou", 5: "QZSS", 6: "GLONASS", 7: "NavIC"}
"""UBX gnssId -> system name (u-blox interface description, GNSS identifiers)."""

BANDS = {
    "GPS": {0: "L1", 3: "L2", 4: "L2", 6: "L5", 7: "L5"},
    "Galileo": {
        0: "E1",
        1: "E1",
        3: "E5a",
        4: "E5a",
        5: "E5b",
        6: "E5b",
        8: "E6",
        9: "E6",
        10: "E6",
    },
}
"""UBX sigId -> band. GPS: L1 C/A; L2 CL, CM; L5 I, Q. Galileo: E1 C, B; E5a I, Q; E5b I,
Q; E6 B, C, A."""


STATUS_MESSAGES = frozenset({"NAV-STATUS", "MON-RF", "MON-HW"})
"""The receiver's own spoofing (NAV-STATUS) and jamming (MON-RF; MON-HW on older
receivers) indicators."""
MON_RF_EPOCHS = 4
"""MON-RF is asked for once every this many navigation epochs (1 s at 4 Hz)."""


def system_name(gnss_id: object) -> str:
    text = str(gnss_id)
    return SYSTEMS.get(int(text), text) if text.isdigit() else text


def band_name(system: str, sig_id: object) -> str:
    """The band of a signal (``"L1"``, ``"E5a"``...); ``"<system>-<sigId>"`` if unknown."""
    table = BANDS.get(system, {})
    text = str(sig_id)
    if text.isdigit() and int(text) in table:
        return table[int(text)]
    return f"{system}-{text}"


def rawx_to_epoch(msg: Any) -> RawEpoch:
    """An RXM-RAWX message as a :class:`RawEpoch` (pyubx2 has applied the scalings)."""
    signals = []
    for i in range(1, int(msg.numMeas) + 1):
        k = f"_{i:02d}"
        system = system_name(getattr(msg, "gnssId" + k))
        signals.append(
            SignalObs(
                system=system,
                sv=int(getattr(msg, "svId" + k)),
                band=band_name(system, getattr(msg, "sigId" + k)),
                pseudorange_m=float(getattr(msg, "prMes" + k)),
                phase_cyc=float(getattr(msg, "cpMes" + k)),
                doppler_hz=float(getattr(msg, "doMes" + k)),
                lock_time_s=float(getattr(msg, "locktime" + k)) * 1e-3,
                cn0_dbhz=float(getattr(msg, "cno" + k)),
                pr_valid=bool(getattr(msg, "prValid" + k)),
                phase_valid=bool(getattr(msg, "cpValid" + k)),
                half_cycle_valid=bool(getattr(msg, "halfCyc" + k)),
                half_cycle_subtracted=bool(getattr(msg, "subHalfCyc" + k)),
            )
        )
    return RawEpoch(
        week=int(msg.week),
        tow_s=float(msg.rcvTow),
        signals=tuple(signals),
        clock_reset=bool(msg.clkReset),
    )


def sfrbx_to_words(msg: Any) -> NavWords:
    n = int(msg.numWords)
    words = tuple(int(getattr(msg, f"dwrd_{i:02d}")) for i in range(1, n + 1))
    system = system_name(msg.gnssId)
    signal = band_name(system, msg.sigId)
    if system == "GPS" and int(msg.sigId) != 0:
        signal = f"{signal}-CNAV"  # L2C / L5 messages: not the LNAV this package decodes
    if system == "Galileo" and int(msg.sigId) != 1:
        signal = f"{signal}-other"  # only the E1-B I/NAV pages are decoded
    return NavWords(system=system, sv=int(msg.svId), words=words, signal=signal)


def pvt_to_fix(msg: Any) -> PvtFix:
    return PvtFix(
        itow_s=float(msg.iTOW_ms) * 1e-3 if hasattr(msg, "iTOW_ms") else _itow_s(msg),
        lat_deg=float(msg.lat),
        lon_deg=float(msg.lon),
        height_m=float(msg.height) * 1e-3,
        height_msl_m=float(msg.hMSL) * 1e-3,
        fix_type=int(msg.fixType),
        carrier_solution=int(msg.carrSoln),
        num_sv=int(msg.numSV),
        h_acc_m=float(msg.hAcc) * 1e-3,
        v_acc_m=float(msg.vAcc) * 1e-3,
        vel_ned_mps=(float(msg.velN) * 1e-3, float(msg.velE) * 1e-3, float(msg.velD) * 1e-3),
    )


def status_to_receiver(msg: Any) -> ReceiverStatus:
    """NAV-STATUS (spoofing), MON-RF or MON-HW (jamming) as a :class:`ReceiverStatus`."""
    ident = msg.identity
    if ident == "NAV-STATUS":
        return ReceiverStatus(
            source=ident, itow_s=_itow_s(msg), spoof_det_state=int(msg.spoofDetState)
        )
    if ident == "MON-RF":
        blocks = range(1, int(msg.nBlocks) + 1)
        states = [int(getattr(msg, f"jammingState_{i:02d}")) for i in blocks]
        inds = [int(getattr(msg, f"jamInd_{i:02d}")) for i in blocks]
        if not states:
            raise ValueError("MON-RF without an RF block")
        return ReceiverStatus(source=ident, jamming_state=max(states), jam_indicator=max(inds))
    return ReceiverStatus(
        source=ident, jamming_state=int(msg.jammingState), jam_indicator=int(msg.jamInd)
    )


def _itow_s(msg: Any) -> float:
    # pyubx2 renders iTOW as a time of day; the raw payload keeps the milliseconds
    return float(int.from_bytes(msg.payload[0:4], "little")) * 1e-3


class UbxSource:
    """Iterates over a UBX byte stream (a file or an open serial port).

    Yields :class:`RawEpoch`, :class:`NavWords`, :class:`PvtFix` and
    :class:`ReceiverStatus` in stream order.
    """

    def __init__(self, stream: IO[bytes]) -> None:
        self.rejected: Counter[str] = Counter()
        self._reader = UBXReader(
            stream,
            protfilter=UBX_PROTOCOL,
            quitonerror=ERR_LOG,
            errorhandler=self._on_error,
        )

    def _on_error(self, err: Exception) -> None:
        self.rejected["bad frame"] += 1
        log.debug("UBX frame rejected: %s", err)

    def __iter__(self) -> Iterator[RawEpoch | NavWords | PvtFix | ReceiverStatus]:
        for _raw, msg in self._reader:
            if msg is None:
                continue
            ident = msg.identity
            try:
                if ident == "RXM-RAWX":
                    yield rawx_to_epoch(msg)
                elif ident == "RXM-SFRBX":
                    yield sfrbx_to_words(msg)
                elif ident == "NAV-PVT":
                    yield pvt_to_fix(msg)
                elif ident in STATUS_MESSAGES:
                    yield status_to_receiver(msg)
            except (AttributeError, TypeError, ValueError) as err:
                self.rejected[f"bad {ident}"] += 1
                log.debug("UBX %s rejected: %s", ident, err)


def read_file(path: str) -> tuple[list[RawEpoch], list[NavWords], list[PvtFix], Counter[str]]:
    """Everything of a recorded ``.ubx`` file, and the rejections counted on the way."""
    epochs: list[RawEpoch] = []
    nav: list[NavWords] = []
    pvt: list[PvtFix] = []
    with open(path, "rb") as f:
        src = UbxSource(f)
        for item in src:
            if isinstance(item, RawEpoch):
                epochs.append(item)
            elif isinstance(item, NavWords):
                nav.append(item)
            elif isinstance(item, PvtFix):
                pvt.append(item)
    return epochs, nav, pvt, src.rejected


def enable_raw_output(port: str = "UART2", rate_per_epoch: int = 1) -> bytes:
    """A CFG-VALSET (RAM layer) turning RXM-RAWX, RXM-SFRBX, NAV-PVT and NAV-STATUS on at
    ``port``, and MON-RF once every :data:`MON_RF_EPOCHS` epochs."""
    keys = [
        (f"CFG_MSGOUT_UBX_RXM_RAWX_{port}", rate_per_epoch),
        (f"CFG_MSGOUT_UBX_RXM_SFRBX_{port}", rate_per_epoch),
        (f"CFG_MSGOUT_UBX_NAV_PVT_{port}", rate_per_epoch),
        (f"CFG_MSGOUT_UBX_NAV_STATUS_{port}", rate_per_epoch),
        (f"CFG_MSGOUT_UBX_MON_RF_{port}", MON_RF_EPOCHS),
    ]
    return bytes(UBXMessage.config_set(SET_LAYER_RAM, TXN_NONE, keys).serialize())


def open_serial(device: str, baud: int, port: str = "UART2") -> UbxSource:
    """Open a live receiver on ``device``, turn its raw output on, and read it."""
    import serial  # the edge only: pyserial

    ser = serial.Serial(device, baud, timeout=2.0)
    ser.write(enable_raw_output(port))
    return UbxSource(ser)

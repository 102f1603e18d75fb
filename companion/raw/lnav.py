"""GPS LNAV ephemeris from the navigation words (IS-GPS-200, subframes 1 to 3).

The receiver hands each subframe over as ten words with the parity bits still attached
(:class:`companion.raw.obs.NavWords`); the 24 data bits of each word are bits 29..6.
Bit offsets below count from the first bit of the telemetry word in the 240 data bits
that are left, as IS-GPS-200 Figure 20-1 lays them out without the parity.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

from companion.raw.obs import NavWords

GPS_PI = 3.1415926535898
"""The value of pi IS-GPS-200 fixes for the semicircle conversions."""

PREAMBLE = 0x8B


@dataclass(frozen=True)
class Ephemeris:
    """One broadcast Keplerian ephemeris, SI units: GPS LNAV (IS-GPS-200 Tables 20-I and
    20-III) or Galileo I/NAV (``system="Galileo"``: ``iode`` and ``iodc`` hold IODnav,
    ``tgd_s`` the E1-E5b group delay, times in Galileo system time of week)."""

    sv: int
    week: int
    iodc: int
    iode: int
    health: int
    ura_index: int
    tgd_s: float
    toc_s: float
    af0_s: float
    af1_sps: float
    af2_sps2: float
    toe_s: float
    sqrt_a: float
    e: float
    m0_rad: float
    delta_n_radps: float
    omega0_rad: float
    omega_dot_radps: float
    i0_rad: float
    idot_radps: float
    w_rad: float
    cuc_rad: float
    cus_rad: float
    crc_m: float
    crs_m: float
    cic_rad: float
    cis_rad: float
    system: str = "GPS"


_PARITY = (
    (29, (1, 2, 3, 5, 6, 10, 11, 12, 13, 14, 17, 18, 20, 23)),
    (30, (2, 3, 4, 6, 7, 11, 12, 13, 14, 15, 18, 19, 21, 24)),
    (29, (1, 3, 4, 5, 7, 8, 12, 13, 14, 15, 16, 19, 20, 22)),
    (30, (2, 4, 5, 6, 8, 9, 13, 14, 15, 16, 17, 20, 21, 23)),
    (30, (1, 3, 5, 6, 7, 9, 10, 14, 15, 16, 17, 18, 21, 22, 24)),
    (29, (3, 5, 6, 8, 9, 10, 11, 13, 15, 19, 22, 23, 24)),
)
"""IS-GPS-200 Table 20-XIV: each parity bit D25..D30, the previous word's D29*/D30* it
starts from, and the source data bits d1..d24 it sums."""


def parity_ok(word: int) -> bool:
    """The parity of one word (D1 in bit 29, D30 in bit 0; D29*, D30* in bits 31, 30)."""
    d29s, d30s = (word >> 31) & 1, (word >> 30) & 1
    data = [((word >> (29 - i)) & 1) ^ d30s for i in range(24)]
    for j, (star, idx) in enumerate(_PARITY):
        p = d29s if star == 29 else d30s
        for i in idx:
            p ^= data[i - 1]
        if p != (word >> (5 - j)) & 1:
            return False
    return True


def data_bits(words: tuple[int, ...]) -> int:
    """The 240 data bits of a subframe as one integer (parity stripped), MSB first."""
    out = 0
    for w in words[:10]:
        out = (out << 24) | ((w >> 6) & 0xFFFFFF)
    return out


def _u(bits: int, start: int, length: int) -> int:
    return (bits >> (240 - start - length)) & ((1 << length) - 1)


def _s(bits: int, start: int, length: int) -> int:
    v = _u(bits, start, length)
    return v - (1 << length) if v >> (length - 1) else v


def subframe_id(bits: int) -> int:
    """The subframe ID in the hand-over word (bits 20-22 of word 2)."""
    return _u(bits, 43, 3)


def _sf1(b: int) -> dict[str, float | int]:
    tgd = _s(b, 160, 8)
    return {
        "week": _u(b, 48, 10),
        "ura_index": _u(b, 60, 4),
        "health": _u(b, 64, 6),
        "iodc": (_u(b, 70, 2) << 8) | _u(b, 168, 8),
        "tgd_s": 0.0 if tgd == -128 else tgd * 2.0**-31,
        "toc_s": _u(b, 176, 16) * 16.0,
        "af2_sps2": _s(b, 192, 8) * 2.0**-55,
        "af1_sps": _s(b, 200, 16) * 2.0**-43,
        "af0_s": _s(b, 216, 22) * 2.0**-31,
    }


def _sf2(b: int) -> dict[str, float | int]:
    return {
        "iode2": _u(b, 48, 8),
        "crs_m": _s(b, 56, 16) * 2.0**-5,
        "delta_n_radps": _s(b, 72, 16) * 2.0**-43 * GPS_PI,
        "m0_rad": _s(b, 88, 32) * 2.0**-31 * GPS_PI,
        "cuc_rad": _s(b, 120, 16) * 2.0**-29,
        "e": _u(b, 136, 32) * 2.0**-33,
        "cus_rad": _s(b, 168, 16) * 2.0**-29,
        "sqrt_a": _u(b, 184, 32) * 2.0**-19,
        "toe_s": _u(b, 216, 16) * 16.0,
    }


def _sf3(b: int) -> dict[str, float | int]:
    return {
        "cic_rad": _s(b, 48, 16) * 2.0**-29,
        "omega0_rad": _s(b, 64, 32) * 2.0**-31 * GPS_PI,
        "cis_rad": _s(b, 96, 16) * 2.0**-29,
        "i0_rad": _s(b, 112, 32) * 2.0**-31 * GPS_PI,
        "crc_m": _s(b, 144, 16) * 2.0**-5,
        "w_rad": _s(b, 160, 32) * 2.0**-31 * GPS_PI,
        "omega_dot_radps": _s(b, 192, 24) * 2.0**-43 * GPS_PI,
        "iode3": _u(b, 216, 8),
        "idot_radps": _s(b, 224, 14) * 2.0**-43 * GPS_PI,
    }


class LnavCollector:
    """Assembles subframes 1-3 of each GPS satellite into :class:`Ephemeris` records.

    A subframe set is complete when subframes 2 and 3 carry the same IODE and it equals
    the 8 low bits of subframe 1's IODC (IS-GPS-200 20.3.4.4). Rejections are counted in
    :attr:`rejected` by reason; unhealthy ephemerides are kept apart, never used.
    """

    def __init__(self, week_rollovers: int = 1) -> None:
        self._rollover = 1024 * week_rollovers
        self._parts: dict[int, dict[int, dict[str, float | int]]] = {}
        self.ephemerides: dict[int, Ephemeris] = {}
        self.rejected: Counter[str] = Counter()

    def add(self, nav: NavWords) -> Ephemeris | None:
        """Take one subframe; return the ephemeris it completes, if it completes one."""
        if nav.system != "GPS" or nav.signal != "L1":
            self.rejected["not GPS LNAV"] += 1
            return None
        if len(nav.words) < 10:
            self.rejected["short subframe"] += 1
            return None
        if not all(parity_ok(w) for w in nav.words[:10]):
            self.rejected["bad parity"] += 1
            return None
        bits = data_bits(nav.words)
        if _u(bits, 0, 8) != PREAMBLE:
            self.rejected["bad preamble"] += 1
            return None
        sid = subframe_id(bits)
        decoders = {1: _sf1, 2: _sf2, 3: _sf3}
        if sid not in decoders:
            return None  # almanac / ionosphere pages: not used here
        parts = self._parts.setdefault(nav.sv, {})
        parts[sid] = decoders[sid](bits)
        if len(parts) < 3:
            return None
        sf1, sf2, sf3 = parts[1], parts[2], parts[3]
        if not (sf2["iode2"] == sf3["iode3"] == (int(sf1["iodc"]) & 0xFF)):
            return None  # a set from two different uploads: wait for the next one
        fields = {**sf1, **sf2, **sf3}
        iode = int(fields.pop("iode2"))
        fields.pop("iode3")
        fields["week"] = int(fields["week"]) + self._rollover
        eph = Ephemeris(sv=nav.sv, iode=iode, **fields)  # type: ignore[arg-type]
        if eph.health != 0:
            self.rejected["unhealthy"] += 1
            return None
        old = self.ephemerides.get(nav.sv)
        if old is None or (old.iode, old.toe_s) != (eph.iode, eph.toe_s):
            self.ephemerides[nav.sv] = eph
        return eph

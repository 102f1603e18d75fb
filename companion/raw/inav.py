"""Galileo I/NAV ephemeris from the E1-B pages (Galileo OS SIS ICD 4.3.5).

The receiver delivers each nominal page as eight 32-bit words: the even half-page in
the first 128 bits, the odd one in the next 128. A word (128 bits) is the even
half-page's data (112 bits, after its even/odd and page-type bits) followed by the odd
half-page's first 16 data bits; a CRC-24Q covers both halves. Word types 1-4 hold the
ephemeris and clock, word type 5 the health and the Galileo week.
"""

from __future__ import annotations

from collections import Counter

from companion.raw.lnav import GPS_PI, Ephemeris
from companion.raw.obs import NavWords

_CRC24Q_POLY = 0x1864CFB


def crc24q(data: bytes) -> int:
    crc = 0
    for byte in data:
        crc ^= byte << 16
        for _ in range(8):
            crc <<= 1
            if crc & 0x1000000:
                crc ^= _CRC24Q_POLY
    return crc & 0xFFFFFF


def _bits(value: int, total: int, start: int, length: int) -> int:
    return (value >> (total - start - length)) & ((1 << length) - 1)


def _signed(v: int, length: int) -> int:
    return v - (1 << length) if v >> (length - 1) else v


def page_word(words: tuple[int, ...]) -> int | None:
    """The 128-bit I/NAV word of one page, or None for an alert page or a CRC failure."""
    page = 0
    for w in words[:8]:
        page = (page << 32) | (w & 0xFFFFFFFF)
    even = page >> 128
    odd = page & ((1 << 128) - 1)
    if _bits(even, 128, 0, 1) != 0 or _bits(odd, 128, 0, 1) != 1:
        raise ValueError("half-pages out of order")
    if _bits(even, 128, 1, 1) or _bits(odd, 128, 1, 1):
        return None  # alert page
    # CRC-24Q over the even half (114 bits) and the odd half's first 82 bits, padded to 200
    crc_in = (_bits(even, 128, 0, 114) << 82) | _bits(odd, 128, 0, 82)
    if crc24q(crc_in.to_bytes(25, "big")) != _bits(odd, 128, 82, 24):
        raise ValueError("CRC")
    return (_bits(even, 128, 2, 112) << 16) | _bits(odd, 128, 2, 16)


def _u(w: int, start: int, length: int) -> int:
    return _bits(w, 128, start, length)


def _s(w: int, start: int, length: int) -> int:
    return _signed(_u(w, start, length), length)


class InavCollector:
    """Assembles word types 1-5 of each Galileo satellite into an :class:`Ephemeris`.

    Words 1-4 must share one IODnav; word 5 must report the E1-B signal healthy and its
    data valid. Rejections are counted by reason in :attr:`rejected`.
    """

    def __init__(self) -> None:
        self._words: dict[int, dict[int, int]] = {}
        self.ephemerides: dict[int, Ephemeris] = {}
        self.rejected: Counter[str] = Counter()

    def add(self, nav: NavWords) -> Ephemeris | None:
        if nav.system != "Galileo" or nav.signal != "E1" or len(nav.words) < 8:
            self.rejected["not Galileo I/NAV E1-B"] += 1
            return None
        try:
            word = page_word(nav.words)
        except ValueError as err:
            self.rejected[f"bad page ({err})"] += 1
            return None
        if word is None:
            return None
        wtype = _u(word, 0, 6)
        if not 1 <= wtype <= 5:
            return None
        got = self._words.setdefault(nav.sv, {})
        got[wtype] = word
        if len(got) < 5:
            return None
        w1, w2, w3, w4, w5 = (got[k] for k in range(1, 6))
        iods = {_u(w, 6, 10) for w in (w1, w2, w3, w4)}
        if len(iods) != 1:
            return None
        iod = iods.pop()
        i = 6 + 41
        bgd_e5b = _s(w5, i + 10, 10) * 2.0**-32
        e5b_hs, e1b_hs = _u(w5, i + 20, 2), _u(w5, i + 22, 2)
        e1b_dvs = _u(w5, i + 25, 1)
        week = _u(w5, i + 26, 12)
        sc = GPS_PI
        eph = Ephemeris(
            sv=nav.sv,
            week=week + 1024,  # GST week 0 is GPS week 1024
            iodc=iod,
            iode=iod,
            health=(e5b_hs << 3) | (e1b_hs << 1) | e1b_dvs,
            ura_index=_u(w3, 120, 8),  # SISA
            tgd_s=bgd_e5b,
            toc_s=_u(w4, 6 + 10 + 6 + 32, 14) * 60.0,
            af0_s=_s(w4, 6 + 10 + 6 + 32 + 14, 31) * 2.0**-34,
            af1_sps=_s(w4, 6 + 10 + 6 + 32 + 14 + 31, 21) * 2.0**-46,
            af2_sps2=_s(w4, 6 + 10 + 6 + 32 + 14 + 31 + 21, 6) * 2.0**-59,
            toe_s=_u(w1, 16, 14) * 60.0,
            m0_rad=_s(w1, 30, 32) * 2.0**-31 * sc,
            e=_u(w1, 62, 32) * 2.0**-33,
            sqrt_a=_u(w1, 94, 32) * 2.0**-19,
            omega0_rad=_s(w2, 16, 32) * 2.0**-31 * sc,
            i0_rad=_s(w2, 48, 32) * 2.0**-31 * sc,
            w_rad=_s(w2, 80, 32) * 2.0**-31 * sc,
            idot_radps=_s(w2, 112, 14) * 2.0**-43 * sc,
            omega_dot_radps=_s(w3, 16, 24) * 2.0**-43 * sc,
            delta_n_radps=_s(w3, 40, 16) * 2.0**-43 * sc,
            cuc_rad=_s(w3, 56, 16) * 2.0**-29,
            cus_rad=_s(w3, 72, 16) * 2.0**-29,
            crc_m=_s(w3, 88, 16) * 2.0**-5,
            crs_m=_s(w3, 104, 16) * 2.0**-5,
            cic_rad=_s(w4, 22, 16) * 2.0**-29,
            cis_rad=_s(w4, 38, 16) * 2.0**-29,
            system="Galileo",
        )
        if e1b_hs != 0 or e1b_dvs != 0:
            self.rejected["unhealthy"] += 1
            return None
        self.ephemerides[nav.sv] = eph
        return eph

"""Every usable broadcast ephemeris in a stream of navigation words, by (system, sv)."""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable

from companion.raw.inav import InavCollector
from companion.raw.lnav import Ephemeris, LnavCollector
from companion.raw.obs import NavWords


def collect_ephemerides(
    nav: Iterable[NavWords], gps_week_rollovers: int = 2
) -> tuple[dict[tuple[str, int], Ephemeris], Counter[str]]:
    """GPS LNAV and Galileo I/NAV ephemerides, the last of each satellite; rejections.

    Other systems' and signals' words are counted under "not decoded".
    """
    gps, gal = LnavCollector(gps_week_rollovers), InavCollector()
    other: Counter[str] = Counter()
    for words in nav:
        if words.system == "GPS" and words.signal == "L1":
            gps.add(words)
        elif words.system == "Galileo" and words.signal == "E1":
            gal.add(words)
        else:
            other["not decoded"] += 1
    ephs = {("GPS", k): v for k, v in gps.ephemerides.items()}
    ephs.update({("Galileo", k): v for k, v in gal.ephemerides.items()})
    rejected = other + Counter({f"GPS: {k}": v for k, v in gps.rejected.items()})
    rejected += Counter({f"Galileo: {k}": v for k, v in gal.rejected.items()})
    return ephs, rejected

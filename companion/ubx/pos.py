"""RTKLIB ``.pos`` solution files (GPST time, latitude, longitude, height, quality)."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from datetime import datetime, timezone

log = logging.getLogger(__name__)

GPS_EPOCH = datetime(1980, 1, 6, tzinfo=timezone.utc)


@dataclass(frozen=True)
class PosRow:
    week: int
    tow_s: float
    lat_deg: float
    lon_deg: float
    height_m: float
    quality: int
    """RTKLIB Q: 1 fixed, 2 float, 4 DGPS, 5 single."""


def read_pos(path: str) -> tuple[list[PosRow], int]:
    """The rows of a ``yyyy/mm/dd hh:mm:ss.sss`` GPST solution file; malformed lines counted."""
    rows: list[PosRow] = []
    bad = 0
    with open(path, encoding="utf-8") as f:
        for line in f:
            if line.startswith("%") or not line.strip():
                continue
            parts = line.split()
            try:
                when = datetime.strptime(f"{parts[0]} {parts[1]}", "%Y/%m/%d %H:%M:%S.%f")
                secs = (when.replace(tzinfo=timezone.utc) - GPS_EPOCH).total_seconds()
                week = int(secs // 604_800)
                rows.append(
                    PosRow(
                        week=week,
                        tow_s=secs - week * 604_800,
                        lat_deg=float(parts[2]),
                        lon_deg=float(parts[3]),
                        height_m=float(parts[4]),
                        quality=int(float(parts[5])),
                    )
                )
            except (IndexError, ValueError):
                bad += 1
    if bad:
        log.warning("%s: %d malformed lines skipped", path, bad)
    return rows, bad

"""``companion inspect``: a T-D PRP track with FIS-RAIM from a recorded ``.ubx`` file.

Epoch 0 is the first epoch with at least five usable satellites (or the first at
``start_s`` after the file's first epoch); its position is ``reference`` (latitude,
longitude, height above the ellipsoid) or else the receiver's own NAV-PVT solution then.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from companion.nav.frames import ecef_to_geodetic, geodetic_to_ecef_m
from companion.raw.broadcast import collect_ephemerides
from companion.raw.raim import FisRaim
from companion.raw.tdprp import Tdprp, TdprpConfig
from companion.ubx.reader import read_file

COLUMNS = (
    "gps_tow_s", "lat_deg", "lon_deg", "alt_m", "e_m", "n_m", "u_m",
    "n_sats", "slope_stat", "residual_stat", "alert",
)  # fmt: skip
"""The track's CSV columns; ``alt_m`` is above the ellipsoid, e/n/u from epoch 0."""


@dataclass(frozen=True)
class TrackEpoch:
    """One solved epoch of the track, for the plot: time from epoch 0 (s), E/N/U (m),
    FIS-RAIM's statistics and limits (NaN where unavailable) and its verdict."""

    t_s: float
    enu_m: tuple[float, float, float]
    slope_mps: float
    residual_m2: float
    residual_limit_m2: float
    available: bool
    slope_alert: bool
    residual_alert: bool


@dataclass(frozen=True)
class InspectSummary:
    epochs: int
    solved: int
    alerts: int
    epoch0_tow_s: float
    rejected: dict[str, int]
    fis_unavailable: int = 0
    fis_restarts: int = 0
    track: tuple[TrackEpoch, ...] = field(default=(), repr=False)
    slope_limit_mps: float = math.nan

    def to_text(self) -> str:
        return (
            f"epoch 0 at GPS time of week {self.epoch0_tow_s:.3f} s; {self.solved} of "
            f"{self.epochs} epochs solved; FIS-RAIM alerts: {self.alerts}, unavailable "
            f"(a subset's separation too noisy) at {self.fis_unavailable} epochs, window "
            f"restarted at {self.fis_restarts} changes of the signal set\n"
            f"rejections: {self.rejected}"
        )


def inspect_file(
    ubx: Path,
    output: Path,
    start_s: float | None = None,
    reference: tuple[float, float, float] | None = None,
    config: TdprpConfig | None = None,
) -> InspectSummary:
    epochs, nav, pvt, rejected = read_file(str(ubx))
    ephs, eph_rejected = collect_ephemerides(nav)
    rejected = rejected + eph_rejected
    if not epochs:
        raise ValueError(f"{ubx}: no RXM-RAWX observations")
    cfg = config or TdprpConfig()
    probe = Tdprp(ephs, np.zeros(3) + 6.4e6, cfg)
    first = None
    for i, ep in enumerate(epochs):
        if start_s is not None:
            if ep.tow_s - epochs[0].tow_s >= start_s:
                first = i
                break
            continue
        usable = {(s.system, s.sv) for s in ep.signals if probe._usable(s) is None}
        if len(usable) >= 5:
            first = i
            break
    if first is None:
        raise ValueError(f"{ubx}: no epoch 0 (five usable satellites, or --start-s too late)")
    ep0 = epochs[first]
    if reference is None:
        fix = min(pvt, key=lambda f: abs(f.itow_s - ep0.tow_s), default=None)
        if fix is None or abs(fix.itow_s - ep0.tow_s) > 0.5:
            raise ValueError(f"{ubx}: no NAV-PVT at epoch 0; give --reference LAT,LON,ALT")
        reference = (fix.lat_deg, fix.lon_deg, fix.height_m)
    lat, lon, alt = reference
    x0 = np.asarray(geodetic_to_ecef_m(math.radians(lat), math.radians(lon), alt), float)
    est = Tdprp(ephs, x0, cfg)
    est.start(ep0)
    fis = FisRaim()
    solved = alerts = 0
    track: list[TrackEpoch] = []
    output.parent.mkdir(parents=True, exist_ok=True)
    with open(output, "w", newline="", encoding="utf-8") as f:
        out = csv.writer(f)
        out.writerow(COLUMNS)
        for ep in epochs[first + 1 :]:
            tp = est.step(ep)
            if tp is None:
                continue
            solved += 1
            res = fis.update(tp)
            la, lo, h = ecef_to_geodetic(*tp.pos_ecef_m)
            alert = bool(res is not None and res.alert)
            alerts += alert
            e, n, u = tp.delta_enu_m
            ok = res is not None and res.available
            track.append(
                TrackEpoch(
                    tp.t_s,
                    (float(e), float(n), float(u)),
                    res.slope_mps if ok and res is not None else math.nan,
                    res.residual_m2 if ok and res is not None else math.nan,
                    res.residual_limit_m2 if ok and res is not None else math.nan,
                    ok,
                    bool(res is not None and res.slope_alert),
                    bool(res is not None and res.residual_alert),
                )
            )
            out.writerow(
                [
                    f"{ep.tow_s:.3f}", f"{math.degrees(la):.9f}", f"{math.degrees(lo):.9f}",
                    f"{h:.4f}", f"{e:.4f}", f"{n:.4f}", f"{u:.4f}",
                    len({k[:2] for k in tp.keys}),
                    "" if res is None or not res.available else f"{res.slope_mps:.5f}",
                    "" if res is None or not res.available else f"{res.residual_m2:.5f}",
                    int(alert),
                ]
            )  # fmt: skip
    rejected.update(est.rejected)
    return InspectSummary(
        len(epochs),
        solved,
        alerts,
        ep0.tow_s,
        dict(rejected),
        fis.unavailable,
        fis.restarts,
        tuple(track),
        fis.config.slope_limit_mps,
    )


def parse_reference(text: str) -> tuple[float, float, float]:
    """``LAT,LON,ALT`` (degrees, degrees, metres above the ellipsoid)."""
    parts = text.split(",")
    if len(parts) != 3:
        raise ValueError(f"--reference wants LAT,LON,ALT, got {text!r}")
    lat, lon, alt = (float(p) for p in parts)
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
        raise ValueError(f"--reference out of range: {text!r}")
    return lat, lon, alt

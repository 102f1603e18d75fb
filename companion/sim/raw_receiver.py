"""A raw receiver beside a simulated flight: the autopilot's receiver 0 seen on its second port.

The ``[raw]`` link (:mod:`companion.raw.link`, docs/raw.md) needs what a u-blox receiver
wired to the companion computer delivers: the broadcast navigation words (RXM-SFRBX),
raw observations at each measurement epoch (RXM-RAWX) and the receiver's own solution
(NAV-PVT), which is also what the autopilot forwards as GPS_RAW_INT. This module makes
them for a :class:`~companion.sim.SimFlight`:

* **Orbits**: real broadcast ephemerides (the navigation words of a recording, e.g. the
  bundled walk cut) and the site they were recorded at: the flight must be flown there
  (:func:`site_overrides`: the scenario's origin, and its boot epoch so that the
  autopilot's UNIX time and the receiver's GPS time agree), within the ephemerides'
  validity.
* **Epochs** (:func:`companion.raw.simulate.simulate_flight`): at receiver 0's fix times,
  from the true antenna position (the simulator's antenna is at the IMU); none inside the
  receiver's own losses (the scenario's outages and no-fix periods, the realistic
  profile's GNSS gaps and no-fix windows). A dropout of every MAVLink stream or an
  autopilot reboot is the autopilot's link, not the receiver: its epochs go on.
* **NAV-PVT**: one per GPS_RAW_INT the autopilot delivered with a 3-D fix or better,
  with that message's latitude, longitude, heights, accuracies and fix (carrier solution
  2 / 1 for RTK fixed / float), at its time of validity: the link matches them to the
  autopilot's fixes to map GPS time onto the autopilot clock. A fix the autopilot's link
  lost has no NAV-PVT here (the receiver made one; nothing in the flight says what it
  held).

Every message is fed at its GPS time as UTC plus ``delay_s`` (the receiver's output
latency), as ``companion replay --raw`` feeds a recording
(:func:`companion.replay.timed_raw_items`).

Not modelled: multipath, the receiver's own solution being computed from these
observations (it is the simulator's fix, with its own error model), signals beyond GPS
L1 C/A and Galileo E1 (:mod:`companion.raw.simulate`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pymap3d

from companion.raw.lnav import Ephemeris
from companion.raw.obs import NavWords, PvtFix, RawEpoch
from companion.raw.simulate import RawSimConfig, simulate_flight
from companion.replay import (
    GPS_EPOCH_UNIX_S,
    GPS_UTC_LEAP_S,
    SECONDS_PER_WEEK,
    RawItem,
    timed_raw_items,
)
from companion.sim.flight import SimFlight, _lla
from companion.types import AutopilotFlavour, FixType, FloatArray

RAW_OUTPUT_DELAY_S = 0.05
"""The receiver's RXM-RAWX / NAV-PVT reach the companion this long after their epoch, s
(as ``bench/raw_link.py`` assumes for the autopilot's fixes)."""
SLIP_PROBABILITY_PER_S = 5e-4
"""Cycle slips per second per satellite: ``bench/tdprp.py``'s simulated approaches."""


@dataclasses.dataclass(frozen=True, slots=True)
class Site:
    """Where and when the ephemerides were recorded: the flight's origin and GPS time."""

    lat_deg: float
    lon_deg: float
    alt_msl_m: float
    geoid_undulation_m: float
    """Ellipsoidal minus MSL height, m."""
    week: int
    tow_first_s: float
    """Earliest GPS time of week a flight may start at (ephemerides valid), s."""
    tow_last_s: float
    """Latest GPS time of week a flight may end at, s."""


def site_of(pvt: PvtFix, week: int, ephemerides: dict[tuple[str, int], Ephemeris]) -> Site:
    """The site of a recording's first NAV-PVT; flights within 2 h of every ephemeris's
    reference time (the broadcast fit interval is 4 h, IS-GPS-200 20.3.4.4), less 10 min."""
    toes = [e.toe_s for e in ephemerides.values()]
    return Site(
        pvt.lat_deg,
        pvt.lon_deg,
        pvt.height_msl_m,
        pvt.height_m - pvt.height_msl_m,
        week,
        max(toes) - 7200.0 + 600.0,
        min(toes) + 7200.0 - 600.0,
    )


def boot_epoch_unix_s(site: Site, tow_boot_s: float) -> float:
    """UNIX time of the autopilot's boot when GPS time of week ``tow_boot_s`` is boot time 0."""
    return GPS_EPOCH_UNIX_S + site.week * SECONDS_PER_WEEK + tow_boot_s - GPS_UTC_LEAP_S


def site_overrides(site: Site, tow_boot_s: float) -> dict[str, float]:
    """Scenario fields that fly a flight at ``site`` with boot at GPS time ``tow_boot_s``."""
    return {
        "lat0_deg": site.lat_deg,
        "lon0_deg": site.lon_deg,
        "alt0_m": site.alt_msl_m,
        "geoid_undulation_m": site.geoid_undulation_m,
        "epoch0_s": boot_epoch_unix_s(site, tow_boot_s),
    }


def receiver_losses(flight: SimFlight) -> list[tuple[float, float]]:
    """Windows (first boot's clock, s) where receiver 0 itself delivers nothing usable: the
    scenario's outages and no-fix downgrades, the realistic GNSS gaps and no-fix periods."""
    out = [
        (e.t_start_s, e.t_end_s)
        for e in flight.scenario.events
        if e.receiver_id == 0
        and (e.kind == "outage" or (e.kind == "downgrade" and e.params.get("mode") == "none"))
    ]
    rz = flight.errors.realism
    if rz is not None:
        out += list(rz.gnss_gaps) + list(rz.gnss_nofix)
    return sorted(out)


def _delivered(flight: SimFlight) -> list[tuple[float, Any]]:
    """(time of validity on the first boot's clock, message) of every GPS_RAW_INT the
    autopilot delivered with a 3-D fix or better, in delivery order."""
    sc = flight.scenario
    ardupilot = sc.flavour is AutopilotFlavour.ARDUPILOT
    rz = flight.errors.realism
    reboot = rz.reboot_t_s if rz is not None else None
    out = []
    for t_rx, msg in flight.messages:
        if msg.get_type() != "GPS_RAW_INT" or msg.fix_type < FixType.FIX_3D:  # type: ignore[attr-defined]
            continue
        if ardupilot:  # UNIX time of the fix
            t_s = msg.time_usec / 1e6 - sc.epoch0_s  # type: ignore[attr-defined]
        else:  # time since (the last) boot
            t_s = msg.time_usec / 1e6  # type: ignore[attr-defined]
            if reboot is not None and t_rx - sc.epoch0_s >= reboot:
                t_s += reboot
        out.append((t_s, msg))
    return out


def delivered_fixes(flight: SimFlight) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Receiver 0's 3-D fixes as the autopilot delivered them, in time order: time of
    validity (first boot's clock, s) and the reported h_acc and v_acc (m)."""
    rows = sorted((t, msg.h_acc / 1000.0, msg.v_acc / 1000.0) for t, msg in _delivered(flight))
    a = np.array(rows, dtype=float).reshape(-1, 3)
    return a[:, 0], a[:, 1], a[:, 2]


def _pvts(flight: SimFlight, tow_boot_s: float) -> list[PvtFix]:
    """A NAV-PVT per GPS_RAW_INT delivered with a 3-D fix or better (module docstring)."""
    out: dict[float, PvtFix] = {}
    for t_s, msg in _delivered(flight):
        tow = round(tow_boot_s + t_s, 3)
        speed = msg.vel / 100.0  # type: ignore[attr-defined]
        cog = math.radians(msg.cog / 100.0)  # type: ignore[attr-defined]
        carrier = {FixType.RTK_FIXED: 2, FixType.RTK_FLOAT: 1}.get(msg.fix_type, 0)  # type: ignore[attr-defined]
        out[tow] = PvtFix(
            itow_s=tow,
            lat_deg=msg.lat / 1e7,  # type: ignore[attr-defined]
            lon_deg=msg.lon / 1e7,  # type: ignore[attr-defined]
            height_m=msg.alt_ellipsoid / 1000.0,  # type: ignore[attr-defined]
            height_msl_m=msg.alt / 1000.0,  # type: ignore[attr-defined]
            fix_type=3,
            carrier_solution=carrier,
            num_sv=int(msg.satellites_visible),  # type: ignore[attr-defined]
            h_acc_m=msg.h_acc / 1000.0,  # type: ignore[attr-defined]
            v_acc_m=msg.v_acc / 1000.0,  # type: ignore[attr-defined]
            vel_ned_mps=(speed * math.cos(cog), speed * math.sin(cog), 0.0),
        )
    return [out[k] for k in sorted(out)]


def raw_receiver_items(
    flight: SimFlight,
    site: Site,
    tow_boot_s: float,
    nav_words: Sequence[NavWords],
    ephemerides: dict[tuple[str, int], Ephemeris],
    rng: np.random.Generator,
    delay_s: float = RAW_OUTPUT_DELAY_S,
) -> list[tuple[float, RawItem]]:
    """The raw receiver's messages beside ``flight`` (module docstring), each with the UNIX
    time it is fed at; the flight must have been flown with :func:`site_overrides` of the
    same ``site`` and ``tow_boot_s``.

    Raises
    ------
    ValueError
        The flight was not flown there and then, or falls outside the ephemerides' validity.
    """
    sc = flight.scenario
    if abs(sc.epoch0_s - boot_epoch_unix_s(site, tow_boot_s)) > 1e-3:
        raise ValueError("the flight's boot epoch is not the raw receiver's tow_boot_s")
    if abs(sc.lat0_deg - site.lat_deg) > 0.1 or abs(sc.lon0_deg - site.lon_deg) > 0.1:
        raise ValueError("the flight is not flown at the ephemerides' site")
    t_fix = flight.errors.gnss[0].t_fix_s
    if len(t_fix) < 2:
        return timed_raw_items(list(nav_words), delay_s)
    if tow_boot_s + t_fix[0] < site.tow_first_s or tow_boot_s + t_fix[-1] > site.tow_last_s:
        raise ValueError("the flight falls outside the ephemerides' validity")
    frame = flight.frame
    t_first = float(t_fix[0])
    rate = sc.gnss_rate_hz
    n = int((t_fix[-1] - t_first) * rate) + 1
    # the antenna's ECEF position at every time simulate_flight asks for (each epoch and
    # 50 ms either side, for the velocity), evaluated on the path at once
    t_rel = (np.arange(n) / rate)[:, None] + np.array([0.0, 0.05, -0.05])[None, :]
    st = flight.truth.path.evaluate(t_first + t_rel.ravel())
    lat, lon, alt = _lla(frame, st.pos_ned_m)
    x, y, z = pymap3d.geodetic2ecef(lat, lon, alt + site.geoid_undulation_m, deg=False)
    ecef = np.column_stack([x, y, z])
    index = {round(float(t) * 1e6): i for i, t in enumerate(t_rel.ravel())}

    def antenna_ecef_m(t: float) -> np.ndarray:
        return ecef[index[round(t * 1e6)]]

    cfg = RawSimConfig(rate_hz=rate, slip_probability_per_s=SLIP_PROBABILITY_PER_S)
    epochs, _ = simulate_flight(
        ephemerides,
        tow_boot_s + t_first,
        float(t_fix[-1] - t_first),
        antenna_ecef_m,
        rng,
        cfg,
        site.week,
    )
    losses = receiver_losses(flight)
    kept: list[RawEpoch] = []
    for j, ep in enumerate(epochs):
        t = t_first + j / rate
        if not any(a <= t < b for a, b in losses):
            kept.append(ep)
    items: list[RawItem] = [*nav_words, *kept, *_pvts(flight, tow_boot_s)]
    return timed_raw_items(items, delay_s)

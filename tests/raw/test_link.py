"""The carrier-phase link (companion.raw.link): time mapping, epoch 0, counted rejections,
trust after a FIS-RAIM alert, silence; on the bundled walk cut."""

from __future__ import annotations

import dataclasses
import math
from functools import lru_cache

import numpy as np
import pytest

from companion.nav.frames import LocalFrame
from companion.raw.link import RawConfig, RawLink, TimeMap
from companion.raw.obs import NavWords, PvtFix, RawEpoch
from companion.types import Alert, AlertCode, FixType, GnssFix, NamedValue, RawSolution
from companion.ubx.reader import UbxSource

from .helpers import UBX

OFFSET_S = -408_600.0
"""The autopilot clock of these tests: GPS time of week plus this."""


@lru_cache(maxsize=1)
def _items() -> tuple[RawEpoch | NavWords | PvtFix, ...]:
    with open(UBX, "rb") as fh:
        return tuple(UbxSource(fh))


def _fix(pvt: PvtFix, offset_s: float = OFFSET_S) -> GnssFix:
    return GnssFix(
        pvt.itow_s + offset_s,
        0.0,
        0,
        FixType.RTK_FIXED,
        math.radians(pvt.lat_deg),
        math.radians(pvt.lon_deg),
        pvt.height_msl_m,
        None,
        None,
        0.0,
        None,
        0.014,
        0.01,
        None,
        None,
        None,
        20,
    )


def _run(
    items,
    config: RawConfig | None = None,
    offset_s: float = OFFSET_S,
    fixes: bool = True,
    nav_first: bool = True,
) -> tuple[RawLink, list[object]]:
    """Feed the link (navigation words first), with the autopilot's fix of each NAV-PVT."""
    link = RawLink(config or RawConfig(file="cut"))
    out: list[object] = []
    stream = list(items)
    if nav_first:
        stream = [i for i in stream if isinstance(i, NavWords)] + [
            i for i in stream if not isinstance(i, NavWords)
        ]
    for item in stream:
        out += link.on_item(item, 0.0)
        if fixes and isinstance(item, PvtFix):
            out += link.on_fix(_fix(item, offset_s))
    return link, out


def test_time_map_needs_agreeing_matches_and_maps_again_after_a_jump() -> None:
    tm = TimeMap(0.05)
    assert tm.add(10.0) and tm.to_autopilot_s(1.0) is None
    tm.add(10.01)
    tm.add(10.02)
    assert tm.offset_s == pytest.approx(10.01)
    assert not tm.add(20.0) and tm.offset_s is not None  # one mismatch: counted, kept
    assert not tm.add(20.0) and not tm.add(20.0)  # three in a row: the clock moved
    assert tm.offset_s is None
    for _ in range(3):
        tm.add(20.0)
    assert tm.to_autopilot_s(1.0) == pytest.approx(21.0)


def test_walk_cut_solutions_are_on_the_autopilot_clock_and_covered() -> None:
    """The autopilot's fixes are the receiver's NAV-PVT: the offset is found once the walk
    moves (standing still, positions repeat and tell nothing), and the carrier solution
    stays within its published 3 sigma of the receiver's own RTK fix."""
    link, out = _run(_items())
    sols = [o for o in out if isinstance(o, RawSolution)]
    assert link.clock.offset_s == pytest.approx(OFFSET_S, abs=1e-6)
    assert len(sols) > 100 and link.anchors == 1
    assert all(s.trusted for s in sols)  # FIS-RAIM available and quiet on the cut
    pvts = {round(p.itow_s, 2): p for p in _items() if isinstance(p, PvtFix)}
    worst = 0.0
    for s in sols:
        p = pvts[round(s.t_s - OFFSET_S, 2)]
        frame = LocalFrame(math.radians(p.lat_deg), math.radians(p.lon_deg), p.height_msl_m)
        err = frame.lla_to_ned(s.lat_rad, s.lon_rad, s.alt_msl_m)
        worst = max(worst, float(np.max(np.abs(err) / np.sqrt(np.diag(s.pos_cov_ned_m2)))))
    assert worst < 3.0
    rejected = link.rejections()
    assert rejected["time not mapped"] > 0  # the static start
    assert rejected["epoch 0: no ephemeris"] > 0  # BeiDou and the like have none decoded
    names = {o.name for o in out if isinstance(o, NamedValue)}
    assert {"CMP_RSTAT", "CMP_RSEP", "CMP_RSLP", "CMP_RRES", "CMP_RE", "CMP_RU"} <= names


def test_without_fixes_nothing_is_passed_on_but_counted() -> None:
    link, out = _run(_items(), fixes=False)
    assert not [o for o in out if isinstance(o, RawSolution)]
    assert link.rejections()["time not mapped"] > 100


def test_fixes_from_another_clock_are_mismatches_not_solutions() -> None:
    """Fixes whose positions match but with a time that jumps back and forth: counted."""
    link = RawLink(RawConfig(file="cut"))
    items = list(_items())
    for item in [i for i in items if isinstance(i, NavWords)]:
        link.on_item(item, 0.0)
    k = 0
    for item in items:
        if isinstance(item, NavWords):
            continue
        link.on_item(item, 0.0)
        if isinstance(item, PvtFix):
            k += 1
            link.on_fix(_fix(item, OFFSET_S + (0.0 if k < 120 else 0.2 * (k % 2))))
    assert link.rejections()["time mismatch"] > 0


def test_missing_ephemerides_are_counted_and_leave_no_epoch_0() -> None:
    """A receiver read from power-up: its observations before any navigation word."""
    obs = [i for i in _items() if not isinstance(i, NavWords)]
    link, out = _run(obs)
    assert not [o for o in out if isinstance(o, RawSolution)]
    assert link.anchors == 0
    assert link.rejections()["epoch 0: fewer than 5 satellites"] > 100


def test_bad_epochs_restart_the_run() -> None:
    items = list(_items())
    epochs = [i for i in items if isinstance(i, RawEpoch)]
    t_reset = epochs[80].tow_s
    t_gap = epochs[100].tow_s
    changed = []
    for item in items:
        if isinstance(item, RawEpoch) and item.tow_s == t_reset:
            item = dataclasses.replace(item, clock_reset=True)
        if isinstance(item, (RawEpoch, PvtFix)):
            tow = item.tow_s if isinstance(item, RawEpoch) else item.itow_s
            if t_gap <= tow < t_gap + 2.0:
                continue  # two seconds lost
        changed.append(item)
    link, out = _run(changed)
    rejected = link.rejections()
    assert rejected["receiver clock reset"] == 1 and rejected["gap in the epochs"] == 1
    anchors = {o.anchor_t_s for o in out if isinstance(o, RawSolution)}
    assert link.anchors == 3 and len(anchors) == 3


def test_a_silent_receiver_is_lost_then_back() -> None:
    """No epoch for 2 s of autopilot time while the fixes come: RAW_LOST, counted; the
    first solution after: RAW_BACK."""
    items = list(_items())
    epochs = [i for i in items if isinstance(i, RawEpoch)]
    t0, t1 = epochs[90].tow_s, epochs[90].tow_s + 3.0
    link = RawLink(RawConfig(file="cut"))
    out: list[object] = []
    for item in [i for i in items if isinstance(i, NavWords)]:
        link.on_item(item, 0.0)
    for item in items:
        if isinstance(item, NavWords):
            continue
        tow = item.tow_s if isinstance(item, RawEpoch) else item.itow_s
        if not t0 <= tow < t1:
            out += link.on_item(item, 0.0)
        if isinstance(item, PvtFix):
            out += link.on_fix(_fix(item))
    codes = [o.code for o in out if isinstance(o, Alert)]
    assert codes == [AlertCode.RAW_LOST, AlertCode.RAW_BACK]
    assert link.rejections()["receiver silent"] == 1


def test_after_an_alert_the_solution_is_not_trusted_until_it_passed_long_enough() -> None:
    """A dither alternates FIS-RAIM's alert and pass: the solution stays untrusted (it
    must not judge a receiver) until ``recovery_s`` of passing."""
    from companion.raw.faults import dither, inject

    items = list(_items())
    first = next(i.tow_s for i in items if isinstance(i, RawEpoch))
    faulty = []
    for item in items:
        if isinstance(item, RawEpoch):
            item = inject([item], "Galileo", 26, first + 15.0, dither(1.0, 10.0))[0]
        faulty.append(item)
    _, out = _run(faulty)
    sols = [o for o in out if isinstance(o, RawSolution)]
    alerts = [o for o in out if isinstance(o, Alert)]
    assert alerts and alerts[0].code is AlertCode.RAW_FAULT
    t_alert = alerts[0].t_s
    assert 0.0 < t_alert - (first + 15.0 + OFFSET_S) < 10.0
    after = [s for s in sols if s.t_s >= t_alert]
    assert after and not any(s.trusted for s in after)
    assert any(not (s.slope_alert or s.residual_alert) for s in after)  # passes between


def test_non_finite_measurements_are_counted_and_dropped() -> None:
    items = list(_items())
    bad = []
    for k, item in enumerate(items):
        if isinstance(item, RawEpoch) and k % 40 == 0:
            sig = dataclasses.replace(item.signals[0], pseudorange_m=math.nan)
            item = dataclasses.replace(item, signals=(sig, *item.signals[1:]))
        bad.append(item)
    link, out = _run(bad)
    assert link.rejections()["non-finite measurement"] >= 3
    sols = [o for o in out if isinstance(o, RawSolution)]
    assert len(sols) > 100 and all(np.all(np.isfinite(s.pos_cov_ned_m2)) for s in sols)

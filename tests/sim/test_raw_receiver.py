"""A simulated flight with the [raw] link's receiver beside it (companion.sim.raw_receiver):
flown at the walk cut's site and time, its carrier-phase solutions reach the integrity
monitor through the replay, and the receiver's own losses have no epochs."""

from __future__ import annotations

import dataclasses
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest

import companion.sim as sim
from companion.config import Config
from companion.raw.broadcast import collect_ephemerides
from companion.raw.obs import PvtFix, RawEpoch
from companion.replay import replay
from companion.sim.raw_receiver import (
    raw_receiver_items,
    receiver_losses,
    site_of,
    site_overrides,
)
from companion.sim.scenarios import Event
from companion.sim.writer import write_tlog
from companion.ubx.reader import read_file

CUT = Path(__file__).resolve().parents[1] / "data" / "walk_0827" / "gnss_1730_cut.ubx"


@lru_cache(maxsize=1)
def walk():
    epochs, words, pvts, _ = read_file(str(CUT))
    ephs, _ = collect_ephemerides(words)
    return site_of(pvts[0], epochs[0].week, ephs), words, ephs


def _flight(tow_boot_s: float, **over):
    site, _, _ = walk()
    sc = sim.make_scenario(
        "px4_rotorcraft", duration_s=70.0, **over, **site_overrides(site, tow_boot_s)
    )
    return sim.simulate(sc, seed=3)


def test_the_carrier_solutions_reach_the_monitor(tmp_path: Path) -> None:
    site, words, ephs = walk()
    tow_boot = site.tow_first_s + 1000.0
    # a 4 s outage of the receiver itself at 40 s: no epoch there
    flight = _flight(tow_boot, events=(Event("outage", 40.0, 44.0),))
    items = raw_receiver_items(flight, site, tow_boot, words, ephs, np.random.default_rng(1))
    epochs = [i for _, i in items if isinstance(i, RawEpoch)]
    pvts = [i for _, i in items if isinstance(i, PvtFix)]
    assert len(epochs) > 250 and len(pvts) > 250
    assert receiver_losses(flight) == [(40.0, 44.0)]
    assert not [e for e in epochs if 40.0 <= e.tow_s - tow_boot < 44.0 - 0.01]
    cfg = Config()
    cfg = dataclasses.replace(cfg, raw=dataclasses.replace(cfg.raw, file="(replay)"))
    tlog = write_tlog(flight, tmp_path / "in.tlog")
    summary = replay(tlog, tmp_path / "out.tlog", cfg, raw=items)
    assert summary.raw_solutions > 150
    assert summary.integrity_stats.get("raw_reference_tested", 0) > 100
    assert "FAULT" not in summary.alerts and "RAW_FAULT" not in summary.alerts
    # every alert raised is logged with the log time that raised it, in order
    logged = [a.code.value for _, a in summary.alert_log]
    assert {c: logged.count(c) for c in set(logged)} == summary.alerts
    times = [t for t, _ in summary.alert_log]
    assert times == sorted(times)


def test_a_flight_outside_the_ephemerides_or_the_site_is_refused() -> None:
    site, words, ephs = walk()
    flight = _flight(site.tow_first_s + 500.0)
    rng = np.random.default_rng(1)
    with pytest.raises(ValueError, match="boot epoch"):
        raw_receiver_items(flight, site, site.tow_first_s + 600.0, words, ephs, rng)
    late = site.tow_last_s - 30.0
    with pytest.raises(ValueError, match="validity"):
        raw_receiver_items(_flight(late), site, late, words, ephs, rng)
    elsewhere = sim.simulate(sim.make_scenario("px4_rotorcraft", duration_s=30.0), seed=1)
    with pytest.raises(ValueError):
        raw_receiver_items(elsewhere, site, site.tow_first_s, words, ephs, rng)

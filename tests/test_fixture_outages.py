"""The outage acceptance on the bundled flights: stale fixes are flagged within 2 s
and never fused, after every outage the first fix fused has passed the gate, and every
RTK_LOST is followed by its RTK_BACK when RTK returns."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import pytest

from companion.config import Config, load_config
from companion.mavlink.decode import LIGHT_MESSAGE_IDS
from companion.mavlink.tlog import TlogReader
from companion.nav.blend import BlendNavigator
from companion.nav.outage import OUTAGE_MODES
from companion.pipeline import Pipeline
from companion.types import AlertCode, NavMode

FIXTURES = Path(__file__).resolve().parent.parent / "sitl_fixtures"
STALE_WITHIN_S = 2.0
"""The acceptance bound on the GNSS_STALE delay, s."""


@dataclass(frozen=True)
class Offer:
    """One fix offered to the blend: when, with the gate or not, in which mode, the result."""

    t_s: float
    gate: bool
    mode: NavMode
    fused: bool
    nis: float
    threshold: float


def _replay(name: str, config: Config, monkeypatch: pytest.MonkeyPatch):
    pipeline = Pipeline(config)
    offers: list[Offer] = []
    on_gnss = BlendNavigator.on_gnss

    def spy(self, meas, *, gate=True):  # type: ignore[no-untyped-def]
        mode = pipeline.engine.outage.mode
        update = on_gnss(self, meas, gate=gate)
        offers.append(Offer(meas.t_s, gate, mode, update.fused, update.nis, update.gate))
        return update

    monkeypatch.setattr(BlendNavigator, "on_gnss", spy)
    for t_rx_s, msg in TlogReader(FIXTURES / f"{name}.tlog", light_ids=LIGHT_MESSAGE_IDS):
        pipeline.on_message(msg, t_rx_s)
    events = json.loads((FIXTURES / f"{name}.json").read_text())["events"]
    return pipeline, offers, events


def test_stale_fixes_are_flagged_within_2_s_and_never_fused(monkeypatch):
    pipeline, offers, events = _replay("stale_fix", Config(), monkeypatch)
    stale = [e for e in events if e["kind"] == "stale"]
    alerts = [a.t_s for a in pipeline.alerts if a.code is AlertCode.GNSS_STALE]
    assert len(stale) == 2
    for ev in stale:
        t0, t1 = ev["t_start_s"], ev["t_end_s"]
        assert any(t0 <= t < t0 + STALE_WITHIN_S for t in alerts), (t0, alerts)
        frozen = [o for o in offers if t0 <= o.t_s < t1]
        assert not any(o.fused for o in frozen), [o for o in frozen if o.fused][:3]


@pytest.mark.parametrize(
    ("name", "config", "gap"),
    [
        # an RTK outage downgrades the fix (DEGRADED): GNSS itself never stops
        ("approach_rtk20", "tactical.toml", False),
        ("approach_rtk40", None, False),
        ("cruise_gnss_loss", None, True),
        ("stale_fix", None, True),
    ],
)
def test_after_every_outage_the_first_fused_fix_passed_the_gate(name, config, gap, monkeypatch):
    cfg = load_config(FIXTURES / config) if config else Config()
    _, offers, _ = _replay(name, cfg, monkeypatch)
    firsts, in_outage = [], False
    for o in offers:
        in_outage = in_outage or o.mode in OUTAGE_MODES
        if in_outage and o.fused:
            firsts.append(o)
            in_outage = False
    if gap:
        assert firsts, "the flight has a GNSS gap: some fix must be fused after it"
    for o in firsts:
        assert o.gate, f"t={o.t_s:.2f} s: fused after an outage without the gate"
        assert o.nis <= o.threshold


@pytest.mark.parametrize(
    ("name", "config", "lost_after_s", "back_type"),
    [
        # corrections extrapolated 3 s, then RTK float 5 s, then 3D until they return
        ("approach_rtk20", "tactical.toml", 8.0, "RTK_FLOAT"),
        ("approach_rtk40", None, 8.0, "RTK_FLOAT"),
        # a receiver downgraded to 3D for 20 s, then RTK fixed again
        ("px4_rotorcraft", None, 0.0, "RTK_FIXED"),
    ],
)
def test_every_rtk_lost_has_its_rtk_back_when_rtk_returns(
    name, config, lost_after_s, back_type, monkeypatch
):
    cfg = load_config(FIXTURES / config) if config else Config()
    pipeline, _, events = _replay(name, cfg, monkeypatch)
    rtk = [a for a in pipeline.alerts if a.code in (AlertCode.RTK_LOST, AlertCode.RTK_BACK)]
    assert [a.code for a in rtk] == [AlertCode.RTK_LOST, AlertCode.RTK_BACK], rtk
    lost, back = rtk
    (event,) = events
    t0, t1 = event["t_start_s"], event["t_end_s"]
    # one fix period (0.1 s at 10 Hz, 0.2 s at PX4's 5 Hz) after each edge
    assert t0 + lost_after_s <= lost.t_s <= t0 + lost_after_s + 0.25
    assert t1 <= back.t_s <= t1 + 0.25
    assert back.text == f"rx0 -> {back_type} after {back.t_s - lost.t_s:.1f} s"

"""The signal monitor (companion.integrity.signal): JAM once per episode with its end, a
flickering flag one episode, silence neither ending nor prolonging it; the spoofing API
the SPOOF logic reads (the receiver's own verdict held, our tests', the evidence); the
published integrity report's states; an autopilot reboot."""

from __future__ import annotations

import pytest

from companion.integrity.signal import (
    JAM_IND_CLEAN_MEAN,
    JAM_IND_CLEAN_SIGMA,
    SignalMonitor,
    SignalMonitorConfig,
)
from companion.types import (
    AlertCode,
    GnssSignalReport,
    IntegrityReport,
    InterferenceState,
    Severity,
)

S = InterferenceState


def _r(
    t: float,
    jam: InterferenceState = S.CLEAN,
    spoof: InterferenceState = S.CLEAN,
    source: str = "raw",
    rx: int = 0,
    ind: float | None = None,
    evidence: tuple[str, ...] = (),
    spoof_evidence: tuple[str, ...] = (),
) -> GnssSignalReport:
    return GnssSignalReport(
        t, rx, source, jam, spoof, ind, evidence + spoof_evidence, spoof_evidence
    )


def _codes(alerts) -> list[AlertCode]:
    return [a.code for a in alerts]


def test_jam_is_raised_once_per_episode_and_ended_after_clean_for_its_dwell() -> None:
    m = SignalMonitor()
    out = []
    for t in range(0, 10):
        out += m.on_report(_r(float(t)))
    assert out == [] and m.jamming_state(9.0) is S.CLEAN
    evidence = ("C/N0 9.0 dB-Hz below its baseline on 10 signals",)
    for t in range(10, 30):  # flickering: jammed, clean, jammed... inside the dwell
        out += m.on_report(_r(float(t), S.DETECTED if t % 3 else S.CLEAN, evidence=evidence))
    assert _codes(out) == [AlertCode.JAM]
    assert out[0].severity is Severity.WARNING and out[0].t_s == 10.0
    assert out[0].text == "rx0 raw: C/N0 9.0 dB-Hz below its baseline on 10 signals"
    assert m.jamming_state(29.0) is S.DETECTED
    for t in range(30, 45):
        out += m.on_report(_r(float(t)))
    assert _codes(out) == [AlertCode.JAM, AlertCode.JAM_END]
    end = out[1]
    assert end.t_s == 40.0 and end.severity is Severity.NOTICE  # clean from 30 s, for 10 s
    assert end.text == "clean for 10 s after 30 s"
    assert m.jamming_state(44.0) is S.CLEAN


def test_silence_neither_ends_nor_prolongs_an_episode() -> None:
    m = SignalMonitor()
    assert _codes(m.on_report(_r(0.0, S.DETECTED))) == [AlertCode.JAM]
    # the jammed receiver says nothing for a minute: the service cannot say it is over
    assert m.jamming_state(60.0) is S.DETECTED
    assert m.on_report(_r(60.0, S.UNKNOWN)) == []  # unknown is not clean
    out = []
    for t in range(61, 75):
        out += m.on_report(_r(float(t)))
    assert _codes(out) == [AlertCode.JAM_END] and out[0].t_s == 71.0
    assert m.jamming_state(200.0) is S.UNKNOWN  # nothing current: not monitored


def test_a_mitigated_jamming_is_published_as_mitigated() -> None:
    m = SignalMonitor()
    m.on_report(_r(0.0, S.MITIGATED, source="receiver", evidence=("receiver jamming warning",)))
    assert m.jamming_state(0.5) is S.MITIGATED
    m.on_report(_r(1.0, S.DETECTED, source="raw"))
    assert m.jamming_state(1.5) is S.DETECTED


def test_the_jamming_indicator_limit_is_the_clean_logs_quantile() -> None:
    cfg = SignalMonitorConfig()
    limit = cfg.jam_indicator_limit
    assert JAM_IND_CLEAN_MEAN + 4.5 * JAM_IND_CLEAN_SIGMA < limit
    assert limit < JAM_IND_CLEAN_MEAN + 5.0 * JAM_IND_CLEAN_SIGMA
    assert 80 / 255 < limit < 90 / 255  # the clean logs reached 57 of 255
    m = SignalMonitor()
    assert m.on_report(_r(0.0, S.CLEAN, source="receiver", ind=57 / 255)) == []
    out = m.on_report(_r(1.0, S.CLEAN, source="receiver", ind=150 / 255))
    assert _codes(out) == [AlertCode.JAM] and "jamming indicator 0.59 (limit 0.33)" in out[0].text
    with pytest.raises(ValueError):
        SignalMonitorConfig(hold_s=0.0)


def test_the_receivers_own_spoofing_verdict_is_held_through_a_flicker() -> None:
    m = SignalMonitor()
    own = ("receiver multiple spoofing indications (NAV-STATUS)",)
    assert m.receiver_verdict(0, 0.0) is S.UNKNOWN
    m.on_report(_r(0.0, source="receiver"))
    assert m.receiver_verdict(0, 0.5) is S.CLEAN
    assert m.on_report(_r(1.0, spoof=S.DETECTED, source="receiver", spoof_evidence=own)) == []
    m.on_report(_r(2.0, spoof=S.CLEAN, source="receiver"))  # flickers back
    m.on_report(_r(3.0, spoof=S.MITIGATED, source="receiver", spoof_evidence=own))
    for t in (3.0, 5.0, 11.0):  # held 10 s after the last report saying it
        assert m.receiver_verdict(0, t) is S.DETECTED
    m.on_report(_r(12.0, spoof=S.CLEAN, source="receiver"))
    assert m.receiver_verdict(0, 12.0) is S.DETECTED  # DETECTED said at 1 s, 3 s...
    assert m.receiver_verdict(0, 13.5) is S.CLEAN  # ... held to 13 s
    assert m.receiver_verdict(1, 5.0) is S.UNKNOWN  # another receiver: nothing said
    assert m.tested_verdict(0, 5.0) is S.UNKNOWN  # our tests said nothing either


def test_spoof_evidence_cites_every_source_the_receivers_own_first() -> None:
    m = SignalMonitor()
    m.on_report(_r(0.0, spoof=S.DETECTED, spoof_evidence=("C/N0 spread 0.4 dB-Hz",)))
    m.on_report(
        _r(1.0, spoof=S.DETECTED, source="autopilot",
           spoof_evidence=("receiver spoofing detected (GNSS_INTEGRITY)",))
    )  # fmt: skip
    m.on_report(_r(1.0, spoof=S.DETECTED, rx=1, spoof_evidence=("clock step 30 m",)))
    assert m.spoof_evidence(0, 2.0) == (
        "autopilot: receiver spoofing detected (GNSS_INTEGRITY)",
        "raw: C/N0 spread 0.4 dB-Hz",
    )
    assert m.tested_verdict(0, 2.0) is S.DETECTED and m.receiver_verdict(0, 2.0) is S.DETECTED
    assert m.spoof_evidence(0, 10.5) == ("autopilot: receiver spoofing detected (GNSS_INTEGRITY)",)
    assert m.spoof_evidence(0, 20.0) == ()
    assert m.spoof_evidence(1, 2.0) == ("raw: clock step 30 m",)
    assert m.stats["spoofing_raw"] == 2 and m.stats["reports_autopilot"] == 1


def test_the_published_report_carries_the_services_verdicts() -> None:
    m = SignalMonitor()
    rep = IntegrityReport(5.0, 3.0, 4.0, True, False)
    assert m.stamp(rep) == rep  # nothing monitored: unknown, unknown
    m.on_report(_r(4.0))
    clean = m.stamp(rep)
    assert (clean.jamming, clean.spoofing) == (S.CLEAN, S.CLEAN)
    m.on_report(_r(4.5, S.DETECTED, S.DETECTED, spoof_evidence=("x",)))
    both = m.stamp(rep)
    assert (both.jamming, both.spoofing) == (S.DETECTED, S.DETECTED)
    # the SPOOF logic's own verdict, when it set one, is published as it is
    mitigated = IntegrityReport(5.0, 3.0, 4.0, True, False, spoofing=S.MITIGATED)
    assert m.stamp(mitigated).spoofing is S.MITIGATED


def test_an_autopilot_reboot_keeps_the_episode_and_its_dwell() -> None:
    m = SignalMonitor()
    m.on_report(_r(500.0, S.DETECTED))
    assert m.on_report(_r(505.0)) == []  # clean from 505 s
    # the autopilot reboots: its clock starts again near 0
    assert m.on_report(_r(3.0)) == []
    assert m.stats["clock_restarts"] == 1
    out = []
    for t in range(4, 16):
        out += m.on_report(_r(float(t)))
    assert _codes(out) == [AlertCode.JAM_END] and out[0].t_s == 13.0  # clean since 505 -> 3

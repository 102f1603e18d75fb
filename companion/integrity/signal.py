"""Signal-level interference: reports in, ``JAM`` / ``JAM_END`` out, and each receiver's
spoofing evidence for the ``SPOOF`` logic (pure: no I/O, no clock).

Takes every :class:`~companion.types.GnssSignalReport` (:meth:`SignalMonitor.on_report`).
Its ``source`` says who speaks:

* ``"autopilot"``: the receiver's own flags as the autopilot relays them (GNSS_INTEGRITY,
  a PX4 log's ``sensor_gps`` flags);
* ``"receiver"``: the receiver's own indicators read on the raw link (u-blox NAV-STATUS
  ``spoofDetState``, MON-RF ``jammingState`` / ``jamInd``);
* ``"raw"``: the service's own signal tests on the raw link's epochs
  (:mod:`companion.raw.signal`: C/N0 uniformity, common C/N0 steps and level, receiver
  clock steps, Doppler against the code's motion).

The first two are **the receiver's own verdict**, the third **our tests' verdict**.

Jamming
-------
``CMP JAM <evidence>`` (WARNING) when any current report (one not older than
``stale_s``) says jamming (MITIGATED or DETECTED), or carries a jamming indicator above
:attr:`SignalMonitorConfig.jam_indicator_limit` (the clean indicator's mean plus its
``P_FA`` quantile, from the real logs). ``CMP JAM_END`` (NOTICE) once the current
reports have said clean, with none jammed, for ``jam_clear_s`` without a break. One of
each per episode: a flag that flickers inside ``jam_clear_s`` is one episode. Reports
that stop (a receiver that lost everything, a link that died) neither prolong nor end an
episode: the service cannot say the jamming is over, so ``JAM`` stands.

Spoofing: the API the ``SPOOF`` logic reads
-------------------------------------------
Per receiver and at the engine's time ``t_s``:

* :meth:`SignalMonitor.receiver_verdict` -- the receiver's own spoofing verdict
  (``"autopilot"`` and ``"receiver"``): the most severe state said within ``hold_s``
  (MITIGATED, DETECTED), else the newest current report's (CLEAN), else UNKNOWN;
* :meth:`SignalMonitor.tested_verdict` -- the same for our tests (``"raw"``);
* :meth:`SignalMonitor.spoof_evidence` -- every spoofing evidence text said within
  ``hold_s``, each prefixed by its source (``"receiver: multiple spoofing indications
  (NAV-STATUS)"``, ``"raw: C/N0 spread 0.7 dB-Hz over 11 signals (limit 1.1)"``), for
  the alert's text.

The hold is the hysteresis: a flag that flickers is one continuous verdict.

**A receiver that says it is spoofed.** The receiver's own DETECTED (u-blox: multiple
spoofing indications; GNSS_INTEGRITY and PX4: DETECTED, which PX4 also sends for a
single u-blox indication) is taken at its word: the service raises ``SPOOF`` citing it
and stops trusting that receiver (excluded, as a receiver shown wrong by a reference),
re-admitted only once its verdict has been below DETECTED for ``hold_s`` *and* the
independent references agree with it again -- never on its own flag alone. MITIGATED
(u-blox: one indication; older PX4: "indicated") and our tests' DETECTED are
**evidence**: cited in ``SPOOF`` and weighed with the inertial and separation tests, no
exclusion on their own (our C/N0 tests are blind to a spoofer that matches a real sky's
power and clock; a single u-blox indication has false alarms). The ``SPOOF`` alert and
the exclusion are :mod:`companion.integrity`'s spoofing logic's; this module only says.

What is published
-----------------
:meth:`SignalMonitor.stamp` fills an :class:`~companion.types.IntegrityReport`
(GNSS_INTEGRITY): ``jamming`` is :meth:`jamming_state` (DETECTED while ``JAM`` stands,
MITIGATED when every jammed source says only that, CLEAN when monitored, UNKNOWN when
no report is current); ``spoofing`` is the report's own when the ``SPOOF`` logic set it
(not UNKNOWN), else :meth:`spoofing_state` (the most severe receiver verdict, CLEAN
when monitored, UNKNOWN when nothing reports).

References
----------
u-blox F9 interface description (NAV-STATUS ``spoofDetState``, MON-RF ``jammingState``,
``jamInd``); MAVLink development set, GNSS_INTEGRITY and GPS_JAMMING_STATE /
GPS_SPOOFING_STATE. docs/methods.md ("Signal-level evidence").
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass

from scipy.stats import norm

from companion.types import (
    Alert,
    AlertCode,
    GnssSignalReport,
    IntegrityReport,
    InterferenceState,
    Severity,
)

log = logging.getLogger(__name__)

OWN_SOURCES = frozenset({"autopilot", "receiver"})
"""Sources that carry the receiver's own verdict."""
TESTED_SOURCES = frozenset({"raw"})
"""Sources that carry the service's own signal tests."""
SEVERITY = {
    InterferenceState.UNKNOWN: 0,
    InterferenceState.CLEAN: 1,
    InterferenceState.MITIGATED: 2,
    InterferenceState.DETECTED: 3,
}
"""Order of the states, least to most severe."""
PRESENT = frozenset({InterferenceState.MITIGATED, InterferenceState.DETECTED})
JAM_IND_CLEAN_MEAN = 32.1 / 255.0
"""Mean of u-blox ``jamInd`` (scaled to 0..1) in clean flights: 618 samples of five real
logs (four ArduPilot .bin UBX1, one PX4 .ulg; 7 to 57 of 255, bench/signal_tests.py)."""
JAM_IND_CLEAN_SIGMA = 10.9 / 255.0
"""Its standard deviation over the same samples (between the logs' means: 11.7; within a
log: 6.8)."""
REBOOT_BACKJUMP_S = 1.0
"""A report this much older than the newest is on a restarted autopilot clock."""


@dataclass(frozen=True, slots=True)
class SignalMonitorConfig:
    """The monitor's dwell times and its jamming-indicator probability."""

    jam_clear_s: float = 10.0
    """Clean reports for this long, without a break, end a jamming episode, s."""
    hold_s: float = 10.0
    """A spoofing verdict or evidence stands this long after the last report saying it, s
    (the hysteresis of :meth:`SignalMonitor.receiver_verdict`)."""
    stale_s: float = 5.0
    """A source silent this long is no longer current, s."""
    jam_indicator_false_alarm: float = 1e-6
    """Probability that a clean receiver's jamming indicator passes the limit, per report."""

    def __post_init__(self) -> None:
        for name in ("jam_clear_s", "hold_s", "stale_s"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0")
        if not 0.0 < self.jam_indicator_false_alarm < 0.5:
            raise ValueError("jam_indicator_false_alarm must be in (0, 0.5)")

    @property
    def jam_indicator_limit(self) -> float:
        """A scaled jamming indicator above this is jamming (1e-6: 0.33, i.e. 84 of 255)."""
        z = float(norm.isf(self.jam_indicator_false_alarm))
        return JAM_IND_CLEAN_MEAN + z * JAM_IND_CLEAN_SIGMA


@dataclass(slots=True)
class _Source:
    """The newest report of one (receiver, source), and its spoofing hold."""

    report: GnssSignalReport
    t_s: float
    spoof_t_s: float = -math.inf
    """When it last said spoofing (MITIGATED or DETECTED)."""
    spoof_state: InterferenceState = InterferenceState.UNKNOWN
    """The most severe spoofing state said since the hold began."""
    spoof_evidence: tuple[str, ...] = ()


class SignalMonitor:
    """See the module docstring. ``stats`` counts reports by source and what they said."""

    def __init__(self, config: SignalMonitorConfig | None = None) -> None:
        self.config = config or SignalMonitorConfig()
        self._jam_limit = self.config.jam_indicator_limit
        self._sources: dict[tuple[int, str], _Source] = {}
        self._last_t_s = -math.inf
        self.jam_since_s: float | None = None
        """When the standing jamming episode began (None: none)."""
        self._clean_since_s: float | None = None
        self.stats: dict[str, int] = {}

    # ------------------------------------------------------------------ input

    def on_report(self, report: GnssSignalReport) -> list[Alert]:
        """Take one report; ``JAM`` / ``JAM_END`` when the episode starts or ends."""
        t = report.t_s
        if not math.isfinite(t):
            self._count("bad_report_time")
            return []
        if t < self._last_t_s - REBOOT_BACKJUMP_S:
            self._rebase(t - self._last_t_s)
        self._last_t_s = max(self._last_t_s, t)
        self._count(f"reports_{report.source}")
        key = (report.receiver_id, report.source)
        src = self._sources.get(key)
        if src is None:
            src = self._sources[key] = _Source(report, t)
        src.report, src.t_s = report, t
        if report.spoofing in PRESENT:
            self._count(f"spoofing_{report.source}")
            if t - src.spoof_t_s > self.config.hold_s:
                src.spoof_state = report.spoofing
            elif SEVERITY[report.spoofing] > SEVERITY[src.spoof_state]:
                src.spoof_state = report.spoofing
            src.spoof_t_s = t
            src.spoof_evidence = report.spoofing_evidence or (f"spoofing {report.spoofing.value}",)
        return self._jam_episode(t)

    # ------------------------------------------------------------------ spoofing API

    def receiver_verdict(self, receiver_id: int, t_s: float) -> InterferenceState:
        """The receiver's own spoofing verdict at ``t_s`` (the module docstring)."""
        return self._verdict(receiver_id, t_s, OWN_SOURCES)

    def tested_verdict(self, receiver_id: int, t_s: float) -> InterferenceState:
        """Our signal tests' spoofing verdict on the receiver at ``t_s``."""
        return self._verdict(receiver_id, t_s, TESTED_SOURCES)

    def spoof_evidence(self, receiver_id: int, t_s: float) -> tuple[str, ...]:
        """Every spoofing evidence said about the receiver within ``hold_s`` of ``t_s``,
        each ``"<source>: <text>"``, the receiver's own first."""
        out: list[str] = []
        for (rx, source), src in sorted(
            self._sources.items(), key=lambda kv: (kv[0][1] not in OWN_SOURCES, kv[0][1])
        ):
            if rx == receiver_id and 0.0 <= t_s - src.spoof_t_s <= self.config.hold_s:
                out += [f"{source}: {text}" for text in src.spoof_evidence]
        return tuple(out)

    def spoofing_state(self, t_s: float) -> InterferenceState:
        """The most severe spoofing verdict of any receiver (own or tested) at ``t_s``."""
        worst = InterferenceState.UNKNOWN
        for rx in {rx for rx, _ in self._sources}:
            for state in (self.receiver_verdict(rx, t_s), self.tested_verdict(rx, t_s)):
                if SEVERITY[state] > SEVERITY[worst]:
                    worst = state
        return worst

    def jamming_state(self, t_s: float) -> InterferenceState:
        """The service's jamming verdict at ``t_s`` (the module docstring)."""
        current = self._current(t_s)
        if self.jam_since_s is not None:
            jammed = [s for s in current if self._jammed(s.report)]
            if jammed and all(s.report.jamming is InterferenceState.MITIGATED for s in jammed):
                return InterferenceState.MITIGATED
            return InterferenceState.DETECTED
        if current:
            return InterferenceState.CLEAN
        return InterferenceState.UNKNOWN

    def stamp(self, report: IntegrityReport) -> IntegrityReport:
        """``report`` with the service's jamming and spoofing verdicts (GNSS_INTEGRITY)."""
        t = report.t_s
        spoofing = report.spoofing
        if spoofing is InterferenceState.UNKNOWN:
            spoofing = self.spoofing_state(t)
        jamming = self.jamming_state(t)
        if spoofing is report.spoofing and jamming is report.jamming:
            return report
        return dataclasses.replace(report, spoofing=spoofing, jamming=jamming)

    # ------------------------------------------------------------------ internals

    def _count(self, name: str) -> None:
        self.stats[name] = self.stats.get(name, 0) + 1

    def _rebase(self, shift_s: float) -> None:
        """The autopilot clock restarted: every time kept moves with it (the dwell and
        hold times continue)."""
        for src in self._sources.values():
            src.t_s += shift_s
            src.spoof_t_s += shift_s
        if self.jam_since_s is not None:
            self.jam_since_s += shift_s
        if self._clean_since_s is not None:
            self._clean_since_s += shift_s
        self._last_t_s += shift_s
        self._count("clock_restarts")

    def _current(self, t_s: float) -> list[_Source]:
        stale = self.config.stale_s
        return [s for s in self._sources.values() if 0.0 <= t_s - s.t_s <= stale]

    def _verdict(self, receiver_id: int, t_s: float, sources: frozenset[str]) -> InterferenceState:
        cfg = self.config
        held = InterferenceState.UNKNOWN
        newest: _Source | None = None
        for (rx, source), src in self._sources.items():
            if rx != receiver_id or source not in sources:
                continue
            if (
                0.0 <= t_s - src.spoof_t_s <= cfg.hold_s
                and SEVERITY[src.spoof_state] > SEVERITY[held]
            ):
                held = src.spoof_state
            if 0.0 <= t_s - src.t_s <= cfg.stale_s and (newest is None or src.t_s > newest.t_s):
                newest = src
        if held is not InterferenceState.UNKNOWN:
            return held
        return newest.report.spoofing if newest is not None else InterferenceState.UNKNOWN

    def _jammed(self, report: GnssSignalReport) -> bool:
        ind = report.jam_indicator
        return report.jamming in PRESENT or (ind is not None and ind > self._jam_limit)

    def _jam_evidence(self, current: list[_Source]) -> str:
        parts = []
        for src in current:
            r = src.report
            if not self._jammed(r):
                continue
            texts = [e for e in r.evidence if e not in r.spoofing_evidence]
            ind = r.jam_indicator
            if ind is not None and ind > self._jam_limit:
                texts.append(f"jamming indicator {ind:.2f} (limit {self._jam_limit:.2f})")
            if not texts:
                texts = [f"jamming {r.jamming.value}"]
            parts.append(f"rx{r.receiver_id} {r.source}: " + ", ".join(texts))
        return "; ".join(parts)

    def _jam_episode(self, t_s: float) -> list[Alert]:
        current = self._current(t_s)
        jammed = any(self._jammed(s.report) for s in current)
        clean = any(s.report.jamming is InterferenceState.CLEAN for s in current)
        if self.jam_since_s is None:
            if not jammed:
                return []
            self.jam_since_s = t_s
            self._clean_since_s = None
            text = self._jam_evidence(current)
            log.warning("jamming: %s", text)
            return [Alert(t_s, AlertCode.JAM, Severity.WARNING, text)]
        if jammed or not clean:
            self._clean_since_s = None
            return []
        if self._clean_since_s is None:
            self._clean_since_s = t_s
        clean_s = t_s - self._clean_since_s
        if clean_s < self.config.jam_clear_s:
            return []
        lasted_s = t_s - self.jam_since_s
        self.jam_since_s = None
        self._clean_since_s = None
        text = f"clean for {clean_s:.0f} s after {lasted_s:.0f} s"
        log.info("jamming over: %s", text)
        return [Alert(t_s, AlertCode.JAM_END, Severity.NOTICE, text)]

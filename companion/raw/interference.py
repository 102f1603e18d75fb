"""The raw receiver's interference reports: its own indicators and our signal tests, as
:class:`~companion.types.GnssSignalReport` samples on the autopilot clock (pure).

Two sources, told apart by ``GnssSignalReport.source``:

* ``"receiver"``: the receiver's own verdicts (u-blox NAV-STATUS ``spoofDetState``,
  MON-RF / MON-HW ``jammingState`` and ``jamInd``), mapped onto MAVLink's states
  (:func:`receiver_states`): 0 unknown, 1 clean, 2 MITIGATED (jamming: "interference
  visible, fix ok"; spoofing: one indication), 3 DETECTED ("interference visible and no
  fix"; multiple spoofing indications). ``jamInd`` is passed on scaled to 0..1.
* ``"raw"``: the signal tests of :mod:`companion.raw.signal` on each epoch.

A source's report goes out when its states or evidence change, and otherwise every
``report_interval_s`` of receiver time (the monitor needs to hear that a source is
clean to end an episode). A report whose receiver time is not mapped onto the
autopilot's yet is not passed on (counted).
"""

from __future__ import annotations

import dataclasses
import math
from collections import Counter

import numpy as np

from companion.nav.frames import geodetic_to_ecef_m
from companion.raw.lnav import Ephemeris
from companion.raw.obs import PvtFix, RawEpoch, ReceiverStatus
from companion.raw.orbit import FloatArray
from companion.raw.signal import SignalTestConfig, SignalTests
from companion.types import GnssSignalReport, InterferenceState

UBLOX_STATES = (
    InterferenceState.UNKNOWN,
    InterferenceState.CLEAN,
    InterferenceState.MITIGATED,
    InterferenceState.DETECTED,
)
"""u-blox ``jammingState`` / ``spoofDetState`` 0..3 as MAVLink's states."""
JAMMING_WORDS = ("unknown", "ok", "warning (interference, fix ok)", "critical (no fix)")
SPOOFING_WORDS = ("unknown", "none", "spoofing indicated", "multiple spoofing indications")
JAM_IND_FULL_SCALE = 255.0
"""u-blox ``jamInd`` at strong CW jamming."""
REPORT_INTERVAL_S = 1.0
"""A source's unchanged verdict is reported again after this long (receiver time)."""


def receiver_states(
    status: ReceiverStatus,
) -> tuple[InterferenceState, InterferenceState, tuple[str, ...], tuple[str, ...]]:
    """(jamming, spoofing, jamming evidence, spoofing evidence) of the receiver's own
    indicators; a value out of 0..3 is UNKNOWN."""
    jam = spoof = InterferenceState.UNKNOWN
    jam_text: list[str] = []
    spoof_text: list[str] = []
    js = status.jamming_state
    if js is not None and 0 <= js <= 3:
        jam = UBLOX_STATES[js]
        if js >= 2:
            jam_text.append(f"receiver jamming {JAMMING_WORDS[js]} ({status.source})")
    ss = status.spoof_det_state
    if ss is not None and 0 <= ss <= 3:
        spoof = UBLOX_STATES[ss]
        if ss >= 2:
            spoof_text.append(f"receiver {SPOOFING_WORDS[ss]} ({status.source})")
    return jam, spoof, tuple(jam_text), tuple(spoof_text)


class InterferenceReports:
    """See the module docstring. ``rejected`` counts what was not passed on."""

    def __init__(
        self,
        receiver_id: int,
        config: SignalTestConfig | None = None,
        report_interval_s: float = REPORT_INTERVAL_S,
    ) -> None:
        self.receiver_id = receiver_id
        self.tests = SignalTests(config)
        self.report_interval_s = report_interval_s
        self.rejected: Counter[str] = Counter()
        self._last: dict[str, tuple[float, tuple[object, ...]]] = {}
        """Source -> (receiver time, content) of its last report."""
        self._tow_s: float | None = None
        """The receiver time of the newest epoch (MON-RF and MON-HW carry none)."""
        self._rx_ecef_m: FloatArray | None = None
        self.reports = 0

    def on_epoch(
        self,
        epoch: RawEpoch,
        pvt: PvtFix | None,
        t_s: float | None,
        ephemerides: dict[tuple[str, int], Ephemeris],
    ) -> list[GnssSignalReport]:
        """The tests of one epoch (``pvt``: its receiver solution, for the lines of
        sight; ``t_s``: its autopilot time, None when not mapped yet)."""
        self._tow_s = epoch.tow_s
        if pvt is not None and pvt.fix_type >= 3 and math.isfinite(pvt.height_m):
            self._rx_ecef_m = np.asarray(
                geodetic_to_ecef_m(
                    math.radians(pvt.lat_deg), math.radians(pvt.lon_deg), pvt.height_m
                )
            )
        v = self.tests.on_epoch(epoch, self._rx_ecef_m, ephemerides)
        evidence = v.jamming_evidence + v.spoofing_evidence
        # the evidence's names, not its numbers, decide whether it changed
        kinds = tuple(" ".join(text.split()[:2]) for text in evidence)
        report = GnssSignalReport(
            t_s=math.nan,
            receiver_id=self.receiver_id,
            source="raw",
            jamming=v.jamming,
            spoofing=v.spoofing,
            evidence=evidence,
            spoofing_evidence=v.spoofing_evidence,
        )
        return self._emit("raw", epoch.tow_s, (v.jamming, v.spoofing, kinds), report, t_s)

    def on_status(self, status: ReceiverStatus, t_s: float | None) -> list[GnssSignalReport]:
        """The receiver's own indicators (``t_s``: the autopilot time of its receiver time,
        None when not mapped)."""
        tow = status.itow_s if status.itow_s is not None else self._tow_s
        if tow is None:
            self.rejected["receiver status before any epoch"] += 1
            return []
        jam, spoof, jam_text, spoof_text = receiver_states(status)
        jam_ind = status.jam_indicator
        report = GnssSignalReport(
            t_s=math.nan,
            receiver_id=self.receiver_id,
            source="receiver",
            jamming=jam,
            spoofing=spoof,
            jam_indicator=None if jam_ind is None else jam_ind / JAM_IND_FULL_SCALE,
            evidence=jam_text + spoof_text,
            spoofing_evidence=spoof_text,
        )
        key = f"receiver {status.source}"
        level = None if jam_ind is None else jam_ind // 16  # a change of 16 is news
        return self._emit(key, tow, (jam, spoof, level), report, t_s)

    def _emit(
        self,
        key: str,
        tow_s: float,
        content: tuple[object, ...],
        report: GnssSignalReport,
        t_s: float | None,
    ) -> list[GnssSignalReport]:
        last = self._last.get(key)
        if (
            last is not None
            and last[1] == content
            and 0.0 <= tow_s - last[0] < self.report_interval_s
        ):
            return []
        if t_s is None or not math.isfinite(t_s):
            self.rejected["signal report: time not mapped"] += 1
            return []
        self._last[key] = (tow_s, content)
        self.reports += 1
        return [dataclasses.replace(report, t_s=t_s)]

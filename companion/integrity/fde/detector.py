"""Receiver fault detection and exclusion: every GNSS fix tested, a faulty receiver excluded.

:meth:`FaultDetector.on_fix` runs for every GNSS fix the navigator was offered:
the fix-level tests (:mod:`companion.integrity.fde.fix_tests`) and solution
separation of this receiver against the other receivers and any independent
reference solutions (:mod:`companion.integrity.fde.pairs`). A failed fix is
counted and alerted (``CMP FAULT ...``); a receiver found faulty
(:mod:`companion.integrity.fde.attribution`) is *excluded* for ``recovery_s``
after its last failure (:meth:`FaultDetector.exclude` tells the engine not to
offer its fixes). A fault that cannot be attributed to one receiver (two
receivers disagree and nothing else arbitrates), or a failed fix the navigator
fused anyway, leaves the fault *unresolved*: integrity is lost until
``recovery_s`` passes without a failure. A reference that fails against a
receiver the navigator does not fuse, while another receiver is in use, proves
nothing about it (the reference carries the fused receiver's errors): the fault
is unresolved.

Pure: no I/O, no clock; time is the fixes' ``t_s`` (and the published
solutions', through :meth:`FaultDetector.advance`).
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from companion.integrity.config import IntegrityConfig
from companion.integrity.fde.attribution import Attribution
from companion.integrity.fde.fix_tests import FixTests, valid_measurement
from companion.integrity.fde.pairs import BARO_REF, REF_PREFIX, PairSeparations
from companion.integrity.fde.receivers import ReceiverState, is_excluded
from companion.nav.baro import BaroReference
from companion.nav.frames import LocalFrame, rotation_between_frames
from companion.nav.navigator import GnssMeasurement, GnssUpdate, NavState
from companion.types import Alert, AlertCode, GnssFix, Output, Severity

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class FixCheck:
    """The verdict of :meth:`FaultDetector.on_fix` on the last fix (for callers and tests)."""

    t_s: float
    receiver_id: int
    failed: bool
    reasons: tuple[str, ...]
    culprits: tuple[int, ...]
    unresolved: bool


class FaultDetector:
    """Fault detection and exclusion over the receivers' fixes (see the module docstring).

    ``stats`` (shared with the rest of the monitor) counts every rejection by reason;
    ``last_check`` is the verdict on the last fix.
    """

    def __init__(self, config: IntegrityConfig, stats: Counter[str]) -> None:
        self.config = config
        self.stats = stats
        self._fix_tests = FixTests(config.false_alarm_prob, stats)
        self._receivers: dict[int, ReceiverState] = {}
        self.pairs = PairSeparations(config, stats)
        self.attribution = Attribution(config, self._receivers, self.pairs)
        self.reset()

    # ------------------------------------------------------------------ state

    def reset(self) -> None:
        """Forget every receiver, pair and fault (autopilot reboot)."""
        self._receivers.clear()
        self.pairs.reset()
        self.attribution.reset()
        self._unresolved_until_s = -math.inf
        self._unresolved_alerted = False
        self._fault_sep_h_m = 0.0
        self._fault_sep_v_m = 0.0
        self.now_s: float | None = None
        """The latest time seen (fixes and published solutions), s."""
        self.last_check: FixCheck | None = None

    def advance(self, t_s: float) -> None:
        """Move the clock to ``t_s`` if it is later (exclusions and faults expire by it)."""
        if self.now_s is None or t_s > self.now_s:
            self.now_s = t_s

    def exclude(self, receiver_id: int) -> bool:
        """True when ``receiver_id`` is currently excluded (do not fuse its fixes)."""
        return is_excluded(self._receivers, receiver_id, self.now_s)

    def shown_wrong(self, receiver_id: int) -> bool:
        """True while ``receiver_id`` is excluded on a separation test's evidence (another
        receiver, a reference), not on its innovation alone."""
        rx = self._receivers.get(receiver_id)
        return rx is not None and self.now_s is not None and self.now_s < rx.shown_wrong_until_s

    def pardon(self, receiver_id: int) -> None:
        """Lift an exclusion: the engine reset the navigator to this receiver (rejected by
        the innovation alone for too long while self-consistent), so the innovation that
        excluded it measured the navigator's error, not the receiver's."""
        rx = self._receivers.get(receiver_id)
        if rx is None:
            return
        if self.now_s is not None and self.now_s < rx.excluded_until_s:
            self.stats["pardoned"] += 1
        rx.excluded_until_s = -math.inf
        rx.alerted = False
        rx.last_nis = 0.0

    def reseed(self, receiver_ids: list[int] | None = None, *, series: bool = True) -> None:
        """The service changed itself (:meth:`IntegrityMonitor.service_changed`): the
        separation series of these receivers (None: every one seen) restart (unless
        ``series`` is False) and their innovation memory is forgotten (it measured them
        against the service as it was)."""
        ids = list(self._receivers) if receiver_ids is None else receiver_ids
        for rid in ids:
            if series:
                self.pairs.restart_receiver(rid, reason="self_change")
            rx = self._receivers.get(rid)
            if rx is not None:
                rx.last_nis = 0.0
                rx.last_nis_t_s = -math.inf

    @property
    def fault_detected(self) -> bool:
        """True while a fault is unresolved or any receiver is excluded."""
        if self.now_s is None:
            return False
        if self.now_s < self._unresolved_until_s:
            return True
        return any(self.now_s < rx.excluded_until_s for rx in self._receivers.values())

    @property
    def fault_unresolved(self) -> bool:
        """True while a detected fault is not attributed to an excluded receiver."""
        return self.now_s is not None and self.now_s < self._unresolved_until_s

    def accuracy_floor_m(self) -> tuple[float, float]:
        """Horizontal and vertical 1-sigma the published accuracies must not undercut, m.

        While a fault is unresolved, two solutions disagree by the largest failing
        separation seen and nothing says which is right: the published solution may be
        off by that much, so GPS_INPUT's accuracies widen to at least it. (0, 0) otherwise.
        """
        if not self.fault_unresolved:
            return 0.0, 0.0
        return self._fault_sep_h_m, self._fault_sep_v_m

    def shift_frame(self, old: LocalFrame, new: LocalFrame) -> None:
        """Re-express stored fixes in the engine's new local frame (re-anchoring)."""
        rot = rotation_between_frames(old, new)
        for rx in self._receivers.values():
            m = rx.last_meas
            if m is None:
                continue
            lat, lon, alt = old.ned_to_lla(m.pos_ned_m)
            rx.last_meas = GnssMeasurement(
                t_s=m.t_s,
                pos_ned_m=new.lla_to_ned(lat, lon, alt),
                pos_var_ned_m2=m.pos_var_ned_m2,
                vel_ned_mps=rot @ np.nan_to_num(m.vel_ned_mps),
                vel_var_ned_m2ps2=m.vel_var_ned_m2ps2,
                fix_type=m.fix_type,
                receiver_id=m.receiver_id,
            )
        self.pairs.rotate(rot)

    # ------------------------------------------------------------------ per fix

    def on_fix(
        self,
        fix: GnssFix,
        meas: GnssMeasurement,
        update: GnssUpdate | None,
        predicted: NavState | None = None,
        references: Mapping[str, NavState] | None = None,
        baro: BaroReference | None = None,
    ) -> list[Output]:
        """Test one fix; returns FAULT alerts (at the onset of a fault, not per fix).

        Parameters
        ----------
        fix : the receiver's fix (for the receiver id and the alert text).
        meas : the same fix in the local NED frame.
        update : what the navigator did with it (its innovation chi-square), or None
            when it was not offered (e.g. the receiver is excluded).
        predicted : the position-potential filter's prediction at the fix time, or None.
        references : independent solutions at (about) the fix time, by name.
        baro : the calibrated barometric height at the fix time (a vertical-only
            independent solution), or None. A disagreement with it leaves the fault
            unresolved (nothing tells which height is wrong).
        """
        t = meas.t_s
        rid = meas.receiver_id
        if not valid_measurement(meas):
            self.stats["bad_measurement"] += 1
            log.warning("rx%d fix at t=%.2f s rejected: non-finite position or variance", rid, t)
            return []
        self.advance(t)
        rx = self._receivers.get(rid)
        if rx is None:
            rx = self._receivers[rid] = ReceiverState()
        reasons: list[str] = []
        culprits: set[int] = set()
        independent: set[int] = set()
        # culprits blamed by a separation test: independent evidence, never pardoned
        unresolved = False
        attribution = self.attribution

        if rx.last_meas is not None and rx.last_meas.fix_type != meas.fix_type:
            self.pairs.restart_receiver(rid)
        sep_results = self.pairs.separations(meas, self._receivers, references, baro, fix.alt_msl_m)
        innov_failed, fix_reasons = self._fix_tests.run(meas, update, predicted)
        if update is not None and update.dof > 0 and math.isfinite(update.nis):
            rx.last_nis = update.nis / update.dof
            rx.last_nis_t_s = t
        if fix_reasons:
            reasons += fix_reasons
            # while a fault is unresolved the navigator may have absorbed it already: a
            # failed innovation test then says nothing about this receiver
            if innov_failed and (
                self.fault_unresolved or not attribution.innovation_is_own(rid, t, sep_results)
            ):
                unresolved = True
                reasons.append("the navigator disagrees with other receivers too")
            else:
                culprits.add(rid)
            if update is not None and update.fused:
                unresolved = True
                reasons.append("fused by the navigator")

        for key, res in sep_results.items():
            if not res.failed:
                continue
            reasons += [f"{key[0]}-{key[1]} {r}" for r in res.reasons]
            self._fault_sep_h_m = max(self._fault_sep_h_m, float(np.hypot(*res.sep_ned_m[:2])))
            self._fault_sep_v_m = max(self._fault_sep_v_m, abs(float(res.sep_ned_m[2])))
            if key[1] == BARO_REF:
                # the receiver's height against the barometer's (calibrated against the
                # fused receiver while no fault is detected)
                self.stats["baro_disagrees"] += 1
                if rid in culprits or t < rx.excluded_until_s:
                    self.stats["baro_vs_excluded"] += 1  # already found faulty
                elif update is None and self._other_receivers(rid, t):
                    # not fused, another receiver is: the receiver pair's own tests judge
                    self.stats["baro_vs_unfused"] += 1
                else:
                    # two heights, and nothing to say which is wrong
                    unresolved = True
                    if attribution.episode_start_s is None:
                        attribution.episode_start_s = t
                continue
            if key[1].startswith(REF_PREFIX):
                if rid in culprits or t < rx.excluded_until_s:
                    culprits.add(rid)  # already found faulty: it stays excluded
                    independent.add(rid)
                elif update is None and self._other_receivers(rid, t):
                    # the reference was anchored from the navigator, which fuses another
                    # receiver: it may carry that one's fault; a disagreement, unresolved
                    self.stats["reference_vs_unfused"] += 1
                    unresolved = True
                    if attribution.episode_start_s is None:
                        attribution.episode_start_s = t
                elif attribution.reference_trusted(key):
                    culprits.add(rid)
                    independent.add(rid)
                else:
                    self.stats["reference_untrusted"] += 1
                continue
            if attribution.episode_start_s is None:
                attribution.episode_start_s = t
            a, b = int(key[0][2:]), int(key[1][2:])
            culprit = attribution.arbitrate(a, b, key, culprits, self.now_s)
            if culprit is None:
                unresolved = True
            else:
                culprits.add(culprit)
                independent.add(culprit)

        rx.last_meas = meas
        outputs: list[Output] = []
        for cid in sorted(culprits):
            outputs += self._exclude_receiver(cid, t, reasons)
            if cid in independent:
                self._receivers[cid].shown_wrong_until_s = t + self.config.recovery_s
        if unresolved:
            self.stats["unresolved"] += 1
            self._unresolved_until_s = t + self.config.recovery_s
            if not self._unresolved_alerted:
                self._unresolved_alerted = True
                text = f"unresolved: {'; '.join(reasons)}"
                outputs.append(Alert(t, AlertCode.FAULT, Severity.CRITICAL, text[:120]))
                log.warning("integrity fault unresolved at t=%.2f s: %s", t, text)
        elif t >= self._unresolved_until_s:
            self._unresolved_alerted = False
            self._fault_sep_h_m = self._fault_sep_v_m = 0.0
        if not reasons and t >= rx.excluded_until_s:
            rx.alerted = False
        if attribution.episode_start_s is not None and not self.fault_detected:
            attribution.episode_start_s = None
        self.last_check = FixCheck(
            t, rid, bool(reasons), tuple(reasons), tuple(sorted(culprits)), unresolved
        )
        return outputs

    def _other_receivers(self, rid: int, t: float) -> bool:
        """Is another receiver, not excluded, giving fixes (within one separation window)?"""
        horizon = self.config.separation_window_s
        return any(
            qid != rid
            and q.last_meas is not None
            and t - q.last_meas.t_s <= horizon
            and not t < q.excluded_until_s
            for qid, q in self._receivers.items()
        )

    def _exclude_receiver(self, rid: int, t: float, reasons: list[str]) -> list[Output]:
        rx = self._receivers.setdefault(rid, ReceiverState())
        rx.excluded_until_s = t + self.config.recovery_s
        rx.last_fail_t_s = t
        self.stats["fault_fixes"] += 1
        if rx.alerted:
            return []
        rx.alerted = True
        self.stats["fault_alerts"] += 1
        text = f"rx{rid} excluded: {'; '.join(reasons)}"
        log.warning("t=%.2f s: %s", t, text)
        return [Alert(t, AlertCode.FAULT, Severity.WARNING, text[:120])]

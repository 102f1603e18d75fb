"""Which solutions are separated: receiver pairs and receivers against reference solutions.

Receiver pairs: a later fix of one receiver against the latest fix of the
other, extrapolated with its velocity. Each receiver against each *reference*
the caller passes: solutions that by construction do not contain this
receiver's recent fixes (an INS prediction coasting from a reset older than the
window, a second navigator that excludes the receiver). A navigator that fuses
the receiver follows a slow ramp (its innovation stays small), which is why its
own prediction is used only in the fix-level tests
(:mod:`companion.integrity.fde.fix_tests`).

An inertial reference (:class:`companion.integrity.coast.CoastState`) drifts:
its separation series restarts when it re-anchors (a step at re-anchoring is
not a fault), and its window tests account for its velocity and acceleration
error (:class:`companion.integrity.fde.separation.ReferenceDrift`).

A pair is keyed by the two solutions' names: ``("rx0", "rx1")`` (lower receiver
id first) or ``("rx0", "ref:ins2")``.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Mapping

import numpy as np

from companion.integrity.coast import CoastState
from companion.integrity.config import IntegrityConfig
from companion.integrity.fde.receivers import ReceiverState
from companion.integrity.fde.separation import ReferenceDrift, SeparationResult, SeparationTracker
from companion.integrity.fde.vertical import VerticalSeparation
from companion.nav.baro import BaroReference
from companion.nav.navigator import AnchoredState, GnssMeasurement, NavState
from companion.types import FloatArray

log = logging.getLogger(__name__)

PairKey = tuple[str, str]
REF_PREFIX = "ref:"
BARO_REF = REF_PREFIX + "baro"
"""The barometer's name in a pair key (a vertical-only reference)."""
"""Prefix of a reference solution's name in a pair key (receivers are ``rx<id>``)."""
_FLOAT_MAX = float(np.finfo(float).max)
"""What ``np.nan_to_num`` puts for an infinity (with its sign)."""


class PairSeparations:
    """The separation trackers of every pair, their latest results and the references' anchors.

    ``latest`` holds each pair's last :class:`SeparationResult` (the evidence for
    attributing a fault); ``ref_anchor_t_s`` the anchor time of each reference pair's
    series. ``stats`` (shared with the rest of the monitor) counts skipped and failed
    separations by reason.
    """

    def __init__(self, config: IntegrityConfig, stats: Counter[str]) -> None:
        self.config = config
        self.stats = stats
        self.reset()

    def reset(self) -> None:
        """Forget every pair."""
        self._trackers: dict[PairKey, SeparationTracker] = {}
        self.latest: dict[PairKey, SeparationResult] = {}
        self._used: dict[PairKey, dict[int, float]] = {}
        """Per receiver pair, the time of each receiver's fix last paired (each once)."""
        self.ref_anchor_t_s: dict[PairKey, float] = {}
        self._vertical: dict[PairKey, VerticalSeparation] = {}
        self._baro_epoch: dict[PairKey, int] = {}

    def restart_receiver(self, receiver_id: int, reason: str = "fix_type") -> None:
        """Restart every separation series of a receiver (its fix type changed, or the
        service changed how it places the receiver's fixes: ``reason`` "self_change").

        The window tests assume one error process over the window; a change of fix type
        (RTK fixed to float, float to 3-D, back) changes the receiver's error and its
        stated accuracy at once, a jump that is not a fault (as Kim, Walter and Powell
        keep one satellite set per approach: a change causes jumps). A self-change also
        forgets the series' latest results, the evidence attribution reads: they measured
        the receiver as it was placed before."""
        tag = f"rx{receiver_id}"
        for key, tracker in self._trackers.items():
            if tag in key:
                tracker.reset()
        for key, vertical in self._vertical.items():
            if tag in key:
                vertical.reset()
        if reason != "fix_type":
            for key in [k for k in self.latest if tag in k]:
                del self.latest[key]
        self.stats[f"series_restarted_{reason}"] += 1

    def rotate(self, rot: FloatArray) -> None:
        """Re-express every series with a (3, 3) frame rotation (the engine re-anchored)."""
        for tracker in self._trackers.values():
            tracker.rotate(rot)
        # heights do not rotate: the barometer's series stand

    def separations(
        self,
        meas: GnssMeasurement,
        receivers: Mapping[int, ReceiverState],
        references: Mapping[str, NavState] | None,
        baro: BaroReference | None = None,
        alt_msl_m: float | None = None,
    ) -> dict[PairKey, SeparationResult]:
        """This fix's separations from the other receivers' latest fixes, then from the
        references, then (its height ``alt_msl_m``) from the barometer, by pair key (only
        the pairs tested at this epoch)."""
        results: dict[PairKey, SeparationResult] = {}
        if len(receivers) > 1:
            self._receiver_separations(meas, receivers, results)
        if references:
            self._reference_separations(meas, references, results)
        if baro is not None and alt_msl_m is not None:
            self._baro_separation(meas, baro, alt_msl_m, results)
        return results

    def restart_baro(self) -> None:
        """Restart every barometer series (not tested for a while: ground effect, no baro)."""
        for vertical in self._vertical.values():
            vertical.reset()

    def _baro_separation(
        self,
        meas: GnssMeasurement,
        baro: BaroReference,
        alt_msl_m: float,
        results: dict[PairKey, SeparationResult],
    ) -> None:
        """The receiver's height less the calibrated barometer's (vertical only)."""
        key = (f"rx{meas.receiver_id}", BARO_REF)
        vertical = self._vertical.get(key)
        cfg = self.config
        if vertical is None:
            vertical = self._vertical[key] = VerticalSeparation(
                cfg.baro_window_s,
                cfg.min_window_points,
                cfg.false_alarm_prob,
                cfg.slope_false_alarm_prob,
                cfg.residual_false_alarm_prob,
            )
        if self._baro_epoch.get(key) != baro.epoch:
            self._baro_epoch[key] = baro.epoch  # a new calibration: a new series
            vertical.reset()
        try:
            res = vertical.update(
                meas.t_s,
                alt_msl_m - baro.alt_msl_m,
                float(meas.pos_var_ned_m2[2]),
                baro.white_var_m2,
                baro.offset_var_m2,
                baro.drift_var_m2ps2,
            )
        except ValueError as exc:
            self.stats["bad_separation"] += 1
            log.warning("barometer separation at t=%.2f s skipped: %s", meas.t_s, exc)
            return
        self.latest[key] = res
        results[key] = res
        for reason in ("slope", "residual", "separation"):
            if any(r.startswith(reason) for r in res.reasons):
                self.stats[f"baro_{reason}"] += 1

    def _tracker(self, key: PairKey) -> SeparationTracker:
        tracker = self._trackers.get(key)
        if tracker is None:
            cfg = self.config
            tracker = SeparationTracker(
                cfg.separation_window_s,
                cfg.min_window_points,
                cfg.false_alarm_prob,
                cfg.slope_false_alarm_prob,
                cfg.residual_false_alarm_prob,
            )
            self._trackers[key] = tracker
        return tracker

    def _receiver_separations(
        self,
        meas: GnssMeasurement,
        receivers: Mapping[int, ReceiverState],
        results: dict[PairKey, SeparationResult],
    ) -> None:
        cfg = self.config
        t = meas.t_s
        rid = meas.receiver_id
        px, py, pz = meas.pos_ned_m.tolist()
        fix_var = meas.pos_var_ned_m2.tolist()
        default_vel_var = cfg.default_vel_var_m2ps2
        for qid, other in receivers.items():
            m = other.last_meas
            if qid == rid or m is None:
                continue
            dt = t - m.t_s
            if not 0.0 <= dt <= cfg.pair_max_dt_s:
                continue
            lo, hi = sorted((rid, qid))
            key = (f"rx{lo}", f"rx{hi}")
            used = self._used.setdefault(key, {})
            if m.t_s <= used.get(qid, -math.inf):
                continue  # each fix of the other receiver is paired once
            used[rid] = t
            used[qid] = m.t_s
            # the other fix carried by dt with its velocity, per axis in floats (3-vectors)
            vn, ve, vd = _nan_to_num(m.vel_ned_mps.tolist())
            vel_var = [
                v if math.isfinite(v) else default_vel_var for v in m.vel_var_ned_m2ps2.tolist()
            ]
            mn, me, md = m.pos_ned_m.tolist()
            sep = [px - (mn + vn * dt), py - (me + ve * dt), pz - (md + vd * dt)]
            if rid != lo:
                sep = [-sep[0], -sep[1], -sep[2]]
            other_var = m.pos_var_ned_m2.tolist()
            cov = np.diag([fix_var[i] + (other_var[i] + vel_var[i] * dt * dt) for i in range(3)])
            res = self._update(key, t, np.array(sep), cov)
            if res is not None:
                results[key] = res

    def _reference_separations(
        self,
        meas: GnssMeasurement,
        references: Mapping[str, NavState],
        results: dict[PairKey, SeparationResult],
    ) -> None:
        cfg = self.config
        t = meas.t_s
        rid = meas.receiver_id
        r_fix = np.diag(meas.pos_var_ned_m2)
        px, py, pz = meas.pos_ned_m.tolist()
        tag = f"rx{rid}"
        for name, ref in references.items():
            dt = t - ref.t_s
            if abs(dt) > cfg.pair_max_dt_s:
                self.stats["reference_too_old"] += 1
                continue
            vn, ve, vd = _nan_to_num(ref.vel_ned_mps.tolist())
            rn, re, rd = ref.pos_ned_m.tolist()
            # the fix less the reference carried by dt, per axis in floats (3-vector)
            sep = np.array([px - (rn + vn * dt), py - (re + ve * dt), pz - (rd + vd * dt)])
            cov = r_fix + ref.pos_cov_ned_m2 + ref.vel_cov_ned_m2ps2 * dt * dt
            key = (tag, REF_PREFIX + name)
            drift: ReferenceDrift | None = None
            if isinstance(ref, CoastState):
                if t - ref.anchor_t_s > cfg.reference_max_age_s:
                    self.stats["reference_coasted_too_long"] += 1
                    continue
                drift = self._coast_drift(key, ref, meas)
                if drift is None:
                    continue
            elif isinstance(ref, AnchoredState):
                self._restart_at_anchor(key, ref.anchor_t_s)
            res = self._update(key, t, sep, cov, drift)
            if res is not None:
                results[key] = res

    def _restart_at_anchor(self, key: PairKey, anchor_t_s: float) -> None:
        """A reference anchored again (its constant error changed by a step): the pair's
        series starts again, as a coasting reference's does at its re-anchoring."""
        if self.ref_anchor_t_s.get(key) != anchor_t_s:
            if key in self.ref_anchor_t_s:
                self.stats["reference_reanchored"] += 1
            self.ref_anchor_t_s[key] = anchor_t_s
            self._tracker(key).reset()

    def _coast_drift(
        self, key: PairKey, ref: CoastState, meas: GnssMeasurement
    ) -> ReferenceDrift | None:
        """The drift of an inertial reference for the window tests; restarts the pair's
        series when the reference re-anchored. None (counted) when it is unusable."""
        anchor = ref.anchor_t_s
        if self.ref_anchor_t_s.get(key) != anchor:
            if key in self.ref_anchor_t_s:
                self.stats["reference_reanchored"] += 1
            self.ref_anchor_t_s[key] = anchor
            self._tracker(key).reset()
        acc_cov = ref.acc_cov_ned_m2ps4
        if acc_cov is None or not math.isfinite(ref.vrw_psd_m2ps3):
            self.stats["bad_reference"] += 1
            return None
        w = self.config.separation_window_s
        try:
            return ReferenceDrift(
                # the fix's variance plus the reference's velocity random walk integrated
                # over one window (an upper bound of its variance about the window's line)
                window_var_m2=meas.pos_var_ned_m2 + ref.vrw_psd_m2ps3 * w**3 / 3.0,
                vel_var_m2ps2=ref.vel_cov_ned_m2ps2.diagonal().copy(),
                acc_var_m2ps4=acc_cov.diagonal().copy(),
            )
        except ValueError as exc:
            self.stats["bad_reference"] += 1
            log.warning("reference %s at t=%.2f s skipped: %s", key[1], meas.t_s, exc)
            return None

    def _update(
        self,
        key: PairKey,
        t: float,
        sep: FloatArray,
        cov: FloatArray,
        drift: ReferenceDrift | None = None,
    ) -> SeparationResult | None:
        try:
            res = self._tracker(key).update(t, sep, cov, drift)
        except ValueError as exc:
            self.stats["bad_separation"] += 1
            log.warning("separation %s-%s at t=%.2f s skipped: %s", key[0], key[1], t, exc)
            return None
        self.latest[key] = res
        if not res.reasons:
            return res
        for reason in ("slope", "residual", "separation"):
            if any(r.startswith(reason) for r in res.reasons):
                self.stats[f"separation_{reason}"] += 1
        return res


def _nan_to_num(values: list[float]) -> list[float]:
    """``np.nan_to_num`` on a few floats: NaN to 0, +-inf to +-the largest float (exactly
    numpy's values, without a numpy call per fix)."""
    if all(map(math.isfinite, values)):
        return values
    return [
        v if math.isfinite(v) else 0.0 if math.isnan(v) else math.copysign(_FLOAT_MAX, v)
        for v in values
    ]

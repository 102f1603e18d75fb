"""The spoofing monitor: receivers that move unlike the IMU, held out until they agree.

:class:`SpoofMonitor` integrates the IMU (:mod:`.inertial`), runs each receiver's drag
test (:mod:`.drag`) on its velocity while airborne, and arbitrates:

* **Detection.** ``persist_fixes`` consecutive failed fixes spanning ``persist_s``:
  ``CMP SPOOF rxN moves <a> m/s2 unlike the IMU over <tau> s ...``. The reference that
  saw it is frozen into an :class:`~.episode.Episode`, the receiver is held out
  (:meth:`SpoofMonitor.excluded`) and the navigator is given that reference carried to
  now (:attr:`SpoofStep.rollback`): what it took from the receiver since the anchor is
  undone.
* **While held out** each of its fixes is compared with the episode's reference (the
  IMU since the anchor, never a solution that has taken its fixes, never the receiver's
  own consistency); the horizontal separation is a floor of the horizontal protection
  level (:meth:`SpoofMonitor.hpl_floor_m`): the service carries a position the receiver
  contradicts, and says by how much.
* **Re-admission** once its position and velocity have agreed with the reference for
  ``readmit_s`` (within the chi-square quantile of ``readmit_false_alarm_prob``), never
  while the receiver's own flag says DETECTED: ``CMP SPOOF_END``. When the reference
  could no longer have seen the largest separation of the episode (its own uncertainty
  grew past it: a MEMS IMU after a minute or two; or nothing ever separated), the
  agreement is *unverified*: the protection level keeps the larger of that separation and
  what the reference cannot rule out, and the alert says so.

Pure: no I/O, no clock.

References
----------
Tanil, Khanafseh, Joerger and Pervan (2018), the INS monitor against spoofers that track
the vehicle; Kim, Walter and Powell (solution separation, exclusion and re-admission).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections import Counter
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from companion.integrity.spoof.config import GRADE_FIELDS, SpoofConfig
from companion.integrity.spoof.drag import DragTest, DragVerdict
from companion.integrity.spoof.episode import Episode, Reference, horizontal_distance2
from companion.integrity.spoof.inertial import InertialIncrements
from companion.nav.navigator import GnssMeasurement, NavState
from companion.types import (
    Alert,
    AlertCode,
    AttitudeSample,
    FixType,
    GnssFix,
    ImuSample,
    InterferenceState,
    Severity,
)

log = logging.getLogger(__name__)

K99_2D = math.sqrt(float(chi2.isf(0.01, 2)))
"""The 99 % radius of a circular 2-D normal in sigmas (3.03)."""


@dataclass(frozen=True, slots=True)
class SpoofStep:
    """What :meth:`SpoofMonitor.on_fix` asks of the engine: ``alerts`` to publish, and a
    ``rollback`` state (the episode's reference carried to now) to restart the navigator
    from, or None."""

    alerts: list[Alert] = field(default_factory=list)
    rollback: NavState | None = None


@dataclass(slots=True)
class _Receiver:
    test: DragTest
    fails: int = 0
    first_fail_t_s: float | None = None
    first_step: bool = False
    """The first failed fix of the current run was a step (:attr:`DragVerdict.step`)."""
    last: DragVerdict | None = None


class SpoofMonitor:
    """See the module docstring. ``stats`` counts tests, detections and re-admissions."""

    def __init__(self, config: SpoofConfig | None = None, gravity_d_mps2: float = 9.80665) -> None:
        self.config = config or SpoofConfig()
        self.inertial = InertialIncrements(gravity_d_mps2)
        self.stats: Counter[str] = Counter()
        self._readmit_thr = float(chi2.isf(self.config.readmit_false_alarm_prob, 2))
        self._receivers: dict[int, _Receiver] = {}
        self.episodes: dict[int, Episode] = {}
        self.lag_sigma_s: float | None = None
        """What is not known of receiver 0's fix placement, s, as the service measured its
        lag (None before: ``lag_sigma_s`` of the configuration, the prior)."""

    def reset(self) -> None:
        """Forget the IMU, the tests and the episodes (autopilot reboot, restart)."""
        self.inertial.reset()
        for rx in self._receivers.values():
            rx.test.reset()
            rx.fails, rx.first_fail_t_s, rx.last = 0, None, None
        self.episodes.clear()

    def widen_grade(self, grade: str) -> None:
        """The service found the IMU worse than configured (its grade check): every figure
        ``grade`` gives that is larger than the configuration's is taken, and each test
        starts again (its references were anchored with the narrow grade's covariance).
        The in-flight calibrations, the episodes and the IMU's increments are kept."""
        wide = SpoofConfig.for_grade(grade)
        cfg = self.config
        changes = {
            name: max(getattr(cfg, name), getattr(wide, name))
            for name in GRADE_FIELDS
            if getattr(wide, name) > getattr(cfg, name)
        }
        if not changes:
            return
        self.config = dataclasses.replace(cfg, **changes)
        for rx in self._receivers.values():
            rx.test.config = self.config
            rx.test.reset()
            rx.fails, rx.first_fail_t_s = 0, None
        self.stats["grade_widened"] += 1

    # ------------------------------------------------------------------ inputs

    def on_attitude(self, sample: AttitudeSample, yaw_correction_rad: float = 0.0) -> None:
        if self.config.enabled:
            self.inertial.on_attitude(sample, yaw_correction_rad)

    def on_imu(self, sample: ImuSample) -> None:
        if self.config.enabled:
            self.inertial.on_imu(sample)

    # ------------------------------------------------------------------ queries

    def excluded(self, receiver_id: int) -> bool:
        """Held out by an episode (not yet re-admitted)."""
        ep = self.episodes.get(receiver_id)
        return ep is not None and not ep.unverified

    def accuracy_floor_m(self) -> float:
        """The published horizontal 1-sigma accuracy's floor while a receiver is held, m:
        its separation over the 99 % factor of a 2-D normal (3.03), so that the published
        99 % bound reaches the receiver's position too. The IMU is trusted over a receiver
        it contradicts, but an IMU can fail as well and nothing here can tell a failed IMU
        from a spoofed receiver: the accuracy says how far apart the two are. After a
        re-admission the IMU could not verify, the floor is the protection level's (the
        largest separation, or what the reference could not rule out): the receiver may
        still be that far off, and nothing has shown otherwise."""
        return self.hpl_floor_m() / K99_2D

    def hpl_floor_m(self) -> float:
        """The horizontal protection level's floor, m: the separation of a held-out
        receiver from its reference (it contradicts the position carried), or the largest
        separation of one re-admitted unverified (0 without an episode)."""
        floor = 0.0
        for ep in self.episodes.values():
            floor = max(floor, ep.max_sep_m if ep.unverified else ep.last_sep_m)
        return floor

    def bridge(self, state: NavState) -> NavState:
        """``state`` (the navigator's, at about the newest IMU time) with its north and east
        replaced by the held-out episode's reference carried there by the IMU alone (the
        sharpest, when several are held): the reference is the last solution no fix of
        the spoofed receiver touched, where the navigator, even restarted from it, may
        carry an attitude or a bias it learnt from the drag and a covariance that does
        not know it. ``state`` itself when none is held."""
        best: NavState | None = None
        inc = None
        for ep in self.episodes.values():
            if ep.unverified:
                continue
            inc = inc or self.inertial.at(state.t_s)
            if inc is None:
                return state
            ref = ep.reference.at(inc, self.inertial.vrw_psd_m2ps3())
            if ref is not None and (
                best is None
                or _sigma_max_m(ref.pos_cov_ned_m2[:2, :2])
                < _sigma_max_m(best.pos_cov_ned_m2[:2, :2])
            ):
                best = ref
        if best is None:
            return state
        self.stats["bridged_on_reference"] += 1
        return _with_vertical_of(best, state)

    def state(self) -> InterferenceState:
        """The service's spoofing verdict for GNSS_INTEGRITY: MITIGATED while a receiver is
        held out (the solution is the IMU's), DETECTED while one re-admitted unverified
        widens the protection level, CLEAN while receivers are tested and every test sees
        ``verified_accel_mps2`` within ``verified_window_s`` (:meth:`verified_mps2`), else
        UNKNOWN: a test too blind to see a fast drag does not say clean."""
        if any(not ep.unverified for ep in self.episodes.values()):
            return InterferenceState.MITIGATED
        if self.episodes:
            return InterferenceState.DETECTED
        if self.verified_mps2() <= self.config.verified_accel_mps2:
            return InterferenceState.CLEAN
        return InterferenceState.UNKNOWN

    def verified_mps2(self) -> float:
        """The smallest drag every tested receiver's test sees within ``verified_window_s``
        (the largest over the receivers), m/s^2; ``inf`` while none is tested."""
        tested = [
            rid
            for rid, rx in self._receivers.items()
            if rx.last is not None and rx.last.tested and rid not in self.episodes
        ]
        if not tested:
            return math.inf
        window = self.config.verified_window_s
        return max(self.detectable_mps2(rid, window) for rid in tested)

    def detectable_mps2(self, receiver_id: int, tau_s: float) -> float:
        """The smallest drag receiver ``receiver_id``'s test sees within ``tau_s``, m/s^2."""
        rx = self._receivers.get(receiver_id)
        if rx is None:
            return math.inf
        return rx.test.detectable_mps2(tau_s, self.inertial.vrw_psd_m2ps3())

    # ------------------------------------------------------------------ per fix

    def on_fix(
        self,
        fix: GnssFix,
        meas: GnssMeasurement | None,
        nav: NavState | None,
        airborne: bool,
        suspected: bool = False,
        own_verdict: InterferenceState = InterferenceState.UNKNOWN,
        evidence: tuple[str, ...] = (),
    ) -> SpoofStep:
        """Test one fix (see the module docstring).

        Parameters
        ----------
        fix : the receiver's fix.
        meas : the same in the local NED frame (None before the frame exists).
        nav : the navigator's state at the fix time, None when it has none.
        airborne : the test runs in flight only (on the ground the autopilot's heading
            can be degrees off before the taxi correction; the filter restarts at take-off).
        suspected : another test holds the receiver out on independent evidence: nothing
            is anchored or learnt from its fixes meanwhile (they may be a drag's).
        own_verdict : the receiver's own spoofing verdict (its flags, relayed or read on the
            raw link: :meth:`companion.integrity.signal.SignalMonitor.receiver_verdict`):
            DETECTED holds it out as a failed drag test does, and keeps it out.
        evidence : signal-level evidence to cite in the alert (``"raw: C/N0 spread ..."``).
        """
        cfg = self.config
        if not cfg.enabled or fix.vel_ne_mps is None or int(fix.fix_type) < int(FixType.FIX_3D):
            return SpoofStep()
        rid = fix.receiver_id
        rx = self._receivers.get(rid)
        if rx is None:
            rx = self._receivers[rid] = _Receiver(DragTest(cfg))
        inc = self.inertial.at(fix.t_s)
        if inc is None:
            self.stats["no_imu"] += 1
            return SpoofStep()
        episode = self.episodes.get(rid)
        if not airborne and episode is None:
            if rx.test.running:
                rx.test.reset()
            rx.fails, rx.first_fail_t_s = 0, None
            return SpoofStep()
        before = self.inertial.at(fix.t_s - cfg.accel_smoothing_s)
        acc = (
            (inc.vel[:2] - before.vel[:2]) / cfg.accel_smoothing_s
            if before is not None and before.epoch == inc.epoch
            else np.zeros(2)
        )
        vrw = self.inertial.vrw_psd_m2ps3()
        held = episode is not None and not episode.unverified
        # the navigator's state and the IMU's increments at its time, for an episode's
        # reference should this fix become an anchor
        nav_inc = self.inertial.at(nav.t_s) if nav is not None else None
        payload = (nav, nav_inc) if nav is not None and nav_inc is not None else None
        measured = self.lag_sigma_s if rid == 0 else None
        rx.test.lag_sigma_s = (
            cfg.lag_sigma_s if measured is None else max(measured, cfg.lag_sigma_floor_s)
        )
        verdict = rx.test.on_fix(
            fix.t_s,
            fix.vel_ne_mps,
            inc,
            acc,
            vrw,
            hold=held or suspected or rx.fails > 0,
            payload=payload,
            placed_s=fix.placed_s,
        )
        rx.last = verdict
        self.stats["tested"] += int(verdict.tested)
        flagged = own_verdict is InterferenceState.DETECTED
        if held and episode is not None:
            if flagged:
                episode.agree_since_s = None  # never re-admitted on its flag's word alone
                return SpoofStep()
            return self._while_held(rx, episode, fix, meas, inc, vrw)
        if flagged and (episode is None or episode.unverified):
            self.stats["receiver_flag"] += 1
            return self._detected(rx, verdict, fix, nav, inc, vrw, evidence, flagged=True)
        if not verdict.failed:
            rx.fails, rx.first_fail_t_s = 0, None
            return SpoofStep()
        self.stats["failed"] += 1
        rx.fails += 1
        if rx.first_fail_t_s is None:
            rx.first_fail_t_s = fix.t_s
            rx.first_step = verdict.step
        if rx.fails < cfg.persist_fixes or fix.t_s - rx.first_fail_t_s < cfg.persist_s:
            return SpoofStep()
        if rx.first_step:
            # a jump of the velocity: which side of it is true the IMU cannot tell (a
            # spoofer letting go looks the same); the fault tests judge it, the drag test
            # starts again from the new level
            self.stats["steps"] += 1
            log.info("t=%.2f s rx%d velocity stepped unlike the IMU: not a drag", fix.t_s, rid)
            rx.test.reset()
            rx.fails, rx.first_fail_t_s = 0, None
            return SpoofStep()
        return self._detected(rx, verdict, fix, nav, inc, vrw, evidence)

    def _detected(
        self,
        rx: _Receiver,
        verdict: DragVerdict,
        fix: GnssFix,
        nav: NavState | None,
        inc: object,
        vrw: float,
        evidence: tuple[str, ...] = (),
        flagged: bool = False,
    ) -> SpoofStep:
        rid = fix.receiver_id
        if flagged:
            # the receiver says so: the youngest reference anchored before its word
            anchor = rx.test.refs[-1] if rx.test.refs else None
            text = f"rx{rid} says it is spoofed"
        else:
            anchor = rx.test.anchor_before_drag()
            a = float(np.hypot(*verdict.acc_ne_mps2))
            text = (
                f"rx{rid} moves {a:.2f} m/s2 unlike the IMU over {verdict.tau_s:.1f} s "
                f"(test {verdict.stat:.0f} > {verdict.threshold:.0f})"
            )
        self.stats["detections"] += 1
        rx.fails, rx.first_fail_t_s = 0, None
        rollback: NavState | None = None
        if anchor is not None and isinstance(anchor.payload, tuple):
            nav_a, inc_a = anchor.payload
            ref = Reference(
                nav_a,
                inc_a,
                anchor.x,
                anchor.p,
                rx.test.wander_m2ps5,
                rx.test.inflation,
            )
            self.episodes[rid] = Episode(rid, fix.t_s, ref)
            rx.test.frozen = True
            carried = ref.at(self.inertial.at(fix.t_s) or anchor.inc, vrw)
            if carried is not None and nav is not None:
                rollback = _with_vertical_of(carried, nav)
            text += ": held out, navigation from the IMU"
        else:
            # no navigator state at the anchor: nothing to roll back to or hold against
            self.stats["detections_without_reference"] += 1
            text += ": no reference to hold it against"
        if evidence:
            text += "; " + "; ".join(evidence)
        log.warning("t=%.2f s SPOOF %s", fix.t_s, text)
        return SpoofStep([Alert(fix.t_s, AlertCode.SPOOF, Severity.CRITICAL, text[:120])], rollback)

    def _while_held(
        self,
        rx: _Receiver,
        ep: Episode,
        fix: GnssFix,
        meas: GnssMeasurement | None,
        inc: object,
        vrw: float,
    ) -> SpoofStep:
        cfg = self.config
        ref = ep.reference.at(inc, vrw)  # type: ignore[arg-type]
        if ref is None or meas is None:
            self.stats["held_no_reference"] += 1
            return SpoofStep()
        sep = meas.pos_ned_m[:2] - ref.pos_ned_m[:2]
        cov = ref.pos_cov_ned_m2[:2, :2] + np.diag(meas.pos_var_ned_m2[:2])
        d2 = horizontal_distance2(sep, cov)
        vel = np.asarray(fix.vel_ne_mps, dtype=float)
        vsep = vel - ref.vel_ned_mps[:2]
        vcov = ref.vel_cov_ned_m2ps2[:2, :2] + rx.test.gnss_vel_var_m2ps2 * np.eye(2)
        dv2 = horizontal_distance2(vsep, vcov)
        ep.last_sep_m = float(np.hypot(*sep))
        ep.max_sep_m = max(ep.max_sep_m, ep.last_sep_m)
        t = fix.t_s
        verdict = rx.last
        contradicted = (
            d2 > self._readmit_thr
            or dv2 > self._readmit_thr
            or (verdict is not None and verdict.failed)
        )
        if contradicted:
            ep.agree_since_s = None
            return SpoofStep()
        if ep.agree_since_s is None:
            ep.agree_since_s = t
        if t - ep.agree_since_s < cfg.readmit_s:
            return SpoofStep()
        sigma_m = _sigma_max_m(cov)
        if math.sqrt(rx.test.threshold) * sigma_m < ep.max_sep_m:
            return self._end(rx, ep, fix)
        # it agrees with a reference too uncertain to have seen what it showed
        return self._end(rx, ep, fix, unverified_m=math.sqrt(self._readmit_thr) * sigma_m)

    def _end(
        self, rx: _Receiver, ep: Episode, fix: GnssFix, unverified_m: float | None = None
    ) -> SpoofStep:
        """Re-admit the receiver: ``SPOOF_END``. ``unverified_m``: the reference it agrees
        with is too uncertain to have seen what the episode showed (a MEMS IMU after a
        minute or two, or an episode that never separated): the protection level keeps
        the larger of that and the largest separation seen until another episode ends
        verified."""
        rid = ep.receiver_id
        rx.test.reset()
        text = (
            f"rx{rid} agrees with the IMU again after {fix.t_s - ep.start_t_s:.0f} s "
            f"(within {ep.last_sep_m:.1f} m): re-admitted"
        )
        if unverified_m is None:
            del self.episodes[rid]
            self.stats["readmitted"] += 1
        else:
            ep.unverified = True
            ep.max_sep_m = max(ep.max_sep_m, unverified_m)
            self.stats["readmitted_unverified"] += 1
            text += f"; the IMU cannot tell +/-{unverified_m:.0f} m: protection kept at it"
        log.warning("t=%.2f s SPOOF_END %s", fix.t_s, text)
        return SpoofStep([Alert(fix.t_s, AlertCode.SPOOF_END, Severity.NOTICE, text[:120])])


def _sigma_max_m(cov: np.ndarray) -> float:
    """Square root of the larger eigenvalue of a (2, 2) covariance, m."""
    return math.sqrt(max(float(np.max(np.linalg.eigvalsh(cov))), 0.0))


def _with_vertical_of(carried: NavState, nav: NavState) -> NavState:
    """``carried``'s north and east with ``nav``'s down (position, velocity and their
    variances): a horizontal drag does not move the height, which the barometer tests."""
    pos = carried.pos_ned_m.copy()
    vel = carried.vel_ned_mps.copy()
    pos[2], vel[2] = nav.pos_ned_m[2], nav.vel_ned_mps[2]
    pc = carried.pos_cov_ned_m2.copy()
    vc = carried.vel_cov_ned_m2ps2.copy()
    pc[2, :], pc[:, 2] = 0.0, 0.0
    vc[2, :], vc[:, 2] = 0.0, 0.0
    pc[2, 2] = nav.pos_cov_ned_m2[2, 2]
    vc[2, 2] = nav.vel_cov_ned_m2ps2[2, 2]
    return NavState(carried.t_s, pos, vel, pc, vc)

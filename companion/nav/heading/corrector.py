"""The taxi heading correction's state machine: one cycle per GNSS fix.

Each GNSS fix is one cycle of Markelov et al. A cycle counts only when the
vehicle is on the ground (:mod:`~companion.nav.heading.ground`), the section is
straight (:mod:`~companion.nav.heading.attitude`), the GNSS ground speed is
between ``min_speed_mps`` and ``max_speed_mps``, and the fix is at least
``min_fix_type`` with a velocity accuracy of at most ``max_vel_acc_mps``. Its
mismatch enters the running statistics (:mod:`~companion.nav.heading.stats`);
once the sample is sufficient the acceptance criteria
(:mod:`~companion.nav.heading.criteria`) make it READY or reject it.

Phases (:class:`~companion.nav.heading.state.HeadingPhase`): ACCUMULATING ->
READY (all criteria hold) -> APPLIED (confirmed, or ``auto_apply``). A failed
criterion, or a position-track sample losing RTK, starts the accumulation over;
the ground station's refusal sends READY back to ACCUMULATING, its undo APPLIED
back to READY (the same candidate, which it may confirm again or refuse). At
take-off an unfinished accumulation is dropped.

What a ground station sees (:class:`~companion.nav.heading.state.HeadingStatus`,
:attr:`HeadingCorrector.status`): IDLE, ACCUMULATING, READY, APPLIED or REJECTED
(after a failed criterion or a refusal, until the next cycle counts). Every change
is announced by an alert (HDG_ACCUM, HDG_READY, HDG_APPLIED, HDG_REJECT,
HDG_UNDONE, HDG_IDLE), and every command (:meth:`HeadingCorrector.on_command`) is
answered by exactly one :class:`~companion.types.CommandResult`.

Pure: no I/O, no clock; time comes from the samples.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from typing import Any

import numpy as np

from companion.nav.heading.attitude import AttitudeHistory
from companion.nav.heading.config import HeadingConfig
from companion.nav.heading.criteria import Verdict, judge_sample
from companion.nav.heading.ground import GroundState
from companion.nav.heading.park import ParkCheck
from companion.nav.heading.state import HeadingPhase, HeadingStatus, restore_state, to_state
from companion.nav.heading.stats import CycleSample, HeadingEstimate
from companion.nav.heading.track import PositionTrack
from companion.nav.rotations import wrap_pi
from companion.types import (
    Alert,
    AlertCode,
    AttitudeSample,
    CommandOutcome,
    CommandResult,
    GnssFix,
    HeadingAction,
    HeadingCommand,
    NamedValue,
    Output,
    Severity,
    VfrHudSample,
)

logger = logging.getLogger(__name__)


class HeadingCorrector:
    """Taxi heading correction (Markelov et al.): a pure, stepwise estimator.

    Feed it :meth:`on_attitude` (INS heading and rate, pitch), :meth:`on_landed_state`
    (``on_ground`` from EXTENDED_SYS_STATE, ``None`` when not sent),
    :meth:`on_vfr_hud` (climb rate for the ground decision) and
    :meth:`on_gnss` (one cycle per fix). Outputs are returned, never sent.

    Publication: while accumulating, READY or APPLIED, every fix that leaves
    at least ``publish_period_s`` since the last publication yields
    ``NamedValue("CMP_HDGC", deg)`` (accumulating: the running mean; READY: the
    candidate; APPLIED: the applied correction) and ``NamedValue("CMP_HDGE", deg)``
    (its 95 % accuracy ``eps``), once there are two cycles. Alerts (one on each change
    of :attr:`status`): HDG_ACCUM, HDG_READY, HDG_APPLIED, HDG_UNDONE, HDG_REJECT,
    HDG_IDLE (:class:`~companion.types.Alert`); commands are answered by
    :meth:`on_command`.

    References
    ----------
    Markelov et al., "INS course correction from satellite navigation before
    take-off": recursions and acceptance criteria (see :mod:`companion.nav.heading`).
    """

    def __init__(self, config: HeadingConfig | None = None) -> None:
        self.config = config if config is not None else HeadingConfig()
        self._z = self.config.z_score
        self._crab_rad = math.radians(self.config.ground_crab_deg)
        self._ins_var_rad2 = math.radians(self.config.ins_yaw_noise_deg) ** 2
        self.rejections: Counter[str] = Counter()
        """Cycles or inputs not used, by reason (counted and logged)."""
        self.reject_alerts = 0
        # attitude buffer (not persisted: it is seconds long)
        self._attitude = AttitudeHistory(self.config, self._reject)
        self._ground = GroundState(self.config)
        # accumulation
        self.phase = HeadingPhase.ACCUMULATING
        self._sample = CycleSample()
        self._track = PositionTrack(self.config, self._reject)
        self._park = ParkCheck(self.config)
        # results
        self._candidate: HeadingEstimate | None = None
        self._applied: HeadingEstimate | None = None
        self._last_publish_t: float | None = None
        self._last_fix_t: float | None = None
        self._source: str | None = None
        """Track source of the current sample ("position" / "velocity"; None: not chosen)."""
        self._rejected = False
        """The last sample was rejected (criterion, parked check or refusal) and no cycle
        has counted since: :attr:`status` REJECTED."""

    # ------------------------------------------------------------------ inputs

    def on_attitude(self, sample: AttitudeSample) -> None:
        """Buffer the INS heading ``yaw_rad`` and its rate (turn detection); the pitch
        enters the ground decision."""
        self._attitude.add(sample)
        if math.isfinite(sample.pitch_rad):
            self._ground.pitch_rad = sample.pitch_rad

    def on_landed_state(self, on_ground: bool | None) -> None:
        """The autopilot's landed state (EXTENDED_SYS_STATE), one input of the ground
        decision (:mod:`companion.nav.heading.ground`); ``None``: not sent."""
        self._ground.set_landed(on_ground)

    @property
    def airborne(self) -> bool:
        """In a flight (landed state "in air" corroborated by the motion); False again
        once back on the ground (:mod:`companion.nav.heading.ground`)."""
        return self._ground.airborne

    def observe_fix(self, fix: GnssFix) -> None:
        """The ground decision at a fix of the configured receiver, in flight too (no
        cycle, nothing counted): it starts and ends :attr:`airborne`."""
        if fix.receiver_id != self.config.receiver_id or not math.isfinite(fix.t_s):
            return
        speed = fix.ground_speed_mps
        if fix.vel_ne_mps is not None:
            vel = np.asarray(fix.vel_ne_mps, dtype=np.float64)
            if vel.shape == (2,) and np.all(np.isfinite(vel)):
                speed = float(math.hypot(vel[0], vel[1]))
        if math.isfinite(speed):
            self._ground.on_ground(fix, speed)

    def on_vfr_hud(self, sample: VfrHudSample) -> None:
        """Climb rate for the ground decision."""
        if math.isfinite(sample.climb_mps):
            self._ground.climb_mps = sample.climb_mps

    def on_command(self, command: HeadingCommand) -> list[Output]:
        """The ground station's command: its alerts, then exactly one
        :class:`~companion.types.CommandResult`. Repeating a command that succeeded
        changes nothing and is accepted again, except undo (nothing is applied then).

        ============  ======================  =====================  ======================
        status        confirm                 refuse                 undo
        ============  ======================  =====================  ======================
        READY         ACCEPTED, applied       ACCEPTED, restarted    DENIED
        APPLIED       ACCEPTED (no change)    DENIED (undo it)       ACCEPTED, READY again
        other         TEMPORARILY_REJECTED    ACCEPTED (no change)   DENIED
        ============  ======================  =====================  ======================
        """
        t_s = command.t_s
        action = command.action
        phase = self.phase
        status = self.status.name.lower()
        if action is HeadingAction.CONFIRM:
            if phase is HeadingPhase.APPLIED:
                return [CommandResult(t_s, CommandOutcome.ACCEPTED)]
            out = self.apply(t_s)
            if self.phase is HeadingPhase.APPLIED:
                return [*out, CommandResult(t_s, CommandOutcome.ACCEPTED)]
            reason = f"confirm: none ready ({status})"
            return [CommandResult(t_s, CommandOutcome.TEMPORARILY_REJECTED, reason)]
        if action is HeadingAction.REFUSE:
            if phase is HeadingPhase.READY:
                logger.info("heading correction refused by the ground station")
                self._restart()
                self._rejected = True
                self.reject_alerts += 1
                return [
                    Alert(t_s, AlertCode.HDG_REJECT, Severity.WARNING, "refused"),
                    CommandResult(t_s, CommandOutcome.ACCEPTED),
                ]
            if phase is HeadingPhase.APPLIED:
                self._reject("command_refuse_applied")
                reason = "refuse: applied; undo it instead"
                return [CommandResult(t_s, CommandOutcome.DENIED, reason)]
            self._reject("command_refuse_not_ready")
            return [CommandResult(t_s, CommandOutcome.ACCEPTED)]
        if phase is HeadingPhase.APPLIED:
            return [*self.undo(t_s), CommandResult(t_s, CommandOutcome.ACCEPTED)]
        self._reject("command_undo_not_applied")
        return [CommandResult(t_s, CommandOutcome.DENIED, f"undo: none applied ({status})")]

    def apply(self, t_s: float) -> list[Output]:
        """Apply the READY candidate (confirmation): ``HDG_APPLIED``; else nothing."""
        if self.phase is not HeadingPhase.READY or self._candidate is None:
            self._reject("apply_not_ready")
            return []
        self._applied = self._candidate
        self.phase = HeadingPhase.APPLIED
        self._rejected = False
        text = self._format(self._applied)
        logger.info("heading correction applied: %s", text)
        return [Alert(t_s, AlertCode.HDG_APPLIED, Severity.NOTICE, text)]

    def undo(self, t_s: float) -> list[Output]:
        """Remove the applied correction (``HDG_UNDONE``): the heading is the autopilot's
        again and the candidate is READY, to confirm again or refuse; else nothing."""
        applied = self._applied
        if self.phase is not HeadingPhase.APPLIED or applied is None:
            self._reject("undo_not_applied")
            return []
        self._applied = None
        self._candidate = applied
        self.phase = HeadingPhase.READY
        text = self._format(applied)
        logger.info("heading correction undone: %s", text)
        return [Alert(t_s, AlertCode.HDG_UNDONE, Severity.NOTICE, f"{text} removed")]

    def end_taxi(self, t_s: float) -> list[Output]:
        """Airborne: the taxi is over. An unfinished accumulation (or a rejected one) is
        dropped, IDLE (``HDG_IDLE``); a READY or APPLIED correction stands."""
        if self.phase is not HeadingPhase.ACCUMULATING:
            return []
        before = self.status
        self._restart()
        self._rejected = False
        self._park.reset()
        if before is HeadingStatus.IDLE:
            return []
        return [Alert(t_s, AlertCode.HDG_IDLE, Severity.NOTICE, "airborne: none applied")]

    def on_gnss(self, fix: GnssFix) -> list[Output]:
        """One cycle: park check, straight-leg test, recursions, criteria, publication."""
        out: list[Output] = []
        if not math.isfinite(fix.t_s):
            self._reject("fix_time_not_finite")
            return out
        if fix.receiver_id != self.config.receiver_id:
            self._reject("other_receiver")
            return out
        if self._last_fix_t is not None and fix.t_s <= self._last_fix_t:
            if fix.t_s < self._last_fix_t - self.config.attitude_buffer_s:
                self._last_fix_t = None  # the clock restarted (autopilot reboot)
            else:
                # a repeated or late fix (a receiver repeating its last solution) would
                # enter the sample twice
                self._reject("fix_not_newer")
                return out
        self._last_fix_t = fix.t_s
        vel = self._fix_velocity(fix)
        if vel is None:
            return out
        vn, ve = vel
        speed = math.hypot(vn, ve)
        on_ground = self.on_ground(fix, speed)
        if not on_ground:
            self._end_leg()
            self._park.reset()
            self._reject("not_on_ground")
        elif self.phase is HeadingPhase.ACCUMULATING:
            out.extend(self._park_step(fix, vn, ve, speed))
            before = self.status
            self._cycle(fix, vn, ve, speed)
            if before is not HeadingStatus.ACCUMULATING and self.status is (
                HeadingStatus.ACCUMULATING
            ):
                source = self._source or self.config.track_source
                text = f"started: {source} track"
                out.append(Alert(fix.t_s, AlertCode.HDG_ACCUM, Severity.INFO, text))
            out.extend(self._maybe_judge(fix.t_s))
        out.extend(self._publish(fix.t_s, on_ground))
        return out

    # ------------------------------------------------------------------ results

    @property
    def status(self) -> HeadingStatus:
        """What a ground station shows (``CMP_HDGS``): see :class:`HeadingStatus`."""
        phase = self.phase
        if phase is HeadingPhase.APPLIED:
            return HeadingStatus.APPLIED
        if phase is HeadingPhase.READY:
            return HeadingStatus.READY
        if self._rejected:
            return HeadingStatus.REJECTED
        return HeadingStatus.ACCUMULATING if self._sample.x_rad else HeadingStatus.IDLE

    def describe(self) -> str:
        """The status and its value, for an announcement (``applied 1.00 ±0.02 n=30``)."""
        status = self.status
        name = status.name.lower()
        if status is HeadingStatus.APPLIED and self._applied is not None:
            return f"{name} {self._format(self._applied)}"
        if status is HeadingStatus.READY and self._candidate is not None:
            return f"{name} {self._format(self._candidate)}"
        if status is HeadingStatus.ACCUMULATING:
            return f"{name} n={len(self._sample.x_rad)}"
        return name

    @property
    def correction_rad(self) -> float:
        """The applied correction (rad), 0 until applied. Subtract it from the INS heading."""
        return self._applied.correction_rad if self._applied is not None else 0.0

    @property
    def applied(self) -> HeadingEstimate | None:
        """The applied estimate, ``None`` until applied."""
        return self._applied

    @property
    def candidate(self) -> HeadingEstimate | None:
        """The READY (or applied) estimate, ``None`` before READY."""
        return self._candidate

    @property
    def park_ok(self) -> bool | None:
        """Latest parked check: passed, failed, or ``None`` when not done."""
        return self._park.ok

    def corrected_yaw_rad(self, yaw_rad: float) -> float:
        """INS heading minus the applied correction, wrapped to [-pi, pi)."""
        return wrap_pi(yaw_rad - self.correction_rad)

    def estimate(self) -> HeadingEstimate:
        """The running estimate of the current accumulation (the recursions of Markelov et al.)."""
        return self._sample.estimate(self._z)

    def mismatches_rad(self) -> np.ndarray:
        """Mismatches of the current accumulation (unwrapped about the mean), rad, shape (n,)."""
        return np.asarray(self._sample.x_rad, dtype=np.float64)

    def cycle_times_s(self) -> np.ndarray:
        """Times of validity of the cycles of the current accumulation, s, shape (n,)."""
        return np.asarray(self._sample.t_s, dtype=np.float64)

    def running_mean_spread_rad(self) -> float:
        """Spread (1 sigma) of the running mean since ``spread_start_cycle``, rad."""
        return self._sample.mean_spread_rad()

    def on_ground(self, fix: GnssFix, speed_mps: float) -> bool:
        """On the ground? From the motion, the autopilot's landed state one input
        (:mod:`companion.nav.heading.ground`)."""
        return self._ground.on_ground(fix, speed_mps)

    def park_verdict(self, vel_ne_mps: np.ndarray) -> Verdict:
        """Parked check: is the mean GNSS velocity (shape (n, 2), m/s) a bias?
        (:func:`~companion.nav.heading.criteria.park_bias_verdict`)."""
        return self._park.verdict(vel_ne_mps)

    def judge(self) -> Verdict:
        """Evaluate the acceptance criteria on the current accumulation.

        Order (the first failure is the reason): sufficiency, park check,
        running-mean spread, dispersion, normality, trend, leg consistency
        (:func:`~companion.nav.heading.criteria.judge_sample`).
        """
        est = self.estimate()
        return judge_sample(
            self._sample, est.eps_rad, self._min_cycles(), self._park.ok, self.config
        )

    # ------------------------------------------------------------------ internals

    def _reject(self, reason: str) -> None:
        self.rejections[reason] += 1
        n = self.rejections[reason]
        if n & (n - 1) == 0:  # log the 1st, 2nd, 4th, 8th ... occurrence
            logger.debug("heading cycle not used: %s (x%d)", reason, n)

    def _fix_velocity(self, fix: GnssFix) -> tuple[float, float] | None:
        if fix.fix_type < self.config.min_fix_type:
            self._reject("fix_type")
            return None
        if fix.vel_ne_mps is None:
            self._reject("no_velocity")
            return None
        vel = np.asarray(fix.vel_ne_mps, dtype=np.float64)
        if vel.shape != (2,) or not np.all(np.isfinite(vel)):
            self._reject("velocity_invalid")
            return None
        if fix.vel_acc_mps is not None and not (
            math.isfinite(fix.vel_acc_mps) and fix.vel_acc_mps <= self.config.max_vel_acc_mps
        ):
            self._reject("vel_acc")
            return None
        return float(vel[0]), float(vel[1])

    def _vel_sigma(self, fix: GnssFix) -> float:
        if fix.vel_acc_mps is None:
            return self.config.default_vel_acc_mps
        return max(fix.vel_acc_mps, self.config.vel_acc_floor_mps)

    def _cycle(self, fix: GnssFix, vn: float, ve: float, speed: float) -> None:
        cfg = self.config
        if speed < cfg.min_speed_mps:
            self._end_leg()
            self._reject("slow")
            return
        got = self._attitude.yaw_at(fix.t_s)
        if got is None:
            self._end_leg()
            return
        yaw, straight = got
        if not straight:
            self._end_leg()
            self._reject("turn")
            return
        if len(self._sample.x_rad) >= cfg.max_cycles:
            self._reject("max_cycles")
            return
        if self._source_for(fix) == "position":
            got_pos = self._track.track(fix)
            if got_pos is None:
                return
            track, sig_track2, t_mid = got_pos
            got_mid = self._attitude.yaw_at(t_mid)
            if got_mid is None:
                return
            yaw = got_mid[0]
            t_cycle = t_mid
        else:
            track = math.atan2(ve, vn)
            sig_track2 = (self._vel_sigma(fix) / speed) ** 2
            t_cycle = fix.t_s
        self._sample.add(
            t_cycle,
            wrap_pi(yaw - track - self._crab_rad),
            math.sqrt(sig_track2 + self._ins_var_rad2),
            spread_start=self._spread_start(),
            min_leg_cycles=cfg.min_leg_cycles,
        )
        self._rejected = False

    def _source_for(self, fix: GnssFix) -> str:
        """The track source of this sample (fixed at its first cycle in ``auto``)."""
        cfg = self.config
        if cfg.track_source != "auto":
            return cfg.track_source
        want = "position" if fix.fix_type >= cfg.pos_min_fix_type else "velocity"
        if self._source is None:
            self._source = want
        elif self._source == "position" and want == "velocity":
            # RTK lost mid-sample: start over on the Doppler track rather than mix
            self._reject("track_source_changed")
            self._restart()
            self._source = want
        return self._source

    def _min_cycles(self) -> int:
        pos = self._source == "position" or self.config.track_source == "position"
        return self.config.pos_min_cycles if pos else self.config.min_cycles

    def _spread_start(self) -> int:
        pos = self._source == "position" or self.config.track_source == "position"
        return self.config.pos_spread_start_cycle if pos else self.config.spread_start_cycle

    def _end_leg(self) -> None:
        self._sample.end_leg()
        self._track.reset()

    def _restart(self) -> None:
        self.phase = HeadingPhase.ACCUMULATING
        self._sample.clear()
        self._track.reset()
        self._candidate = None
        self._source = None

    def _park_step(self, fix: GnssFix, vn: float, ve: float, speed: float) -> list[Output]:
        reason = self._park.step(fix, vn, ve, speed, self._ground)
        if reason is None:
            return []
        self._rejected = True
        self.reject_alerts += 1
        return [Alert(fix.t_s, AlertCode.HDG_REJECT, Severity.WARNING, reason)]

    def _maybe_judge(self, t_s: float) -> list[Output]:
        cfg = self.config
        est = self.estimate()
        min_legs = max(cfg.min_legs, cfg.suspect_min_legs if self._park.suspect else 1)
        if est.n < self._min_cycles() or self._sample.full_legs < min_legs:
            return []
        if math.degrees(est.eps_rad) > cfg.eps_limit_deg and est.n < cfg.max_cycles:
            return []
        verdict = self.judge()
        if not verdict.ok:
            logger.warning("heading correction rejected: %s %s", verdict.reason, verdict.details)
            self._restart()
            self._rejected = True
            self.reject_alerts += 1
            return [Alert(t_s, AlertCode.HDG_REJECT, Severity.WARNING, verdict.reason)]
        self._candidate = est
        self.phase = HeadingPhase.READY
        text = self._format(est)
        logger.info("heading correction ready: %s (%s)", text, verdict.details)
        out: list[Output] = [Alert(t_s, AlertCode.HDG_READY, Severity.NOTICE, text)]
        if cfg.auto_apply:
            out.extend(self.apply(t_s))
        return out

    # publication -------------------------------------------------------------

    def _format(self, est: HeadingEstimate) -> str:
        return f"{math.degrees(est.correction_rad):.2f} ±{math.degrees(est.eps_rad):.2f} n={est.n}"

    def _publish(self, t_s: float, on_ground: bool) -> list[Output]:
        if self.phase is HeadingPhase.APPLIED:
            est = self._applied
        elif self.phase is HeadingPhase.READY:
            est = self._candidate
        else:
            est = self.estimate()
        if est is None or est.n < 2 or (self.phase is HeadingPhase.ACCUMULATING and not on_ground):
            return []
        if (
            self._last_publish_t is not None
            and t_s - self._last_publish_t < self.config.publish_period_s
            and t_s >= self._last_publish_t
        ):
            return []
        self._last_publish_t = t_s
        return [
            NamedValue(t_s, "CMP_HDGC", math.degrees(est.correction_rad)),
            NamedValue(t_s, "CMP_HDGE", math.degrees(est.eps_rad)),
        ]

    # persistence -------------------------------------------------------------

    def to_state(self) -> dict[str, Any]:
        """Plain, JSON-compatible dictionary of everything that must survive a restart
        (:func:`companion.nav.heading.state.to_state`)."""
        return to_state(self)

    @classmethod
    def from_state(cls, config: HeadingConfig, state: dict[str, Any]) -> HeadingCorrector:
        """Rebuild a corrector from :meth:`to_state` output (ValueError when malformed)."""
        obj = cls(config)
        restore_state(obj, state)
        return obj

"""The service at the MAVLink level, without I/O: messages in, packed frames out.

One :class:`Pipeline` is what both drivers run — the asyncio service (live
links) and the tlog replay — so there is no replay-only or live-only logic.
It is fed parsed MAVLink messages with their receive time and asked what to
send; it never opens a socket or reads a clock (the drivers pass ``t_rx_s``:
wall time live, log time in a replay).

It owns the decoder (MAVLink -> typed samples), the pure engine, the encoder
(outputs -> MAVLink), the stream requests made when the autopilot first
appears and after it reboots, the check of the rates actually received, the
parameter protocol (:mod:`companion.params`: the configuration as MAVLink
parameters; a live change applied by :meth:`Pipeline.reconfigure`), and the
periodic output (our HEARTBEAT at ``link.heartbeat_rate_hz``, its
``system_status`` from the navigation's health; the paced rest of a parameter
list) with its clock: a driver asks :meth:`Pipeline.next_due_s` when to call
:meth:`Pipeline.on_timer` next, on the same clock as the ``t_rx_s`` it passes
(docs/replay.md).

A raw receiver beside the autopilot (``[raw]``, :mod:`companion.raw.link`): its decoded
messages come in through :meth:`Pipeline.on_raw`, the autopilot's fixes are shown to
it (they map its GPS time onto the autopilot clock), its carrier-phase solutions go to
the engine and its alerts and status values out.

Commands (the MAVLink command protocol): every COMMAND_LONG or COMMAND_INT the
decoder finds addressed to us is answered by exactly one COMMAND_ACK to its sender,
a retransmission with the original's result (:mod:`companion.mavlink.commands`);
a result other than ACCEPTED or UNSUPPORTED comes with its reason in a
``CMP HDG_CMD`` STATUSTEXT.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from companion.config import Config
from companion.engine import Engine
from companion.engine.gnss_lag import MeasuredLag
from companion.engine.lag_control import LagControl
from companion.mavlink.autopilot_params import AutopilotParams
from companion.mavlink.commands import DecodedCommand, Retransmissions
from companion.mavlink.decode import Decoder
from companion.mavlink.decode.rejections import Rejected, count_rejection
from companion.mavlink.encode import Encoder
from companion.mavlink.ids import (
    MAV_RESULT_ACCEPTED,
    MAV_RESULT_DENIED,
    MAV_RESULT_FAILED,
    MAV_RESULT_TEMPORARILY_REJECTED,
    MAV_RESULT_UNSUPPORTED,
    MAV_STATE_ACTIVE,
    MAV_STATE_CRITICAL,
    MAV_STATE_STANDBY,
)
from companion.mavlink.params import REQUEST_TYPES as PARAM_REQUEST_TYPES
from companion.mavlink.params import decode_request as decode_param_request
from companion.mavlink.px4_agp import Px4AgpSetup
from companion.mavlink.streams import RateMonitor, select_streams, stream_requests
from companion.params import LIVE_KEYS, ParamServer
from companion.raw.link import RawLink
from companion.raw.obs import NavWords, PvtFix, RawEpoch, ReceiverStatus
from companion.types import (
    Alert,
    AlertCode,
    AttitudeSample,
    AutopilotFlavour,
    CommandOutcome,
    CommandResult,
    GnssFix,
    GnssSignalReport,
    HeadingCommand,
    HeartbeatSample,
    ImuSample,
    NavMode,
    NavSolution,
    Output,
    RawSolution,
    RebootEvent,
    Severity,
)

log = logging.getLogger(__name__)

ARDUPILOT_MIN_LOOP_HZ = 50.0
"""ArduPlane's and ArduRover's default SCHED_LOOP_RATE (Copter's is 400 Hz), Hz."""
ARDUPILOT_STREAM_FRACTION = 0.8
"""ArduPilot grants a stream at most this fraction of its loop rate."""
ROUND_TRIP_S = 1e-5
"""An engine due time mapped to the driver's clock and back may come back this early, s."""
RATE_CHECK_PERIOD_S = 10.0
"""How often the received rates are compared with the requested ones (autopilot time)."""
STREAM_NEEDS: dict[str, tuple[str, ...]] = {
    "GNSS": ("GPS_RAW_INT",),
    "IMU": ("HIGHRES_IMU", "RAW_IMU", "SCALED_IMU2", "SCALED_IMU", "SCALED_IMU3"),
    "attitude": ("ATTITUDE", "ATTITUDE_QUATERNION"),
}
"""What the estimators need, each met by any one of its messages (ArduPilot sends
RAW_IMU/SCALED_IMU2 and ATTITUDE, PX4 HIGHRES_IMU and ATTITUDE_QUATERNION)."""
MAV_RESULTS: dict[CommandOutcome, int] = {
    CommandOutcome.ACCEPTED: MAV_RESULT_ACCEPTED,
    CommandOutcome.TEMPORARILY_REJECTED: MAV_RESULT_TEMPORARILY_REJECTED,
    CommandOutcome.DENIED: MAV_RESULT_DENIED,
    CommandOutcome.FAILED: MAV_RESULT_FAILED,
}
"""The engine's answer to a command -> COMMAND_ACK.result."""
DATA_KINDS = frozenset({ImuSample, AttitudeSample, GnssFix})
"""Samples that carry the autopilot clock forward (HEARTBEAT and the like take its latest
time): the driver's clock is mapped onto the autopilot's by the newest of them."""
NAV_STATES: dict[NavMode, int] = {
    NavMode.INIT: 0,
    NavMode.NORMAL: 1,
    NavMode.DEGRADED: 2,
    NavMode.BRIDGING: 3,
    NavMode.REACQUIRING: 4,
    NavMode.LOST: 5,
}
"""Our HEARTBEAT's ``custom_mode``: the navigation state (docs/mavlink.md), with
:data:`NAV_NO_GNSS` and :data:`NAV_SILENT`."""
NAV_NO_GNSS = 6
"""``custom_mode`` while ``NO_GNSS`` stands: no usable fix, not navigating."""
NAV_SILENT = 7
"""``custom_mode`` while ``NO_DATA`` stands: the autopilot sends no data, not navigating."""
COMMAND_ALERTS = frozenset(
    {AlertCode.HDG_APPLIED, AlertCode.HDG_REJECT, AlertCode.HDG_UNDONE, AlertCode.HDG_CMD}
)
"""Alerts a command raises: announced whatever the STATUSTEXT rate limit (one per command)."""


@dataclass(slots=True)
class PipelineStats:
    """What a driver prints in its summary."""

    messages_in: int = 0
    messages_out: int = 0
    out_by_type: Counter[str] = field(default_factory=Counter)
    rate_warnings: int = 0
    stream_requests: int = 0
    commands: Counter[str] = field(default_factory=Counter)
    """COMMAND_ACKs sent, by result name (``ACCEPTED``, ``DENIED`` ...)."""


_RESULT_NAMES = {
    MAV_RESULT_ACCEPTED: "ACCEPTED",
    MAV_RESULT_TEMPORARILY_REJECTED: "TEMPORARILY_REJECTED",
    MAV_RESULT_DENIED: "DENIED",
    MAV_RESULT_UNSUPPORTED: "UNSUPPORTED",
    MAV_RESULT_FAILED: "FAILED",
}


class Pipeline:
    """Decoder -> engine -> encoder, plus stream requests, command answers and the
    periodic HEARTBEAT."""

    def __init__(self, config: Config | None = None) -> None:
        self.config = config or Config()
        self.decoder = Decoder(self.config.decoder)
        cfg = self.config
        self.engine = Engine(
            cfg.engine,
            cfg.outage,
            cfg.heading,
            cfg.blend,
            cfg.integrity,
            cfg.potential,
            cfg.coast,
            cfg.baro,
            cfg.imu_innovations,
            cfg.spoof,
        )
        self.encoder = Encoder(self.config.encoder)
        self.stats = PipelineStats()
        self.rates = RateMonitor(self.config.streams.rates_hz())
        self._autopilot: tuple[int, int] | None = None
        self._next_rate_check_s: float | None = None
        self._short_streams: set[str] = set()
        self.alerts: list[Alert] = []
        """Every alert raised, in order (for the drivers' summaries)."""
        self._heartbeat_period_s = 1.0 / self.config.link.heartbeat_rate_hz
        self._next_heartbeat_s = -math.inf
        """When our next HEARTBEAT is due (driver clock, s): at once before the first."""
        self.retransmissions = Retransmissions()
        """The last answer to each command sender (a lost ACK's command comes again)."""
        self.params = ParamServer(self.config, self.config.encoder.dialect)
        """The parameter protocol (companion.params): its ``overrides`` are what the
        driver persists whenever its ``changes`` move."""
        self._data_clock: tuple[float, float] | None = None
        """(``t_rx_s``, autopilot ``t_s``) of the newest data sample: the driver's clock
        mapped onto the engine's while no sample comes."""
        self._inertial_clock = False
        """:attr:`_data_clock` is from an IMU or attitude sample (not a fix's validity time)."""
        self.agp = Px4AgpSetup(self.config.encoder.gps_id)
        """PX4's aux global position set-up: the GLOBAL_POSITION_SENSOR id read from the
        autopilot (:mod:`companion.mavlink.px4_agp`)."""
        self.encoder.agp_hold = True  # until the autopilot's id is read (or not answered)
        self.autopilot_params = AutopilotParams()
        """ArduPilot's parameters the service adapts to (GPS instance types and lags, loop
        rate): read over the parameter protocol when it appears and after a reboot."""
        self._loop_rate_hz: float | None = None
        self._warned_no_mav_gps = False
        dec = self.config.decoder
        self.lags = LagControl(
            self.engine, self.decoder.gnss.delay_s, dec.gnss_delay_s, dec.gnss_delay_measure
        )
        """The receivers' lags: receiver 0's measured in flight and carried in, every change
        told to the engine (:mod:`companion.engine.lag_control`)."""
        self.lag = self.lags.tracker
        """Receiver 0's lag measured in flight (:mod:`companion.engine.gnss_lag`)."""
        self.raw: RawLink | None = RawLink(self.config.raw) if self.config.raw.enabled else None
        """The raw receiver's carrier-phase link (``[raw]``; :mod:`companion.raw.link`)."""

    def enable_raw(self) -> RawLink:
        """The raw link, made now if the configuration named no device or file (a replay
        given a .ubx beside its log)."""
        if self.raw is None:
            self.raw = RawLink(self.config.raw)
        return self.raw

    def on_raw(
        self, item: RawEpoch | NavWords | PvtFix | ReceiverStatus, t_rx_s: float
    ) -> list[bytes]:
        """One message of the raw receiver (decoded at the edge); return the frames to send:
        its carrier-phase solution goes to the engine (the integrity monitor's redundant
        solution), as do its interference reports (the receiver's own indicators, the
        signal tests); FIS-RAIM's alerts and the ``CMP_R*`` values are published."""
        link = self.enable_raw()
        return self._raw_outputs(link.on_item(item, t_rx_s))

    def _raw_outputs(
        self, outputs: Sequence[RawSolution | GnssSignalReport | Output]
    ) -> list[bytes]:
        frames: list[bytes] = []
        for out in outputs:
            if isinstance(out, (RawSolution, GnssSignalReport)):
                frames += [f for o in self.engine.handle(out) for f in self._encode(o)]
            elif isinstance(out, Alert):
                self.engine.stats.alerts[out.code.value] += 1
                frames += self._encode(out)
            else:
                frames += self._encode(out)
        return frames

    # ------------------------------------------------------------------ in

    def on_message(self, msg: Any, t_rx_s: float) -> list[bytes]:
        """Take one parsed MAVLink message; return the frames to send."""
        self.stats.messages_in += 1
        if msg._type in PARAM_REQUEST_TYPES:
            return self._on_param_request(msg, t_rx_s)
        if msg._type == "PARAM_VALUE":
            return self._on_autopilot_param(msg)
        samples = self.decoder.decode(msg, t_rx_s)
        if not samples:
            early: list[bytes] = []
            decoder = self.decoder
            if self._autopilot is None and decoder.autopilot_heartbeats and decoder.system_id:
                # the autopilot's HEARTBEAT before any timed message (ArduCopter sends none
                # on a port until asked): ask for the streams now, or nothing ever comes
                early = self._on_autopilot_heartbeat(decoder.system_id)
            command = decoder.take_command()
            return early if command is None else early + self._answer(command, None, t_rx_s)
        frames: list[bytes] = []
        handle = self.engine.handle
        lags = self.lags
        for sample in samples:
            kind = type(sample)
            if kind is ImuSample:
                lags.on_imu(sample)  # type: ignore[arg-type]
            elif kind is AttitudeSample:
                lags.on_attitude(sample)  # type: ignore[arg-type]
            elif kind is GnssFix:
                measured = lags.on_fix(sample)  # type: ignore[arg-type]
                if measured is not None:
                    frames += self._on_measured_lag(measured, sample.t_s)
                self.engine.gnss_lag_sigma_s = self._lag_sigma_s()
            if kind is HeadingCommand:
                command = self.decoder.take_command()  # left with every HeadingCommand
                if command is not None:
                    frames += self._answer(command, sample, t_rx_s)  # type: ignore[arg-type]
                continue
            if kind is HeartbeatSample:
                frames += self._on_autopilot_heartbeat(sample.system_id)  # type: ignore[union-attr]
            elif kind is RebootEvent:
                self._restart_agp()
                self._data_clock = None
                self._inertial_clock = False
                self.autopilot_params.reset()  # what was derived stands until read again
                lags.restart()
                frames += self._request_streams()
            else:
                self.rates.observe(msg._type, sample.t_s)
                if kind is GnssFix and self.raw is not None:
                    frames += self._raw_outputs(self.raw.on_fix(sample))  # type: ignore[arg-type]
                if kind in DATA_KINDS and (kind is not GnssFix or not self._inertial_clock):
                    # a fix's time is its time of validity, before its arrival by the
                    # receiver's latency: the inertial streams carry the clock when they run
                    self._data_clock = (t_rx_s, sample.t_s)
                    self._inertial_clock = kind is not GnssFix
            outputs = handle(sample)
            if outputs:
                for out in outputs:
                    frames += self._encode(out)
        next_check_s = self._next_rate_check_s
        t_last_s = samples[-1].t_s
        if next_check_s is None or t_last_s >= next_check_s:
            frames += self._check_rates(t_last_s)
        if (
            t_last_s >= self.autopilot_params.next_s
            and self._autopilot is not None
            and self.decoder.flavour is AutopilotFlavour.ARDUPILOT
        ):
            msgs = self.autopilot_params.requests(
                t_last_s, self._autopilot, self.config.encoder.dialect
            )
            frames += [self._pack(m) for m in msgs]
        if self.agp.verdict is None and self._autopilot is not None and self._feeds_px4():
            frames += self._agp_requests(t_last_s)
        return frames

    # ------------------------------------------------------------------ the autopilot's parameters

    def _on_autopilot_param(self, msg: Any) -> list[bytes]:
        """A PARAM_VALUE: the autopilot's (whoever asked) may change what we derive from it."""
        decoder = self.decoder
        try:
            hdr = msg._header
            ours = (
                hdr.srcSystem == decoder.system_id
                and hdr.srcComponent == decoder.autopilot_component
            )
            name = str(msg.param_id)
            value = float(msg.param_value)
        except (AttributeError, TypeError, ValueError):
            count_rejection(decoder.rejections, "corrupt_frame")
            return []
        if not ours:
            count_rejection(decoder.rejections, "unhandled_type")
            return []
        decoder.accepted["PARAM_VALUE"] += 1
        if decoder.flavour is AutopilotFlavour.PX4:
            return self._on_px4_param(msg) if self._feeds_px4() else []
        if not self.autopilot_params.on_value(name, value):
            return []
        return self._apply_autopilot_params()

    def _apply_autopilot_params(self) -> list[bytes]:
        """The GPS_INPUT id, our own injection, the receivers' lags and the stream rates
        from the autopilot's parameters (:mod:`companion.mavlink.autopilot_params`)."""
        ap = self.autopilot_params
        encoder = self.encoder
        instance = ap.mav_gps_instance
        wanted = instance if self.config.encoder.gps_id_from_autopilot else None
        if wanted != encoder.gps_id_override:
            encoder.gps_id_override = wanted
            if wanted is not None:
                log.info(
                    "autopilot GPS %d takes GPS_INPUT (GPS%d_TYPE 14): sending gps_id %d",
                    wanted + 1,
                    wanted + 1,
                    wanted,
                )
        feeds = self.config.encoder.output in ("auto", "gps_input")
        gnss = self.decoder.gnss
        injected = (
            instance if feeds and instance is not None and encoder.gps_id == instance else None
        )
        # the autopilot may fuse what we publish: through a gap, its attitude would be
        # built on our own output (the engine's gap_attitude)
        self.engine.autopilot_fuses_output = injected is not None
        if injected != gnss.injected_receiver:
            gnss.injected_receiver = injected
            if injected is not None:
                log.info(
                    "GPS %d reports our own GPS_INPUT back (%s): not a receiver",
                    injected + 1,
                    "GPS_RAW_INT" if injected == 0 else "GPS2_RAW",
                )
        for receiver in (0, 1):
            self.lags.parameter(receiver, ap.gps_delay_s(receiver))
        if feeds and instance is None and ap.types_known and not self._warned_no_mav_gps:
            self._warned_no_mav_gps = True
            log.warning(
                "no GPS instance of the autopilot takes GPS_INPUT (GPS1_TYPE / GPS2_TYPE 14): "
                "what the service publishes is ignored by the autopilot"
            )
        loop_hz = ap.loop_rate_hz
        if loop_hz is not None and loop_hz != self._loop_rate_hz:
            old_cap = self._max_stream_hz()
            self._loop_rate_hz = loop_hz
            cap = self._max_stream_hz()
            if any(
                min(r, cap or math.inf) != min(r, old_cap or math.inf)
                for r in self.config.streams.rates_hz().values()
            ):
                return self._request_streams()
        return []

    def _lag_sigma_s(self) -> float | None:
        """What is not known of receiver 0's fix placement, s: the measured lag's difference
        from the one in use, or its sigma if larger (None before two windows measured it:
        the spoofing monitor then takes its prior)."""
        m = self.lag.measured() if self.lag is not None else None
        if m is None or m.windows < 2:
            return None
        return max(abs(m.lag_s - self.lags.delay_s[0]), m.sigma_s)

    def _on_measured_lag(self, m: MeasuredLag, t_s: float) -> list[bytes]:
        """Receiver 0's lag measured: the fixes carried to it (:meth:`LagControl.switch`)
        unless the configuration gives a lag (then only logged). The autopilot's parameter
        is what its own filter assumes, not a measurement of the stamps it sends: where it
        disagrees, the measurement is used and the disagreement announced."""
        said = f"{m.lag_s * 1000.0:.0f}+/-{m.sigma_s * 1000.0:.0f} ms"
        if self.config.decoder.gnss_delay_s > 0.0:
            log.warning(
                "GNSS receiver 0: configured lag %.3f s, measured %s: the configured one kept",
                self.config.decoder.gnss_delay_s,
                said,
            )
            return []
        self.lags.switch(m.lag_s, t_s)
        log.warning(
            "GNSS receiver 0: lag measured %s (IMU stamps %.0f ms late): fixes carried to it",
            said,
            m.imu_offset_s * 1000.0,
        )
        ap_s = self.autopilot_params.gps_delay_s(0)
        if ap_s is None:
            return []
        alert = Alert(
            t_s,
            AlertCode.AP_CONFIG,
            Severity.WARNING,
            f"GPS1_DELAY_MS {ap_s * 1000.0:.0f}, lag {said}",  # one STATUSTEXT
        )
        log.warning("CMP %s %s", alert.code.value, alert.text)
        self.encoder.allow_next(alert.code)
        return self._encode(alert)

    def bad_frames(self, count: int) -> None:
        """The byte parser dropped ``count`` corrupt frames: count them as rejections."""
        if count > 0:
            self.decoder.bad_frame(count)

    def unknown_frames(self, count: int) -> None:
        """The byte parser skipped ``count`` valid frames of message ids the dialect does not
        know: counted ``unknown_message``, not corrupt."""
        if count > 0:
            self.decoder.unknown_frame(count)

    # ------------------------------------------------------------------ timer

    def next_due_s(self) -> float:
        """When :meth:`on_timer` next has something to send, on the driver's ``t_rx_s``
        clock (s); ``-inf`` before the first call: due at once. The engine's due time
        (:meth:`Engine.next_due_s`, autopilot clock) is mapped through the newest data
        sample: a silence's alerts come at their time, not with the next message."""
        return min(self._next_heartbeat_s, self.params.next_due_s(), self._engine_due_rx_s())

    def _engine_due_rx_s(self) -> float:
        clock = self._data_clock
        if clock is None:
            return math.inf
        due_s = self.engine.next_due_s()
        if not math.isfinite(due_s):
            return math.inf
        rx0, t0 = clock
        return rx0 + (due_s - t0)

    def on_timer(self, t_rx_s: float) -> list[bytes]:
        """The periodic output due at ``t_rx_s`` (nothing when called early): what the
        engine raises when no sample comes (:meth:`Engine.on_clock`: GNSS_LOST, NO_DATA,
        NO_GNSS at their time; streams are requested again when the data stops), the next
        PARAM_VALUEs of a parameter list being sent, and our HEARTBEAT, the next one a
        heartbeat period after ``t_rx_s``. A replay calls it at each :meth:`next_due_s`
        before the record that follows it, the service when its timer wakes."""
        frames = self._engine_timer(t_rx_s)
        frames += [self._pack(m) for m in self.params.on_timer(t_rx_s)]
        if t_rx_s < self._next_heartbeat_s:
            return frames
        self._next_heartbeat_s = t_rx_s + self._heartbeat_period_s
        frames.append(self.heartbeat())
        return frames

    def _engine_timer(self, t_rx_s: float) -> list[bytes]:
        clock = self._data_clock
        if clock is None:
            return []
        engine = self.engine
        due_s = engine.next_due_s()
        rx0, t0 = clock
        t_s = t0 + (t_rx_s - rx0)
        # the round trip through the driver's clock (UNIX time: 0.2 us resolution) may
        # land a hair before the due time: fire at the due time itself
        if not t_s >= due_s - ROUND_TRIP_S:
            return []
        silent = engine.watch.silent
        frames: list[bytes] = []
        for out in engine.on_clock(max(t_s, due_s)):
            frames += self._encode(out)
        if engine.watch.silent and not silent:
            frames += self._request_streams()  # a stopped stream may be a reset stream rate
        return frames

    # ------------------------------------------------------------------ parameters

    def _on_param_request(self, msg: Any, t_rx_s: float) -> list[bytes]:
        """PARAM_REQUEST_LIST / _READ / PARAM_SET: answered by :attr:`params` when addressed
        to us; a parameter set that the running service takes live is applied at once."""
        decoder = self.decoder
        try:
            request = decode_param_request(
                msg, self.encoder.system_id, decoder.config.own_component
            )
        except Rejected as exc:
            count_rejection(decoder.rejections, exc.args[0])
            return []
        answer = self.params.handle(request, self.config, t_rx_s)
        if answer.rejection is None:
            decoder.accepted[msg._type] += 1
        else:
            count_rejection(decoder.rejections, answer.rejection)
        frames = [self._pack(m) for m in answer.messages]
        if answer.config is not None:
            frames += self.reconfigure(answer.config)
        return frames

    def reconfigure(self, config: Config) -> list[bytes]:
        """Run with ``config`` from now on. Only the keys of
        :data:`companion.params.LIVE_KEYS` may differ from the running configuration
        (ValueError otherwise, before anything changes). New stream rates are requested
        from the autopilot at once (the frames returned); the heartbeat follows its new
        rate from the next one; the encoder and the engine apply theirs."""
        old = self.config
        changed = [
            f.name
            for f in dataclasses.fields(Config)
            if getattr(config, f.name) != getattr(old, f.name)
        ]
        for block in changed:
            new_block, old_block = getattr(config, block), getattr(old, block)
            fixed = [
                f.name
                for f in dataclasses.fields(new_block)
                if getattr(new_block, f.name) != getattr(old_block, f.name)
                and f.name not in LIVE_KEYS.get(block, frozenset())
            ]
            if fixed:
                raise ValueError(f"[{block}] {', '.join(fixed)}: only at a restart")
        self.config = config
        frames: list[bytes] = []
        for block in changed:
            if block == "encoder":
                self.encoder.reconfigure(config.encoder)
                self.agp.configured_id = config.encoder.gps_id
                frames += self._apply_autopilot_params()
            elif block == "link":
                old_period_s = self._heartbeat_period_s
                self._heartbeat_period_s = period_s = 1.0 / config.link.heartbeat_rate_hz
                due_s = self._next_heartbeat_s
                self._next_heartbeat_s = min(due_s, due_s - old_period_s + period_s)
            elif block == "streams":
                self.rates = RateMonitor(config.streams.rates_hz())
                frames += self._request_streams()
            else:
                self.engine.reconfigure(block, getattr(config, block))
        log.info("configuration changed live: [%s]", "], [".join(changed))
        return frames

    # ------------------------------------------------------------------ out

    def heartbeat(self) -> bytes:
        """Our HEARTBEAT: ``system_status`` from the navigation's health (ACTIVE while
        navigating, STANDBY before the first fix, CRITICAL when lost, silent or without
        GNSS), ``custom_mode`` the navigation state (:data:`NAV_STATES`)."""
        engine = self.engine
        watch = engine.watch
        mode = engine.outage.mode
        if watch.silent:
            status, state = MAV_STATE_CRITICAL, NAV_SILENT
        elif watch.waiting and watch.no_gnss_announced:
            status, state = MAV_STATE_CRITICAL, NAV_NO_GNSS
        elif mode is NavMode.LOST:
            status, state = MAV_STATE_CRITICAL, NAV_STATES[mode]
        elif mode is NavMode.INIT:
            status, state = MAV_STATE_STANDBY, NAV_STATES[mode]
        else:
            status, state = MAV_STATE_ACTIVE, NAV_STATES[mode]
        return self._pack(self.encoder.heartbeat(status, state))

    @property
    def flavour(self) -> AutopilotFlavour:
        """The autopilot family (decides GPS_INPUT vs GLOBAL_POSITION_SENSOR)."""
        return self.decoder.flavour

    def _answer(
        self, command: DecodedCommand, sample: HeadingCommand | None, t_rx_s: float
    ) -> list[bytes]:
        """Exactly one COMMAND_ACK to the sender of a command addressed to us, after what
        carrying it out publishes. A retransmission (:class:`Retransmissions`) gets the
        original's result and is not carried out again; the result decoding decided
        (``command.result``) is sent as is; otherwise the engine carries out ``sample``
        and its :class:`~companion.types.CommandResult` is the answer. A reason (not for
        ACCEPTED or UNSUPPORTED) goes to the operator as ``CMP HDG_CMD <reason>``."""
        request = command.request
        frames: list[bytes] = []
        repeated = self.retransmissions.repeat(request, t_rx_s)
        if repeated is not None:
            result = repeated
            log.info("command %d retransmitted: answered %d again", request.command, result)
        elif command.result is not None or sample is None:
            result = MAV_RESULT_FAILED if command.result is None else command.result
            frames += self._command_reason(result, command.reason)
        else:
            outcome, reason, outputs = self._carry_out(sample)
            for out in outputs:
                if isinstance(out, Alert) and out.code in COMMAND_ALERTS:
                    self.encoder.allow_next(out.code)
                frames += self._encode(out)
            result = MAV_RESULTS[outcome]
            frames += self._command_reason(result, reason)
        self.retransmissions.remember(request, result, t_rx_s)
        self.stats.commands[_RESULT_NAMES.get(result, str(result))] += 1
        ack = self.encoder.command_ack(
            request.command, result, request.source_system, request.source_component
        )
        return frames + [self._pack(ack)]

    def _carry_out(self, sample: HeadingCommand) -> tuple[CommandOutcome, str, list[Output]]:
        """The engine's outcome of a command, its reason and its other outputs. The
        command must be answered whatever happens: an error is FAILED, logged, not raised."""
        try:
            outputs = self.engine.handle(sample)
        except Exception:  # answered FAILED: the service carries on
            log.exception("heading command %s failed", sample.action.value)
            return CommandOutcome.FAILED, "failed: internal error (see log)", []
        results = [o for o in outputs if isinstance(o, CommandResult)]
        others: list[Output] = [o for o in outputs if not isinstance(o, CommandResult)]
        if len(results) != 1:
            log.error("heading command %s: %d results", sample.action.value, len(results))
            return CommandOutcome.FAILED, "failed: no single answer", others
        return results[0].outcome, results[0].reason, others

    def _command_reason(self, result: int, reason: str) -> list[bytes]:
        """``CMP HDG_CMD <reason>`` for a command not accepted (none without a reason)."""
        if result in (MAV_RESULT_ACCEPTED, MAV_RESULT_UNSUPPORTED) or not reason:
            return []
        temporary = result == MAV_RESULT_TEMPORARILY_REJECTED
        severity = Severity.NOTICE if temporary else Severity.WARNING
        t_s = self.decoder.last_t_s
        alert = Alert(0.0 if t_s is None else t_s, AlertCode.HDG_CMD, severity, reason)
        self.encoder.allow_next(alert.code)
        return self._encode(alert)

    def _encode(self, out: Output) -> list[bytes]:
        if type(out) is NavSolution:  # the ramp of a new lag steps by its accuracy
            self.lags.solution_h_acc_m = out.h_acc_m  # type: ignore[union-attr]
        elif isinstance(out, Alert):
            self.alerts.append(out)
            log.warning("CMP %s %s", out.code.value, out.text)
        stats = self.stats
        frames = []
        for name, frame in self.encoder.encode_frames(out, self.decoder.flavour):
            stats.out_by_type[name] += 1
            frames.append(frame)
        stats.messages_out += len(frames)
        return frames

    def _pack(self, msg: Any) -> bytes:
        stats = self.stats
        stats.messages_out += 1
        stats.out_by_type[msg._type] += 1
        return self.encoder.pack(msg)

    def _on_autopilot_heartbeat(self, system_id: int) -> list[bytes]:
        if self.decoder.system_id is not None and self.encoder.system_id != self.decoder.system_id:
            self.encoder.system_id = self.decoder.system_id
        first = self._autopilot is None
        self._autopilot = (system_id, 1)
        if first:
            self._restart_agp()
        return self._request_streams() if first else []

    def _restart_agp(self) -> None:
        """A new autopilot, or it rebooted: its aux global position set-up is read again;
        until then the configured id, and no feedback guard."""
        self.agp.restart()
        self.encoder.agp_id = None
        self.encoder.agp_hold = True
        self.encoder.feedback_guard = False

    def _feeds_px4(self) -> bool:
        """The solution goes to PX4 as GLOBAL_POSITION_SENSOR."""
        output = self.config.encoder.output
        return output == "global_position_sensor" or (
            output == "auto" and self.decoder.flavour is AutopilotFlavour.PX4
        )

    def _agp_requests(self, t_s: float | None) -> list[bytes]:
        """PARAM_REQUEST_READs of PX4's aux global position parameters, when due."""
        if self._autopilot is None:
            return []
        msgs = self.agp.requests(self.encoder.dialect_module, self._autopilot, t_s)
        self.encoder.agp_hold = self.agp.waiting
        return [self._pack(m) for m in msgs]

    def _on_px4_param(self, msg: Any) -> list[bytes]:
        """A PARAM_VALUE from PX4: one of its aux global position parameters sets the
        GLOBAL_POSITION_SENSOR id; a problem is announced (``CMP AP_CONFIG``)."""
        decoder = self.decoder
        verdict = self.agp.on_param_value(msg)
        if verdict is None:
            return []
        self.encoder.agp_id = verdict.sensor_id
        self.encoder.agp_hold = False
        # what PX4 fuses must not be built on what PX4 derived from it
        self.encoder.feedback_guard = verdict.fused
        if verdict.problem is None:
            return []
        t_s = decoder.last_t_s
        alert = Alert(
            0.0 if t_s is None else t_s, AlertCode.AP_CONFIG, Severity.WARNING, verdict.problem
        )
        self.encoder.allow_next(alert.code)
        return self._encode(alert)

    def _request_streams(self) -> list[bytes]:
        if self._autopilot is None:
            return []
        frames = self._agp_requests(None) if self._feeds_px4() else []
        sysid, compid = self._autopilot
        flavour = self.decoder.flavour
        rates = select_streams(flavour, self.config.streams.rates_hz(), self._max_stream_hz())
        msgs = stream_requests(sysid, compid, flavour, rates)
        self.stats.stream_requests += 1
        self.rates = RateMonitor(rates)
        self._next_rate_check_s = None
        log.info("requested %d streams from autopilot %d", len(msgs), sysid)
        return [self._pack(m) for m in msgs] + frames

    def _max_stream_hz(self) -> float | None:
        """The fastest rate the autopilot grants a stream: ArduPilot denies an interval
        whose milliseconds times 800 are below its loop period in microseconds
        (GCS_MAVLINK::set_message_interval), i.e. above 0.8 of ``SCHED_LOOP_RATE``; until
        that is read, 0.8 of the slowest default loop (Plane, Rover: 50 Hz)."""
        if self.decoder.flavour is not AutopilotFlavour.ARDUPILOT:
            return None
        loop_hz = ARDUPILOT_MIN_LOOP_HZ if self._loop_rate_hz is None else self._loop_rate_hz
        return 1000.0 / math.ceil(1000.0 / (ARDUPILOT_STREAM_FRACTION * loop_hz) - 1e-9)

    def _check_rates(self, t_s: float) -> list[bytes]:
        """Warn (in the log) when a needed stream arrives below its requested rate;
        once when it starts falling short and once when it recovers."""
        if self._next_rate_check_s is None:
            self._next_rate_check_s = t_s + RATE_CHECK_PERIOD_S
            return []
        if t_s < self._next_rate_check_s:
            return []
        self._next_rate_check_s = t_s + RATE_CHECK_PERIOD_S
        requested = self.rates.rates_hz
        short: dict[str, str] = {}
        for need, names in STREAM_NEEDS.items():
            wanted = [requested[n] for n in names if n in requested]
            if not wanted:
                continue
            got, best = max((self.rates.measured_hz(n, t_s), n) for n in names)
            want, what = min(wanted), "requested"
            receiver_hz = self.autopilot_params.gnss_rate_hz
            if need == "GNSS" and receiver_hz is not None and receiver_hz < want:
                # distinct fixes (repeats are dropped) come no faster than the receiver's rate
                want, what = receiver_hz, "the receiver's rate"
            if got < self.rates.min_fraction * want:
                short[need] = f"{need} at {got:.1f} Hz (best: {best}), {what} {want:g} Hz"
        for need in sorted(set(short) - self._short_streams):
            self.stats.rate_warnings += 1
            log.warning("stream rate: %s", short[need])
        for need in sorted(self._short_streams - set(short)):
            log.info("stream rate: %s back to the requested rate", need)
        self._short_streams = set(short)
        return []

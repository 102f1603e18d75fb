"""Replay a recorded flight through the service, as fast as the CPU allows.

The flight is a telemetry log (.tlog), an ArduPilot DataFlash log (.bin) or a PX4
ULog (.ulg), told apart by content (:func:`companion.mavlink.logs.open_flight_log`;
the latter two read as the MAVLink streams a telemetry log of the flight holds).

Every message the service would send is written to the output .tlog, stamped
with the input log's time of the message that caused it; what the pipeline sends
on its timer (our HEARTBEAT, ``link.heartbeat_rate_hz`` of log time; the alerts due
while no message comes: GNSS_LOST, NO_DATA, NO_GNSS) is sent at its due time, in log
time, before the next record, as the live service's timer would: a silence in the log
produces its alerts when they were due, not when the next record arrives. The
replay is deterministic: the same input and configuration give byte-identical
output (docs/replay.md).

With a raw receiver's recording beside the log (``raw``: a u-blox .ubx with RXM-RAWX,
RXM-SFRBX and NAV-PVT, :mod:`companion.raw.link`), its messages are fed between the
log's records at their own time: the epoch's GPS time less :data:`GPS_UTC_LEAP_S`
(a telemetry log's record times are UNIX time) plus ``raw_delay_s``. Its navigation
words are all given first: an aircraft's receiver has its ephemerides from before the
flight, and a recording that starts with the flight would otherwise leave the first
half-minute without any (a recording is what the replay has; the live link takes
them as they come).
"""

from __future__ import annotations

import itertools
import logging
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from companion.config import Config
from companion.mavlink.decode import LIGHT_MESSAGE_IDS
from companion.mavlink.logs import open_flight_log
from companion.mavlink.tlog import TlogError, TlogWriter, describe_file
from companion.pipeline import Pipeline
from companion.raw.obs import NavWords, PvtFix, RawEpoch, ReceiverStatus
from companion.types import Alert

RawItem = RawEpoch | NavWords | PvtFix | ReceiverStatus

log = logging.getLogger(__name__)

PROGRESS_EVERY_MESSAGES = 20_000
GPS_EPOCH_UNIX_S = 315_964_800.0
"""1980-01-06 00:00:00 UTC as UNIX time."""
GPS_UTC_LEAP_S = 18.0
"""GPS time minus UTC since 2017-01-01 (IERS): no leap second announced since."""
SECONDS_PER_WEEK = 604_800.0


@dataclass(frozen=True, slots=True)
class ReplaySummary:
    """What a replay did, for the summary line and the tests."""

    messages_in: int
    messages_out: int
    out_by_type: dict[str, int]
    rejections: dict[str, int]
    alerts: dict[str, int]
    log_duration_s: float
    wall_s: float
    corrupt_records: int
    raw_solutions: int = 0
    """Carrier-phase solutions the raw link passed to the engine (``--raw``)."""
    raw_rejections: dict[str, int] = field(default_factory=dict)
    integrity_stats: dict[str, int] = field(default_factory=dict)
    """The integrity monitor's counters (rejections and tests by reason)."""
    alert_log: tuple[tuple[float, Alert], ...] = ()
    """Every alert raised, in order, with the log time of the record (or timer tick) that
    raised it: what was raised, before the STATUSTEXT rate limit (``bench/false_alerts.py``)."""

    def to_text(self) -> str:
        """A short human summary."""
        rate = self.messages_in / self.wall_s if self.wall_s > 0 else float("inf")
        lines = [
            f"replayed {self.messages_in} messages ({self.log_duration_s:.1f} s of flight) "
            f"in {self.wall_s:.2f} s ({rate:,.0f} msg/s)",
            f"published {self.messages_out} messages: "
            + ", ".join(f"{k} {v}" for k, v in sorted(self.out_by_type.items())),
            "rejected: "
            + (", ".join(f"{k} {v}" for k, v in sorted(self.rejections.items())) or "none"),
            "alerts: " + (", ".join(f"{k} {v}" for k, v in sorted(self.alerts.items())) or "none"),
        ]
        if self.raw_solutions or self.raw_rejections:
            raw = ", ".join(f"{k} {v}" for k, v in sorted(self.raw_rejections.items()))
            lines.append(
                f"raw receiver: {self.raw_solutions} carrier-phase solutions; rejected: "
                + (raw or "none")
            )
        return "\n".join(lines)


def timed_raw_items(items: Iterable[RawItem], delay_s: float = 0.0) -> list[tuple[float, RawItem]]:
    """A raw receiver's messages in stream order with the UNIX time each is fed at: the
    navigation words first (time ``-inf``), an epoch and its NAV-PVT at the epoch's GPS
    time as UTC plus ``delay_s`` (a NAV-PVT before any epoch is dropped: no week); a
    receiver status without a time of its own (MON-RF, MON-HW) at the newest epoch's."""
    words: list[tuple[float, RawItem]] = []
    timed: list[tuple[float, RawItem]] = []
    week: int | None = None
    for item in items:
        if isinstance(item, NavWords):
            words.append((-float("inf"), item))
            continue
        if isinstance(item, RawEpoch):
            week = item.week
            tow_s = item.tow_s
        elif week is None:
            continue
        elif item.itow_s is not None:
            tow_s = item.itow_s
        # else a receiver status without a time (MON-RF, MON-HW): the newest epoch's
        utc_s = GPS_EPOCH_UNIX_S + week * SECONDS_PER_WEEK + tow_s - GPS_UTC_LEAP_S
        timed.append((utc_s + delay_s, item))
    timed.sort(key=lambda pair: pair[0])  # stable: an epoch before its NAV-PVT
    return words + timed


def read_raw(
    path: Path, delay_s: float = 0.0
) -> tuple[list[tuple[float, RawItem]], dict[str, int]]:
    """:func:`timed_raw_items` of a .ubx file, and the frames its reader rejected."""
    from companion.ubx.reader import UbxSource

    with open(path, "rb") as fh:
        source = UbxSource(fh)
        items = list(source)
    return timed_raw_items(items, delay_s), dict(source.rejected)


def replay(
    in_path: Path,
    out_path: Path,
    config: Config | None = None,
    progress: Callable[[str], None] | None = None,
    raw: Iterable[tuple[float, RawItem]] | None = None,
    raw_reader_rejections: dict[str, int] | None = None,
) -> ReplaySummary:
    """Feed ``in_path`` through a :class:`Pipeline`, writing what it sends to ``out_path``.

    Raises ``companion.mavlink.tlog.TlogError`` when the input cannot be read: missing,
    another format, or no record in it (the message says what the file looks like; no
    output is written then). A tlog with some corrupt records replays the rest.
    """
    # the decoder is the only consumer of the messages: light messages where it takes them;
    # a DataFlash .bin or a PX4 .ulg (by content) is read as the streams its .tlog holds
    # a telemetry log is parsed with the dialect the service parses its links with
    dialect = (config or Config()).encoder.dialect
    reader = open_flight_log(in_path, light_ids=LIGHT_MESSAGE_IDS, dialect=dialect)
    prefix = getattr(reader, "stats_prefix", "tlog_")
    records = iter(reader)
    first_record = next(records, None)
    if first_record is None:  # before the pipeline is built: the error is all that is said
        if prefix == "tlog_":
            raise TlogError(f"{in_path}: no tlog record: {describe_file(in_path)}")
        raise TlogError(
            f"{in_path}: {reader.what} with nothing to replay in it "
            "(no IMU, attitude, GNSS or position record)"
        )
    pipeline = Pipeline(config)
    raw_iter: Iterator[tuple[float, RawItem]] = iter(raw if raw is not None else ())
    next_raw = next(raw_iter, None)
    if raw is not None:
        pipeline.enable_raw()
    wall0 = time.perf_counter()
    first_t: float | None = None
    last_t = 0.0
    due_s = pipeline.next_due_s()
    count = 0
    alert_log: list[tuple[float, Alert]] = []

    def log_alerts(t_s: float) -> None:
        """Stamp the alerts the last call raised with its log time."""
        alert_log.extend((t_s, a) for a in pipeline.alerts[len(alert_log) :])

    with TlogWriter(out_path) as writer:

        def timer_until(t_s: float) -> None:
            """What the pipeline's timer sends up to ``t_s``, at its due times."""
            nonlocal due_s
            while due_s <= t_s:
                # at its due time (the first is due at once: at the first record)
                t_due_s = max(due_s, last_t)
                frames = pipeline.on_timer(t_due_s)
                log_alerts(t_due_s)
                if frames:
                    writer.write_frames(t_due_s, frames)
                next_s = pipeline.next_due_s()
                if not next_s > due_s:  # nothing moved it on: leave it to the next record
                    break
                due_s = next_s

        for t_rx_s, msg in itertools.chain((first_record,), records):
            if first_t is None:
                first_t = last_t = t_rx_s
            while next_raw is not None and next_raw[0] <= t_rx_s:
                # the raw receiver's messages due before this record, in time order
                t_raw_s = max(next_raw[0], last_t)
                timer_until(t_raw_s)
                frames = pipeline.on_raw(next_raw[1], t_raw_s)
                log_alerts(t_raw_s)
                if frames:
                    writer.write_frames(t_raw_s, frames)
                last_t = t_raw_s
                due_s = pipeline.next_due_s()
                next_raw = next(raw_iter, None)
            timer_until(t_rx_s)
            last_t = t_rx_s
            frames = pipeline.on_message(msg, t_rx_s)
            log_alerts(t_rx_s)
            if frames:
                writer.write_frames(t_rx_s, frames)
            due_s = pipeline.next_due_s()
            count += 1
            if progress is not None and count % PROGRESS_EVERY_MESSAGES == 0:
                progress(f"{in_path.name}: {count} messages, {t_rx_s - first_t:.0f} s of flight")
    tlog = prefix == "tlog_"
    if tlog:  # a corrupt region of a tlog is a corrupt frame, as live
        pipeline.bad_frames(reader.stats["bad_region"])
    rejections = dict(pipeline.decoder.rejections)
    for reason, n in reader.stats.items():
        if n and reason != "bad_bytes" and not (tlog and reason == "bad_region"):
            rejections[f"{prefix}{reason}"] = n
    return ReplaySummary(
        messages_in=pipeline.stats.messages_in,
        messages_out=pipeline.stats.messages_out,
        out_by_type=dict(pipeline.stats.out_by_type),
        rejections=rejections,
        alerts={k: v for k, v in pipeline.engine.stats.alerts.items()},
        log_duration_s=(last_t - first_t) if first_t is not None else 0.0,
        wall_s=time.perf_counter() - wall0,
        corrupt_records=reader.stats["bad_region"],
        raw_solutions=pipeline.raw.solutions if pipeline.raw is not None else 0,
        integrity_stats=dict(pipeline.engine.integrity.stats),
        raw_rejections={
            **(pipeline.raw.rejections() if pipeline.raw is not None else {}),
            **(raw_reader_rejections or {}),
        },
        alert_log=tuple(alert_log),
    )

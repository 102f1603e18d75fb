"""Scoring a replay against its own input, without truth (``companion evaluate OUT
--against-input IN``).

There is no truth for a real flight. Outside its gaps the receiver's own fixes in the
input log are the reference; across a gap, the first fix after it, against what holding
the last fix and constant-velocity extrapolation would have given. The receiver side is
the input tlog decoded by the service's own :class:`~companion.mavlink.decode.Decoder`
(same units, same clock, same rejections as a replay); the published side is the output
tlog read back with :mod:`companion.mavlink.readback`. One figure per acceptance rule,
each with its threshold and a pass mark (None: not applicable to this log).

Clocks
    Positions are compared on the autopilot clock (``t_s``: fix time of validity,
    ``GPS_INPUT.time_usec``), made continuous across autopilot reboots (each reboot's
    clock continues where the previous one stopped). Everything about alerts, silences
    and message rates is on the record clock of the tlogs (``t_rx``): a replay stamps
    each output record with the input record that caused it, so both logs share it.
Published solution
    GPS_INPUT (ArduPilot) or GLOBAL_POSITION_SENSOR (PX4; "fix type >= 3" is its
    PRIMARY, not UNHEALTHY flag, velocity from the GLOBAL_POSITION_INT of the same
    millisecond). Accuracies are 1-sigma (docs/mavlink.md). 95 % horizontal radius =
    :data:`H95_PER_SIGMA` (``sqrt(chi2.ppf(0.95, 2))`` = 2.448) x sigma, 99 % =
    :data:`H99_PER_SIGMA` (``sqrt(chi2.ppf(0.99, 2))`` = 3.035) x sigma. With neither
    message (autopilot never identified) GLOBAL_POSITION_INT is used, with no fix type.
Receiver fix
    A decoded GPS_RAW_INT / GPS2_RAW with ``fix_type >= 3``. Its 1-sigma horizontal
    accuracy is ``h_acc`` when reported, else HDOP x ``UERE_M`` (2.5 m), else the fix
    type's fallback: the service's own rule (:func:`companion.nav.gnss.gnss_measurement`);
    how many came from HDOP is reported.
Concurrent fix
    The receiver track interpolated linearly to the published time between the two
    consecutive fixes of that receiver that bracket it, both 3-D and at most
    :func:`max_bracket_s` apart (:data:`SPACING_FACTOR` x the receiver's median 3-D fix
    interval, at least :data:`BRACKET_MIN_S`: a missed epoch is not a gap, while a chord
    over 1 s departs from a path accelerating at a by a/8 m at most, 0.65 m for an
    aircraft turning at 15 deg/s at 20 m/s): never across a gap or a no-fix. With two
    receivers the nearer one is the reference.
1. Never confidently wrong
    Every published solution with fix type >= 3 and a concurrent fix: the *horizontal*
    distance to it (vertical reported, not judged: receivers' heights are 1.5-2x worse
    and the failure seen is horizontal). Wrong: more than :data:`WRONG_LIMIT_M`. Coverage:
    fraction whose distance is within ``H95 * sqrt(sigma_pub^2 + sigma_rx^2)`` (the two
    95 % radii root-sum-squared); required >= :data:`COVERAGE_REQUIRED`.
2. Receiver use
    Time the receiver reports a 3-D fix with >= :data:`USE_MIN_SATELLITES` satellites,
    from :data:`USE_SETTLE_S` after its first 3-D fix (each fix weighted by the time to the
    next, at most :func:`max_bracket_s`; the last by the median interval). The service
    is using it when its latest ``CMP_OUTG`` (time since the last fused fix while in an
    outage, else 0) is 0 and its latest HEARTBEAT is ACTIVE (STANDBY = not started,
    CRITICAL = LOST), both no older than :data:`STATUS_MAX_AGE_S`: navigation mode NORMAL
    or DEGRADED. Required >= :data:`USE_REQUIRED`. (Whether a second source showed the
    receiver wrong is not judged here.)
3. GNSS gaps
    Consecutive receiver fixes (any receiver) :data:`GAP_MIN_S` or more apart in
    autopilot time; also the end of the log when the data streams run on that long
    after the last fix (no closure then).

    * Alert latency: from the last fix's record to the first :data:`LOSS_ALERT_CODES`
      alert before the gap's first fix; 0 when the service was already in an outage (its
      latest loss alert newer than its latest GNSS_BACK, and its ``CMP_OUTG`` at the last
      fix, where fresh, not 0: a GNSS_BACK may have been rate-limited away); "missed"
      when none.
      Required <= :data:`GAP_ALERT_MAX_S`. A slow, irregular link (a ground station's
      1 Hz telemetry) cannot be alerted 1.5 s after each last fix without an alert per
      long interval: while the service's ``GNSS_SLOW`` announcement is in force (newer
      than its ``GNSS_STEADY``), the next fix is due by the link's rhythm, measured here
      from the input (the longest interval under :data:`GAP_MIN_S` between the
      receiver's 3-D fixes in the :data:`RHYTHM_WINDOW_S` before the last fix), and the
      latency is counted from then; a gap over before an alert was owed (due +
      :data:`GAP_ALERT_MAX_S`) had the announcement for its alert ("rhythm").
    * Closure: the last solution published before the first fix after the gap was read
      (record time strictly earlier), carried to the fix's time with its own published
      velocity (at most :data:`CLOSURE_MAX_AGE_S`), against that fix: horizontal
      distance. Hold: last fix vs that fix. Constant velocity: last fix moved by its own
      velocity over the gap. Ratio: closure / min(hold, constant velocity). Inside 99 %:
      closure <= H99 x the published sigma of that solution.
    * IMU rate: samples of each decoded IMU stream inside the gap over its length, the
      best stream; :data:`IMU_MIN_HZ` or more is "IMU running".
    * Required, over the gaps with the IMU running: median ratio <= :data:`RATIO_MEDIAN_MAX`,
      every ratio <= :data:`RATIO_ANY_MAX`, every closure inside its 99 % bound. A gap with
      no solution to close is a failure. A closure within :data:`CLOSURE_TIE_M` (the
      published position's rounding) of the better of hold and constant velocity is judged
      a tie (ratio 1).
4. Whole-stream dropouts
    No decoded navigation sample (IMU, attitude, GNSS, the autopilot's own position,
    VFR_HUD, landed state: everything but HEARTBEAT and SYSTEM_TIME) for
    :data:`DROPOUT_MIN_S` on the record clock. The first solution published at or after
    the resume record against the first 3-D fix read at or after it, the fix carried to
    the solution's time by its own velocity (comparable only within
    :func:`max_bracket_s`); required inside the solution's own 99 % bound.
5. No GNSS at start
    When no 3-D fix is read within :data:`NO_GNSS_ALERT_MAX_S` of the first record of the
    autopilot's system (or never: a log without GNSS), the first loss alert after that
    record; required within :data:`NO_GNSS_ALERT_MAX_S`.
6. STATUSTEXT
    Every whole text the service sent (chunks joined): total, mean per minute of log, and
    the most in any :data:`TEXT_WINDOW_S` window starting at a text, real changes left
    out; required <= :data:`TEXT_MAX_PER_WINDOW`. A real change is a loss or return alert
    (:data:`REAL_CHANGE_CODES`) sent while the input itself shows a gap of at least
    :data:`GAP_MIN_S` between 3-D fixes or a dropout of every stream of at least
    :data:`DROPOUT_MIN_S` (from its start to :data:`GAP_ALERT_MAX_S` after its end).
    Parked: consecutive 3-D fixes (at most :func:`max_bracket_s` apart) slower than
    :data:`PARKED_SPEED_MPS` (ground speed) for at least :data:`PARKED_MIN_S`. A flap is
    an alert inside a parked interval whose key (code and text with every number removed)
    already occurred in that interval; required: no flap of :data:`FLAP_CODES` (phase and
    integrity).
"""

from __future__ import annotations

import bisect
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pymap3d
from scipy import stats

from companion.evaluate.against_input_report import (
    AgainstInput,
    ConfidenceResult,
    DropoutResult,
    GapResult,
    GapsSummary,
    NoGnssResult,
    ReceiverUseResult,
    TextResult,
)
from companion.evaluate.results import EvaluationError
from companion.evaluate.score import H95_PER_SIGMA
from companion.mavlink.decode import LIGHT_MESSAGE_IDS, Decoder, DecoderConfig
from companion.mavlink.ids import MAV_COMP_ID_ONBOARD_COMPUTER, MAV_STATE_ACTIVE
from companion.mavlink.readback import (
    PublishedFix,
    PublishedHeartbeat,
    PublishedPosition,
    PublishedSensorFix,
    PublishedText,
    TextJoiner,
    from_service,
    parse_alert,
    read_message,
)
from companion.mavlink.tlog import TlogError, TlogReader, describe_file
from companion.nav.gnss import FALLBACK_H_STD_M, UERE_M, UNKNOWN_H_STD_M
from companion.types import (
    FixType,
    FloatArray,
    GnssFix,
    HeartbeatSample,
    ImuSample,
    NamedValue,
    RebootEvent,
)

H99_PER_SIGMA: float = float(np.sqrt(stats.chi2.ppf(0.99, 2)))
"""2-D 99 % radius per 1-sigma of a circular Gaussian (3.035)."""
WRONG_LIMIT_M = 25.0
COVERAGE_REQUIRED = 0.95
SPACING_FACTOR = 1.5
BRACKET_MIN_S = 1.0
USE_MIN_SATELLITES = 6
USE_SETTLE_S = 10.0
USE_REQUIRED = 0.98
STATUS_MAX_AGE_S = 2.0
GAP_MIN_S = 3.0
GAP_ALERT_MAX_S = 1.5
IMU_MIN_HZ = 20.0
RATIO_MEDIAN_MAX = 1.0
RATIO_ANY_MAX = 1.5
CLOSURE_TIE_M = 0.008
"""A closure this close to the better of hold and constant velocity is judged equal to it
(ratio 1): half the diagonal of the published position's step (1e-7 deg of latitude and
longitude, 1.1 cm north), the rounding any published closure carries."""
CLOSURE_MAX_AGE_S = 1.0
DROPOUT_MIN_S = 3.0
NO_GNSS_ALERT_MAX_S = 5.0
TEXT_WINDOW_S = 60.0
TEXT_MAX_PER_WINDOW = 6
REAL_CHANGE_CODES: frozenset[str] = frozenset(
    {"GNSS_LOST", "BRIDGING", "GNSS_BACK", "NO_DATA", "DATA_BACK"}
)
"""Alerts that announce a loss or a return: a real change when the input shows one
(BRIDGING: retired, in older replays)."""
PARKED_SPEED_MPS = 0.5
PARKED_MIN_S = 10.0
LOSS_ALERT_CODES: frozenset[str] = frozenset({"GNSS_LOST", "BRIDGING", "NO_GNSS", "NO_DATA"})
"""Alerts that say GNSS is gone (docs/mavlink.md): GNSS_LOST (BRIDGING, retired, in older
replays); NO_GNSS (no fix has started the navigation); NO_DATA (every stream stopped, GNSS
with them)."""
BACK_ALERT_CODES: frozenset[str] = frozenset({"GNSS_BACK"})
SLOW_ALERT_CODE = "GNSS_SLOW"
STEADY_ALERT_CODE = "GNSS_STEADY"
RHYTHM_WINDOW_S = 60.0
"""The minute of a slow link's fixes before a gap whose longest interval is its rhythm."""
FLAP_CODES: frozenset[str] = frozenset({"INTEGRITY", "CAT"})
"""Codes whose repetition while parked is phase or integrity flapping."""

_NUMBER_RE = re.compile(r"[-+]?\d+(?:\.\d*)?")


# --------------------------------------------------------------------------- reading


@dataclass(frozen=True, slots=True, eq=False)
class _Fixes:
    """Receiver 3-D fixes (or all fixes of one receiver), sorted by autopilot time."""

    t_u: FloatArray
    t_rx: FloatArray
    rx: np.ndarray
    ok3d: np.ndarray
    lat: FloatArray
    lon: FloatArray  # unwrapped
    alt: FloatArray
    vn: FloatArray  # NaN when unknown
    ve: FloatArray
    speed: FloatArray
    sats: FloatArray  # NaN when unknown
    sigma_h: FloatArray
    from_hdop: np.ndarray

    def take(self, mask: np.ndarray) -> _Fixes:
        return _Fixes(*(getattr(self, f)[mask] for f in _FIX_FIELDS))


_FIX_FIELDS = _Fixes.__dataclass_fields__.keys()


@dataclass(slots=True)
class _Input:
    fixes: _Fixes  # every decoded fix, any type, sorted by t_u
    imu: dict[tuple[str, int], FloatArray]  # stream -> sample times t_u
    data_t_rx: FloatArray
    data_t_u: FloatArray
    first_autopilot_t_rx: float | None
    first_t_rx: float
    last_t_rx: float
    reboot_t_rx: list[float]
    offsets: list[float]
    records: int


@dataclass(slots=True)
class _Output:
    source: str | None
    t_u: FloatArray
    t_rx: FloatArray
    fix_type: np.ndarray  # -1 unknown
    lat: FloatArray
    lon: FloatArray
    alt: FloatArray
    vel: FloatArray  # (n, 3), NaN when unknown
    sigma_h: FloatArray  # NaN when none
    outg_t_u: FloatArray
    outg: FloatArray
    hb_t_rx: FloatArray
    hb_status: np.ndarray
    texts: list[tuple[float, str, int]]  # (t_rx, text, severity)
    alerts: list[tuple[float, str, str]]  # (t_rx, code, rest)
    records: int


def _receiver_sigma(fix: GnssFix) -> tuple[float, bool]:
    """The receiver's 1-sigma horizontal accuracy as the service takes it, and whether it
    came from HDOP."""
    if fix.h_acc_m is not None:
        return fix.h_acc_m, False
    if fix.hdop is not None:
        return fix.hdop * UERE_M, True
    return FALLBACK_H_STD_M.get(fix.fix_type, UNKNOWN_H_STD_M), False


def _read_input(path: Path, decoder_config: DecoderConfig | None) -> _Input:
    try:
        reader = TlogReader(path, light_ids=LIGHT_MESSAGE_IDS)
        records = list(reader)
    except TlogError as exc:
        raise EvaluationError(str(exc)) from exc
    if not records:
        raise EvaluationError(f"{path}: no tlog record: {describe_file(path)}")
    decoder = Decoder(decoder_config)
    rows: list[tuple[Any, ...]] = []
    imu: dict[tuple[str, int], list[float]] = {}
    data_rx: list[float] = []
    data_tu: list[float] = []
    reboot_rx: list[float] = []
    offsets = [0.0]
    for t_rx, msg in records:
        for sample in decoder.decode(msg, t_rx):
            if isinstance(sample, RebootEvent):
                reboot_rx.append(t_rx)
                offsets.append(offsets[-1] + sample.previous_t_s - sample.t_s)
                continue
            t_u = sample.t_s + offsets[-1]
            if isinstance(sample, HeartbeatSample):
                continue
            data_rx.append(t_rx)
            data_tu.append(t_u)
            if isinstance(sample, GnssFix):
                sigma, from_hdop = _receiver_sigma(sample)
                vel = sample.vel_ne_mps
                rows.append(
                    (
                        t_u,
                        t_rx,
                        sample.receiver_id,
                        int(sample.fix_type) >= int(FixType.FIX_3D),
                        sample.lat_rad,
                        sample.lon_rad,
                        sample.alt_msl_m,
                        math.nan if vel is None else float(vel[0]),
                        math.nan if vel is None else float(vel[1]),
                        sample.ground_speed_mps,
                        math.nan if sample.satellites is None else float(sample.satellites),
                        sigma,
                        from_hdop,
                    )
                )
            elif isinstance(sample, ImuSample):
                imu.setdefault((sample.source, sample.imu_id), []).append(t_u)
    sysid = decoder.system_id
    first_ap: float | None = None
    if sysid is not None:
        for t_rx, msg in records:
            hdr = msg._header
            if hdr.srcSystem == sysid and hdr.srcComponent != MAV_COMP_ID_ONBOARD_COMPUTER:
                first_ap = t_rx
                break
    rows.sort(key=lambda r: (r[0], r[2]))
    cols = list(zip(*rows, strict=True)) if rows else [()] * 13
    fixes = _Fixes(
        t_u=np.asarray(cols[0], dtype=np.float64),
        t_rx=np.asarray(cols[1], dtype=np.float64),
        rx=np.asarray(cols[2], dtype=np.int64),
        ok3d=np.asarray(cols[3], dtype=bool),
        lat=np.asarray(cols[4], dtype=np.float64),
        lon=np.unwrap(np.asarray(cols[5], dtype=np.float64)) if rows else np.zeros(0),
        alt=np.asarray(cols[6], dtype=np.float64),
        vn=np.asarray(cols[7], dtype=np.float64),
        ve=np.asarray(cols[8], dtype=np.float64),
        speed=np.asarray(cols[9], dtype=np.float64),
        sats=np.asarray(cols[10], dtype=np.float64),
        sigma_h=np.asarray(cols[11], dtype=np.float64),
        from_hdop=np.asarray(cols[12], dtype=bool),
    )
    order = np.argsort(np.asarray(data_rx), kind="stable")
    return _Input(
        fixes=fixes,
        imu={k: np.sort(np.asarray(v)) for k, v in imu.items()},
        data_t_rx=np.asarray(data_rx, dtype=np.float64)[order],
        data_t_u=np.asarray(data_tu, dtype=np.float64)[order],
        first_autopilot_t_rx=first_ap,
        first_t_rx=records[0][0],
        last_t_rx=records[-1][0],
        reboot_t_rx=reboot_rx,
        offsets=offsets,
        records=len(records),
    )


def _read_output(path: Path, inp: _Input) -> _Output:
    try:
        records = list(TlogReader(path))
    except TlogError as exc:
        raise EvaluationError(str(exc)) from exc

    def t_unified(t_s: float, t_rx: float) -> float:
        return t_s + inp.offsets[bisect.bisect_right(inp.reboot_t_rx, t_rx)]

    fix_rows: list[tuple[float, ...]] = []
    sensor_rows: list[tuple[float, ...]] = []
    gpi_rows: list[tuple[float, ...]] = []
    gpi_vel: dict[tuple[float, int], tuple[float, float, float]] = {}
    outg: list[tuple[float, float]] = []
    hbs: list[tuple[float, int]] = []
    texts: list[tuple[float, str, int]] = []
    joiner = TextJoiner()
    for t_rx, msg in records:
        if not from_service(msg):
            continue
        item = read_message(msg)
        if isinstance(item, PublishedFix):
            fix_rows.append(
                (
                    t_unified(item.t_s, t_rx),
                    t_rx,
                    item.fix_type,
                    item.lat_rad,
                    item.lon_rad,
                    item.alt_msl_m,
                    *item.vel_ned_mps,
                    math.nan if item.h_acc_m is None else item.h_acc_m,
                )
            )
        elif isinstance(item, PublishedSensorFix):
            sensor_rows.append(
                (
                    t_unified(item.t_s, t_rx),
                    t_rx,
                    int(FixType.FIX_3D) if item.healthy else int(FixType.NO_FIX),
                    item.lat_rad,
                    item.lon_rad,
                    item.alt_msl_m,
                    math.nan,
                    math.nan,
                    math.nan,
                    math.nan if item.h_acc_m is None else item.h_acc_m,
                )
            )
        elif isinstance(item, PublishedPosition):
            t_u = t_unified(item.t_s, t_rx)
            gpi_vel[(t_rx, round(item.t_s * 1000.0))] = item.vel_ned_mps
            gpi_rows.append(
                (
                    t_u,
                    t_rx,
                    -1,
                    item.lat_rad,
                    item.lon_rad,
                    item.alt_msl_m,
                    *item.vel_ned_mps,
                    math.nan,
                )
            )
        elif isinstance(item, NamedValue):
            if item.name == "CMP_OUTG":
                outg.append((t_unified(item.t_s, t_rx), item.value))
        elif isinstance(item, PublishedHeartbeat):
            hbs.append((t_rx, item.system_status))
        elif isinstance(item, PublishedText):
            done = joiner.add(t_rx, item)
            if done is not None:
                texts.append(done)
    texts += joiner.unfinished()
    texts.sort(key=lambda x: x[0])
    if fix_rows:
        rows, source = fix_rows, "GPS_INPUT"
    elif sensor_rows:
        # GLOBAL_POSITION_SENSOR carries no velocity: the GLOBAL_POSITION_INT of the
        # same solution (same record, same millisecond) does
        rows, source = [], "GLOBAL_POSITION_SENSOR"
        for r in sensor_rows:
            v = gpi_vel.get((r[1], round((r[0] - t_unified(0.0, r[1])) * 1000.0)))
            rows.append(r if v is None else (*r[:6], *v, r[9]))
    elif gpi_rows:
        rows, source = gpi_rows, "GLOBAL_POSITION_INT"
    else:
        rows, source = [], None
    rows.sort(key=lambda r: r[1])  # record order (stable): "published before" is by t_rx
    arr = np.asarray(rows, dtype=np.float64).reshape(-1, 10)
    alerts: list[tuple[float, str, str]] = []
    for t_rx, text, _sev in texts:
        parsed = parse_alert(text)
        if parsed is not None:
            alerts.append((t_rx, parsed[0], parsed[1]))
    o = np.asarray(outg, dtype=np.float64).reshape(-1, 2)
    o = o[np.argsort(o[:, 0], kind="stable")]
    h = np.asarray(hbs, dtype=np.float64).reshape(-1, 2)
    return _Output(
        source=source,
        t_u=arr[:, 0],
        t_rx=arr[:, 1],
        fix_type=arr[:, 2].astype(np.int64),
        lat=arr[:, 3],
        lon=arr[:, 4],
        alt=arr[:, 5],
        vel=arr[:, 6:9],
        sigma_h=arr[:, 9],
        outg_t_u=o[:, 0],
        outg=o[:, 1],
        hb_t_rx=h[:, 0],
        hb_status=h[:, 1].astype(np.int64),
        texts=texts,
        alerts=alerts,
        records=len(records),
    )


# --------------------------------------------------------------------------- geometry


def _ne(
    lat: FloatArray,
    lon: FloatArray,
    alt: FloatArray,
    lat0: FloatArray,
    lon0: FloatArray,
    alt0: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """North, east, up (m) of (lat, lon, alt) in the local frame at (lat0, lon0, alt0)."""
    lon = lon0 + (lon - lon0 + math.pi) % (2.0 * math.pi) - math.pi
    n, e, d = pymap3d.geodetic2ned(lat, lon, alt, lat0, lon0, alt0, deg=False)
    return (
        np.asarray(n, dtype=np.float64),
        np.asarray(e, dtype=np.float64),
        -np.asarray(d, dtype=np.float64),
    )


def _median_interval(t: FloatArray) -> float:
    d = np.diff(t)
    d = d[d > 0]
    return float(np.median(d)) if d.size else math.inf


def max_bracket_s(t: FloatArray) -> float:
    """Longest interval between consecutive fixes (times ``t``) still one track, s:
    SPACING_FACTOR x the median interval, at least BRACKET_MIN_S, less than GAP_MIN_S."""
    nominal = _median_interval(t)
    if not math.isfinite(nominal):
        return BRACKET_MIN_S
    return min(max(SPACING_FACTOR * nominal, BRACKET_MIN_S), GAP_MIN_S - 1e-9)


def _concurrent(
    fixes: _Fixes, t_q: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, np.ndarray, np.ndarray]:
    """One receiver's track (all its fixes, sorted) at ``t_q``: lat, lon, alt, 1-sigma,
    whether that sigma came from HDOP, valid (see the module docstring: bracketing 3-D
    fixes, never across a gap)."""
    t = fixes.t_u
    _, first = np.unique(t, return_index=True)
    f = fixes.take(first)
    t = f.t_u
    limit = max_bracket_s(t[f.ok3d])
    n = t.size
    j = np.searchsorted(t, t_q, side="right") - 1
    jj = np.clip(j, 0, max(n - 1, 0))
    j1 = np.clip(j + 1, 0, max(n - 1, 0))
    out = np.full(t_q.shape, np.nan)
    if n == 0:
        none = np.zeros(t_q.shape, dtype=bool)
        return out, out.copy(), out.copy(), out.copy(), none, none.copy()
    exact = (j >= 0) & (t[jj] == t_q) & f.ok3d[jj]
    span = t[j1] - t[jj]
    bracket = (j >= 0) & (j + 1 < n) & f.ok3d[jj] & f.ok3d[j1] & (span <= limit)
    valid = exact | bracket
    w = np.where(bracket & (span > 0), (t_q - t[jj]) / np.where(span > 0, span, 1.0), 0.0)
    w = np.where(exact, 0.0, w)

    def lerp(x: FloatArray) -> FloatArray:
        return np.where(valid, x[jj] + w * (x[j1] - x[jj]), np.nan)

    hdop = valid & (f.from_hdop[jj] | f.from_hdop[j1])
    return lerp(f.lat), lerp(f.lon), lerp(f.alt), lerp(f.sigma_h), hdop, valid


# --------------------------------------------------------------------------- metrics


def _confidence(inp: _Input, out: _Output) -> ConfidenceResult:
    claims = out.fix_type >= int(FixType.FIX_3D)
    idx = np.nonzero(claims)[0]
    t_q = out.t_u[idx]
    best_h = np.full(idx.shape, np.inf)
    best_v = np.full(idx.shape, np.nan)
    best_sig = np.full(idx.shape, np.nan)
    best_hdop = np.zeros(idx.shape, dtype=bool)
    for rx in np.unique(inp.fixes.rx):
        f = inp.fixes.take(inp.fixes.rx == rx)
        lat, lon, alt, sig, hdop, valid = _concurrent(f, t_q)
        if not valid.any():
            continue
        n, e, u = _ne(
            out.lat[idx][valid],
            out.lon[idx][valid],
            out.alt[idx][valid],
            lat[valid],
            lon[valid],
            alt[valid],
        )
        h = np.hypot(n, e)
        sel = np.nonzero(valid)[0]
        better = h < best_h[sel]
        tgt = sel[better]
        best_h[tgt] = h[better]
        best_v[tgt] = u[better]
        best_sig[tgt] = sig[sel][better]
        best_hdop[tgt] = hdop[sel][better]
    ok = np.isfinite(best_h)
    h = best_h[ok]
    n_eval = int(h.size)
    if n_eval == 0:
        return ConfidenceResult(
            n_claims=int(idx.size),
            n_evaluated=0,
            n_no_concurrent_fix=int(idx.size),
            n_wrong=0,
            max_h_m=None,
            max_h_t_s=None,
            max_v_m=None,
            coverage=None,
            n_receiver_sigma_from_hdop=0,
            passed_wrong=None,
            passed_coverage=None,
        )
    sig_pub = out.sigma_h[idx][ok]
    bound = H95_PER_SIGMA * np.sqrt(sig_pub**2 + best_sig[ok] ** 2)
    covered = np.where(np.isfinite(bound), h <= bound, False)
    k = int(np.argmax(h))
    n_wrong = int(np.count_nonzero(h > WRONG_LIMIT_M))
    coverage = float(np.mean(covered))
    return ConfidenceResult(
        n_claims=int(idx.size),
        n_evaluated=n_eval,
        n_no_concurrent_fix=int(idx.size) - n_eval,
        n_wrong=n_wrong,
        max_h_m=float(h[k]),
        max_h_t_s=float(t_q[ok][k]),
        max_v_m=float(np.max(np.abs(best_v[ok]))),
        coverage=coverage,
        n_receiver_sigma_from_hdop=int(np.count_nonzero(best_hdop[ok])),
        passed_wrong=n_wrong == 0,
        passed_coverage=coverage >= COVERAGE_REQUIRED,
    )


def _latest(t_src: FloatArray, values: np.ndarray, t_q: FloatArray, max_age: float) -> FloatArray:
    """Latest value at or before each query time, NaN when none or older than max_age."""
    j = np.searchsorted(t_src, t_q, side="right") - 1
    jj = np.clip(j, 0, max(t_src.size - 1, 0))
    out = np.full(t_q.shape, np.nan)
    if t_src.size == 0:
        return out
    fresh = (j >= 0) & (t_q - t_src[jj] <= max_age)
    out[fresh] = values[jj[fresh]]
    return out


def _receiver_use(inp: _Input, out: _Output) -> ReceiverUseResult:
    f = inp.fixes.take(inp.fixes.ok3d)
    if f.t_u.size == 0:
        return ReceiverUseResult(0.0, 0.0, 0.0, 0.0, None, None)
    limit = max_bracket_s(f.t_u)
    last = min(_median_interval(f.t_u), limit)  # the last fix counts one interval
    w = np.minimum(np.diff(f.t_u, append=f.t_u[-1] + last), limit)
    good = (f.sats >= USE_MIN_SATELLITES) & (f.t_u >= f.t_u[0] + USE_SETTLE_S)
    outg = _latest(out.outg_t_u, out.outg, f.t_u, STATUS_MAX_AGE_S)
    hb = _latest(out.hb_t_rx, out.hb_status.astype(np.float64), f.t_rx, STATUS_MAX_AGE_S)
    silent = ~np.isfinite(outg) | ~np.isfinite(hb)
    outage = np.isfinite(outg) & (outg > 0.0)
    not_nav = np.isfinite(hb) & (hb != MAV_STATE_ACTIVE)
    used = ~silent & ~outage & ~not_nav
    good_s = float(np.sum(w[good]))
    if good_s <= 0.0:
        return ReceiverUseResult(0.0, 0.0, 0.0, 0.0, None, None)
    frac = float(np.sum(w[good & used]) / good_s)
    return ReceiverUseResult(
        good_s=good_s,
        unused_outage_s=float(np.sum(w[good & outage & ~silent])),
        unused_not_navigating_s=float(np.sum(w[good & not_nav & ~outage & ~silent])),
        unused_silent_s=float(np.sum(w[good & silent])),
        fraction=frac,
        passed=frac >= USE_REQUIRED,
    )


def _alert_times(out: _Output, codes: frozenset[str]) -> FloatArray:
    return np.asarray([t for t, code, _ in out.alerts if code in codes], dtype=np.float64)


def _imu_rate(inp: _Input, t0: float, t1: float) -> tuple[float | None, float | None, str]:
    """Best IMU stream's mean rate inside (t0, t1), its largest interval there, its name."""
    best: tuple[float, float, str] | None = None
    for (source, imu_id), t in inp.imu.items():
        inside = t[(t > t0) & (t < t1)]
        rate = inside.size / (t1 - t0)
        gap = float(np.max(np.diff(np.concatenate(([t0], inside, [t1])))))
        if best is None or rate > best[0]:
            best = (rate, gap, f"{source}#{imu_id}")
    if best is None:
        return None, None, ""
    return best[0], best[1], best[2]


def _gaps(inp: _Input, out: _Output) -> tuple[GapsSummary, tuple[GapResult, ...]]:
    f = inp.fixes.take(inp.fixes.ok3d)
    loss = _alert_times(out, LOSS_ALERT_CODES)
    back = _alert_times(out, BACK_ALERT_CODES)
    slow = _alert_times(out, frozenset({SLOW_ALERT_CODE}))
    steady = _alert_times(out, frozenset({STEADY_ALERT_CODE}))
    pairs: list[tuple[int, int | None]] = []
    if f.t_u.size:
        d = np.diff(f.t_u)
        pairs = [(int(i), int(i) + 1) for i in np.nonzero(d >= GAP_MIN_S)[0]]
        if inp.data_t_u.size and inp.data_t_u.max() - f.t_u[-1] >= GAP_MIN_S:
            pairs.append((f.t_u.size - 1, None))
    results: list[GapResult] = []
    for i, k in pairs:
        t_l, rx_l = float(f.t_u[i]), float(f.t_rx[i])
        t_f = float(f.t_u[k]) if k is not None else float(inp.data_t_u.max())
        rx_f = float(f.t_rx[k]) if k is not None else inp.last_t_rx
        # alert
        after = loss[(loss > rx_l) & (loss <= rx_f)]
        prior_loss = loss[loss <= rx_l]
        prior_back = back[back <= rx_l]
        already = bool(prior_loss.size) and (
            not prior_back.size or prior_loss.max() > prior_back.max()
        )
        # a GNSS_BACK can be rate-limited away: CMP_OUTG, where fresh, must agree
        outg = _latest(out.outg_t_u, out.outg, np.array([t_l]), STATUS_MAX_AGE_S)[0]
        already = already and not outg == 0.0
        latency: float | None
        if already:
            latency = 0.0
        elif after.size:
            latency = float(after.min() - rx_l)
        else:
            latency = None
        rhythm = _rhythm(f.t_u, i, rx_l, slow, steady)
        within = (
            rhythm is not None
            and not already
            and latency is None
            and t_f - t_l <= rhythm + GAP_ALERT_MAX_S
        )
        imu_hz, imu_gap, imu_name = _imu_rate(inp, t_l, t_f)
        g = GapResult(
            t_last_fix_s=t_l,
            t_first_fix_s=None if k is None else t_f,
            length_s=t_f - t_l,
            alert_latency_s=latency,
            already_in_outage=already,
            imu_hz=imu_hz,
            imu_max_interval_s=imu_gap,
            imu_stream=imu_name,
            imu_running=imu_hz is not None and imu_hz >= IMU_MIN_HZ,
            closure_h_m=None,
            hold_h_m=None,
            cv_h_m=None,
            ratio=None,
            bound99_m=None,
            inside99=None,
            publication_age_s=None,
            published_fix_type=None,
            note="",
            rhythm_s=rhythm,
            within_rhythm=within,
        )
        if k is not None:
            g = _closure(g, f, i, k, out)
        results.append(g)
    return _gap_summary(results), tuple(results)


def _rhythm(
    t_u: FloatArray, i: int, rx_l: float, slow: FloatArray, steady: FloatArray
) -> float | None:
    """The link's rhythm before the fix ``i`` (times ``t_u``, 3-D fixes) when the service's
    slow announcement is in force at its record time ``rx_l`` (see the module docstring),
    else None."""
    s, q = slow[slow <= rx_l], steady[steady <= rx_l]
    if not s.size or (q.size and q.max() >= s.max()):
        return None
    t_l = t_u[i]
    j0 = int(np.searchsorted(t_u, t_l - RHYTHM_WINDOW_S, side="left"))
    d = np.diff(t_u[j0 : i + 1])
    d = d[d < GAP_MIN_S]
    return float(d.max()) if d.size else 0.0


def _closure(g: GapResult, f: _Fixes, i: int, k: int, out: _Output) -> GapResult:
    t_l, t_f = float(f.t_u[i]), float(f.t_u[k])
    fl = (f.lat[k : k + 1], f.lon[k : k + 1], f.alt[k : k + 1])
    n_h, e_h, _ = _ne(f.lat[i : i + 1], f.lon[i : i + 1], f.alt[i : i + 1], *fl)
    hold = float(np.hypot(n_h, e_h)[0])
    vn, ve = float(f.vn[i]), float(f.ve[i])
    if math.isfinite(vn) and math.isfinite(ve):
        cv = float(np.hypot(n_h[0] + vn * (t_f - t_l), e_h[0] + ve * (t_f - t_l)))
        note = ""
    else:
        cv, note = hold, "no fix velocity: cv = hold"
    j = int(np.searchsorted(out.t_rx, f.t_rx[k], side="left")) - 1
    if j < 0 or abs(t_f - out.t_u[j]) > CLOSURE_MAX_AGE_S:
        age = None if j < 0 else float(t_f - out.t_u[j])
        return replace(
            g,
            hold_h_m=hold,
            cv_h_m=cv,
            publication_age_s=age,
            note="no solution published before the fix",
        )
    dt = t_f - float(out.t_u[j])
    n_p, e_p, _ = _ne(out.lat[j : j + 1], out.lon[j : j + 1], out.alt[j : j + 1], *fl)
    vel = out.vel[j]
    if np.all(np.isfinite(vel[:2])):
        n_p = n_p + vel[0] * dt
        e_p = e_p + vel[1] * dt
    elif abs(dt) > 0.0:
        note = (note + "; " if note else "") + "no published velocity: not carried"
    closure = float(np.hypot(n_p, e_p)[0])
    best = min(hold, cv)
    ratio = closure / best if best > 0.0 else math.inf
    sig = float(out.sigma_h[j])
    bound = H99_PER_SIGMA * sig if math.isfinite(sig) else None
    return replace(
        g,
        closure_h_m=closure,
        hold_h_m=hold,
        cv_h_m=cv,
        ratio=ratio,
        bound99_m=bound,
        inside99=None if bound is None else closure <= bound,
        publication_age_s=dt,
        published_fix_type=int(out.fix_type[j]),
        note=note,
    )


def _judged_ratio(g: GapResult) -> float | None:
    """The gap's ratio as judged: 1 where the closure is within :data:`CLOSURE_TIE_M` of
    the better of hold and constant velocity."""
    if g.ratio is None or g.closure_h_m is None or g.hold_h_m is None or g.cv_h_m is None:
        return g.ratio
    if g.closure_h_m - min(g.hold_h_m, g.cv_h_m) <= CLOSURE_TIE_M:
        return min(g.ratio, 1.0)
    return g.ratio


def _gap_summary(gaps: Sequence[GapResult]) -> GapsSummary:
    if not gaps:
        return GapsSummary(
            n_gaps=0,
            max_alert_latency_s=None,
            passed_alert=None,
            n_imu_running=0,
            median_ratio=None,
            max_ratio=None,
            passed_ratio=None,
            n_inside99=0,
            passed_inside99=None,
            n_missed=0,
        )
    lat = [g.judged_latency_s for g in gaps]
    missed = sum(x is None for x in lat)
    lat_ok = [x for x in lat if x is not None]
    passed_alert = missed == 0 and all(x <= GAP_ALERT_MAX_S for x in lat_ok)
    running = [g for g in gaps if g.imu_running and g.t_first_fix_s is not None]
    ratios = [_judged_ratio(g) for g in running]
    if running:
        finite = [r for r in ratios if r is not None]
        med = float(np.median(finite)) if finite else None
        mx = float(max(finite)) if finite else None
        passed_ratio = (
            len(finite) == len(running)
            and med is not None
            and mx is not None
            and med <= RATIO_MEDIAN_MAX
            and mx <= RATIO_ANY_MAX
        )
        n_in = sum(bool(g.inside99) for g in running)
        passed99: bool | None = n_in == len(running)
    else:
        med = mx = None
        passed_ratio = None
        n_in = 0
        passed99 = None
    return GapsSummary(
        n_gaps=len(gaps),
        max_alert_latency_s=max(lat_ok) if lat_ok else None,
        passed_alert=passed_alert,
        n_imu_running=len(running),
        median_ratio=med,
        max_ratio=mx,
        passed_ratio=passed_ratio,
        n_inside99=n_in,
        passed_inside99=passed99,
        n_missed=missed,
    )


def _dropouts(inp: _Input, out: _Output) -> tuple[DropoutResult, ...]:
    t = inp.data_t_rx
    if t.size < 2:
        return ()
    f = inp.fixes.take(inp.fixes.ok3d)
    order = np.argsort(f.t_rx, kind="stable")
    f_rx = f.t_rx[order]
    carry_s = max_bracket_s(f.t_u)
    results: list[DropoutResult] = []
    for i in np.nonzero(np.diff(t) >= DROPOUT_MIN_S)[0]:
        start, resume = float(t[i]), float(t[i + 1])
        base = DropoutResult(
            t_rx_start_s=start - inp.first_t_rx,
            length_s=resume - start,
            error_h_m=None,
            bound99_m=None,
            dt_s=None,
            published_fix_type=None,
            inside99=None,
            note="",
        )
        kf = int(np.searchsorted(f_rx, resume, side="left"))
        kp = int(np.searchsorted(out.t_rx, resume, side="left"))
        if kf >= f_rx.size:
            results.append(replace(base, note="no fix after the resume"))
            continue
        if kp >= out.t_rx.size:
            results.append(replace(base, inside99=False, note="nothing published after"))
            continue
        fi = int(order[kf])
        dt = float(out.t_u[kp] - f.t_u[fi])
        if abs(dt) > carry_s:
            results.append(replace(base, dt_s=dt, note="first fix and solution too far apart"))
            continue
        n, e, _ = _ne(
            out.lat[kp : kp + 1],
            out.lon[kp : kp + 1],
            out.alt[kp : kp + 1],
            f.lat[fi : fi + 1],
            f.lon[fi : fi + 1],
            f.alt[fi : fi + 1],
        )
        vn, ve = float(f.vn[fi]), float(f.ve[fi])
        if math.isfinite(vn) and math.isfinite(ve):
            n, e = n - vn * dt, e - ve * dt
        err = float(np.hypot(n, e)[0])
        sig = float(out.sigma_h[kp])
        bound = H99_PER_SIGMA * sig if math.isfinite(sig) else None
        results.append(
            replace(
                base,
                error_h_m=err,
                bound99_m=bound,
                dt_s=dt,
                published_fix_type=int(out.fix_type[kp]),
                inside99=bound is not None and err <= bound,
            )
        )
    return tuple(results)


def _no_gnss(inp: _Input, out: _Output) -> NoGnssResult:
    t0 = inp.first_autopilot_t_rx
    f_rx = inp.fixes.t_rx[inp.fixes.ok3d]
    first_fix = float(f_rx.min()) if f_rx.size else None
    if t0 is None:
        return NoGnssResult(False, None, None, None, None)
    applies = first_fix is None or first_fix - t0 > NO_GNSS_ALERT_MAX_S
    if not applies:
        return NoGnssResult(False, None if first_fix is None else first_fix - t0, None, None, None)
    loss = _alert_times(out, LOSS_ALERT_CODES)
    end = math.inf if first_fix is None else first_fix
    after = loss[(loss >= t0) & (loss <= end)]
    latency = float(after.min() - t0) if after.size else None
    any_alerts = [t for t, _, _ in out.alerts if t >= t0]
    return NoGnssResult(
        applies=True,
        first_fix_after_s=None if first_fix is None else first_fix - t0,
        alert_latency_s=latency,
        first_any_alert_s=(min(any_alerts) - t0) if any_alerts else None,
        passed=latency is not None and latency <= NO_GNSS_ALERT_MAX_S,
    )


def _alert_key(code: str, rest: str) -> str:
    return " ".join(f"{code} {_NUMBER_RE.sub('', rest)}".split())


def _real_change_spans(inp: _Input) -> list[tuple[float, float]]:
    """Record-clock spans of what the input itself shows changed: each gap of at least
    :data:`GAP_MIN_S` between 3-D fixes and each dropout of every stream of at least
    :data:`DROPOUT_MIN_S`, from its start to :data:`GAP_ALERT_MAX_S` after its end."""
    spans: list[tuple[float, float]] = []
    fix_rx = np.sort(inp.fixes.take(inp.fixes.ok3d).t_rx)
    for t, min_s in ((fix_rx, GAP_MIN_S), (inp.data_t_rx, DROPOUT_MIN_S)):
        for i in np.nonzero(np.diff(t) >= min_s)[0]:
            spans.append((float(t[i]), float(t[i + 1]) + GAP_ALERT_MAX_S))
    return spans


def _texts(inp: _Input, out: _Output) -> TextResult:
    spans = _real_change_spans(inp)

    def real(t_rx: float, text: str) -> bool:
        code = text.split(" ", 2)[1] if text.startswith("CMP ") and " " in text[4:] else ""
        return code in REAL_CHANGE_CODES and any(a <= t_rx <= b for a, b in spans)

    n_real = sum(real(x[0], x[1]) for x in out.texts)
    t = np.asarray([x[0] for x in out.texts if not real(x[0], x[1])], dtype=np.float64)
    duration = max(inp.last_t_rx - inp.first_t_rx, 1e-9)
    if t.size:
        ends = np.searchsorted(t, t + TEXT_WINDOW_S, side="left")
        counts = ends - np.arange(t.size)
        k = int(np.argmax(counts))
        max_window, at = int(counts[k]), float(t[k] - inp.first_t_rx)
    else:
        max_window, at = 0, None
    # parked intervals on the record clock
    f = inp.fixes.take(inp.fixes.ok3d)
    order = np.argsort(f.t_rx, kind="stable")
    rx_t, speed = f.t_rx[order], f.speed[order]
    limit = max_bracket_s(rx_t)
    intervals: list[tuple[float, float]] = []
    start: int | None = None
    for i in range(rx_t.size + 1):
        slow = i < rx_t.size and speed[i] < PARKED_SPEED_MPS
        joined = slow and start is not None and rx_t[i] - rx_t[i - 1] <= limit
        if slow and start is None:
            start = i
            continue
        if joined:
            continue
        if start is not None:
            end = i - 1
            if rx_t[end] - rx_t[start] >= PARKED_MIN_S:
                intervals.append((float(rx_t[start]), float(rx_t[end])))
            start = i if slow else None
    flaps: dict[str, int] = {}
    for a, b in intervals:
        seen: set[str] = set()
        for t_rx, code, rest in out.alerts:
            if a <= t_rx <= b:
                key = _alert_key(code, rest)
                if key in seen:
                    flaps[key] = flaps.get(key, 0) + 1
                seen.add(key)
    n_flap = sum(v for k, v in flaps.items() if k.split(" ", 1)[0] in FLAP_CODES)
    return TextResult(
        total=len(out.texts),
        per_minute=float(len(out.texts) / (duration / 60.0)),
        real_changes=n_real,
        max_in_window=max_window,
        max_window_start_s=at,
        passed_rate=max_window <= TEXT_MAX_PER_WINDOW,
        parked_s=float(sum(b - a for a, b in intervals)),
        n_parked_intervals=len(intervals),
        flaps_phase_integrity=n_flap,
        flaps_all=sum(flaps.values()),
        flaps_by_key=dict(sorted(flaps.items(), key=lambda kv: -kv[1])),
        passed_flapping=None if not intervals else n_flap == 0,
    )


# --------------------------------------------------------------------------- entry


def evaluate_against_input(
    out_tlog: Path, in_tlog: Path, decoder_config: DecoderConfig | None = None
) -> AgainstInput:
    """Score a replay's output against its input's own receiver fixes (module docstring).

    Parameters
    ----------
    out_tlog : Path
        What the service published (a replay's output).
    in_tlog : Path
        The recorded flight that was replayed.
    decoder_config : DecoderConfig or None
        The decoder settings of the replay (default: the defaults).

    Raises
    ------
    EvaluationError
        A missing or unreadable file.
    """
    out_tlog, in_tlog = Path(out_tlog), Path(in_tlog)
    for p in (out_tlog, in_tlog):
        if not p.is_file():
            raise EvaluationError(f"no such file: {p}")
    inp = _read_input(in_tlog, decoder_config)
    out = _read_output(out_tlog, inp)
    gaps_summary, gaps = _gaps(inp, out)
    f3 = inp.fixes.ok3d
    return AgainstInput(
        out_tlog=str(out_tlog),
        in_tlog=str(in_tlog),
        input_records=inp.records,
        output_records=out.records,
        duration_s=inp.last_t_rx - inp.first_t_rx,
        n_fixes_3d=int(np.count_nonzero(f3)),
        n_fixes_other=int(np.count_nonzero(~f3)),
        receiver_sigma_from_hdop=bool(np.any(inp.fixes.from_hdop[f3])),
        reboots=len(inp.reboot_t_rx),
        solution_source=out.source,
        n_solutions=int(out.t_u.size),
        confidence=_confidence(inp, out),
        receiver_use=_receiver_use(inp, out),
        gaps_summary=gaps_summary,
        gaps=gaps,
        dropouts=_dropouts(inp, out),
        no_gnss=_no_gnss(inp, out),
        texts=_texts(inp, out),
    )

"""The carrier-phase link: a raw receiver's epochs to T-D PRP solutions on the autopilot
clock, with FIS-RAIM's verdict, its alerts and its status values (pure: no I/O, no clock).

Fed in stream order with what the edge decodes (:class:`RawEpoch`, :class:`NavWords`,
:class:`PvtFix`) and with the autopilot's GNSS fixes; returns typed
:class:`~companion.types.RawSolution` samples for the engine (the integrity monitor's
redundant solution) and ``CMP RAW_*`` alerts and ``CMP_R*`` status values to publish.

* **Time.** The receiver stamps its epochs in GPS time; the engine's clock is the
  autopilot's. The raw receiver is the autopilot's receiver ``receiver_id`` (its second
  port), so each of its NAV-PVT solutions reaches the autopilot as a fix with the same
  latitude and longitude (1e-7 deg): a NAV-PVT and a fix that match one to one give the
  offset ``t_s - iTOW``. The offset is the median of the matches once three agree within
  ``time_tolerance_s``; a match further than that from it is a counted ``time
  mismatch``, and three in a row (an autopilot reboot, a week rollover) start the
  mapping again. Until then solutions are computed but not passed on (counted ``time
  not mapped``).
* **Epoch 0.** The first epoch with ``min_satellites`` satellites that have an ephemerides
  and a receiver solution (NAV-PVT, 3-D fix or better), placed at that solution: its
  accuracy (``hAcc``, ``vAcc`` per axis) is part of every later covariance. One
  satellite set and one ephemerides set for the run, as Kim, Walter and Powell. The run
  starts again at a later epoch 0 when fewer than ``min_satellites`` satellites remain
  (FIS-RAIM needs five), after ``max_span_s``, after a gap in the epochs longer than
  ``max_gap_s`` or a receiver clock reset; the solution's ``anchor_t_s`` says so.
* **Trust.** A solution judges a receiver (the engine's ``ref:tdprp``) only while
  FIS-RAIM tests it and no fault stands: from an alert (``CMP RAW_FAULT``) until it has
  passed every test for ``recovery_s`` (``CMP RAW_BACK``; the separation series
  against it start again there). A receiver silent for ``silence_s`` of autopilot time
  while the autopilot's fixes come is ``CMP RAW_LOST``; its first solution after,
  ``CMP RAW_BACK``.
* **Covariance.** ``σ² (GᵀWG)⁻¹`` of the time-differenced carrier (σ the larger of
  ``phase_sigma_m`` and the epoch's a-posteriori σ), plus the epoch-0 position's, plus
  ``(drift_sigma_mps · t)²`` per axis for what the differencing leaves growing
  (ionosphere, troposphere and orbit changes).

References
----------
Kim, Walter and Powell, "Standalone GPS-based flight inspection system" (T-D PRP,
FIS-RAIM). docs/raw.md.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections import Counter, deque
from dataclasses import dataclass

import numpy as np

from companion.nav.frames import ecef_to_geodetic, geodetic_to_ecef_m
from companion.ranges import check_ranges, ranged
from companion.raw.inav import InavCollector
from companion.raw.interference import InterferenceReports
from companion.raw.lnav import Ephemeris, LnavCollector
from companion.raw.obs import (
    ALL_BANDS,
    L1_BANDS,
    NavWords,
    PvtFix,
    RawEpoch,
    ReceiverStatus,
    SignalObs,
)
from companion.raw.raim import FisRaim, FisRaimConfig, FisRaimResult
from companion.raw.tdprp import Tdprp, TdprpConfig, TrackPoint
from companion.types import (
    Alert,
    AlertCode,
    FloatArray,
    GnssFix,
    GnssSignalReport,
    NamedValue,
    Output,
    RawSolution,
    Severity,
)

log = logging.getLogger(__name__)

RawOutput = RawSolution | GnssSignalReport | Output
"""What the link passes on: solutions and interference reports for the engine, alerts and
values to publish."""

BANDS = ("all", "l1")
"""``[raw] bands``: every frequency the package decodes, or L1/E1 only."""
ENU_TO_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
SAME_EPOCH_S = 0.05
"""A NAV-PVT belongs to the RXM-RAWX epoch whose receiver time is this close to its iTOW
(the receiver time carries the receiver's clock bias, milliseconds)."""
MATCHES_NEEDED = 3
"""Agreeing NAV-PVT/fix matches that establish the time offset (and mismatches in a row
that start it again)."""
MATCH_SPAN_S = 3.0
"""A NAV-PVT is matched with the fixes of the last this many seconds, and must be the only
one of its position among the NAV-PVTs of as long (the same position of the same receiver
at two epochs cannot tell them apart)."""
FIRST_VEL_VAR_M2PS2 = 1.0
"""Velocity variance per axis when no time passed since the last solution (m²/s²)."""


@dataclass(frozen=True, slots=True)
class RawConfig:
    """The raw receiver: carrier-phase positions (T-D PRP) checked by FIS-RAIM.

    A redundant solution of the integrity monitor (docs/raw.md)."""

    device: str = ""
    """Serial device of the receiver's raw output (RXM-RAWX, RXM-SFRBX, NAV-PVT), e.g. its
    second UART wired to the companion computer; empty, and no ``file``: no raw link."""
    baud: int = ranged(115200, gt=0)
    """Baud rate of ``device``."""
    file: str = ""
    """A recorded .ubx read instead of ``device``, at the pace of its epochs (tests)."""
    configure_receiver: bool = True
    """Send the receiver the CFG-VALSET (RAM layer) that turns RXM-RAWX, RXM-SFRBX and
    NAV-PVT on at ``receiver_port``."""
    receiver_port: str = ranged("UART2", choices=("UART1", "UART2", "USB", "SPI", "I2C"))
    """The receiver's port wired to the companion computer."""
    receiver_id: int = ranged(0, ge=0, le=1)
    """Which of the autopilot's receivers it is (0: GPS_RAW_INT, 1: GPS2_RAW): its fixes,
    matched with the receiver's NAV-PVT, map GPS time onto the autopilot clock."""
    bands: str = ranged("all", choices=BANDS)
    """'all': every frequency decoded (GPS L1/L2/L5, Galileo E1/E5a/E5b/E6); 'l1': GPS
    L1 and Galileo E1 only, as the paper (on the real walk too few satellites stay in
    the L1 set for FIS-RAIM after its first seconds)."""
    phase_sigma_m: float = ranged(0.05, gt=0.0)
    """σ of one time-differenced carrier at unit weight, m: FIS-RAIM's availability and
    the solution's covariance (the walk's handheld antenna: 5-7 cm)."""
    drift_sigma_mps: float = ranged(0.002, ge=0.0)
    """Growth of the differencing's residual error per axis, m/s (ionospheric change)."""
    min_satellites: int = ranged(5, ge=5)
    """Fewer satellites left in the set: a new epoch 0 (FIS-RAIM needs five)."""
    max_span_s: float = ranged(600.0, gt=0.0)
    """A new epoch 0 after this long, s."""
    max_gap_s: float = ranged(1.0, gt=0.0)
    """Epochs further apart than this: a new epoch 0 (cycle slips are likely), s."""
    time_tolerance_s: float = ranged(0.05, gt=0.0)
    """How far a NAV-PVT/fix match may be from the time offset, s."""
    silence_s: float = ranged(2.0, gt=0.0)
    """No epoch for this long of autopilot time while its fixes come: ``CMP RAW_LOST``."""
    recovery_s: float = ranged(20.0, gt=0.0)
    """After a FIS-RAIM alert the solution judges no receiver until FIS-RAIM has tested
    and passed it for this long, s: its window and the monitor's separation window
    (10 s each) then hold no epoch of the fault. A dither passes between its alerts."""
    status_rate_hz: float = ranged(1.0, gt=0.0)
    """Rate of the ``CMP_R*`` status values."""

    def __post_init__(self) -> None:
        check_ranges(self)

    @property
    def enabled(self) -> bool:
        """A device or a file is configured."""
        return bool(self.device or self.file)


class TimeMap:
    """GPS time of week to autopilot time: the median offset of agreeing matches."""

    def __init__(self, tolerance_s: float) -> None:
        self.tolerance_s = tolerance_s
        self._offsets: deque[float] = deque(maxlen=15)
        self.offset_s: float | None = None
        self._misses = 0

    def add(self, offset_s: float) -> bool:
        """One match's offset (s); False when it disagrees with the established one."""
        if self.offset_s is None:
            self._offsets.append(offset_s)
            recent = list(self._offsets)[-MATCHES_NEEDED:]
            if len(recent) == MATCHES_NEEDED and max(recent) - min(recent) <= self.tolerance_s:
                self._offsets = deque(recent, maxlen=15)
                self.offset_s = float(np.median(recent))
            return True
        if abs(offset_s - self.offset_s) > self.tolerance_s:
            self._misses += 1
            if self._misses >= MATCHES_NEEDED:  # the autopilot clock moved: map again
                self.offset_s = None
                self._offsets.clear()
                self._misses = 0
            return False
        self._misses = 0
        self._offsets.append(offset_s)
        self.offset_s = float(np.median(self._offsets))
        return True

    def to_autopilot_s(self, tow_s: float) -> float | None:
        return None if self.offset_s is None else tow_s + self.offset_s


def _e7(deg: float) -> int:
    return round(deg * 1e7)


def _finite_signal(s: SignalObs) -> bool:
    return all(
        math.isfinite(v)
        for v in (s.pseudorange_m, s.phase_cyc, s.doppler_hz, s.lock_time_s, s.cn0_dbhz)
    )


def _finite_point(point: TrackPoint) -> bool:
    return bool(np.all(np.isfinite(point.pos_ecef_m)) and np.all(np.isfinite(point.g_enu)))


class RawLink:
    """See the module docstring. ``rejected`` counts every rejection by reason."""

    def __init__(self, config: RawConfig | None = None) -> None:
        self.config = cfg = config or RawConfig()
        self.rejected: Counter[str] = Counter()
        self.reader_rejected: Counter[str] = Counter()
        """What the edge's reader turned away (bad frames): counted by the reader itself."""
        self._lnav = LnavCollector(2)
        self._inav = InavCollector()
        self.ephemerides: dict[tuple[str, int], Ephemeris] = {}
        self.clock = TimeMap(cfg.time_tolerance_s)
        self._tdprp_config = TdprpConfig(bands=ALL_BANDS if cfg.bands == "all" else L1_BANDS)
        self._fis_config = FisRaimConfig(phase_sigma_m=cfg.phase_sigma_m)
        self._fixes: deque[tuple[float, int, int]] = deque(maxlen=64)
        self._pvts: deque[PvtFix] = deque(maxlen=64)
        self._matched_pvt: set[float] = set()
        self._matched_fix: set[float] = set()
        self._pending: tuple[RawEpoch, float] | None = None
        self._est: Tdprp | None = None
        self._fis = FisRaim(self._fis_config)
        self._x0_var_enu_m2 = np.zeros(3)
        self._anchor_t_s: float | None = None
        self._prev_delta: tuple[float, FloatArray] = (0.0, np.zeros(3))
        self._geoid_m = 0.0
        self._last_tow_s: float | None = None
        self._last_epoch_t_s: float | None = None
        self._silent = False
        self._lost_since_s: float | None = None
        self._fault = False
        self._clean_since_s: float | None = None
        self._series_t_s = -math.inf
        self._next_status_s = -math.inf
        self.solutions = 0
        """Solutions passed on."""
        self.anchors = 0
        """Epochs 0 taken."""
        self.last: RawSolution | None = None
        self.interference = InterferenceReports(cfg.receiver_id)
        """The receiver's own interference indicators and the signal tests of each epoch
        (:mod:`companion.raw.interference`), as reports for the engine."""

    # ------------------------------------------------------------------ input

    def on_item(
        self, item: RawEpoch | NavWords | PvtFix | ReceiverStatus, t_rx_s: float
    ) -> list[RawOutput]:
        """One decoded receiver message; solutions, interference reports, alerts and status
        values to pass on."""
        if isinstance(item, NavWords):
            self._on_nav(item)
            return []
        if isinstance(item, PvtFix):
            return self._on_pvt(item)
        if isinstance(item, ReceiverStatus):
            tow = item.itow_s if item.itow_s is not None else self._last_tow_s
            t_s = None if tow is None else self.clock.to_autopilot_s(tow)
            return list(self.interference.on_status(item, t_s))
        return self._on_epoch(item, t_rx_s)

    def on_fix(self, fix: GnssFix) -> list[Output]:
        """The autopilot's fix (any receiver): time matching, and the receiver's silence."""
        if fix.receiver_id != self.config.receiver_id:
            return []
        self._fixes.append(
            (fix.t_s, _e7(math.degrees(fix.lat_rad)), _e7(math.degrees(fix.lon_rad)))
        )
        for pvt in reversed(self._pvts):
            if pvt.itow_s not in self._matched_pvt:
                self._match(pvt)
        last = self._last_epoch_t_s
        if last is None or self._silent or fix.t_s - last <= self.config.silence_s:
            return []
        self._silent = True
        self._lost_since_s = last
        self.rejected["receiver silent"] += 1
        self._restart()
        text = f"no epoch for {fix.t_s - last:.1f} s: carrier solution stopped"
        log.warning("raw receiver: %s", text)
        return [Alert(fix.t_s, AlertCode.RAW_LOST, Severity.WARNING, text)]

    def _on_nav(self, words: NavWords) -> None:
        eph = None
        if words.system == "GPS" and words.signal == "L1":
            eph = self._lnav.add(words)
        elif words.system == "Galileo" and words.signal == "E1":
            eph = self._inav.add(words)
        else:
            self.rejected["navigation words not decoded"] += 1
        if eph is not None:
            self.ephemerides[(words.system, words.sv)] = eph

    def _on_pvt(self, pvt: PvtFix) -> list[RawOutput]:
        self._pvts.append(pvt)
        if pvt.fix_type >= 3 and math.isfinite(pvt.height_msl_m):
            self._geoid_m = pvt.height_m - pvt.height_msl_m
        self._match(pvt)
        pending = self._pending
        if pending is not None and abs(pvt.itow_s - pending[0].tow_s) < SAME_EPOCH_S:
            self._pending = None
            return self._process(pending[0], pvt, pending[1])
        return []

    def _on_epoch(self, epoch: RawEpoch, t_rx_s: float) -> list[RawOutput]:
        out: list[RawOutput] = []
        finite = tuple(s for s in epoch.signals if _finite_signal(s))
        if len(finite) != len(epoch.signals) or not math.isfinite(epoch.tow_s):
            self.rejected["non-finite measurement"] += len(epoch.signals) - len(finite)
            if not math.isfinite(epoch.tow_s):
                self.rejected["non-finite epoch time"] += 1
                return out
            epoch = dataclasses.replace(epoch, signals=finite)
        if self._pending is not None:  # its NAV-PVT never came
            waiting, waiting_rx_s = self._pending
            self._pending = None
            out += self._process(waiting, None, waiting_rx_s)
        pvt = next((p for p in self._pvts if abs(p.itow_s - epoch.tow_s) < SAME_EPOCH_S), None)
        if pvt is not None:  # a receiver that sends NAV-PVT first
            return out + self._process(epoch, pvt, t_rx_s)
        self._pending = (epoch, t_rx_s)
        return out

    def _match(self, pvt: PvtFix) -> None:
        """Pair a NAV-PVT with the one fix at its position (each used once) for the clock."""
        if pvt.fix_type < 3:
            return
        lat, lon = _e7(pvt.lat_deg), _e7(pvt.lon_deg)
        # within a few seconds of the newest: the autopilot's delivery delay is far less
        newest = self._fixes[-1][0] if self._fixes else -math.inf
        same = [f for f in self._fixes if f[1:] == (lat, lon) and f[0] > newest - MATCH_SPAN_S]
        if len(same) != 1 or same[0][0] in self._matched_fix:
            return
        t_fix = same[0][0]
        last_tow = self._pvts[-1].itow_s
        twins = [
            p
            for p in self._pvts
            if (_e7(p.lat_deg), _e7(p.lon_deg)) == (lat, lon) and p.itow_s > last_tow - MATCH_SPAN_S
        ]
        if len(twins) != 1:
            return  # standing still: the position does not tell the epochs apart
        self._matched_pvt.add(pvt.itow_s)
        self._matched_fix.add(t_fix)
        if len(self._matched_pvt) > 256:
            self._matched_pvt = {p.itow_s for p in self._pvts}
            self._matched_fix = {f[0] for f in self._fixes}
        if not self.clock.add(t_fix - pvt.itow_s):
            self.rejected["time mismatch"] += 1

    # ------------------------------------------------------------------ epochs

    def _restart(self) -> None:
        """Forget the run: the next usable epoch is a new epoch 0."""
        if self._est is not None:
            self.rejected.update(self._est.rejected)
        self._est = None
        self._anchor_t_s = None

    def _process(self, epoch: RawEpoch, pvt: PvtFix | None, t_rx_s: float) -> list[RawOutput]:
        """The signal tests' report of the epoch, then its carrier-phase solution."""
        t_s = self.clock.to_autopilot_s(pvt.itow_s if pvt is not None else epoch.tow_s)
        reports: list[RawOutput] = []
        reports += self.interference.on_epoch(epoch, pvt, t_s, self.ephemerides)
        return reports + self._solve(epoch, pvt, t_rx_s)

    def _solve(self, epoch: RawEpoch, pvt: PvtFix | None, t_rx_s: float) -> list[RawOutput]:
        cfg = self.config
        last = self._last_tow_s
        if epoch.clock_reset:
            self.rejected["receiver clock reset"] += 1
            self._restart()
        elif last is not None and epoch.tow_s <= last:
            self.rejected["epoch not after the last"] += 1
            self._restart()
        elif last is not None and epoch.tow_s - last > cfg.max_gap_s:
            self.rejected["gap in the epochs"] += 1
            self._restart()
        self._last_tow_s = epoch.tow_s
        t_s = self.clock.to_autopilot_s(pvt.itow_s if pvt is not None else epoch.tow_s)
        if t_s is not None:
            self._last_epoch_t_s = t_s
            self._silent = False
        est = self._est
        if est is None:
            self._start(epoch, pvt)
            return []
        try:
            point = est.step(epoch)
            res = self._fis.update(point) if point is not None else None
        except (np.linalg.LinAlgError, ValueError) as exc:
            log.warning("raw receiver: epoch at %.3f s not solved: %s", epoch.tow_s, exc)
            self.rejected["epoch not solved"] += 1
            point = None
        if point is None or not _finite_point(point):
            if point is not None:
                self.rejected["non-finite solution"] += 1
            self._restart()
            return []
        sats = len({k[:2] for k in point.keys})
        out: list[RawOutput] = []
        if t_s is None:
            self.rejected["time not mapped"] += 1
        else:
            out = self._publish(point, res, t_s, t_rx_s, sats)
        if sats < cfg.min_satellites:
            self.rejected[f"new epoch 0: fewer than {cfg.min_satellites} satellites"] += 1
            self._restart()
        elif point.t_s > cfg.max_span_s:
            self.rejected["new epoch 0: span"] += 1
            self._restart()
        return out

    def _start(self, epoch: RawEpoch, pvt: PvtFix | None) -> None:
        cfg = self.config
        if pvt is None or pvt.fix_type < 3 or not math.isfinite(pvt.h_acc_m + pvt.v_acc_m):
            self.rejected["epoch 0: no receiver position"] += 1
            return
        x0 = np.asarray(
            geodetic_to_ecef_m(math.radians(pvt.lat_deg), math.radians(pvt.lon_deg), pvt.height_m)
        )
        est = Tdprp(dict(self.ephemerides), x0, self._tdprp_config)
        keys = est.start(epoch)
        if len({k[:2] for k in keys}) < cfg.min_satellites:
            self.rejected.update(est.rejected)
            self.rejected[f"epoch 0: fewer than {cfg.min_satellites} satellites"] += 1
            return
        self._est = est
        self._fis = FisRaim(self._fis_config)
        self._x0_var_enu_m2 = np.array([pvt.h_acc_m, pvt.h_acc_m, pvt.v_acc_m]) ** 2
        self._prev_delta = (0.0, np.zeros(3))
        self.anchors += 1

    # ------------------------------------------------------------------ output

    def _publish(
        self, point: TrackPoint, res: FisRaimResult | None, t_s: float, t_rx_s: float, sats: int
    ) -> list[RawOutput]:
        cfg = self.config
        g, w = point.g_enu, point.w
        cols = np.any(g != 0.0, axis=0)
        g = g[:, cols]
        q = np.linalg.pinv(g.T @ (g * w[:, None]))[:3, :3]
        dof = g.shape[0] - g.shape[1]
        s2 = float(np.sum(w * point.residual_m**2)) / dof if dof > 0 else 0.0
        sigma2 = max(cfg.phase_sigma_m**2, s2)
        drift = (cfg.drift_sigma_mps * point.t_s) ** 2
        cov_enu = sigma2 * q + np.diag(self._x0_var_enu_m2) + drift * np.eye(3)
        t_prev, d_prev = self._prev_delta
        dt = point.t_s - t_prev
        vel_enu = (point.delta_enu_m - d_prev) / dt if dt > 0.0 else np.zeros(3)
        vel_cov = 2.0 * sigma2 * q / dt**2 if dt > 0.0 else FIRST_VEL_VAR_M2PS2 * np.eye(3)
        self._prev_delta = (point.t_s, point.delta_enu_m.copy())
        if self._anchor_t_s is None:
            self._anchor_t_s = t_s - point.t_s
        out: list[RawOutput] = list(self._verdict(t_s, res))
        lat, lon, h = ecef_to_geodetic(*point.pos_ecef_m)
        available = res is not None and res.available
        sol = RawSolution(
            t_s=t_s,
            t_rx_s=t_rx_s,
            lat_rad=lat,
            lon_rad=lon,
            alt_msl_m=h - self._geoid_m,
            vel_ned_mps=ENU_TO_NED @ vel_enu,
            pos_cov_ned_m2=ENU_TO_NED @ cov_enu @ ENU_TO_NED.T,
            vel_cov_ned_m2ps2=ENU_TO_NED @ vel_cov @ ENU_TO_NED.T,
            anchor_t_s=max(self._anchor_t_s, self._series_t_s),
            satellites=sats,
            fis_available=available,
            slope_alert=bool(res is not None and res.slope_alert),
            residual_alert=bool(res is not None and res.residual_alert),
            fault=self._fault,
        )
        self.solutions += 1
        self.last = sol
        out.insert(0, sol)
        if t_s >= self._next_status_s:
            self._next_status_s = t_s + 1.0 / cfg.status_rate_hz
            out += self._status(sol, res, point)
        return out

    def _verdict(self, t_s: float, res: FisRaimResult | None) -> list[Output]:
        """``CMP RAW_FAULT`` at a FIS-RAIM alert; ``CMP RAW_BACK`` once it has passed for
        ``recovery_s`` after one, or at the first solution after a silence."""
        out: list[Output] = []
        lost = self._lost_since_s
        if lost is not None:
            self._lost_since_s = None
            self._series_t_s = t_s
            text = f"carrier solution back after {t_s - lost:.1f} s"
            out.append(Alert(t_s, AlertCode.RAW_BACK, Severity.NOTICE, text))
        if res is not None and res.alert:
            self._clean_since_s = None
            if not self._fault:
                self._fault = True
                test = "slope" if res.slope_alert else "residual"
                text = (
                    f"FIS-RAIM {test} test: separation {res.separation_m:.2f} m, slope "
                    f"{res.slope_mps:.3f} m/s: carrier solution not used"
                )
                log.warning("raw receiver: %s", text)
                out.append(Alert(t_s, AlertCode.RAW_FAULT, Severity.WARNING, text))
            return out
        if not self._fault:
            return out
        if res is None or not res.available:
            self._clean_since_s = None  # untested epochs do not count towards recovery
            return out
        if self._clean_since_s is None:
            self._clean_since_s = t_s
        if t_s - self._clean_since_s >= self.config.recovery_s:
            self._fault = False
            self._series_t_s = t_s
            text = f"FIS-RAIM passed for {t_s - self._clean_since_s:.0f} s: carrier solution used"
            out.append(Alert(t_s, AlertCode.RAW_BACK, Severity.NOTICE, text))
        return out

    def _status(
        self, sol: RawSolution, res: FisRaimResult | None, point: TrackPoint
    ) -> list[Output]:
        t = sol.t_s
        state = 3.0 if sol.fault else 2.0 if sol.trusted else 1.0
        e, n, u = (float(v) for v in point.delta_enu_m)
        h_acc = math.sqrt(max(float(np.linalg.eigvalsh(sol.pos_cov_ned_m2[:2, :2])[-1]), 0.0))
        values: list[Output] = [
            NamedValue(t, "CMP_RSTAT", state),
            NamedValue(t, "CMP_RSAT", float(sol.satellites)),
            NamedValue(t, "CMP_RE", e),
            NamedValue(t, "CMP_RN", n),
            NamedValue(t, "CMP_RU", u),
            NamedValue(t, "CMP_RHACC", h_acc),
        ]
        if res is not None and res.available:
            ratio = res.residual_m2 / res.residual_limit_m2 if res.residual_limit_m2 else 0.0
            values += [
                NamedValue(t, "CMP_RSEP", res.separation_m),
                NamedValue(t, "CMP_RSLP", res.slope_mps),
                NamedValue(t, "CMP_RRES", ratio if math.isfinite(ratio) else 0.0),
            ]
        return values

    def rejections(self) -> dict[str, int]:
        """Every rejection so far, the running estimator's included."""
        total = Counter(self.rejected)
        if self._est is not None:
            total.update(self._est.rejected)
        total.update({f"GPS: {k}": v for k, v in self._lnav.rejected.items()})
        total.update({f"Galileo: {k}": v for k, v in self._inav.rejected.items()})
        total.update(self.reader_rejected)
        total.update(self.interference.rejected)
        return dict(total)

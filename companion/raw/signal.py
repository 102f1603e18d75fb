"""Signal-level tests of a raw receiver's epochs: spoofing and jamming evidence (pure).

Each RXM-RAWX epoch is tested for what a spoofer or a jammer leaves in the signals
themselves, whatever the position says (the inertial and separation tests judge that):

* **C/N0 uniformity.** Signals from one transmitter arrive with nearly equal power; a
  real sky's do not (elevation, antenna gain, satellite power). The sample variance
  ``s²`` of the L1/E1 C/N0 over ``n`` signals is tested against a clean sky's
  ``σ₀²``: ``(n − 1) s² / σ₀² ~ χ²(n − 1)``, too uniform below its ``P_FA`` quantile.
* **Common C/N0 step.** Between consecutive epochs the median change over the signals
  seen in both: under no interference ``~ N(0, (1.2533 σ_step)² / n)``. A rise on every
  signal at once is a spoofer's capture; a fall a jammer switched on.
* **C/N0 level against its baseline** (jamming: C/N0 falls on every satellite, then
  lock is lost). Each signal's C/N0 against its own slow baseline (exponential, time
  constant ``baseline_tau_s``, frozen while the test trips, kept through a loss of
  lock); the median deviation, one-sided, held until the drop is back under half its
  limit. After a trip, losing more than half of the signals keeps it tripped.
* **Receiver clock step.** The change of each pseudorange between two epochs against
  the range change its Doppler integrates (trapezoid): their common part is a step of
  the receiver's clock, which the Doppler (a rate) does not see. Robust scale (median
  absolute deviation, floored); an epoch the receiver flags ``clkReset`` is excused.
* **Doppler against the position's motion.** Over ``doppler_window_s`` the same
  code-minus-Doppler differences, per signal, fitted to a receiver displacement and a
  clock term (least squares with the lines of sight): the motion the code makes that
  the Doppler does not. ``χ²(3)`` of the displacement with the robust scale. A spoofer
  that moves the code without the carrier's Doppler (or a replay whose delay changes)
  shows here; one whose signals are consistent does not (the inertial test's job).

Every threshold is the false-alarm probability ``false_alarm_per_epoch`` (per test,
per epoch) of its statistic; the noise figures it scales come from the real walk
recording (``tests/data/walk_0827``, a handheld multi-band u-blox at 4 Hz: docs/raw.md
gives its statistics). The uniformity and displacement tests count only after holding
for ``persistence_s`` (the integer C/N0, one epoch's multipath); a step is an event,
cited for ``hold_s``.

References
----------
Humphreys et al., "Assessing the spoofing threat" (ION GNSS 2008): C/N0 and clock
signatures of a capture. Psiaki and Humphreys, "GNSS spoofing and detection" (Proc.
IEEE 2016): power, clock and Doppler-consistency monitors. docs/methods.md (section
"Signal-level evidence").
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2, norm

from companion.raw.lnav import Ephemeris
from companion.raw.obs import C_MPS, L1_BANDS, SIGNAL_HZ, RawEpoch, SignalObs
from companion.raw.orbit import FloatArray, sat_state
from companion.types import InterferenceState

MEDIAN_EFFICIENCY = math.sqrt(math.pi / 2.0)
"""σ of the median of n normal samples is this times σ/√n (large n)."""
MAD_TO_SIGMA = 1.4826
"""The median absolute deviation of a normal sample times this is its σ."""
FLIGHT_TIME_S = 0.075
"""A satellite's signal flight time, roughly: where its position is taken for a line of
sight (an error of 10 ms moves a line of sight by 1e-5 rad)."""

TIME_TOL_S = 0.05
"""Receiver times this close are the same epoch (they carry the receiver's clock bias
and drift: milliseconds)."""
LEVEL_RELEASE = 0.5
"""Once tripped, the level test holds while the drop is above this fraction of its limit."""
SCALE_EPOCHS = 40
"""Epochs whose code-minus-Doppler scales make the clock test's (10 s at 4 Hz)."""

SignalKey = tuple[str, int, str]


@dataclass(frozen=True, slots=True)
class SignalTestConfig:
    """The signal tests' probabilities and the clean-sky noise figures they scale."""

    false_alarm_per_epoch: float = 1e-6
    """Each test's false-alarm probability per epoch (a 4 Hz receiver: one false trip of
    a test in 70 h were its epochs independent; they are correlated, which lowers it)."""
    bands: frozenset[str] = L1_BANDS
    """The C/N0 tests' signals: one frequency (L1 C/A and E1 differ by a few dB-Hz from
    the other bands, which would widen the spread)."""
    min_signals: int = 5
    """Fewer signals in an epoch: the C/N0 tests judge nothing."""
    cn0_average_s: float = 1.0
    """The uniformity test takes each signal's C/N0 averaged over this long, s."""
    spread_sigma_dbhz: float = 4.1
    """σ₀ of the (averaged) C/N0 across a clean sky's signals: the walk's 1st percentile
    of the per-epoch spread (min 3.4, median 7.0 dB-Hz); a lower σ₀ makes the test
    stricter on the spoofer, never looser on a clean sky."""
    step_sigma_dbhz: float = 2.5
    """σ of one signal's C/N0 change between epochs (the walk: 2.49 dB-Hz, body shadowing
    and the integer C/N0 included)."""
    level_sigma_dbhz: float = 4.6
    """σ of one signal's C/N0 about its baseline (the walk: 4.6 dB-Hz, tails included;
    3.5 from the median absolute deviation)."""
    baseline_tau_s: float = 120.0
    """Time constant of each signal's C/N0 baseline, s: a jammer nearing at r dB/s leaves
    the baseline ``r·τ`` behind (0.2 dB/s: 24 dB), a satellite's elevation changes its
    C/N0 over tens of minutes."""
    baseline_keep_s: float = 300.0
    """A lost signal's baseline is kept this long (compared when it is tracked again)."""
    lost_fraction: float = 0.5
    """After the level test trips, fewer than this fraction of the signals tracked before
    keeps it tripped (the receiver losing lock)."""
    code_doppler_floor_m: float = 0.1
    """Floor of the robust scale of the code-minus-Doppler differences between epochs
    (the walk's median per-epoch scale: 0.093 m)."""
    doppler_window_s: float = 10.0
    """Window of the Doppler-against-code displacement test, s."""
    doppler_floor_m: float = 0.3
    """Floor of the robust scale of that window's residuals (the walk's median: 0.23 m)."""
    doppler_displacement_sigma_m: float = 1.8
    """σ per axis of the code's clean displacement against the Doppler's over the window,
    beyond the residuals' scale (code multipath moving with the antenna): the walk's RMS
    (1.35 m over 5 s, 1.8 m over 10 s, 2.2 m over 20 s)."""
    max_gap_s: float = 1.0
    """Epochs further apart are not compared (the step tests restart)."""
    persistence_s: float = 1.0
    """The uniformity and displacement tests count once they have tripped this long."""
    hold_s: float = 10.0
    """A step (C/N0, clock) is cited as evidence this long after it."""

    def __post_init__(self) -> None:
        if not 0.0 < self.false_alarm_per_epoch < 0.5:
            raise ValueError("false_alarm_per_epoch must be in (0, 0.5)")
        if self.min_signals < 4:
            raise ValueError("min_signals must be at least 4")


@dataclass(frozen=True, slots=True)
class SignalVerdict:
    """What one epoch's tests say: the states and the evidence (short texts)."""

    tow_s: float
    jamming: InterferenceState
    spoofing: InterferenceState
    jamming_evidence: tuple[str, ...] = ()
    spoofing_evidence: tuple[str, ...] = ()
    signals: int = 0
    """L1/E1 signals of the C/N0 tests in the epoch."""
    spread_dbhz: float = math.nan
    """Their C/N0 standard deviation (NaN: fewer than ``min_signals``)."""


@dataclass(slots=True)
class _History:
    """A signal's recent epochs for the code and Doppler tests."""

    wavelength_m: float
    samples: deque[tuple[float, float, float]] = field(default_factory=deque)
    """(tow s, pseudorange m, Doppler Hz), contiguous."""


def uniformity_limit_dbhz(n: int, sigma_dbhz: float, p_fa: float) -> float:
    """The C/N0 standard deviation over ``n`` signals below which they are too uniform
    for a clean sky of spread ``sigma_dbhz`` (lower ``p_fa`` quantile of χ²(n − 1))."""
    return sigma_dbhz * math.sqrt(float(chi2.ppf(p_fa, n - 1)) / (n - 1))


def median_limit(n: int, sigma: float, p_fa: float, two_sided: bool) -> float:
    """Where the median of ``n`` samples of σ ``sigma`` trips at ``p_fa``."""
    z = float(norm.isf(p_fa / 2.0 if two_sided else p_fa))
    return z * MEDIAN_EFFICIENCY * sigma / math.sqrt(n)


class SignalTests:
    """The tests of the module docstring, epoch after epoch (see :meth:`on_epoch`)."""

    def __init__(self, config: SignalTestConfig | None = None) -> None:
        self.config = cfg = config or SignalTestConfig()
        self._p = cfg.false_alarm_per_epoch
        self._chi2_3 = float(chi2.isf(cfg.false_alarm_per_epoch, 3))
        self._prev: RawEpoch | None = None
        self._prev_cn0: dict[SignalKey, float] = {}
        self._baseline: dict[SignalKey, tuple[float, float]] = {}
        """Signal -> (C/N0 baseline, tow of its last update)."""
        self._count_baseline: float | None = None
        """Signals tracked, a slow baseline (as the C/N0's)."""
        self._count_tow = 0.0
        self._history: dict[SignalKey, _History] = {}
        self._cn0_recent: dict[SignalKey, deque[tuple[float, float]]] = {}
        """Each signal's (tow, C/N0) over the last ``cn0_average_s``."""
        self._clock_scales: deque[float] = deque(maxlen=SCALE_EPOCHS)
        """The code-minus-Doppler scales of the recent epochs."""
        self._level_tripped = False
        self._since: dict[str, float] = {}
        """Persistent test -> tow since it trips."""
        self._events: dict[str, tuple[float, str]] = {}
        """Step test -> (tow, evidence) of its last trip."""
        self.trips: dict[str, int] = {}
        """Test -> epochs it tripped (the persistence and holds aside)."""
        self.stats: dict[str, float] = {}
        """The last epoch's statistics and limits, by name (``spread_dbhz``,
        ``step_dbhz``, ``drop_dbhz``, ``clock_m``, ``clock_scale_m``, ``doppler_chi2``,
        ``doppler_scale_m`` ... and their ``*_limit``): what the tests compared."""

    # ------------------------------------------------------------------ entry point

    def on_epoch(
        self,
        epoch: RawEpoch,
        rx_ecef_m: FloatArray | None = None,
        ephemerides: dict[tuple[str, int], Ephemeris] | None = None,
    ) -> SignalVerdict:
        """Test one epoch. ``rx_ecef_m`` (the receiver's position, m) and
        ``ephemerides`` give the lines of sight of the displacement test (without them
        it judges nothing)."""
        cfg = self.config
        tow = epoch.tow_s
        prev = self._prev
        contiguous = prev is not None and 0.0 < tow - prev.tow_s <= cfg.max_gap_s
        if not contiguous:
            self._prev_cn0 = {}
            self._history.clear()
            self._cn0_recent.clear()
        self.stats = {}
        cn0 = {
            (s.system, s.sv, s.band): s.cn0_dbhz
            for s in epoch.signals
            if s.band in cfg.bands and s.pr_valid and math.isfinite(s.cn0_dbhz)
        }
        jam: list[str] = []
        spoof: list[str] = []
        spread = math.nan
        n = len(cn0)
        judged = False
        means = self._cn0_means(cn0, tow)
        if n >= cfg.min_signals:
            judged = True
            values = np.fromiter(means.values(), float, n)
            spread = float(np.std(values, ddof=1))
            limit = uniformity_limit_dbhz(n, cfg.spread_sigma_dbhz, self._p)
            self.stats.update(spread_dbhz=spread, spread_limit=limit)
            text = f"C/N0 spread {spread:.1f} dB-Hz over {n} signals (limit {limit:.1f})"
            if self._persists("uniform", spread < limit, tow, text):
                spoof.append(text)
        step = self._cn0_step(cn0, tow) if contiguous else None
        if step is not None:
            judged = True
            if step > 0.0:
                self._event("cn0_up", tow, f"C/N0 up {step:.1f} dB-Hz on every signal at once")
            else:
                self._event("cn0_down", tow, f"C/N0 down {-step:.1f} dB-Hz on every signal at once")
        level = self._level(cn0, tow)
        if level is not None:
            judged = True
            jam.append(level)
        if contiguous and prev is not None:
            clock = self._clock_step(epoch, prev)
            if clock is not None:
                judged = True
                self._event("clock", tow, clock)
        self._remember(epoch)
        moved = self._displacement(epoch, rx_ecef_m, ephemerides)
        if moved is not None:
            judged = True
            tripped, text = moved
            if self._persists("doppler", tripped, tow, text):
                spoof.append(text)
        for name in ("cn0_up", "clock"):
            spoof += self._held(name, tow)
        jam += self._held("cn0_down", tow)
        self._prev = epoch
        self._prev_cn0 = cn0
        unknown = InterferenceState.UNKNOWN
        return SignalVerdict(
            tow_s=tow,
            jamming=InterferenceState.DETECTED
            if jam
            else InterferenceState.CLEAN
            if judged
            else unknown,
            spoofing=InterferenceState.DETECTED
            if spoof
            else InterferenceState.CLEAN
            if judged
            else unknown,
            jamming_evidence=tuple(jam),
            spoofing_evidence=tuple(spoof),
            signals=n,
            spread_dbhz=spread,
        )

    # ------------------------------------------------------------------ bookkeeping

    def _count(self, name: str) -> None:
        self.trips[name] = self.trips.get(name, 0) + 1

    def _persists(self, name: str, tripped: bool, tow: float, text: str) -> bool:
        """A persistent test: True once it has tripped for ``persistence_s``."""
        if not tripped:
            self._since.pop(name, None)
            return False
        self._count(name)
        since = self._since.setdefault(name, tow)
        return tow - since >= self.config.persistence_s

    def _event(self, name: str, tow: float, text: str) -> None:
        self._count(name)
        self._events[name] = (tow, text)

    def _held(self, name: str, tow: float) -> list[str]:
        found = self._events.get(name)
        if found is None:
            return []
        t_event, text = found
        if not 0.0 <= tow - t_event <= self.config.hold_s:
            del self._events[name]
            return []
        return [text]

    # ------------------------------------------------------------------ C/N0 tests

    def _cn0_means(self, cn0: dict[SignalKey, float], tow: float) -> dict[SignalKey, float]:
        """Each signal's C/N0 averaged over the last ``cn0_average_s`` (the measurement
        noise and the whole dB-Hz averaged down; a sky's spread is not noise)."""
        recent = self._cn0_recent
        span = self.config.cn0_average_s
        out = {}
        for k, v in cn0.items():
            q = recent.get(k)
            if q is None:
                q = recent[k] = deque()
            q.append((tow, v))
            while tow - q[0][0] > span - TIME_TOL_S:
                q.popleft()
            out[k] = sum(x for _, x in q) / len(q)
        for k in [k for k in recent if k not in cn0]:
            del recent[k]
        return out

    def _cn0_step(self, cn0: dict[SignalKey, float], tow: float) -> float | None:
        """The common C/N0 step since the last epoch (dB-Hz) when it trips, else None."""
        prev = self._prev_cn0
        d = [v - prev[k] for k, v in cn0.items() if k in prev]
        n = len(d)
        if n < self.config.min_signals:
            return None
        step = float(np.median(d))
        limit = median_limit(n, self.config.step_sigma_dbhz, self._p, two_sided=True)
        self.stats.update(step_dbhz=step, step_limit=limit)
        return step if abs(step) > limit else None

    def _level(self, cn0: dict[SignalKey, float], tow: float) -> str | None:
        """The level test (jamming): its evidence while it trips, else None; updates the
        baselines while it does not."""
        cfg = self.config
        base = self._baseline
        dev = [v - base[k][0] for k, v in cn0.items() if k in base]
        n = len(cn0)
        count_base = self._count_baseline
        evidence: str | None = None
        if len(dev) >= cfg.min_signals:
            drop = -float(np.median(dev))
            limit = median_limit(len(dev), cfg.level_sigma_dbhz, self._p, two_sided=False)
            self.stats.update(drop_dbhz=drop, drop_limit=limit)
            if self._level_tripped:
                limit *= LEVEL_RELEASE  # hysteresis: a drop near the limit is one episode
            if drop > limit:
                evidence = f"C/N0 {drop:.1f} dB-Hz below its baseline on {len(dev)} signals"
        if (
            evidence is None
            and self._level_tripped
            and count_base is not None
            and n < cfg.lost_fraction * count_base
        ):
            evidence = f"lock lost: {n} of {count_base:.0f} signals tracked"
        self._level_tripped = evidence is not None
        if evidence is not None:
            self._count("level")
            return evidence
        # no interference: the baselines follow (each signal's, and the count's)
        tau = cfg.baseline_tau_s
        for k, v in cn0.items():
            old = base.get(k)
            if old is None:
                base[k] = (v, tow)
            else:
                w = 1.0 - math.exp(-max(tow - old[1], 0.0) / tau)
                base[k] = (old[0] + w * (v - old[0]), tow)
        if n >= cfg.min_signals:
            if count_base is None:
                self._count_baseline = float(n)
            else:
                w = 1.0 - math.exp(-max(tow - self._count_tow, 0.0) / tau)
                self._count_baseline = count_base + w * (n - count_base)
            self._count_tow = tow
        for k in [k for k, (_, t) in base.items() if tow - t > cfg.baseline_keep_s]:
            del base[k]
        return None

    # ------------------------------------------------------------------ code and Doppler

    @staticmethod
    def _wavelength(s: SignalObs) -> float | None:
        hz = SIGNAL_HZ.get(s.band)
        return None if hz is None else C_MPS / hz

    def _code_doppler(self, s: SignalObs, p: SignalObs, dt_s: float) -> float | None:
        """Code change minus the Doppler's range change between two epochs, m."""
        wl = self._wavelength(s)
        if wl is None or not (s.pr_valid and p.pr_valid) or s.lock_time_s < dt_s:
            return None
        v = (s.pseudorange_m - p.pseudorange_m) + wl * 0.5 * (s.doppler_hz + p.doppler_hz) * dt_s
        return v if math.isfinite(v) else None

    def _clock_step(self, epoch: RawEpoch, prev: RawEpoch) -> str | None:
        """The receiver clock's step since the last epoch when it trips, else None."""
        cfg = self.config
        if epoch.clock_reset:
            return None
        dt = epoch.tow_s - prev.tow_s
        before = {(s.system, s.sv, s.band): s for s in prev.signals}
        diffs = []
        for s in epoch.signals:
            p = before.get((s.system, s.sv, s.band))
            if p is not None:
                v = self._code_doppler(s, p, dt)
                if v is not None:
                    diffs.append(v)
        n = len(diffs)
        if n < cfg.min_signals:
            return None
        d = np.asarray(diffs)
        c = float(np.median(d))
        # the scale of a few signals' MAD is itself uncertain: the recent epochs' median
        # (a step moves every difference alike: it leaves the scale), or this epoch's
        # when larger (a burst of multipath)
        own = MAD_TO_SIGMA * float(np.median(np.abs(d - c)))
        self._clock_scales.append(own)
        scale = max(own, float(np.median(self._clock_scales)), cfg.code_doppler_floor_m)
        limit = median_limit(n, scale, self._p, two_sided=True)
        self.stats.update(clock_m=c, clock_scale_m=scale, clock_limit=limit)
        if abs(c) <= limit:
            return None
        return f"receiver clock step {c:.1f} m ({c / C_MPS * 1e9:.0f} ns, limit {limit:.1f} m)"

    def _remember(self, epoch: RawEpoch) -> None:
        """Keep each signal's contiguous (tow, code, Doppler) over the Doppler window."""
        cfg = self.config
        seen = set()
        for s in epoch.signals:
            wl = self._wavelength(s)
            if wl is None or not s.pr_valid:
                continue
            key = (s.system, s.sv, s.band)
            seen.add(key)
            h = self._history.get(key)
            if h is None or not h.samples or s.lock_time_s < epoch.tow_s - h.samples[-1][0]:
                h = self._history[key] = _History(wl)
            h.samples.append((epoch.tow_s, s.pseudorange_m, s.doppler_hz))
            while h.samples and epoch.tow_s - h.samples[0][0] > cfg.doppler_window_s + TIME_TOL_S:
                h.samples.popleft()
        for key in [k for k in self._history if k not in seen]:
            del self._history[key]

    def _displacement(
        self,
        epoch: RawEpoch,
        rx_ecef_m: FloatArray | None,
        ephemerides: dict[tuple[str, int], Ephemeris] | None,
    ) -> tuple[bool, str] | None:
        """The code's displacement against the Doppler's over the window: (tripped,
        evidence), or None when it cannot be judged."""
        cfg = self.config
        if rx_ecef_m is None or not ephemerides:
            return None
        tow = epoch.tow_s
        rows, d = [], []
        for (system, sv, band), h in self._history.items():
            eph = ephemerides.get((system, sv))
            if band not in cfg.bands:
                continue  # one signal per satellite: a satellite's bands share its errors
            s = h.samples
            if eph is None or len(s) < 2 or tow - s[0][0] < cfg.doppler_window_s - TIME_TOL_S:
                continue
            t = np.fromiter((x[0] for x in s), float, len(s))
            if np.any(np.diff(t) > cfg.max_gap_s):
                continue
            dop = np.fromiter((x[2] for x in s), float, len(s))
            integral = float(np.sum(0.5 * (dop[1:] + dop[:-1]) * np.diff(t)))
            pos = sat_state(eph, tow - FLIGHT_TIME_S).pos_ecef_m
            los = pos - rx_ecef_m
            u = los / np.linalg.norm(los)
            rows.append([-u[0], -u[1], -u[2], 1.0])
            d.append(s[-1][1] - s[0][1] + h.wavelength_m * integral)
        n = len(d)
        if n < cfg.min_signals:
            return None
        g = np.asarray(rows)
        y = np.asarray(d)
        keep = np.ones(n, bool)
        x = np.zeros(4)
        scale = cfg.doppler_floor_m
        for _ in range(2):  # a fit, then again without the outliers it shows
            x, *_ = np.linalg.lstsq(g[keep], y[keep], rcond=None)
            r = y - g @ x
            mad = float(np.median(np.abs(r[keep] - np.median(r[keep]))))
            scale = max(MAD_TO_SIGMA * mad, cfg.doppler_floor_m)
            new_keep = np.abs(r) <= 5.0 * scale
            if new_keep.sum() < cfg.min_signals or np.array_equal(new_keep, keep):
                break
            keep = new_keep
        gk = g[keep]
        try:
            cov = scale**2 * np.linalg.inv(gk.T @ gk)[:3, :3]
            cov += cfg.doppler_displacement_sigma_m**2 * np.eye(3)
            stat = float(x[:3] @ np.linalg.solve(cov, x[:3]))
        except np.linalg.LinAlgError:
            return None
        rate = float(np.linalg.norm(x[:3])) / cfg.doppler_window_s
        self.stats.update(
            doppler_chi2=stat, doppler_limit=self._chi2_3, doppler_scale_m=scale, doppler_mps=rate
        )
        text = (
            f"code moves {rate:.2f} m/s from the Doppler over {cfg.doppler_window_s:.0f} s "
            f"(chi2 {stat:.0f}, limit {self._chi2_3:.0f})"
        )
        return stat > self._chi2_3, text

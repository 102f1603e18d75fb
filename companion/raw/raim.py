"""FIS-RAIM of Kim, Walter and Powell, and a standard residual RAIM for comparison.

FIS-RAIM (solution separation): at each epoch the n solutions that each leave one
satellite out; the test statistic is the largest distance between a subset solution
and the all-in-view one. Over a sliding window of that time series a straight line is
fitted: the *slope test* trips on a slope beyond ``slope_limit_mps`` (a slow ramp), the
*residual test* on a residual sum of squares about the line beyond
σ² · χ²⁻¹(95 %, m − 2) with σ = 30 cm and m points in the window (a dither).

The series is one quantity only while the linear system is the same: when a signal
leaves the set (a slip, a lost signal) every separation changes by a step, so the window
starts again, and the slope test waits for a full window (its threshold is set for
one). The tests assume the separation's own noise is within the residual test's σ:
the predicted σ of each subset's separation, σ_φ·sqrt(λmax(P_j − P)) (P, P_j the
position covariances of the full and the subset solution at unit weight σ_φ), must stay
below ``residual_sigma_m``, else FIS-RAIM is *unavailable* at that epoch (as RAIM is
when its protection level exceeds the alert limit): no test, no alert, counted.

Standard RAIM: the weighted sum of squared residuals of one epoch's least-squares
solution against χ²⁻¹(1 − P_fa, rows − unknowns), σ given.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.stats import chi2

from companion.raw.orbit import FloatArray
from companion.raw.tdprp import TrackPoint, wls


@dataclass(frozen=True)
class FisRaimConfig:
    window_s: float = 10.0
    slope_limit_mps: float = 0.015
    """Half the 30 cm vertical limit gained within one window (0.15 m / 10 s)."""
    residual_sigma_m: float = 0.30
    residual_prob: float = 0.95
    min_points: int = 8
    recompute_window: bool = False
    """At a change of the signal set, solve the window's past epochs again with the
    signals left instead of starting the window again: no blind time for the slope
    test, but on the walk it trips where the walking starts (docs/raw.md)."""
    phase_sigma_m: float = 0.05
    """σ of one signal's time-differenced carrier at unit weight (zenith): the walk's
    a-posteriori σ while walking is 5-7 cm (0.7 cm standing), multipath of a handheld
    antenna; Kim, Walter and Powell's aircraft in open sky would be nearer 1 cm."""


@dataclass(frozen=True)
class FisRaimResult:
    t_s: float
    separation_m: float
    slope_mps: float
    residual_m2: float
    residual_limit_m2: float
    slope_alert: bool
    residual_alert: bool
    available: bool = True
    """False where a subset's predicted separation σ exceeds the residual test's σ."""
    separation_sigma_m: float = 0.0
    """The largest predicted separation σ of the subsets."""

    @property
    def alert(self) -> bool:
        return self.slope_alert or self.residual_alert


def subset_separations(point: TrackPoint) -> dict[tuple[str, int], float]:
    """Distance (m, 3-D) between each leave-one-satellite-out solution and the full one.

    Subsets that cannot be solved (fewer rows than unknowns, fewer than four
    satellites) are left out.
    """
    return {sat: d for sat, (d, _) in subset_geometry(point).items()}


def subset_geometry(point: TrackPoint) -> dict[tuple[str, int], tuple[float, float]]:
    """Per satellite left out: (separation m, sqrt(λmax(P_j − P)) per metre of σ_φ).

    The second is the separation's predicted σ at unit-weight phase σ of 1 m: the
    largest standard deviation, over directions, of the difference of two weighted
    least-squares solutions that share every row but the left-out ones (its covariance
    is P_j − P for the weights used).
    """
    g, y, w = point.g_enu, point.y_m, point.w
    full = wls(g, y, w)[:3]
    p_full = np.linalg.pinv(g.T @ (g * w[:, None]))[:3, :3]
    sats = sorted({k[:2] for k in point.keys})
    out: dict[tuple[str, int], tuple[float, float]] = {}
    for sat in sats:
        keep = np.array([k[:2] != sat for k in point.keys])
        gs = g[keep]
        used = np.any(gs != 0.0, axis=0)
        gs = gs[:, used]
        if len(sats) - 1 < 4 or gs.shape[0] <= gs.shape[1] - 1:
            continue
        if np.linalg.matrix_rank(gs) < gs.shape[1]:
            continue
        ws = w[keep]
        sub = wls(gs, y[keep], ws)[:3]
        p_sub = np.linalg.pinv(gs.T @ (gs * ws[:, None]))[:3, :3]
        amp = math.sqrt(max(float(np.linalg.eigvalsh(p_sub - p_full).max()), 0.0))
        out[sat] = (float(np.linalg.norm(sub - full)), amp)
    return out


@dataclass
class FisRaim:
    config: FisRaimConfig = field(default_factory=FisRaimConfig)

    def __post_init__(self) -> None:
        self._series: deque[tuple[float, float]] = deque()
        self._points: deque[TrackPoint] = deque()
        self._limits: dict[int, float] = {}
        self._keys: tuple[tuple[str, int, str], ...] = ()
        self._since_s = math.inf
        self.restarts = 0
        """Windows started again because the set of signals changed."""
        self.unavailable = 0
        """Epochs without a test: a subset's predicted separation σ too large."""
        self.slope_waiting = 0
        """Available epochs without the slope test: its window not yet full again."""

    def update(self, point: TrackPoint) -> FisRaimResult | None:
        """Add one epoch; None while fewer than five satellites leave no separation."""
        cfg = self.config
        if point.keys != self._keys:
            if self._keys:
                self.restarts += 1
            if cfg.recompute_window:
                self._recompute(point.keys)
            else:
                self._clear()
            self._keys = point.keys
        geo = subset_geometry(point)
        if not geo:
            self._clear()
            return None
        sep = max(d for d, _ in geo.values())
        sigma = cfg.phase_sigma_m * max(a for _, a in geo.values())
        if sigma > cfg.residual_sigma_m:
            self.unavailable += 1
            self._clear()
            return FisRaimResult(point.t_s, sep, 0.0, 0.0, math.inf, False, False, False, sigma)
        if not self._series:
            self._since_s = point.t_s
        self._series.append((point.t_s, sep))
        self._points.append(point)
        while self._series and self._series[0][0] < point.t_s - cfg.window_s:
            self._series.popleft()
            self._points.popleft()
        m = len(self._series)
        full = point.t_s - self._since_s >= cfg.window_s
        self.slope_waiting += not full
        if m < cfg.min_points:
            return FisRaimResult(point.t_s, sep, 0.0, 0.0, math.inf, False, False, True, sigma)
        t = np.array([p[0] for p in self._series])
        s = np.array([p[1] for p in self._series])
        a = np.vstack([t - t.mean(), np.ones(m)]).T
        coef, *_ = np.linalg.lstsq(a, s, rcond=None)
        rss = float(np.sum((s - a @ coef) ** 2))
        lim = self._limits.get(m)
        if lim is None:
            lim = cfg.residual_sigma_m**2 * float(chi2.ppf(cfg.residual_prob, m - 2))
            self._limits[m] = lim
        slope = float(coef[0])
        return FisRaimResult(
            point.t_s,
            sep,
            slope,
            rss,
            lim,
            full and slope > cfg.slope_limit_mps,
            rss > lim,
            True,
            sigma,
        )

    def _clear(self) -> None:
        self._series.clear()
        self._points.clear()

    def _recompute(self, keys: tuple[tuple[str, int, str], ...]) -> None:
        """The window's separations again, each past epoch solved with ``keys`` only."""
        series: deque[tuple[float, float]] = deque()
        points: deque[TrackPoint] = deque()
        for p in self._points:
            sub = restrict(p, keys)
            geo = subset_geometry(sub) if sub is not None else {}
            if sub is not None and geo:
                series.append((p.t_s, max(d for d, _ in geo.values())))
                points.append(sub)
        self._series, self._points = series, points
        if series:
            self._since_s = max(self._since_s, series[0][0])


def restrict(point: TrackPoint, keys: tuple[tuple[str, int, str], ...]) -> TrackPoint | None:
    """The epoch's linear system with only the rows of ``keys`` (None if one is missing).

    A separation does not depend on the point the system was linearised about (both
    solutions move with it), so a past epoch restricted to today's signals gives the
    separation today's set would have had then.
    """
    index = {k: i for i, k in enumerate(point.keys)}
    if any(k not in index for k in keys):
        return None
    rows = np.array([index[k] for k in keys], dtype=int)
    return replace(
        point,
        keys=keys,
        g_enu=point.g_enu[rows],
        y_m=point.y_m[rows],
        w=point.w[rows],
        residual_m=point.residual_m[rows],
        iono_change_m=point.iono_change_m[rows],
    )


def chi2_raim(
    g: FloatArray, y: FloatArray, w: FloatArray, sigma_m: float, p_fa: float = 1e-3
) -> tuple[float, float, bool]:
    """Standard residual RAIM of one epoch: (statistic, threshold, alert).

    The statistic is Σ w_k r_k² / σ² of the weighted least-squares residuals ``r``
    (weights ``w`` relative, σ the noise at unit weight).
    """
    dof = g.shape[0] - np.linalg.matrix_rank(g)
    if dof < 1:
        return 0.0, np.inf, False
    r = y - g @ wls(g, y, w)
    stat = float(np.sum(w * r * r)) / sigma_m**2
    lim = float(chi2.ppf(1.0 - p_fa, dof))
    return stat, lim, stat > lim

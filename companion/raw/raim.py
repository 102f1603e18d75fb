"""FIS-RAIM of Kim, Walter and Powell, and a standard residual RAIM for comparison.

FIS-RAIM (solution separation): at each epoch the n solutions that each leave one
satellite out; the test statistic is the largest distance between a subset solution
and the all-in-view one. Over a sliding window of that time series a straight line is
fitted: the *slope test* trips on a slope beyond ``slope_limit_mps`` (a slow ramp), the
*residual test* on a residual sum of squares about the line beyond
σ² · χ²⁻¹(95 %, m − 2) with σ = 30 cm and m points in the window (a dither).

Standard RAIM: the weighted sum of squared residuals of one epoch's least-squares
solution against χ²⁻¹(1 − P_fa, rows − unknowns), σ given.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

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


@dataclass(frozen=True)
class FisRaimResult:
    t_s: float
    separation_m: float
    slope_mps: float
    residual_m2: float
    residual_limit_m2: float
    slope_alert: bool
    residual_alert: bool

    @property
    def alert(self) -> bool:
        return self.slope_alert or self.residual_alert


def subset_separations(point: TrackPoint) -> dict[tuple[str, int], float]:
    """Distance (m, 3-D) between each leave-one-satellite-out solution and the full one.

    Subsets that cannot be solved (fewer rows than unknowns, fewer than four
    satellites) are left out.
    """
    g, y, w = point.g_enu, point.y_m, point.w
    full = wls(g, y, w)[:3]
    sats = sorted({k[:2] for k in point.keys})
    out: dict[tuple[str, int], float] = {}
    for sat in sats:
        keep = np.array([k[:2] != sat for k in point.keys])
        gs = g[keep]
        used = np.any(gs != 0.0, axis=0)
        gs = gs[:, used]
        if len(sats) - 1 < 4 or gs.shape[0] <= gs.shape[1] - 1:
            continue
        if np.linalg.matrix_rank(gs) < gs.shape[1]:
            continue
        sub = wls(gs, y[keep], w[keep])[:3]
        out[sat] = float(np.linalg.norm(sub - full))
    return out


@dataclass
class FisRaim:
    config: FisRaimConfig = field(default_factory=FisRaimConfig)

    def __post_init__(self) -> None:
        self._series: deque[tuple[float, float]] = deque()
        self._limits: dict[int, float] = {}

    def update(self, point: TrackPoint) -> FisRaimResult | None:
        """Add one epoch; None while fewer than five satellites leave no separation."""
        seps = subset_separations(point)
        if not seps:
            return None
        cfg = self.config
        sep = max(seps.values())
        self._series.append((point.t_s, sep))
        while self._series and self._series[0][0] < point.t_s - cfg.window_s:
            self._series.popleft()
        m = len(self._series)
        if m < cfg.min_points:
            return FisRaimResult(point.t_s, sep, 0.0, 0.0, np.inf, False, False)
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
            point.t_s, sep, slope, rss, lim, slope > cfg.slope_limit_mps, rss > lim
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

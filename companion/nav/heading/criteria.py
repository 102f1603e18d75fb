"""Acceptance criteria of the taxi heading correction: is the sample ready, or rejected?

Evaluated once the sample is sufficient (``eps <= eps_limit_deg`` and at least
``min_cycles`` cycles), in this order; the first failure is the reason:

* **park check**: before the taxi, the GNSS velocity while parked (speed at
  or below ``park_speed_mps`` for ``park_time_s``) must show no bias
  (:func:`park_bias_verdict`);
* **spread of the running mean** ``sigma[mean] <= mean_spread_limit_deg``
  (the recursion of :class:`~companion.nav.heading.stats.RunningStats`
  applied to the running mean, over the cycles from ``spread_start_cycle`` on);
* **dispersion**: the observed scatter against the expected sum of the GNSS
  track-angle variance ``(vel_acc / speed)^2`` and the INS course variance
  (one-sided chi-square test: a larger scatter than the sensors explain means
  something unmodelled, such as a changing crab angle);
* **normality** of the mismatch (D'Agostino-Pearson, ``scipy.stats.normaltest``)
  on the mismatches standardised by their expected per-cycle sigma, so that
  legs at different speeds do not make a scale mixture look heavy-tailed;
* **stationarity**: no significant trend of the mismatch in time and no
  significant difference between legs (a velocity bias makes the mismatch
  depend on the track direction), each only when the change is also larger
  than ``max_drift_deg``.

References
----------
Markelov et al., "INS course correction from satellite navigation before
take-off": sufficiency, the parking-stand check, the running-mean spread, the
dispersion and normality criteria. The trend and leg tests (aimed at its
"changing crab angle" and "biased GNSS velocity" failure modes) and the
standardised normality test are additions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from companion.nav.heading.config import HeadingConfig
from companion.nav.heading.stats import CycleSample


@dataclass(frozen=True, slots=True)
class Verdict:
    """Outcome of the acceptance criteria: ``reason`` is empty when all hold."""

    ok: bool
    reason: str
    details: dict[str, float]


def park_bias_verdict(vel_ne_mps: np.ndarray, alpha: float, max_bias_mps: float) -> Verdict:
    """Parked check: is the mean GNSS velocity (shape (n, 2), m/s) a bias?

    A bias is declared when the mean velocity is both significant (Hotelling
    T^2 against zero, approximated by chi-square with 2 degrees of freedom at
    ``alpha``) and larger than ``max_bias_mps``.

    References
    ----------
    Markelov et al., parking-stand check (GNSS speed <= 0.2 m/s for 10-30 s).
    """
    n = vel_ne_mps.shape[0]
    if n < 3:
        return Verdict(False, "park_too_few", {"n": float(n)})
    mean = vel_ne_mps.mean(axis=0)
    cov = np.cov(vel_ne_mps, rowvar=False) / n
    cov += np.eye(2) * 1e-12
    t2 = float(mean @ np.linalg.solve(cov, mean))
    limit = float(stats.chi2.ppf(1.0 - alpha, 2))
    bias = float(np.hypot(mean[0], mean[1]))
    details = {"bias_mps": bias, "t2": t2, "t2_limit": limit, "n": float(n)}
    if t2 > limit and bias > max_bias_mps:
        return Verdict(False, f"gnss_vel_bias {bias:.3f}m/s", details)
    return Verdict(True, "", details)


def judge_sample(
    sample: CycleSample,
    eps_rad: float,
    min_cycles: int,
    park_ok: bool | None,
    cfg: HeadingConfig,
) -> Verdict:
    """Evaluate the acceptance criteria on ``sample`` (the order of the module docstring).

    ``eps_rad`` is the sample's accuracy, ``min_cycles`` the fewest cycles of its
    track source, ``park_ok`` the latest parked check (``None``: not done).
    """
    x = np.asarray(sample.x_rad, dtype=np.float64)
    sig = np.asarray(sample.sigma_rad, dtype=np.float64)
    t = np.asarray(sample.t_s, dtype=np.float64)
    leg = np.asarray(sample.leg, dtype=np.int64)
    n = x.size
    d: dict[str, float] = {"n": float(n), "eps_deg": math.degrees(eps_rad)}
    if n < min_cycles or math.degrees(eps_rad) > cfg.eps_limit_deg:
        return Verdict(False, f"insufficient eps={math.degrees(eps_rad):.3f}", d)
    if cfg.require_park_check and park_ok is not True:
        reason = "no_park_check" if park_ok is None else "gnss_vel_bias"
        return Verdict(False, reason, d)
    # spread of the running mean (Markelov et al.: sigma[mean] <= 0.3 deg)
    spread_deg = math.degrees(sample.mean_spread_rad())
    d["spread_deg"] = spread_deg
    if spread_deg > cfg.mean_spread_limit_deg:
        return Verdict(False, f"mean_spread {spread_deg:.2f}>{cfg.mean_spread_limit_deg}", d)
    resid = x - sample.stats.mean
    reason = (
        _dispersion(resid, sig, n, cfg, d)
        or _normality(resid, sig, cfg, d)
        or _trend(resid, sig, t, n, cfg, d)
        or _legs_differ(x, sig, leg, cfg, d)
    )
    return Verdict(not reason, reason, d)


def _dispersion(
    resid: np.ndarray, sig: np.ndarray, n: int, cfg: HeadingConfig, d: dict[str, float]
) -> str:
    """Observed scatter vs GNSS track + INS course variances (chi-square); "" when it holds."""
    t_disp = float(np.sum((resid / sig) ** 2))
    disp_limit = float(stats.chi2.ppf(1.0 - cfg.dispersion_alpha, n - 1))
    d["dispersion_ratio"] = t_disp / (n - 1)
    d["dispersion_limit_ratio"] = disp_limit / (n - 1)
    if t_disp > disp_limit:
        return f"dispersion {t_disp / (n - 1):.2f}x"
    return ""


def _normality(resid: np.ndarray, sig: np.ndarray, cfg: HeadingConfig, d: dict[str, float]) -> str:
    """Normality of the standardised mismatch (D'Agostino-Pearson); "" when it holds."""
    z = resid / sig
    p_norm = float(stats.normaltest(z).pvalue)
    d["normality_p"] = p_norm
    if p_norm < cfg.normality_alpha:
        return f"not_normal p={p_norm:.1e}"
    return ""


def _trend(
    resid: np.ndarray,
    sig: np.ndarray,
    t: np.ndarray,
    n: int,
    cfg: HeadingConfig,
    d: dict[str, float],
) -> str:
    """Trend of the mismatch in time (weighted least squares, t test); "" when none."""
    w = 1.0 / sig**2
    tc = t - np.sum(w * t) / np.sum(w)
    stt = float(np.sum(w * tc * tc))
    if stt > 0.0:
        slope = float(np.sum(w * tc * resid) / stt)
        rss = float(np.sum(w * (resid - slope * tc) ** 2))
        se = math.sqrt(rss / (n - 2) / stt)
        t_stat = abs(slope) / se if se > 0 else math.inf
        drift_deg = abs(math.degrees(slope) * float(t[-1] - t[0]))
        t_limit = float(stats.t.ppf(1.0 - cfg.stationarity_alpha / 2.0, n - 2))
        d["drift_deg"] = drift_deg
        d["trend_t"] = t_stat
        if t_stat > t_limit and drift_deg > cfg.max_drift_deg:
            return f"trend {drift_deg:.2f}deg"
    return ""


def _legs_differ(
    x: np.ndarray, sig: np.ndarray, leg: np.ndarray, cfg: HeadingConfig, d: dict[str, float]
) -> str:
    """Leg consistency (weighted one-way analysis of variance, F test); "" when consistent."""
    w = 1.0 / sig**2
    legs = [k for k in np.unique(leg) if np.count_nonzero(leg == k) >= cfg.min_leg_cycles]
    if len(legs) >= 2:
        sel = np.isin(leg, legs)
        xs, ws, ls = x[sel], w[sel], leg[sel]
        m_all = float(np.sum(ws * xs) / np.sum(ws))
        between = 0.0
        within = 0.0
        means = []
        for k in legs:
            mk = ls == k
            wk = ws[mk]
            m_k = float(np.sum(wk * xs[mk]) / np.sum(wk))
            means.append(m_k)
            between += float(np.sum(wk)) * (m_k - m_all) ** 2
            within += float(np.sum(wk * (xs[mk] - m_k) ** 2))
        k_legs = len(legs)
        n_sel = xs.size
        f_stat = (between / (k_legs - 1)) / (within / (n_sel - k_legs))
        f_limit = float(stats.f.ppf(1.0 - cfg.stationarity_alpha, k_legs - 1, n_sel - k_legs))
        leg_range_deg = math.degrees(max(means) - min(means))
        d["leg_f"] = f_stat
        d["leg_range_deg"] = leg_range_deg
        if f_stat > f_limit and leg_range_deg > cfg.max_drift_deg:
            return f"legs_differ {leg_range_deg:.2f}deg"
    return ""

"""The vertical prior from recent GNSS heights (companion.nav.vertical_prior)."""

from __future__ import annotations

import numpy as np
from scipy.stats import chi2

from companion.nav.vertical_prior import VerticalPrior, VerticalPriorConfig


def fed(heights_d_m: np.ndarray, rate_hz: float = 5.0, var_m2: float = 0.01) -> VerticalPrior:
    prior = VerticalPrior()
    for k, d in enumerate(heights_d_m):
        prior.add_fix(k / rate_hz, float(d), var_m2)
    return prior


T_LAST = 299 / 5.0


def test_level_history_pulls_the_ins_change_not_its_start() -> None:
    rng = np.random.default_rng(3)
    prior = fed(rng.normal(0.0, 0.05, 300))  # 60 s level, 5 cm noise
    var_c = prior.change_var(T_LAST + 10.0)
    assert var_c is not None
    # about twice the noise variance (two noisy fixes), inflated by the 6-lag bound
    assert 2 * 0.05**2 * 0.7 < var_c < 2 * 0.05**2 * 6 / chi2.ppf(0.05, 6) * 1.3
    # the INS at the gap's start: 2.0 m down, 0.3 m sigma (its error is the fixes' too)
    assert prior.combine(T_LAST + 0.1, 2.0, 0.09) is None  # no change yet: the INS alone
    both = prior.combine(T_LAST + 10.0, 2.5, 0.09 + 1.0)  # moved 0.5 m, 1 m sigma of growth
    assert both is not None
    d_c, var_c2 = both
    assert abs(d_c - 2.0) < 0.05  # near the start, not near the last fix's 0 m
    assert 0.09 < var_c2 < 0.09 + var_c  # the shared start's variance is kept


def test_a_descent_begun_in_the_gap_withdraws_the_prediction_for_the_rest_of_it() -> None:
    prior = fed(np.zeros(300))
    prior.combine(T_LAST + 0.5, 0.0, 0.01)
    # descending at 3 m/s (down grows): the INS says so, its change within 0.3 m sigma
    assert prior.combine(T_LAST + 2.0, 4.5, 0.01 + 0.09) is None
    assert prior.disagrees
    # back at the old height later in the same gap: still the INS alone
    assert prior.combine(T_LAST + 5.0, 0.0, 0.01 + 0.25) is None
    prior.add_fix(T_LAST + 6.0, 18.0, 0.01)  # the gap ends: the next one starts afresh
    prior.combine(T_LAST + 6.2, 18.0, 0.01)
    assert prior.combine(T_LAST + 6.5, 18.01, 0.02) is not None
    assert not prior.disagrees


def test_a_climbing_history_gives_a_wide_prediction() -> None:
    prior = fed(-2.0 * np.arange(300) / 5.0)  # climbing at 2 m/s
    var_c = prior.change_var(T_LAST + 10.0)
    assert var_c is not None
    assert var_c > (2.0 * 10.0) ** 2
    # an INS that keeps climbing at 2 m/s agrees and keeps most of its change
    prior.combine(T_LAST + 0.1, 0.0, 0.04)
    both = prior.combine(T_LAST + 10.0, -19.8, 0.04 + 1.0)
    assert both is not None
    assert both[0] < -19.0


def test_no_prediction_beyond_what_the_window_measures() -> None:
    prior = fed(np.zeros(50))  # 10 s of fixes
    last = 49 / 5.0
    assert prior.change_var(last + 5.0) is not None
    assert prior.change_var(last + 10.5) is None
    assert prior.combine(last + 10.5, 0.0, 1.0) is None
    assert VerticalPrior().change_var(1.0) is None  # no fixes


def test_the_window_and_bad_fixes() -> None:
    prior = VerticalPrior(VerticalPriorConfig(window_s=10.0))
    for k in range(100):
        prior.add_fix(k * 0.2, 0.0, 0.01)
    prior.add_fix(30.0, float("nan"), 0.01)
    prior.add_fix(5.0, 0.0, 0.01)  # out of order
    assert len(prior._fixes) == 51
    prior.restart()
    assert prior.change_var(21.0) is None

"""Windows of the blend's NIS against the chi-square bound: the in-flight IMU grade check."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from companion.nav.imu_innovations import ImuInnovationCheck, ImuInnovationConfig

GATE_6 = float(chi2.isf(1e-4, 6))  # the blend's default gate for a 6-component fix


def feed(check: ImuInnovationCheck, scale: float, seconds: float, seed: int, **kw: object):
    """Fixes at 10 Hz whose NIS is ``scale`` times a chi2(6) draw (scale 1: a filter whose
    innovation covariance is right). Returns the first time the grade is doubted."""
    rng = np.random.default_rng(seed)
    consistent = bool(kw.get("consistent", True))
    for k in range(int(seconds * 10)):
        t = 10.0 + 0.1 * k
        nis = scale * float(rng.chisquare(6))
        if kw.get("glitch") and k % 100 == 50:
            nis = 1e6  # one wild fix per window
        check.on_innovation(t, nis, 6, GATE_6, consistent)
        if check.doubted:
            return t
    return None


def test_consistent_innovations_pass_with_the_right_mean() -> None:
    check = ImuInnovationCheck()
    assert feed(check, 1.0, 600.0, 1) is None
    assert check.judged == 59  # one window per 10 s, the last still open
    ratios = [w.ratio for w in check.windows]
    assert all(0.85 < r < 1.15 for r in ratios)  # sum NIS / sum dof: 1 +- sqrt(2 / 600)
    assert not any(w.failed for w in check.windows)
    # the bound: chi2 at 1e-7 for 600 dof is 1.35 per dof; the margin 1.5 is above it
    assert check.windows[-1].bound == pytest.approx(1.5)


def test_innovations_persistently_above_the_grade_doubt_it() -> None:
    check = ImuInnovationCheck()
    t = feed(check, 2.0, 600.0, 2)
    assert t is not None and t < 10.0 + 3 * 10.0 + 0.2  # the third window closes it
    assert sum(w.failed for w in check.windows) == 3
    # a margin: 1.3 times the expected NIS never fails a window
    assert feed(ImuInnovationCheck(), 1.3, 600.0, 3) is None


def test_an_inconsistent_receiver_says_nothing_about_the_imu() -> None:
    check = ImuInnovationCheck()
    assert feed(check, 5.0, 300.0, 4, consistent=False) is None
    assert check.judged == 0
    assert check.skipped_fixes == 3000


def test_one_wild_fix_counts_at_most_as_the_gate() -> None:
    check = ImuInnovationCheck()
    assert feed(check, 1.0, 600.0, 5, glitch=True) is None
    assert check.judged > 50


def test_a_restart_drops_the_open_window_only() -> None:
    check = ImuInnovationCheck(ImuInnovationConfig(windows_needed=2, windows_span=2))
    feed(check, 2.0, 15.0, 6)  # one failed window, the next half full
    assert check.judged == 1 and check.windows[0].failed
    check.restart()
    feed(check, 2.0, 10.5, 7)
    assert check.doubted  # the failed window before the restart still counts


def test_config_is_checked() -> None:
    with pytest.raises(ValueError, match="windows_needed"):
        ImuInnovationConfig(windows_needed=4, windows_span=3)
    with pytest.raises(ValueError):
        ImuInnovationConfig(min_ratio=0.5)

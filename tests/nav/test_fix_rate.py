"""The rhythm of a receiver's fixes: slow once, with hysteresis; outages are not rhythm."""

from __future__ import annotations

import numpy as np

from companion.nav.fix_rate import LATENESS_KEPT, FixRhythm

ENTER_S, LEAVE_S, MAX_S = 0.5, 0.35, 3.0


def feed(rhythm: FixRhythm, lateness: list[float]) -> list[bool]:
    changes = []
    for x in lateness:
        c = rhythm.on_fix(x, ENTER_S, LEAVE_S, MAX_S)
        if c is not None:
            changes.append(c)
    return changes


def test_a_5hz_receiver_missing_epochs_is_never_slow():
    rng = np.random.default_rng(3)
    lateness = [0.2 * (1 + int(rng.random() < 0.2)) for _ in range(500)]  # 20 % missed
    rhythm = FixRhythm()
    assert feed(rhythm, lateness) == [] and not rhythm.slow


def test_a_jittery_1hz_link_is_slow_once_and_steady_only_well_below():
    rng = np.random.default_rng(4)
    rhythm = FixRhythm()
    slow = [float(x) for x in rng.choice((0.6, 0.8, 1.0, 1.4, 2.6), 300)]
    assert feed(rhythm, slow) == [True]
    assert 2.5 < rhythm.longest_s < MAX_S
    # a 5 Hz stretch: the median crosses 0.5 s and 0.35 s once each, no flapping
    assert feed(rhythm, [0.2] * LATENESS_KEPT) == [False]


def test_outages_do_not_make_the_rhythm():
    rhythm = FixRhythm()
    assert feed(rhythm, [0.2, 10.0, 0.2, 25.0] * 20) == []
    assert rhythm.longest_s == 0.2

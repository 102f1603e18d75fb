"""A slow, jittery link (a ground station's 1 Hz telemetry): said once, not per fix.

A constructed straight flight whose IMU, attitude and GNSS streams each come at about
1 Hz with intervals from 0.6 to 2.6 s (seeded), the fixes 0.15 s late, driven through
the engine as a driver does (its timer at :meth:`Engine.next_due_s`): the receiver is
announced slow once (``GNSS_SLOW``), no long interval is a GNSS loss or a silence, every
fix is used, the published accuracy covers the truth between fixes; a real 10 s gap is
still one ``GNSS_LOST``. The real recording of such a link, where present, replayed.
"""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from companion.config import load_config
from companion.engine import Engine
from companion.engine.silence import DATA_INTERVALS_KEPT, StreamWatch
from companion.evaluate.against_input import evaluate_against_input
from companion.nav.earth import gravity_mps2
from companion.replay import replay
from companion.types import (
    Alert,
    AlertCode,
    AttitudeSample,
    ImuSample,
    NavSolution,
    Output,
    Sample,
)
from tests.helpers import ORIGIN, Line, fix_at

INTERVALS_S = (0.6, 0.8, 0.8, 1.0, 1.0, 1.0, 1.2, 1.6, 2.0, 2.6)
"""A telemetry stream's intervals (drawn at random, seeded)."""
DELIVERY_S = 0.15
"""How late each fix arrives after its time of validity."""
LINE = Line()
PHOENIX = (
    Path(__file__).resolve().parents[2]
    / "shared"
    / "realdata"
    / "flights"
    / "real_gcs_copter_phoenix_mission1"
    / "real_gcs_copter_phoenix_mission1.tlog"
)


def _times(rng: np.random.Generator, t0: float, t1: float) -> list[float]:
    out, t = [], t0 + float(rng.uniform(0.0, 1.0))
    while t < t1:
        out.append(t)
        t += float(rng.choice(INTERVALS_S))
    return out


def slow_stream(
    duration_s: float, seed: int, gnss_gap: tuple[float, float] | None = None
) -> list[tuple[float, Sample]]:
    """(arrival time, sample) of the three ~1 Hz streams, in arrival order."""
    rng = np.random.default_rng(seed)
    t0 = 10.0
    vel = np.array(LINE.vel_ned_mps)
    f_b = np.array([0.0, 0.0, -gravity_mps2(ORIGIN.lat0_rad, ORIGIN.alt0_m)])
    yaw = math.atan2(vel[1], vel[0])
    items: list[tuple[float, Sample]] = []
    for t in _times(rng, t0, t0 + duration_s):
        items.append((t, ImuSample(t, t, f_b, np.zeros(3), 0, "TEST")))
    for t in _times(rng, t0, t0 + duration_s):
        items.append((t, AttitudeSample(t, t, 0.0, 0.0, yaw, np.zeros(3))))
    for t in _times(rng, t0, t0 + duration_s):
        if gnss_gap is not None and gnss_gap[0] <= t - t0 < gnss_gap[1]:
            continue
        items.append((t + DELIVERY_S, fix_at(t, LINE.pos_ned_m(t, t0), vel)))
    items.sort(key=lambda x: x[0])
    return items


def drive(items: list[tuple[float, Sample]]) -> list[Output]:
    """The engine fed as a driver does: its timer fires at :meth:`Engine.next_due_s`."""
    engine = Engine()
    outputs: list[Output] = []
    for t_arrival, sample in items:
        while (due := engine.next_due_s()) < t_arrival:
            outputs += engine.on_clock(due)
        outputs += engine.handle(sample)
    return outputs


def alert_codes(outputs: list[Output], after_s: float = 0.0) -> Counter[str]:
    return Counter(o.code.value for o in outputs if isinstance(o, Alert) and o.t_s >= after_s)


def test_a_slow_jittery_link_is_announced_once_and_raises_no_loss_per_interval():
    outputs = drive(slow_stream(600.0, seed=7))
    assert alert_codes(outputs)[AlertCode.GNSS_SLOW.value] == 1
    # once its rhythm is measured (its first 8 fixes), no interval is a loss or a silence
    counts = alert_codes(outputs, after_s=40.0)
    for code in (AlertCode.GNSS_LOST, AlertCode.GNSS_BACK, AlertCode.NO_DATA):
        assert counts[code.value] == 0, code


def test_between_slow_fixes_the_published_accuracy_grows_and_covers_the_truth():
    outputs = drive(slow_stream(300.0, seed=11))
    sols = [o for o in outputs if isinstance(o, NavSolution)]
    assert len(sols) > 200
    covered = []
    for s in sols:
        pos = ORIGIN.lla_to_ned(s.lat_rad, s.lon_rad, s.alt_msl_m)
        truth = LINE.pos_ned_m(s.t_s, 10.0)
        err = float(np.hypot(*(pos - truth)[:2]))
        covered.append(err <= 2.448 * s.h_acc_m)
    assert np.mean(covered) >= 0.95
    # the accuracy of a publication carried from a fix grows with the time since it
    h_acc = [s.h_acc_m for s in sols]
    assert max(h_acc) > 1.5 * min(h_acc)


def test_a_real_gap_in_a_slow_link_is_one_loss_and_one_return():
    outputs = drive(slow_stream(300.0, seed=7, gnss_gap=(150.0, 160.0)))
    alerts = [o for o in outputs if isinstance(o, Alert) and o.t_s >= 40.0]
    lost = [a for a in alerts if a.code is AlertCode.GNSS_LOST]
    back = [a for a in alerts if a.code is AlertCode.GNSS_BACK]
    assert len(lost) == 1 and len(back) == 1
    assert 160.0 <= lost[0].t_s <= 160.0 + 4.0 + 0.1  # within gnss_timeout_max_s of the gap


@pytest.mark.skipif(not PHOENIX.is_file(), reason=f"no real recording at {PHOENIX}")
def test_the_real_ground_station_recording_is_no_alert_storm(tmp_path):
    """The 1 Hz ground-station recording: 169 GNSS_LOST, 155 GNSS_BACK and 16 silences
    (each a navigation restart) before the rhythm was measured."""
    config = load_config(None)
    summary = replay(PHOENIX, tmp_path / "out.tlog", config)
    counts = summary.alerts
    assert counts.get(AlertCode.GNSS_SLOW.value, 0) == 1
    assert counts.get(AlertCode.GNSS_LOST.value, 0) <= 25
    assert counts.get(AlertCode.NO_DATA.value, 0) <= 8
    assert sum(counts.values()) <= 60
    # the receiver used (94 % with a restart per silence), every gap alerted in time
    res = evaluate_against_input(tmp_path / "out.tlog", PHOENIX, config.decoder)
    assert res.receiver_use.passed
    assert res.gaps_summary.passed_alert
    assert res.confidence.passed_wrong and res.confidence.passed_coverage


def test_the_silence_timeout_follows_the_links_longest_pause_bounded():
    """Twice the longest recent pause that was no silence, between 2 s and 5 s; a fast
    link keeps 2 s; an old long pause leaves the window."""
    fast = StreamWatch(2.0, 3.0, 30.0, 2.0, 5.0)
    for k in range(1000):
        fast.on_data(k * 0.02)
    assert fast.timeout_s == 2.0
    slow = StreamWatch(2.0, 3.0, 30.0, 2.0, 5.0)
    t = 0.0
    for dt in (0.5, 1.0, 1.4, 0.9):
        t += dt
        assert slow.on_data(t) is None
    assert slow.timeout_s == pytest.approx(2.8)  # 2 x 1.4 s
    t += 2.5  # no silence (2.5 < 2.8): it lengthens the timeout, to the bound
    assert slow.on_data(t) is None
    assert slow.timeout_s == 5.0
    for _ in range(DATA_INTERVALS_KEPT):  # the 2.5 s pause leaves the window
        t += 0.5
        slow.on_data(t)
    assert slow.timeout_s == 2.0
    t += 2.2  # now a silence: ends with its length, and teaches nothing
    assert slow.on_data(t) == pytest.approx(2.2)
    assert slow.timeout_s == 2.0

"""Outage monitor: loss, downgrade, stale/frozen fixes, reacquisition."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from companion.nav.outage import OutageConfig, OutageMonitor
from companion.types import AlertCode, FixType, NavMode, Severity
from tests.helpers import Line, fix_at

LINE = Line((30.0, 0.0, 0.0))


def fix(t, **kw):
    return fix_at(t, LINE.pos_ned_m(t, 0.0), np.array(LINE.vel_ned_mps), **kw)


def codes(alerts):
    return [a.code for a in alerts]


def start(mon, t_end=2.0):
    for k in range(int(t_end * 10)):
        t = k / 10
        v = mon.assess(fix(t))
        assert v.usable
        mon.gate_result(t, True)


def test_first_fix_is_not_gated_then_everything_is():
    mon = OutageMonitor()
    first = mon.assess(fix(0.0))
    assert first.usable and not first.gate
    mon.gate_result(0.0, True)
    assert mon.mode is NavMode.NORMAL
    assert mon.assess(fix(0.1)).gate


def test_timeout_reacquire_and_back_after_n_gated_fixes():
    mon = OutageMonitor()
    start(mon)
    assert mon.tick(2.5) == []
    lost = mon.tick(2.95)
    assert codes(lost) == [AlertCode.GNSS_LOST]
    assert mon.outage_s(5.0) == pytest.approx(5.0 - 1.9)
    for k, t in enumerate((6.0, 6.1, 6.2)):
        v = mon.assess(fix(t))
        assert v.usable and v.gate
        out = mon.gate_result(t, True)
        if k < 2:
            assert mon.mode is NavMode.REACQUIRING and out == []
    assert codes(out) == [AlertCode.GNSS_BACK]
    assert mon.mode is NavMode.NORMAL


def test_a_slow_receiver_is_late_after_its_own_intervals_not_the_fixed_timeout():
    """A 1 Hz receiver (a telemetry link): 1.2 s without a fix is no outage (1.5 of its
    intervals), 1.6 s is; a 10 Hz receiver keeps the configured 1 s."""
    mon = OutageMonitor()
    for t in range(6):  # fixes at 0..5 s, 1 s apart
        assert mon.assess(fix(float(t))).usable
        mon.gate_result(float(t), True)
    assert mon.timeout_s == pytest.approx(1.5)
    assert mon.tick(6.2) == []
    assert codes(mon.tick(6.6)) == [AlertCode.GNSS_LOST]
    fast = OutageMonitor()
    start(fast)
    assert fast.timeout_s == pytest.approx(1.0)
    assert codes(fast.tick(2.95)) == [AlertCode.GNSS_LOST]
    fast.reset()
    assert fast.timeout_s == pytest.approx(1.0)


def test_rejected_fixes_while_reacquiring_lead_to_reinitialisation():
    cfg = OutageConfig(reacquire_max_rejects=4)
    mon = OutageMonitor(cfg)
    start(mon)
    mon.tick(4.0)
    mon.gate_result(6.0, True)  # one gated fix: REACQUIRING
    for k in range(4):
        mon.gate_result(6.1 + k / 10, False)
    verdict = mon.assess(fix(6.6))
    assert verdict.reinitialise and not verdict.gate
    # one alert for the change: the GNSS_BACK that ends the outage says re-initialised
    assert AlertCode.FAULT not in codes(verdict.alerts) and mon.resets == 1
    back = mon.reinitialised(6.6)
    assert codes(back) == [AlertCode.GNSS_BACK] and "re-initialised" in back[0].text


def test_downgrade_rtk_lost_once_and_degraded_mode():
    mon = OutageMonitor()
    start(mon)
    v = mon.assess(fix(2.0, fix_type=FixType.RTK_FLOAT, h_acc_m=0.3))
    assert codes(v.alerts) == []  # float is still RTK
    v = mon.assess(fix(2.1, fix_type=FixType.FIX_3D, h_acc_m=2.0))
    assert codes(v.alerts) == [AlertCode.RTK_LOST]
    mon.gate_result(2.1, True)
    assert mon.mode is NavMode.DEGRADED
    v = mon.assess(fix(2.2, fix_type=FixType.FIX_3D, h_acc_m=2.0))
    assert codes(v.alerts) == []


def test_rtk_back_follows_each_rtk_lost_once():
    """A receiver that announced RTK_LOST says RTK_BACK (with the outage's length) on its
    first RTK fix again, once; float counts as RTK; a receiver reaching RTK for the first
    time, or still without it, says nothing."""
    mon = OutageMonitor()
    # converging: 3D, then RTK for the first time is no return
    for k in range(10):
        v = mon.assess(fix(k / 10, fix_type=FixType.FIX_3D, h_acc_m=1.0))
        assert codes(v.alerts) == []
        mon.gate_result(k / 10, True)
    assert codes(mon.assess(fix(1.0)).alerts) == []
    mon.gate_result(1.0, True)
    assert codes(mon.assess(fix(1.1, fix_type=FixType.DGPS)).alerts) == [AlertCode.RTK_LOST]
    for k in range(2, 30):  # the outage: nothing more
        assert codes(mon.assess(fix(1.0 + k / 10, fix_type=FixType.FIX_3D)).alerts) == []
    back = mon.assess(fix(4.1, fix_type=FixType.RTK_FLOAT, h_acc_m=0.3)).alerts
    assert codes(back) == [AlertCode.RTK_BACK]
    assert back[0].severity is Severity.NOTICE
    assert back[0].text == "rx0 -> RTK_FLOAT after 3.0 s"
    assert codes(mon.assess(fix(4.2)).alerts) == []  # float -> fixed: still RTK
    # a second outage, ended by fresh corrections: its own pair
    old = replace(fix(5.0), dgps_age_s=12.0)
    assert codes(mon.assess(old).alerts) == [AlertCode.RTK_LOST]
    fresh = replace(fix(6.5), dgps_age_s=1.0)
    back = mon.assess(fresh).alerts
    assert codes(back) == [AlertCode.RTK_BACK]
    assert back[0].text == "rx0 -> RTK_FIXED after 1.5 s"


def test_rtk_back_is_per_receiver_and_forgotten_on_reset():
    mon = OutageMonitor()
    start(mon)
    mon.assess(fix(2.0, receiver_id=1))
    assert codes(mon.assess(fix(2.1, fix_type=FixType.FIX_3D, receiver_id=1)).alerts) == [
        AlertCode.RTK_LOST
    ]
    # receiver 0 stayed RTK: its fixes say nothing; receiver 1's return is its own
    assert codes(mon.assess(fix(2.2)).alerts) == []
    back = mon.assess(fix(2.3, receiver_id=1)).alerts
    assert [(a.code, a.text) for a in back] == [
        (AlertCode.RTK_BACK, "rx1 -> RTK_FIXED after 0.2 s")
    ]
    # an outage cut by an autopilot reboot: the new boot's first RTK fix is no return
    mon.assess(fix(3.0, fix_type=FixType.FIX_3D))
    mon.reset()
    start(mon)
    assert all(a.code is not AlertCode.RTK_BACK for a in mon.assess(fix(2.5)).alerts)


def test_old_corrections_count_as_rtk_lost():
    mon = OutageMonitor(OutageConfig(rtk_max_age_s=5.0))
    start(mon)
    old = replace(fix(2.0), dgps_age_s=8.0)
    assert codes(mon.assess(old).alerts) == [AlertCode.RTK_LOST]


def test_accuracy_jump_is_degraded():
    mon = OutageMonitor()
    start(mon)
    mon.assess(fix(2.0, h_acc_m=0.5))
    mon.gate_result(2.0, True)
    assert mon.mode is NavMode.DEGRADED


def test_no_fix_is_unusable():
    mon = OutageMonitor()
    start(mon)
    v = mon.assess(fix(2.0, fix_type=FixType.NO_FIX))
    assert not v.usable and v.reason == "fix_type_1"


def test_repeated_positions_when_parked_are_not_stale():
    mon = OutageMonitor()
    parked = fix_at(0.0, np.zeros(3), np.zeros(3))
    for k in range(50):
        v = mon.assess(replace(parked, t_s=k / 10))
        assert v.usable
        mon.gate_result(k / 10, True)


def test_frozen_but_jittering_fix_is_stale_within_the_window():
    mon = OutageMonitor()
    start(mon)
    rng = np.random.default_rng(1)
    frozen_at = LINE.pos_ned_m(2.0, 0.0)
    flagged_at = None
    for k in range(30):
        t = 2.0 + k / 10
        jitter = np.array([*rng.normal(0.0, 0.05, 2), 0.0])
        v = mon.assess(fix_at(t, frozen_at + jitter, np.array(LINE.vel_ned_mps)))
        if not v.usable:
            flagged_at = t
            assert AlertCode.GNSS_STALE in codes(v.alerts)
            break
        mon.gate_result(t, True)
    assert flagged_at is not None and flagged_at - 2.0 <= 2.0


def test_long_bridge_is_lost():
    mon = OutageMonitor(OutageConfig(max_bridge_s=30.0))
    start(mon)
    mon.tick(5.0)
    alerts = mon.tick(40.0)
    assert AlertCode.INTEGRITY in codes(alerts)
    assert mon.mode is NavMode.LOST


@pytest.mark.parametrize(
    "bad",
    [
        {"gnss_timeout_s": 0.0},
        {"stale_motion_ratio": 1.5},
        {"min_fix_type": 9},
        {"reacquire_fixes": 0},
        {"accuracy_jump_ratio": 1.0},
    ],
)
def test_config_validation_names_the_field(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        OutageConfig(**bad)


# ---------------------------------------------------------------- bounded rejection


def rx_fix(t, offset=(0.0, 0.0, 0.0), receiver_id=0):
    """A 3D fix on the line, 10 satellites, HDOP 1.2, h_acc 2 m (5 Hz in the tests below)."""
    f = fix_at(
        t,
        LINE.pos_ned_m(t, 0.0) + np.array(offset),
        np.array(LINE.vel_ned_mps),
        fix_type=FixType.FIX_3D,
        h_acc_m=2.0,
        receiver_id=receiver_id,
    )
    return replace(f, satellites=10, hdop=1.2)


def used_until(mon, t_end, **kw):
    """Fixes every 0.2 s up to ``t_end``, each used by the navigator."""
    for k in range(int(round(t_end / 0.2)) + 1):
        f = rx_fix(k * 0.2, **kw)
        v = mon.assess(f)
        assert v.usable and not v.reinitialise
        mon.gate_result(f.t_s, True)
        mon.used(f)
    return (k + 1) * 0.2


def test_a_healthy_receiver_against_a_drifting_prediction_resets_the_navigator():
    """The gate rejects a receiver that moved from its last used fix exactly as its own
    velocity says: the prediction is what is off. After reset_after_rejected_fixes the
    next fix re-initialises the navigator, with one FAULT alert saying so."""
    mon = OutageMonitor()
    t = used_until(mon, 4.0)
    verdicts = []
    for k in range(4):
        f = rx_fix(t + k * 0.2)
        v = mon.assess(f)
        verdicts.append(v)
        if v.reinitialise:
            break
        mon.rejected(f)
        mon.gate_result(f.t_s, False)
    assert [v.reinitialise for v in verdicts] == [False, False, True]
    assert codes(verdicts[-1].alerts) == [AlertCode.FAULT]
    assert "navigator reset to it" in verdicts[-1].alerts[0].text
    assert mon.resets == 1


def test_a_frozen_receiver_is_stale_by_its_own_velocity_and_never_reset_to():
    """Same co-ordinates while its velocity says 31.6 m/s: stale at the second repeat,
    whatever the navigator predicts, and never a reset however long it lasts."""
    mon = OutageMonitor()
    t = used_until(mon, 4.0)
    frozen = rx_fix(t - 0.2)
    verdicts = [mon.assess(replace(frozen, t_s=t + k * 0.2)) for k in range(50)]
    assert not any(v.usable for v in verdicts)
    assert codes(verdicts[0].alerts) == [AlertCode.GNSS_STALE]
    assert sum(AlertCode.GNSS_STALE in codes(v.alerts) for v in verdicts) == 1
    assert not any(v.reinitialise for v in verdicts)


def test_the_same_fix_twice_is_a_repeat_without_an_alert():
    mon = OutageMonitor()
    t = used_until(mon, 2.0)
    again = mon.assess(rx_fix(t - 0.2))
    assert not again.usable and again.reason == "repeated" and again.alerts == ()


def test_after_a_glitch_the_reset_waits_for_the_bounded_rejection_time():
    """A 30 m step breaks the receiver's chain: its innovation may be right. The reset
    comes only after reset_after_rejection_s with the receiver consistent since the step
    (ArduPilot EKF3's glitch handling: gate, then after a timeout reset to GNSS)."""
    cfg = OutageConfig()
    mon = OutageMonitor(cfg)
    t0 = used_until(mon, 4.0)
    reset_at = None
    for k in range(40):
        f = rx_fix(t0 + k * 0.2, offset=(30.0, 0.0, 0.0))
        v = mon.assess(f)
        if v.reinitialise:
            reset_at = f.t_s
            break
        mon.rejected(f)
    assert reset_at is not None
    assert reset_at - t0 >= cfg.reset_after_rejection_s
    assert reset_at - t0 <= cfg.reset_after_rejection_s + 0.5


def test_a_receiver_contradicted_by_a_second_receiver_is_never_reset_to():
    """A 30 m step on receiver 0 while receiver 1 (consistent) stays on the line."""
    mon = OutageMonitor()
    for k in range(21):
        for rid in (0, 1):
            f = rx_fix(k * 0.2, receiver_id=rid)
            mon.assess(f)
            mon.gate_result(f.t_s, True)
            mon.used(f)
    for k in range(1, 60):
        t = 4.0 + k * 0.2
        mon.assess(rx_fix(t, receiver_id=1))
        f = rx_fix(t, offset=(30.0, 0.0, 0.0))
        v = mon.assess(f)
        assert not v.reinitialise, t
        mon.rejected(f)


def test_independent_evidence_stops_the_rejection_clock():
    mon = OutageMonitor()
    t = used_until(mon, 4.0)
    for k in range(30):
        f = rx_fix(t + k * 0.2)
        assert not mon.assess(f, shown_wrong=True).reinitialise
        mon.rejected(f)
    mon.rejection_explained(0)
    assert mon.rejected_for_s(0, t + 6.0) == 0.0


def test_reset_alerts_are_rate_limited_and_counted():
    """A reset every 0.6 s for 8 s: one alert per 5 s interval, the next one counting the
    resets in between."""
    mon = OutageMonitor(OutageConfig(reset_alert_interval_s=5.0))
    t = used_until(mon, 4.0)
    alerts = []
    while t < 12.0:
        f = rx_fix(t)
        t += 0.2
        v = mon.assess(f)
        if v.reinitialise:
            alerts += v.alerts
            mon.reinitialised(f.t_s)
            mon.used(f)
        else:
            mon.rejected(f)
    assert mon.resets >= 10
    assert len(alerts) == 2
    assert alerts[1].t_s - alerts[0].t_s >= 5.0
    assert "more since the last alert" in alerts[1].text


def test_a_jittery_telemetry_receiver_is_slow_once_and_timed_by_its_longest_lateness():
    """A ~1 Hz receiver through a telemetry link (intervals 0.6, 0.8, 1.0, 1.4 s in turn,
    each fix arriving 0.3 s after its time): slow, said once (GNSS_SLOW), and late only
    past 1.5 x its longest recent lateness (1.4 + 0.3 s): no loss per long interval; one
    gated fix ends its outage."""
    mon = OutageMonitor()
    t = 0.0
    raised = []
    for k in range(21):  # 20 intervals, five of each
        t += (0.6, 0.8, 1.0, 1.4)[k % 4]
        v = mon.assess(fix(t), now_s=t + 0.3)
        assert v.usable
        raised += v.alerts
        raised += mon.gate_result(t, True)
        raised += mon.tick(t + 0.3)
    assert codes(raised) == [AlertCode.GNSS_SLOW]
    assert mon.rhythm.slow
    assert mon.timeout_s == pytest.approx(1.5 * (1.4 + 0.3))
    assert mon.tick(t + 2.5) == []  # not due yet
    lost = mon.tick(t + 2.6)
    assert codes(lost) == [AlertCode.GNSS_LOST]
    t += 3.0
    mon.assess(fix(t), now_s=t + 0.3)
    back = mon.gate_result(t, True)
    assert codes(back) == [AlertCode.GNSS_BACK] and mon.mode is NavMode.NORMAL

"""The autopilot link's HEARTBEAT watch: when it warns, what it says, when it stops."""

from __future__ import annotations

import pytest

from companion.mavlink.watch import HeartbeatWatch


def test_nothing_before_the_link_opens_then_a_warning_at_the_timeout_and_every_repeat():
    watch = HeartbeatWatch("master udpin:127.0.0.1:14550", timeout_s=5.0, repeat_s=30.0)
    assert watch.check(1000.0) is None and watch.next_due_s() == float("inf")
    watch.start(100.0)
    watch.start(101.0)  # a re-open keeps the window
    watch.received(4000, frames=0, bad_frames=7, bad_bytes=3990)
    assert watch.next_due_s() == 105.0
    assert watch.check(104.9) is None
    line = watch.check(105.0)
    assert line == (
        "no autopilot heartbeat on master udpin:127.0.0.1:14550 after 5 s: 4000 bytes, "
        "0 good frames, 7 bad (3990 bytes not MAVLink): wrong baud rate or not MAVLink?"
    )
    assert watch.check(106.0) is None  # once, then every repeat_s
    watch.received(1000, bad_frames=1, bad_bytes=1000)  # still counted
    again = watch.check(135.0)
    assert again is not None and "after 35 s: 5000 bytes" in again
    assert watch.next_due_s() == 165.0 and watch.warnings == 2


def test_a_heartbeat_ends_the_silence_and_a_later_one_is_reported_again():
    watch = HeartbeatWatch("master tcp:127.0.0.1:5760", timeout_s=5.0, repeat_s=30.0)
    watch.start(0.0)
    assert watch.check(5.0) is not None
    assert watch.heartbeat(12.0) == "autopilot heartbeat on master tcp:127.0.0.1:5760 after 12 s"
    assert watch.check(16.9) is None
    assert watch.heartbeat(13.0) is None  # no warning pending: nothing to say
    watch.received(800, frames=20)
    lost = watch.check(18.0)
    assert lost == (
        "no autopilot heartbeat on master tcp:127.0.0.1:5760 for 5 s: 800 bytes, "
        "20 good frames, 0 bad (0 bytes not MAVLink): MAVLink, but no autopilot "
        "(wrong port or system id?)"
    )


def test_a_silent_link_says_nothing_arrived():
    watch = HeartbeatWatch("master /dev/ttyAMA0", timeout_s=2.0, repeat_s=10.0)
    watch.start(0.0)
    line = watch.check(2.5)
    assert line is not None and line.endswith(
        "nothing received (wiring, or the autopilot does not send here?)"
    )


def test_bad_periods_are_refused():
    with pytest.raises(ValueError):
        HeartbeatWatch("x", 0.0, 1.0)

"""The real events of a log and how the texts said them (``bench/realdata.py``'s count),
on logs built so that the answer is known by hand."""

from __future__ import annotations

from pathlib import Path

import pytest

from companion.evaluate.events_said import EventsSaid, events_said
from companion.types import AlertCode
from tests.test_evaluate_against_input import Logs, base, ticks


def said_of(logs: Logs, folder: Path) -> EventsSaid:
    in_path, out_path = logs.write(folder)
    return events_said(out_path, in_path)


def flight(logs: Logs) -> None:
    """IMU 50 Hz and fixes 5 Hz from 8 s to 40 s (none before: no GNSS at start); every
    stream silent from 10 to 15 s (a dropout); fixes missing from 25 to 30 s, the IMU
    running (a GNSS gap)."""
    base(logs, 40.0, skip=(10.0, 15.0))
    for t in ticks(8.0, 40.0, 5.0):
        if not (10.0 < t < 15.0 or 25.0 < t < 30.0):
            logs.fix(t, 5.0 * t, 0.0, 5.0, 0.0)


def test_each_event_found_in_the_timestamps_and_its_start_and_end_said(tmp_path: Path) -> None:
    logs = Logs()
    flight(logs)
    logs.alert(3.0, AlertCode.NO_GNSS, "no usable fix for 3 s: not navigating")
    logs.alert(8.2, AlertCode.GNSS_BACK, "first fix after 8.2 s: navigating")
    logs.alert(11.0, AlertCode.NO_DATA, "no IMU, attitude, GNSS for 1.0 s")
    logs.alert(15.0, AlertCode.DATA_BACK, "after 5.0 s: restart from next fix")
    logs.alert(26.0, AlertCode.GNSS_LOST, "no GNSS messages 1.0 s: bridging")
    logs.alert(30.6, AlertCode.GNSS_BACK, "after 5.6 s")
    res = said_of(logs, tmp_path)
    kinds = [(e.kind, e.start_s, e.end_s) for e in res.events]
    assert kinds == [
        ("no gnss", 0.0, pytest.approx(8.0)),
        ("dropout", pytest.approx(10.0), pytest.approx(15.0)),
        ("gnss gap", pytest.approx(25.0), pytest.approx(30.0)),
    ]
    assert [(e.start_said_by, e.end_said_by) for e in res.events] == [
        ("NO_GNSS", "GNSS_BACK"),
        ("NO_DATA", "DATA_BACK"),
        ("GNSS_LOST", "GNSS_BACK"),
    ]
    assert res.events[1].start_latency_s == pytest.approx(1.0)
    assert (res.n_start_said, res.n_end_said, res.n_closed) == (3, 3, 3)
    assert res.cell() == "3/3 start, 3/3 end"
    # six texts in 40 s of log: a log shorter than a minute is its own minute
    assert res.texts == 6 and res.per_minute == pytest.approx(6.0)
    assert res.max_in_window == 6


def test_an_unsaid_start_a_late_return_and_a_loss_already_said(tmp_path: Path) -> None:
    """The dropout said by nothing, the GNSS gap said by a loss in force before it (no
    return since) and ended by a return later than the allowed 1.5 s: one start said by
    'already', no end said."""
    logs = Logs()
    flight(logs)
    logs.alert(24.0, AlertCode.GNSS_LOST, "no usable fix 1.0 s: bridging")
    logs.alert(32.0, AlertCode.GNSS_BACK, "after 8.0 s")
    res = said_of(logs, tmp_path)
    said = {e.kind: (e.start_said_by, e.start_latency_s, e.end_said_by) for e in res.events}
    assert said == {
        "no gnss": (None, None, None),
        "dropout": (None, None, None),
        "gnss gap": ("already", 0.0, None),
    }
    assert res.cell() == "1/3 start, 0/3 end"


def test_a_gnss_gap_inside_a_dropout_is_one_event(tmp_path: Path) -> None:
    """Fixes missing from 10 to 18 s, every other stream from 10 to 15 s: one event, the
    dropout, spanning both (its return is said once the fixes are back)."""
    logs = Logs()
    base(logs, 30.0, skip=(10.0, 15.0))
    for t in ticks(0.0, 30.0, 5.0):
        if not 10.0 < t < 18.0:
            logs.fix(t, 5.0 * t, 0.0, 5.0, 0.0)
    logs.alert(11.0, AlertCode.NO_DATA, "no IMU, attitude, GNSS for 1.0 s")
    logs.alert(15.0, AlertCode.DATA_BACK, "after 5.0 s: restart from next fix")
    res = said_of(logs, tmp_path)
    (event,) = res.events
    assert (event.kind, event.start_s, event.end_s) == (
        "dropout",
        pytest.approx(10.0),
        pytest.approx(18.0),
    )
    assert (event.start_said_by, event.end_said_by) == ("NO_DATA", "DATA_BACK")

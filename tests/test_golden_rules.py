"""The comparison rules of tests/golden on made-up records: what passes, what does not,
and what a failure says (the replays themselves: tests/test_replay_golden.py)."""

from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np
import pytest

from tests.golden import rules
from tests.golden.compare import compare, compare_events, failures, report
from tests.golden.flights import compare_truth
from tests.golden.record import T_RX, ReplayRecord, load, save

N = 50
PERIOD_US = 100_000


def _record() -> ReplayRecord:
    """A flight of 5 s at 10 Hz: GPS_INPUT and GLOBAL_POSITION_INT, two alerts."""
    t = np.arange(N, dtype=np.int64) * PERIOD_US
    lat = 521650369 + np.arange(N, dtype=np.int64) * 300
    fix = {
        T_RX: t,
        "time_usec": 10_000_000 + t,
        "fix_type": np.full(N, 6),
        "ignore_flags": np.zeros(N, dtype=np.int64),
        "lat": lat,
        "lon": np.full(N, 209669998),
        "alt": np.linspace(300.0, 290.0, N).astype(np.float32).astype(np.float64),
        "vn": np.full(N, 32.91024398803711),
        "horiz_accuracy": np.full(N, 0.5),
        "vert_accuracy": np.full(N, 1.0),
        "speed_accuracy": np.full(N, 0.1),
    }
    gpi = {T_RX: t, "lat": lat.copy(), "hdg": np.full(N, 35999), "vx": np.full(N, 3291)}
    meta = {
        "texts": [[1.0, 5, "CMP CAT none -> CAT III"], [3.0, 4, "CMP FAULT chi2 35.9 > 35.4"]],
        "heartbeats": [[0.0, {"system_status": 3}]],
        "records": 3 * N,
        "messages": {"GPS_INPUT": N, "GLOBAL_POSITION_INT": N},
        "summary": {"alerts": {"CAT": 1, "FAULT": 1}, "log_duration_s": 5.0},
        "evaluation": {"overall": {"n": 50, "h_rms_m": 0.03, "h95_coverage": 0.94}},
    }
    return ReplayRecord(meta=meta, series={"GPS_INPUT": fix, "GLOBAL_POSITION_INT": gpi})


def _changed(**edits) -> ReplayRecord:
    new = copy.deepcopy(_record())
    for where, change in edits.items():
        key, field = where.split("__")
        col = new.series[key][field]
        new.series[key][field] = change(col.copy())
    return new


def _beyond(new: ReplayRecord) -> list[str]:
    return [d.where for d in failures(compare(_record(), new))]


def test_a_record_agrees_with_itself_and_reads_back_from_its_files(tmp_path: Path) -> None:
    assert compare(_record(), _record()) == []
    save(_record(), tmp_path, "case")
    back = load(tmp_path, "case")
    assert back is not None and compare(_record(), back) == []
    assert load(tmp_path, "other") is None


def test_a_position_may_flip_by_one_unit_not_two_unless_its_sigma_allows() -> None:
    def bump(units: int, i: int = 7):
        return lambda c: np.where(np.arange(N) == i, c + units, c)

    assert _beyond(_changed(GPS_INPUT__lat=bump(1))) == []
    assert _beyond(_changed(GPS_INPUT__lat=bump(2))) == ["GPS_INPUT.lat"]
    # 1 % of a 0.5 m sigma is 0.45 units of latitude: still one unit; of 50 m, 45 units
    wide = _changed(GPS_INPUT__lat=bump(40))
    wide.series["GPS_INPUT"]["horiz_accuracy"] = np.full(N, 50.0)
    ref = _record()
    ref.series["GPS_INPUT"]["horiz_accuracy"] = np.full(N, 50.0)
    assert failures(compare(ref, wide)) == []


def test_accuracies_agree_to_a_relative_1e5() -> None:
    assert _beyond(_changed(GPS_INPUT__horiz_accuracy=lambda c: c * (1 + 0.5e-5))) == []
    moved = _changed(GPS_INPUT__horiz_accuracy=lambda c: c * 1.001)
    assert _beyond(moved) == ["GPS_INPUT.horiz_accuracy"]


def test_velocity_altitude_heading_and_fix_type() -> None:
    assert _beyond(_changed(GPS_INPUT__vn=lambda c: c + 0.009)) == []
    assert _beyond(_changed(GPS_INPUT__vn=lambda c: c + 0.02)) == ["GPS_INPUT.vn"]
    # 1 % of the 1 m vertical sigma: 1 cm
    assert _beyond(_changed(GPS_INPUT__alt=lambda c: c + 0.009)) == []
    assert _beyond(_changed(GPS_INPUT__alt=lambda c: c + 0.02)) == ["GPS_INPUT.alt"]
    # across north: 359.99 deg and 0.00 deg are one unit apart; unknown is not a heading
    assert _beyond(_changed(GLOBAL_POSITION_INT__hdg=lambda c: c * 0)) == []
    assert _beyond(_changed(GLOBAL_POSITION_INT__hdg=lambda c: c * 0 + 65535)) == [
        "GLOBAL_POSITION_INT.hdg"
    ]
    assert _beyond(_changed(GPS_INPUT__fix_type=lambda c: c - 1)) == ["GPS_INPUT.fix_type"]


def test_a_missing_message_or_alert_fails_and_says_where() -> None:
    short = _record()
    short.series["GPS_INPUT"] = {k: v[:-1] for k, v in short.series["GPS_INPUT"].items()}
    assert _beyond(short) == ["GPS_INPUT"]
    no_alert = _record()
    no_alert.meta["texts"] = no_alert.meta["texts"][:1]
    differences = compare(_record(), no_alert)
    assert [d.where for d in failures(differences)] == ["STATUSTEXT"]
    assert "2 vs 1 of them" in report("case", differences)


def test_an_alert_within_two_samples_and_a_last_digit_agree_three_samples_do_not() -> None:
    ref = _record().meta["texts"]
    late = [
        [t + 0.2 * (i == 1), sev, text.replace("35.9", "36.0")]
        for i, (t, sev, text) in enumerate(ref)
    ]
    later = [[t + 0.3 * (i == 1), sev, text] for i, (t, sev, text) in enumerate(ref)]
    other = [[t, sev, text.replace("FAULT", "INTEGRITY")] for t, sev, text in ref]
    assert failures(compare_events("STATUSTEXT", ref, late, 0.2 * (1 + 1e-9), _same)) == []
    assert failures(compare_events("STATUSTEXT", ref, later, 0.2 * (1 + 1e-9), _same))
    assert failures(compare_events("STATUSTEXT", ref, other, 0.2 * (1 + 1e-9), _same))


def _same(a, b):
    return rules.texts_agree(a[1], b[1]) if a[0] == b[0] else (False, math.inf)


def test_counts_are_exact_and_evaluation_figures_have_their_tolerance() -> None:
    new = _record()
    new.meta["summary"]["alerts"]["FAULT"] = 2
    new.meta["evaluation"]["overall"]["h95_coverage"] = 0.94 + 1.5 / 50
    assert [d.where for d in failures(compare(_record(), new))] == ["summary.alerts.FAULT"]
    new.meta["evaluation"]["overall"]["h_rms_m"] = 0.031
    assert "evaluation.overall.h_rms_m" in [d.where for d in failures(compare(_record(), new))]


def test_a_failure_names_case_field_time_and_values() -> None:
    text = report("case/x", compare(_record(), _changed(GPS_INPUT__lat=lambda c: c + 5)))
    assert "case/x" in text and "GPS_INPUT.lat at +0.000 s: 521650369 vs 521650374" in text
    assert "5 x tolerance, 50 of 50 beyond" in text


@pytest.mark.parametrize(
    ("ref", "new", "ok"),
    [
        ("20.9805192585", "20.9805192586", True),
        ("-0.00001", "0.00000", True),
        ("1.5", "1.50", False),
        ("3", "5", False),
        ("rtk_fixed", "rtk_float", False),
    ],
)
def test_numbers_in_texts_agree_to_their_last_digit(ref: str, new: str, ok: bool) -> None:
    assert rules.texts_agree(ref, new)[0] is ok


def test_truth_rows_compared_column_by_column() -> None:
    header = "t_s,lat_deg,phase"
    ref = [header, "10.000000,52.1650369000,taxi", "10.100000,52.1650370000,taxi"]
    flip = [header, "10.000000,52.1650369001,taxi", ref[2]]
    moved = [header, "10.000000,52.1650369002,taxi", ref[2]]
    assert failures(compare_truth(ref, flip)) == []
    assert [d.where for d in failures(compare_truth(ref, moved))] == ["truth.lat_deg"]
    assert failures(compare_truth(ref, ref[:2]))

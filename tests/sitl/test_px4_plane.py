"""PX4 SIH airplane (airframe 10041) with the service on the onboard link.

One flight of :mod:`tests.sitl.px4_runner` (``gnss_cut --airframe 10041``): runway take-off,
cruise in Hold (PX4's loiter circle) with a healthy GNSS, a 20 s GNSS cut in the circle
(MAV_CMD_INJECT_FAILURE), GNSS back. PX4 fuses the service's aux global position
(``EKF2_AGP0_ID`` read by the service, ``EKF2_AGP0_CTRL = 1``), as the quadrotor's test
sets it up. Scored against SIH's truth (HIL_STATE_QUATERNION) on PX4's clock.

PX4's own error over the cut with the fusion and without it (two flights each) is
printed by ``python bench/sitl_px4.py --airframe 10041`` (docs/sitl.md, PX4 SIH airplane).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.sitl.harness import run_scenario
from tests.sitl.locate import skip_unless
from tests.sitl.px4_runner import AGP_ID, PLANE_TAKEOFF_ALT_M

pytestmark = [pytest.mark.sitl, skip_unless("px4/run-sih.sh", "px4/bin/px4")]

RUNNER = "tests.sitl.px4_runner"
CUT_S = 20.0
CLIMB_S = 25.0
CRUISE_S = 30.0
BAD_IN_CRUISE = ("GNSS_STALE", "GNSS_LOST", "FAULT")
BAD_IN_CUT = ("GNSS_BACK", "GNSS_LOST", "FAULT")
ALERT_DELAY_MAX_S = 1.5
PX4_FUSED_CRUISE_MAX_M = 0.15


@pytest.fixture(scope="module")
def flight(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    tmp = tmp_path_factory.mktemp("sitl_px4_plane")
    args = [
        "gnss_cut",
        "--airframe",
        "10041",
        "--fusion",
        "1",
        "--climb-s",
        f"{CLIMB_S:g}",
        "--hover-s",
        f"{CRUISE_S:g}",
        "--pre-window-s",
        f"{CRUISE_S:g}",
        "--cut-s",
        f"{CUT_S:g}",
        "--after-s",
        "8",
    ]
    return run_scenario(RUNNER, args, Path(tmp) / "px4_plane.json", timeout_s=400.0)


def _alerts(run: dict[str, Any], codes: tuple[str, ...], t0: float, t1: float) -> list[Any]:
    return [
        (t, text)
        for t, text in run["service_alerts"]
        if t0 <= t < t1 and any(text.startswith(f"CMP {c}") for c in codes)
    ]


def _first(run: dict[str, Any], code: str, t0: float) -> float:
    times = [t for t, text in run["service_alerts"] if t >= t0 and text.startswith(f"CMP {code}")]
    return min(times) - t0 if times else float("inf")


def test_the_plane_flies_the_circle(flight: dict[str, Any]) -> None:
    assert flight["truth_climb_m"] > 0.75 * PLANE_TAKEOFF_ALT_M, flight["truth_climb_m"]
    in_cut = [
        v for t, v in flight["truth_speed_mps"] if flight["t_cut_s"] <= t < flight["t_back_s"]
    ]
    assert in_cut and min(in_cut) > 4.0, in_cut  # flying, not rolling on the runway


def test_healthy_cruise(flight: dict[str, Any]) -> None:
    """No GNSS_STALE, GNSS_LOST or FAULT from take-off to the cut, and the service's
    horizontal error over the cruise no larger than PX4's own (same flight, PX4 fusing
    the service; against PX4 alone the service's 3-5 cm mean was below its 6 cm in the
    bench's flights, too close to assert in one)."""
    bad = _alerts(flight, BAD_IN_CRUISE, flight["t_takeoff_s"], flight["t_cut_s"])
    assert not bad, bad
    svc, px4 = flight["service_pre"], flight["px4_pre"]
    assert svc["n"] > 100 and px4["n"] > 100
    assert svc["mean_m"] <= px4["mean_m"], (svc, px4)


def test_gnss_cut_alerts(flight: dict[str, Any]) -> None:
    """GNSS_LOST within 1.5 s of the cut, GNSS_BACK within 1.5 s of GNSS returning, and no
    GNSS_BACK, GNSS_LOST or FAULT in between."""
    t_cut, t_back = flight["t_cut_s"], flight["t_back_s"]
    lost = _first(flight, "GNSS_LOST", t_cut)
    assert lost <= ALERT_DELAY_MAX_S, flight["service_alerts"]
    back = _first(flight, "GNSS_BACK", t_back)
    assert back <= ALERT_DELAY_MAX_S, flight["service_alerts"]
    between = _alerts(flight, BAD_IN_CUT, t_cut + lost + 1e-3, t_back)
    assert not between, between


def test_published_accuracy_covers_the_error_through_the_cut(flight: dict[str, Any]) -> None:
    assert flight["service_cover_n_cut"] > 100
    assert flight["service_cover_95_cut"] >= 0.95, flight["service_worst_ratio"]
    assert flight["service_cover_95"] >= 0.95


def test_px4_fuses_the_service_and_gets_nothing_from_the_gap(flight: dict[str, Any]) -> None:
    assert flight["service_ids"] == [AGP_ID]
    assert flight["service_sensor_before_cut"] > 50
    assert flight["service_sensor_in_cut"] == 0
    assert any(on for _, on in flight["px4_aux_fused"])


def test_px4_fusing_the_service_is_as_good_as_alone_in_cruise(flight: dict[str, Any]) -> None:
    """PX4 fusing the service, set up with ``EKF2_AGP0_DELAY`` = EKF2's fusion horizon,
    within PX4_FUSED_CRUISE_MAX_M of the truth on average over the cruise. Measured
    (60 s cruise, docs/sitl.md): 0.06 m alone; fused 0.07-0.08 m with the set-up, 0.74 m
    with the delay left at 0 (PX4 compares the aux position with its newest position),
    0.28 m with 100 ms."""
    px4 = flight["px4_pre"]
    assert px4["n"] > 100
    assert px4["mean_m"] <= PX4_FUSED_CRUISE_MAX_M, px4

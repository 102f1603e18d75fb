"""Repeated healthy cruises beside ArduPlane and ArduCopter SITL: the service raises nothing
against itself (flown before: "lag measured 83+/-5 ms", 0.2 s later ``FAULT rx0 excluded:
innovation chi2 196.6``, GNSS_LOST and a re-initialisation, in otherwise clean flights).

Each vehicle flies the same healthy flight three times (no GPS outage): the plane its
circuit for 300 s of cruise, long enough that the service measures the GNSS lag and
carries it in during the cruise; the copter its hover and circuit. From the service's
start to the end: no FAULT, GNSS_LOST or GNSS_STALE. ``GPS1_DELAY_MS`` is 100 ms against
the 83 ms this SITL stamps (docs/sitl.md): the service switches its own lag in flight,
the change the issue saw blamed on the receiver.
"""

from __future__ import annotations

from typing import Any

import pytest

from tests.sitl.harness import run_scenario
from tests.sitl.locate import skip_unless
from tests.sitl.test_ardupilot import PARAMS, RUNNER, SPEEDUP

pytestmark = [pytest.mark.sitl, skip_unless("arduplane", "arducopter")]

RUNS = 3
PLANE_CRUISE_S = 300.0
COPTER_CRUISE_S = 120.0
FLIGHTS = {
    "plane": ("--cruise-s", f"{PLANE_CRUISE_S:g}"),
    "copter": (
        "--vehicle",
        "copter",
        "--settle-s",
        "15",
        "--hover-s",
        "20",
        "--cruise-s",
        f"{COPTER_CRUISE_S:g}",
    ),
}
SELF_ALARMS = ("FAULT", "GNSS_LOST", "GNSS_STALE")


@pytest.fixture(
    scope="module",
    params=[(v, k) for v in FLIGHTS for k in range(RUNS)],
    ids=lambda p: f"{p[0]}{p[1]}",
)
def healthy(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> dict[str, Any]:
    vehicle, run = request.param
    args = [
        "flight",
        "--speedup",
        f"{SPEEDUP:g}",
        "--outage-s",
        "0",
        "--after-s",
        "0",
        "--params",
        PARAMS,
        *FLIGHTS[vehicle],
    ]
    out = tmp_path_factory.mktemp("sitl") / f"healthy_{vehicle}{run}.json"
    result = run_scenario(RUNNER, args, out, timeout_s=600.0)
    result["vehicle"] = vehicle
    return result


def _codes(result: dict[str, Any], *codes: str) -> list[tuple[float, str]]:
    return [(t, a) for t, a in result["all_alerts"] if a.split()[1] in codes]


def test_no_alarm_against_itself(healthy: dict[str, Any]) -> None:
    """From the service's start (before the take-off) to the end of the cruise."""
    assert _codes(healthy, *SELF_ALARMS) == [], healthy["companion_log_tail"][-2000:]
    svc = healthy["healthy"]["service"]
    cruise_s = PLANE_CRUISE_S if healthy["vehicle"] == "plane" else COPTER_CRUISE_S
    assert svc["n"] > 0.8 * 10 * cruise_s  # published at 10 Hz throughout


def test_the_lag_switched_in_a_plane_cruise_raises_nothing(healthy: dict[str, Any]) -> None:
    """In every plane flight the lag is measured in flight (the AP_CONFIG that says it
    disagrees with GPS1_DELAY_MS), at 78-88 ms, at least a minute before the cruise ends,
    and nothing is raised after it."""
    if healthy["vehicle"] != "plane":
        pytest.skip("the copter's short circuit need not measure the lag")
    said = _codes(healthy, "AP_CONFIG")
    assert said, healthy["companion_log_tail"][-2000:]
    t_lag, text = said[0]
    assert healthy["t_armed_s"] <= t_lag <= healthy["healthy"]["t1_s"] - 60.0
    lag_ms = float(text.split("lag ")[1].split("+/-")[0])
    assert 78.0 <= lag_ms <= 88.0, text
    assert not [a for a in _codes(healthy, *SELF_ALARMS) if a[0] >= t_lag]

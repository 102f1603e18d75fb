"""The committed fixtures in sitl_fixtures/ read back with pymavlink, right types and rates,
and are what the simulator flies today."""

from __future__ import annotations

import collections
import json
from pathlib import Path

import numpy as np
import pytest
from pymavlink import mavutil

from companion.sim import make_scenario
from tests.golden import flights
from tests.golden.compare import failures, report

FIXTURES = Path(__file__).resolve().parents[2] / "sitl_fixtures"
REQUIRED = (
    "taxi",
    "approach_rtk20",
    "approach_rtk40",
    "cruise_gnss_loss",
    "stale_fix",
    "ramp_fault",
    "dither_fault",
    "px4_rotorcraft",
    "nominal",
    "taxi_realistic",
    "approach_rtk20_realistic",
    "cruise_gnss_loss_realistic",
    "nominal_realistic",
    "copter_realistic",
    "copter_radio_realistic",
    "px4_rotorcraft_realistic",
)
REALISTIC = tuple(n for n in REQUIRED if n.endswith("_realistic"))


def test_required_fixtures_present_and_small() -> None:
    for name in REQUIRED:
        for ext in (".tlog", ".truth.csv", ".json"):
            assert (FIXTURES / f"{name}{ext}").is_file(), f"{name}{ext} missing"
    total = sum(p.stat().st_size for p in FIXTURES.iterdir() if p.is_file())
    assert total < 40e6
    assert (FIXTURES / "README.md").is_file()


@pytest.mark.parametrize("name", REQUIRED)
def test_fixture_is_current(name: str) -> None:
    """The sidecar's parameters are what make_scenario(name) gives today (else regenerate)."""
    side = json.loads((FIXTURES / f"{name}.json").read_text())
    assert side["parameters"] == json.loads(json.dumps(make_scenario(name).as_dict()))


@pytest.mark.slow
@pytest.mark.golden
@pytest.mark.parametrize("name", flights.COMPARED)
def test_fixture_is_what_the_simulator_flies(name: str, tmp_path: Path) -> None:
    """A fixture flown again (``companion simulate <name> --seed 1``) is the committed one:
    its tlog message by message, its truth CSV (formatting included) and its sidecar, at
    the tolerances of tests/golden/rules.py (another CPU's arithmetic moves the last bits;
    ``python -m tests.golden.flights`` lists what moved)."""
    flights.fly(name, tmp_path)
    differences = flights.compare_flight(FIXTURES, tmp_path, name)
    assert not failures(differences), report(name, differences)


@pytest.mark.slow
@pytest.mark.parametrize("name", [n for n in REQUIRED if n not in REALISTIC])
def test_fixture_reads_back(name: str) -> None:
    side = json.loads((FIXTURES / f"{name}.json").read_text())
    par = side["parameters"]
    conn = mavutil.mavlink_connection(str(FIXTURES / f"{name}.tlog"), dialect="ardupilotmega")
    counts: collections.Counter[str] = collections.Counter()
    imu_t: list[float] = []
    gps_t: list[float] = []
    while (m := conn.recv_match()) is not None:
        typ = m.get_type()
        counts[typ] += 1
        if typ == par["imu_message"]:
            imu_t.append(m.time_usec / 1e6 if hasattr(m, "time_usec") else m.time_boot_ms / 1e3)
        elif typ == "GPS_RAW_INT":
            gps_t.append(m.time_usec / 1e6)
    assert "BAD_DATA" not in counts
    assert dict(counts) == side["message_counts"]
    dur = side["duration_s"]
    assert counts[par["imu_message"]] == pytest.approx(par["imu_rate_hz"] * dur, abs=2)
    att = "ATTITUDE_QUATERNION" if par["flavour"] == "px4" else "ATTITUDE"
    assert counts[att] == pytest.approx(par["attitude_rate_hz"] * dur, abs=2)
    assert np.median(np.diff(imu_t)) == pytest.approx(1.0 / par["imu_rate_hz"], abs=1.1e-3)
    assert np.median(np.diff(gps_t)) == pytest.approx(1.0 / par["gnss_rate_hz"], abs=1e-6)
    assert counts["HEARTBEAT"] == pytest.approx(dur, abs=1)
    lines = (FIXTURES / f"{name}.truth.csv").read_text().splitlines()
    assert len(lines) - 1 == pytest.approx(par["truth_rate_hz"] * dur + 1, abs=1)

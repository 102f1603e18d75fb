"""``companion simulate --many``: varied flights, reproducible from the seed."""

from __future__ import annotations

import pytest

from companion.cli import main
from companion.mavlink.tlog import TlogReader
from companion.sim.fleet import FLEET_SCENARIOS, write_fleet


def test_many_flights_are_varied_and_reproducible(tmp_path):
    a = write_fleet(tmp_path / "a", 3, seed=4, duration_s=30.0)
    b = write_fleet(tmp_path / "b", 3, seed=4, duration_s=30.0)
    assert [p.name for p in a] == [f"{name}.tlog" for name in FLEET_SCENARIOS[:3]]
    assert [p.read_bytes() for p in a] == [p.read_bytes() for p in b]
    for p in a:
        assert p.with_name(p.stem + ".truth.csv").is_file()
        fixes = [m.time_usec for _t, m in TlogReader(p) if m.get_type() == "GPS_RAW_INT"]
        gap_s = max(t1 - t0 for t0, t1 in zip(fixes, fixes[1:], strict=False)) / 1e6
        assert gap_s >= 4.0  # the outage half-way through


def test_many_on_the_command_line(tmp_path, capsys):
    assert main(["simulate", "--many", "2", "--duration", "30", "--out", str(tmp_path)]) == 0
    assert "2 flights under" in capsys.readouterr().out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["flight_0000", "flight_0001"]


def test_many_refuses_nonsense(tmp_path):
    with pytest.raises(ValueError, match="at least 1"):
        write_fleet(tmp_path, 0)
    assert main(["simulate", "taxi", "--many", "2", "--out", str(tmp_path)]) == 1

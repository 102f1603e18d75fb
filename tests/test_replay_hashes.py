"""Every bundled flight replays byte-identical to the hashes recorded before the
package was restructured (``tests/golden/replay_hashes.py`` says how to record)."""

from __future__ import annotations

import json

import pytest

from tests.golden import replay_hashes as golden

RECORDED: dict[str, str] = json.loads(golden.HASHES.read_text())
CASES = golden.cases()


@pytest.mark.parametrize(("name", "tlog", "cfg"), CASES, ids=[c[0] for c in CASES])
def test_bundled_flight_replays_byte_identical(name, tlog, cfg):
    assert golden.replay_hash(tlog, cfg) == RECORDED[name]


def test_real_flights_replay_byte_identical():
    cases = golden.realdata_cases()
    if not cases:
        pytest.skip(f"the real flights are not beside this clone ({golden.REALDATA})")
    changed = [name for name, tlog, cfg in cases if golden.replay_hash(tlog, cfg) != RECORDED[name]]
    assert changed == []


def test_simulated_flights_unchanged():
    found = golden.other_hashes()
    assert found == {name: RECORDED[name] for name in found}

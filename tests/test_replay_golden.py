"""Every bundled flight replays to the outputs recorded in ``tests/golden/replays``, at the
tolerances of ``tests/golden/rules.py`` (not byte for byte: another CPU's arithmetic
library moves the last bits); a replay is byte for byte deterministic on the machine
that runs it; and the tolerance does not hide a deliberate change of an estimate.

Record again after a change of the outputs that is meant:
``python -m tests.golden.replays --record`` (docs/replay.md, "Golden outputs").
"""

from __future__ import annotations

import pytest

from tests.golden import cases as golden_cases
from tests.golden import replays as golden
from tests.golden.compare import compare, failures, report

pytestmark = pytest.mark.golden

CASES = golden_cases.cases()
REAL = golden_cases.realdata_cases()
DETERMINISM = (
    "taxi/combine",
    "px4_rotorcraft_realistic/default",
    "copter_radio_realistic/tactical",
)
"""Replayed twice: the potential filter's seeded optimiser and the heading correction, the
PX4 output, a radio link's bursts and a reboot."""
_OUTPUT: dict[str, bytes] = {}
"""The output tlogs of the cases of DETERMINISM replayed by the comparison below."""


def _check(name, tlog, cfg):
    ref = golden.recorded(name)
    assert ref is not None, f"{name}: nothing recorded (python -m tests.golden.replays --record)"
    new, out = golden.replay_case(name, tlog, cfg)
    if name in DETERMINISM:
        _OUTPUT[name] = out
    differences = compare(ref, new)
    hint = f"\nmeant? record again: python -m tests.golden.replays --record -k {name}"
    assert not failures(differences), report(name, differences) + hint


@pytest.mark.parametrize(("name", "tlog", "cfg"), CASES, ids=[c[0] for c in CASES])
def test_bundled_flight_replays_as_recorded(name, tlog, cfg):
    _check(name, tlog, cfg)


@pytest.mark.skipif(
    not REAL, reason=f"the real flights are not beside this clone ({golden_cases.REALDATA})"
)
@pytest.mark.parametrize(("name", "tlog", "cfg"), REAL, ids=[c[0] for c in REAL])
def test_real_flight_replays_as_recorded(name, tlog, cfg):
    _check(name, tlog, cfg)


@pytest.mark.parametrize("name", DETERMINISM)
def test_replay_is_deterministic_on_this_machine(name):
    _, tlog, cfg = next(c for c in CASES if c[0] == name)
    first = _OUTPUT.get(name) or golden.replay_case(name, tlog, cfg)[1]
    assert golden.replay_case(name, tlog, cfg)[1] == first


def test_a_noise_figure_ten_percent_off_fails_the_comparison():
    """The accelerometer's white noise (``blend.accel_vrw_mps_rts``) 10 % higher: the
    published accuracies and protection levels move beyond their tolerance, not only the
    evaluation's figures (positions and velocities stay within theirs). A gate's
    false-alarm probability 10 % higher (its chi-square threshold 0.5-1.2 % lower) moved
    no output of approach_rtk20 or ramp_fault: the noise figure is the change tested."""
    name, tlog, cfg = next(c for c in CASES if c[0] == "approach_rtk20/default")
    vrw = golden_cases.config_for(cfg).blend.accel_vrw_mps_rts
    new, _ = golden.replay_case(name, tlog, cfg, blend={"accel_vrw_mps_rts": 1.1 * vrw})
    ref = golden.recorded(name)
    assert ref is not None
    beyond = failures(compare(ref, new))
    moved = {d.where for d in beyond}
    expected = {
        "GPS_INPUT.speed_accuracy",
        "GPS_INPUT.vert_accuracy",
        "NAMED_VALUE_FLOAT:CMP_VPL.value",
    }
    assert expected <= moved, report(name, beyond)

"""The simulator's fault flights (a 4 cm/s ramp and a 1 m dither, after Kim, Walter and
Powell) and the nominal flight.

The monitor is driven with the flights' typed samples by
:func:`companion.sim.integrity_runs.run_samples` (pass-through navigator on the
primary receiver, every fix to the monitor), independently of the engine.
"""

from __future__ import annotations

import pytest

sim = pytest.importorskip("companion.sim")

from companion.integrity.monitor import IntegrityMonitor  # noqa: E402
from companion.sim.integrity_runs import run_samples  # noqa: E402


@pytest.mark.parametrize("name", ["ramp_fault", "dither_fault"])
def test_fault_flight_is_detected_and_alerted_before_1m(name: str) -> None:
    flight = sim.simulate(sim.make_scenario(name), seed=1)
    (event,) = [e for e in flight.events if e.kind in ("ramp", "dither")]
    res = run_samples(flight.samples, IntegrityMonitor())
    assert not [a for a in res.alarms if a[0] < event.t_start_s], res.alarms
    after = [a for a in res.alarms if a[0] >= event.t_start_s]
    assert after, "fault not alerted"
    t_alert, code, _text = after[0]
    assert code == "FAULT"
    codes = {a[1] for a in after}
    assert "INTEGRITY" in codes  # nothing arbitrates between the receivers: integrity lost
    dt = t_alert - event.t_start_s
    if name == "ramp_fault":
        rate = abs(event.params["rate_ned_mps"][2])
        assert rate * dt < 1.0  # caught before it reaches 1 m
    else:
        assert dt < 5.0


def test_nominal_flight_raises_no_fault_or_integrity_alert() -> None:
    flight = sim.simulate(sim.make_scenario("nominal"), seed=1)
    res = run_samples(flight.samples, IntegrityMonitor())
    assert res.alarms == ()
    assert res.monitor.stats["fault_fixes"] == 0


def test_one_receiver_with_the_inertial_coast_catches_the_ramp_flight_before_1m() -> None:
    """A 4 cm/s ramp with one receiver (tactical IMU): the blend follows it, the
    inertial coast's references catch it before it reaches 1 m; nothing before."""
    from companion.integrity.coast import CoastConfig
    from companion.nav.blend import BlendConfig
    from companion.sim.integrity_runs import run_samples_ins

    flight = sim.simulate(sim.make_scenario("ramp_fault", second_receiver=False), seed=1)
    (event,) = [e for e in flight.events if e.kind == "ramp"]
    blend, coast = BlendConfig.for_grade("tactical"), CoastConfig.for_grade("tactical")
    res = run_samples_ins(flight.samples, IntegrityMonitor(), blend, coast)
    assert not [a for a in res.alarms if a[0] < event.t_start_s], res.alarms
    after = [a for a in res.alarms if a[0] >= event.t_start_s]
    assert after and "ref:ins" in after[0][2]
    rate = abs(event.params["rate_ned_mps"][2])
    assert rate * (after[0][0] - event.t_start_s) < 1.0
    assert res.excluded_first_s.get(0) == after[0][0]
    # the same flight without the references: the blend follows the ramp, nothing is seen
    # before it has grown past a metre
    base = run_samples_ins(flight.samples, IntegrityMonitor(), blend, coast, use_coast=False)
    assert not [a for a in base.alarms if a[0] < event.t_start_s + 1.0 / rate]

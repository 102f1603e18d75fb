"""Barometer messages to typed samples: SCALED_PRESSURE(2), HIGHRES_IMU's abs_pressure."""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as apm

from companion.types import BaroSample, ImuSample
from tests.mavlink.test_decode import AP, one, ready


def test_scaled_pressure_and_pressure2() -> None:
    d = ready()
    s = one(d, apm.MAVLink_scaled_pressure_message(10_020, 1001.5, 0.0, 2150, 0))
    assert isinstance(s, BaroSample)
    assert s.t_s == 10.02 and s.baro_id == 0 and s.source == "SCALED_PRESSURE"
    assert s.pressure_pa == 100_150.0 and s.temperature_c == 21.5
    s2 = one(d, apm.MAVLink_scaled_pressure2_message(10_030, 990.0, 0.0, -500, 0))
    assert isinstance(s2, BaroSample) and s2.baro_id == 1 and s2.temperature_c == -5.0


def test_implausible_pressure_is_a_counted_rejection() -> None:
    d = ready()
    for p_hpa in (0.0, 5.0, 2000.0, math.nan):
        msg = apm.MAVLink_scaled_pressure_message(10_020, p_hpa, 0.0, 2000, 0)
        assert d.decode(AP.parsed(msg), 1.0) == []
    assert d.rejections["baro_out_of_range"] == 3
    assert d.rejections["nan_field"] == 1


def test_highres_imu_carries_the_barometer_when_flagged() -> None:
    d = ready(12)
    flagged = apm.MAVLink_highres_imu_message(
        10_010_000, 0.5, -0.25, -9.75, 0.1, 0.0, 0.0, 0, 0, 0, 950.5, 0, 10, 20, 0x3FF, 0
    )
    out = d.decode(AP.parsed(flagged), 1.0)
    assert [type(s) for s in out] == [ImuSample, BaroSample]
    baro = out[1]
    assert isinstance(baro, BaroSample)
    assert baro.t_s == out[0].t_s == 10.01 and baro.pressure_pa == 95_050.0
    assert baro.source == "HIGHRES_IMU"
    # bit 9 clear: the field is not the barometer's
    unflagged = apm.MAVLink_highres_imu_message(
        10_020_000, 0.5, -0.25, -9.75, 0.1, 0.0, 0.0, 0, 0, 0, 950.5, 0, 10, 20, 0x3F, 0
    )
    assert [type(s) for s in d.decode(AP.parsed(unflagged), 1.0)] == [ImuSample]
    # flagged but implausible: the IMU sample stays, the field is counted apart
    bad = apm.MAVLink_highres_imu_message(
        10_030_000, 0.5, -0.25, -9.75, 0.1, 0.0, 0.0, 0, 0, 0, 0.0, 0, 10, 20, 0x3FF, 0
    )
    assert [type(s) for s in d.decode(AP.parsed(bad), 1.0)] == [ImuSample]
    assert d.field_rejections["baro_out_of_range"] == 1
    assert "baro_out_of_range" not in d.rejections

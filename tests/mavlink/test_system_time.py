"""SYSTEM_TIME gives the exact epoch-to-boot offset; the configured GNSS delay is applied."""

from __future__ import annotations

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as apm

from companion.mavlink.decode import Decoder, DecoderConfig
from tests.mavlink._util import Packer, attitude, gps_raw, heartbeat

AP = Packer()
EPOCH0_S = 1_700_000_000.0


def system_time(t_ms: int) -> object:
    return apm.MAVLink_system_time_message(int(round((EPOCH0_S + t_ms / 1000) * 1e6)), t_ms)


def run(decoder: Decoder, latency_s: float = 0.12) -> np.ndarray:
    decoder.decode(AP.parsed(heartbeat()), 0.0)
    errors = []
    for i in range(1000):  # 10 s of 100 Hz attitude, SYSTEM_TIME at 1 Hz
        t_ms = 5000 + 10 * i
        decoder.decode(AP.parsed(attitude(t_ms)), 0.0)
        if i % 100 == 0:
            assert decoder.decode(AP.parsed(system_time(t_ms)), 0.0) == []
        if i % 20 == 12:  # 5 Hz GPS stamped with its time of validity, sent later
            t_fix = t_ms / 1000 - latency_s
            out = decoder.decode(AP.parsed(gps_raw(int(round((EPOCH0_S + t_fix) * 1e6)))), 0.0)
            errors.append(out[0].t_s - t_fix)
    return np.array(errors)


def test_system_time_puts_epoch_stamped_fixes_on_their_time_of_validity():
    decoder = Decoder()
    errors = run(decoder)
    # without SYSTEM_TIME the mapping is late by the 120 ms latency; with it, exact
    np.testing.assert_allclose(errors, 0.0, atol=2e-6)
    assert decoder.epoch_offset_s == pytest.approx(EPOCH0_S, abs=1e-6)
    assert decoder.accepted["SYSTEM_TIME"] == 10


def test_configured_gnss_delay_is_subtracted():
    decoder = Decoder(DecoderConfig(gnss_delay_s=0.05))
    errors = run(decoder)
    np.testing.assert_allclose(errors, -0.05, atol=2e-6)


def test_gnss_delay_is_validated():
    with pytest.raises(ValueError, match="gnss_delay_s"):
        DecoderConfig(gnss_delay_s=-0.1)

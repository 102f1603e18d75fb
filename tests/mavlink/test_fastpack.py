"""Encoder.pack packs what pymavlink's msg.pack packs, byte for byte."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as apm

from companion.mavlink.encode import Encoder, EncoderConfig
from companion.mavlink.encode.packing import _pack_plan
from companion.types import (
    Alert,
    AlertCode,
    AutopilotFlavour,
    FixType,
    IntegrityReport,
    NamedValue,
    Output,
    Severity,
)
from tests.mavlink.test_encode import solution
from tests.mavlink.test_messages import _raw_frame


def test_every_plain_message_packs_like_pymavlink() -> None:
    # every message class of the dialect, with field values decoded from random payloads
    # (and an all-zero one: the trailing-zero truncation down to one byte)
    rng = np.random.default_rng(7)
    enc = Encoder(system_id=42)
    ref = apm.MAVLink(None, srcSystem=42, srcComponent=191)
    rx = apm.MAVLink(None)
    packed_here = 0
    for msg_id, cls in sorted(apm.mavlink_map.items()):
        for k in range(3):
            size = cls.unpacker.size
            payload = bytes(size) if k == 0 else rng.integers(0, 256, size, dtype=np.uint8)
            frame = _raw_frame(msg_id, bytes(payload), cls.crc_extra)
            msg_a = rx.decode(bytearray(frame))
            msg_b = rx.decode(bytearray(frame))
            ref.seq = enc._packer.mav.seq
            got = enc.pack(msg_a)
            want = bytes(msg_b.pack(ref))
            assert got == want, cls.msgname
            assert bytes(msg_a.get_msgbuf()) == bytes(msg_b.get_msgbuf())
            assert msg_a.get_crc() == msg_b.get_crc()
            assert bytes(msg_a.get_payload()) == bytes(msg_b.get_payload())
            assert vars(msg_a.get_header()) == vars(msg_b.get_header())
            packed_here += _pack_plan(apm, cls) is not False
    assert packed_here > 300


def test_sequence_wraps_and_decodes() -> None:
    enc = Encoder(system_id=7)
    rx = apm.MAVLink(None)
    for i in range(300):
        data = enc.pack(apm.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3))
        msg = rx.decode(bytearray(data))
        assert msg.get_header().seq == i % 256
        assert msg.get_srcSystem() == 7 and msg.get_srcComponent() == 191


def _outputs() -> list[Output]:
    """Every kind of output, odd ones included (dropped, malformed, non-finite)."""
    rng = np.random.default_rng(11)
    outs: list[Output] = []
    for i in range(40):
        a = rng.normal(size=(3, 3))
        sol = solution(
            t_s=100.0 + 0.1 * i + rng.uniform(0.0, 1e-3),
            sigma_ne=(rng.uniform(0.001, 3.0), rng.uniform(0.001, 3.0)),
            yaw=None if i % 7 == 0 else rng.uniform(-4.0, 8.0),
            fix=FixType(i % 9),
        )
        outs.append(sol)
        # full covariances (the closed-form eigenvalues), list-valued vectors (general path)
        outs.append(replace(sol, vel_cov_ned_m2ps2=a @ a.T, pos_cov_ned_m2=a @ a.T))
        outs.append(replace(sol, vel_ned_mps=[1.0, -2.0, 0.25]))  # type: ignore[arg-type]
        outs.append(NamedValue(t_s=sol.t_s, name="CMP_HPL", value=float(rng.normal())))
    outs.append(replace(sol, lat_rad=math.nan))  # dropped: non-finite
    outs.append(replace(sol, vel_ned_mps=np.zeros(2)))  # dropped: malformed
    outs.append(NamedValue(t_s=1.0, name="NAME_TOO_LONG", value=1.0))  # dropped
    outs.append(NamedValue(t_s=1.0, name="CMP_X", value=math.inf))  # dropped
    outs.append(Alert(t_s=5.0, code=AlertCode.GNSS_LOST, severity=Severity.WARNING, text="x"))
    outs.append(
        IntegrityReport(t_s=5.0, hpl_m=3.0, vpl_m=4.0, integrity_ok=True, fault_detected=False)
    )
    return outs


@pytest.mark.parametrize(
    ("output", "flavour", "dialect"),
    [
        ("auto", AutopilotFlavour.ARDUPILOT, "ardupilotmega"),
        ("auto", AutopilotFlavour.PX4, "ardupilotmega"),
        ("auto", AutopilotFlavour.UNKNOWN, "ardupilotmega"),
        ("gps_input", AutopilotFlavour.UNKNOWN, "development"),
    ],
)
def test_encode_frames_is_encode_then_pack(
    output: str, flavour: AutopilotFlavour, dialect: str
) -> None:
    # the direct path gives the frames (bytes, sequence numbers, names) of encode + pack
    cfg = EncoderConfig(output=output, dialect=dialect, gps_input_yaw=output == "gps_input")
    a, b = Encoder(cfg, system_id=9), Encoder(cfg, system_id=9)
    want: list[tuple[str, bytes]] = []
    got: list[tuple[str, bytes]] = []
    for out in _outputs() * 7:  # past a sequence-number wrap
        want += [(m.get_type(), a.pack(m)) for m in a.encode(out, flavour)]
        got += b.encode_frames(out, flavour)
    assert got == want
    assert len(want) > 256
    assert a.dropped == b.dropped and sum(b.dropped.values()) == 4 * 7
    assert a.suppressed == b.suppressed


def test_encode_frames_signing_falls_back_to_pymavlink() -> None:
    a, b = Encoder(system_id=3), Encoder(system_id=3)
    for enc in (a, b):
        enc._packer.mav.signing.sign_outgoing = True
        enc._packer.mav.signing.secret_key = bytes(32)
        enc._packer.mav.signing.link_id = 0
        enc._packer.mav.signing.timestamp = 1
    sol = solution()
    want = [(m.get_type(), a.pack(m)) for m in a.encode(sol, AutopilotFlavour.ARDUPILOT)]
    got = b.encode_frames(sol, AutopilotFlavour.ARDUPILOT)
    assert got == want and all(f[2] & 0x01 for _, f in got)  # signed frames

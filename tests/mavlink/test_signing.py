"""MAVLink 2 signing at the edge: our signatures are pymavlink's, byte for byte, and
verify with pymavlink; the verifier refuses unsigned, forged, replayed and stale frames
and counts them; the parser drops what the verifier refuses."""

from __future__ import annotations

import asyncio
import hashlib
import logging

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as apm

from companion.config import ConfigError, config_from_dict
from companion.mavlink.framing import FrameParser
from companion.mavlink.link import UdpLink, open_link
from companion.mavlink.signing import (
    BAD_SIGNATURE,
    MAVLINK_EPOCH_UNIX_S,
    NEW_STREAM_MAX_AGE,
    REPLAYED,
    STALE,
    TIMESTAMP_UNITS_PER_S,
    UNSIGNED,
    LinkSigning,
    LinkSigningConfig,
    Signer,
    Verifier,
    key_from_bytes,
    load_key,
    passphrase_key,
    timestamp_at,
)
from tests.mavlink._util import attitude, gps_raw, heartbeat, raw_imu

KEY = passphrase_key("correct horse battery staple")
OTHER_KEY = passphrase_key("wrong passphrase")
T0 = timestamp_at(1_767_225_600.0)  # 2026-01-01


def command(param1: float = 1.0) -> apm.MAVLink_command_long_message:
    return apm.MAVLink_command_long_message(1, 191, 31010, 0, param1, 0, 0, 0, 0, 0, 0)


def messages() -> list:
    return [
        heartbeat(),
        raw_imu(1_000_000),
        attitude(1000),
        gps_raw(2_000_000),
        command(),
        apm.MAVLink_statustext_message(6, b"CMP HDG_READY 1.00 +/-0.02 n=30"),
        apm.MAVLink_named_value_float_message(1000, b"CMP_HACC", 0.25),
        apm.MAVLink_heartbeat_message(0, 0, 0, 0, 0, 0),  # payload truncated to 1 byte
    ]


def pymavlink_signed(
    msg, key: bytes, link_id: int, timestamp: int, sysid=255, compid=190, seq=0
) -> bytes:
    """``msg`` packed and signed by pymavlink with the timestamp ``timestamp``."""
    mav = apm.MAVLink(None, sysid, compid)
    mav.seq = seq
    mav.signing.secret_key = key
    mav.signing.link_id = link_id
    mav.signing.timestamp = timestamp
    mav.signing.sign_outgoing = True
    return bytes(msg.pack(mav))


def pymavlink_unsigned(msg, sysid=255, compid=190, seq=0) -> bytes:
    mav = apm.MAVLink(None, sysid, compid)
    mav.seq = seq
    return bytes(msg.pack(mav))


def pymavlink_receiver(key: bytes) -> apm.MAVLink:
    """A pymavlink receiver that accepts only frames signed with ``key``."""
    rx = apm.MAVLink(None)
    rx.signing.secret_key = key
    rx.signing.timestamp = 0
    return rx


# ----------------------------------------------------------------------------- keys, time


def test_passphrase_key_is_sha256_of_the_ascii_passphrase_as_mavproxy_hashes_it():
    # MAVProxy modules/mavproxy_signing.py: passphrase_to_key = sha256(passphrase.encode("ascii"))
    assert passphrase_key("abc") == bytes.fromhex(
        "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
    )
    assert len(KEY) == 32
    with pytest.raises(UnicodeEncodeError):
        passphrase_key("clé")


def test_key_files_raw_or_hex(tmp_path):
    raw = bytes(range(32))
    assert key_from_bytes(raw) == raw
    assert key_from_bytes(raw.hex().encode() + b"\n") == raw
    assert key_from_bytes(b"  " + raw.hex().upper().encode() + b"\r\n") == raw
    for bad in (b"", bytes(31), bytes(33), b"zz" * 32, raw.hex().encode()[:-2]):
        with pytest.raises(ValueError, match="not a signing key"):
            key_from_bytes(bad)
    path = tmp_path / "key"
    path.write_bytes(raw)
    assert load_key(LinkSigningConfig(mode="require", key_file=str(path))) == raw
    assert load_key(LinkSigningConfig(mode="sign", passphrase="abc")) == passphrase_key("abc")
    with pytest.raises(ValueError, match="key_file .*missing"):
        load_key(LinkSigningConfig(mode="require", key_file=str(tmp_path / "missing")))
    path.write_bytes(b"short")
    with pytest.raises(ValueError, match="not a signing key"):
        load_key(LinkSigningConfig(mode="require", key_file=str(path)))


def test_timestamps_count_10us_since_2015():
    assert timestamp_at(MAVLINK_EPOCH_UNIX_S) == 0
    assert timestamp_at(MAVLINK_EPOCH_UNIX_S + 1.5) == 150_000
    assert timestamp_at(0.0) == 0  # a clock not set yet
    assert TIMESTAMP_UNITS_PER_S == 100_000


# ----------------------------------------------------------------------------- config


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ({"mode": "on"}, "[signing.gcs] mode must be one of ['off', 'sign', 'require']"),
        ({"mode": "require"}, "[signing.gcs] mode 'require' needs a key_file or a passphrase"),
        ({"mode": "sign", "key_file": "k", "passphrase": "p"}, "not both"),
        ({"mode": "sign", "passphrase": "pâté"}, "[signing.gcs] passphrase must be ASCII"),
        ({"link_id": 256}, "[signing.gcs] link_id must be in [0, 255], got 256"),
        ({"mode": "sign", "key": "x"}, "[signing.gcs] unknown key 'key'"),
    ],
)
def test_signing_config_errors_name_the_key(table, message):
    with pytest.raises(ConfigError) as err:
        config_from_dict({"signing": {"gcs": table}})
    assert message in str(err.value)


def test_signing_is_off_by_default_and_configurable_per_link():
    cfg = config_from_dict({})
    assert cfg.signing.autopilot.mode == "off" and cfg.signing.gcs.mode == "off"
    cfg = config_from_dict({"signing": {"gcs": {"mode": "require", "passphrase": "x"}}})
    assert cfg.signing.gcs.enabled and not cfg.signing.autopilot.enabled
    assert "x" not in repr(cfg.signing.gcs)  # the passphrase is not printed


# ----------------------------------------------------------------------------- signer


@pytest.mark.parametrize("link_id", [0, 7, 255])
def test_our_signed_frames_are_pymavlinks_byte_for_byte(link_id):
    signer = Signer(KEY, link_id, T0)
    for seq, msg in enumerate(messages()):
        unsigned = pymavlink_unsigned(msg, 1, 191, seq)
        ours = signer.sign(unsigned)
        assert ours == pymavlink_signed(msg, KEY, link_id, T0 + 1 + seq, 1, 191, seq), msg
        assert len(ours) == len(unsigned) + 13
        assert ours[2] == 1  # the SIGNED incompatibility flag
    assert signer.signed == len(messages())


@settings(max_examples=60, deadline=None)
@given(data=st.binary(min_size=0, max_size=253), seq=st.integers(0, 255))
def test_signatures_match_pymavlink_for_every_payload_length(data, seq):
    """ENCAPSULATED_DATA's payload is 255 bytes before MAVLink 2 truncates its trailing
    zeros: every payload length the CRC correction must handle."""
    msg = apm.MAVLink_encapsulated_data_message(7, list(data.ljust(253, b"\0")))
    unsigned = pymavlink_unsigned(msg, 1, 191, seq)
    ours = Signer(KEY, 3, T0).sign(unsigned)
    assert ours == pymavlink_signed(msg, KEY, 3, T0 + 1, 1, 191, seq)


def test_our_signed_frames_verify_with_pymavlink():
    signer = Signer(KEY, 2, T0)
    rx = pymavlink_receiver(KEY)
    for seq, msg in enumerate(messages()):
        decoded = rx.decode(bytearray(signer.sign(pymavlink_unsigned(msg, 1, 191, seq), T0)))
        assert decoded.get_type() == msg.get_type()
        assert decoded._signed and decoded._link_id == 2
    assert rx.signing.goodsig_count == len(messages()) and rx.signing.badsig_count == 0
    # and a receiver with another key refuses them
    other = pymavlink_receiver(OTHER_KEY)
    with pytest.raises(apm.MAVError, match="Invalid signature"):
        other.decode(bytearray(signer.sign(pymavlink_unsigned(heartbeat(), 1, 191))))


def test_the_timestamp_follows_the_wall_clock_and_never_goes_back():
    signer = Signer(KEY, 0, T0)
    ts = lambda frame: int.from_bytes(frame[-12:-6], "little")  # noqa: E731
    frame = pymavlink_unsigned(heartbeat())
    assert ts(signer.sign(frame)) == T0 + 1
    assert ts(signer.sign(frame, T0 + 500_000)) == T0 + 500_000  # the wall clock moved on
    assert ts(signer.sign(frame, T0)) == T0 + 500_001  # the clock stepped back: we do not
    signer.advance_to(T0 + 900_000)
    assert ts(signer.sign(frame, T0)) == T0 + 900_001
    signer.advance_to(T0)  # never backwards
    assert signer.timestamp == T0 + 900_001


def test_frames_that_cannot_be_signed_pass_unchanged():
    signer = Signer(KEY, 0, T0)
    v1 = apm.MAVLink(None, 1, 191)
    v1_frame = bytes(heartbeat().pack(v1, force_mavlink1=True))
    signed = pymavlink_signed(heartbeat(), KEY, 0, T0)
    for frame in (v1_frame, signed, b"\xfd\x09"):
        assert signer.sign(frame) == frame
    assert signer.unsignable == 3 and signer.signed == 0 and signer.timestamp == T0


# ----------------------------------------------------------------------------- verifier


def make_verifier(require: bool = True, timestamp: int = T0) -> Verifier:
    return Verifier(KEY, require, Signer(KEY, 0, timestamp), "gcs")


def test_valid_signed_frames_are_accepted_and_move_our_timestamp():
    verifier = make_verifier()
    for k in range(3):
        assert verifier.accept(pymavlink_signed(command(), KEY, 0, T0 + 10 + k, seq=k))
    assert verifier.accepted_signed == 3 and not verifier.rejections
    assert verifier._signer.timestamp == T0 + 12  # the peer's later timestamp is adopted


def test_unsigned_frames_are_refused_when_required_and_accepted_otherwise(caplog):
    frame = pymavlink_unsigned(command())
    v1 = bytes(command().pack(apm.MAVLink(None, 255, 190), force_mavlink1=True))
    required = make_verifier(require=True)
    with caplog.at_level(logging.WARNING, logger="companion.mavlink.signing"):
        for _ in range(12):
            assert not required.accept(frame)
        assert not required.accept(v1)
    assert required.rejections == {UNSIGNED: 13}
    # logged on the 1st and the 10th only (rate-limited), naming the link and the sender
    logged = [r.getMessage() for r in caplog.records]
    assert len(logged) == 2
    assert "gcs link: MAVLink frame refused: unsigned_frame (from 255/190; 1 so far)" in logged[0]
    optional = make_verifier(require=False)
    assert optional.accept(frame) and optional.accept(v1)
    assert optional.accepted_unsigned == 2 and not optional.rejections


def test_forged_and_wrong_key_frames_are_refused_in_both_modes():
    for require in (True, False):
        verifier = make_verifier(require)
        good = pymavlink_signed(command(), KEY, 0, T0 + 10)
        forged = bytearray(good)
        forged[-1] ^= 0x01  # one bit of the signature
        assert not verifier.accept(forged)
        assert not verifier.accept(pymavlink_signed(command(), OTHER_KEY, 0, T0 + 11))
        assert verifier.rejections == {BAD_SIGNATURE: 2}
        # a forged frame did not claim the stream: the genuine one still passes
        assert verifier.accept(good)


def test_a_forged_frame_with_a_far_timestamp_does_not_block_the_stream():
    verifier = make_verifier()
    forged = bytearray(pymavlink_signed(command(), OTHER_KEY, 0, T0 + 10**9))
    assert not verifier.accept(forged)
    assert verifier.accept(pymavlink_signed(command(), KEY, 0, T0 + 10))


def test_replayed_and_older_timestamps_are_refused_per_stream():
    verifier = make_verifier()
    first = pymavlink_signed(command(), KEY, 0, T0 + 100)
    assert verifier.accept(first)
    assert not verifier.accept(first)  # the same frame again
    assert not verifier.accept(pymavlink_signed(command(), KEY, 0, T0 + 99))  # older
    assert verifier.rejections == {REPLAYED: 2}
    # other streams (link id, component, system) keep their own timestamps
    assert verifier.accept(pymavlink_signed(command(), KEY, 1, T0 + 50))
    assert verifier.accept(pymavlink_signed(command(), KEY, 0, T0 + 50, compid=191))
    assert verifier.accept(pymavlink_signed(command(), KEY, 0, T0 + 50, sysid=254))
    assert verifier.accept(pymavlink_signed(command(), KEY, 0, T0 + 101))


def test_a_new_stream_more_than_a_minute_behind_us_is_refused():
    verifier = make_verifier(timestamp=T0)
    assert not verifier.accept(pymavlink_signed(command(), KEY, 0, T0 - NEW_STREAM_MAX_AGE - 1))
    assert verifier.rejections == {STALE: 1}
    assert verifier.accept(pymavlink_signed(command(), KEY, 1, T0 - NEW_STREAM_MAX_AGE + 1))


def test_link_signing_pairs_signer_and_verifier():
    cfg = LinkSigningConfig(mode="require", passphrase="x", link_id=9)
    signing = LinkSigning(cfg, passphrase_key("x"), T0, "gcs")
    frame = signing.sign(pymavlink_unsigned(heartbeat(), 1, 191), T0)
    assert frame[-13] == 9 and signing.timestamp == T0 + 1
    assert not signing.accept(pymavlink_unsigned(command()))
    with pytest.raises(ValueError):
        LinkSigning(LinkSigningConfig(), KEY, T0, "gcs")


# ----------------------------------------------------------------------------- parser


def test_the_parser_drops_refused_frames_and_keeps_the_rest():
    verifier = make_verifier()
    good = [pymavlink_signed(command(k % 2), KEY, 0, T0 + 10 + k, seq=k) for k in range(4)]
    stream = (
        good[0]
        + pymavlink_unsigned(command())  # refused: unsigned
        + good[1]
        + pymavlink_signed(command(), OTHER_KEY, 0, T0 + 30)  # refused: wrong key
        + good[2]
        + good[2]  # refused: replayed
        + b"\x00garbage"
        + good[3]
    )
    parser = FrameParser(frame_check=verifier.accept)
    out = []
    for k in range(0, len(stream), 7):  # in small chunks, as a serial link delivers
        out += parser.feed(stream[k : k + 7])
    assert [m.get_seq() for m in out] == [0, 1, 2, 3]
    assert [m.param1 for m in out] == [0.0, 1.0, 0.0, 1.0]
    assert parser.refused_frames == 3 and parser.good_frames == 4
    assert parser.bad_frames == 1  # the garbage only: refused frames are not corrupt
    assert verifier.rejections == {UNSIGNED: 1, BAD_SIGNATURE: 1, REPLAYED: 1}


def test_a_corrupted_signed_frame_is_a_corrupt_frame_not_a_signature_refusal():
    verifier = make_verifier()
    frame = bytearray(pymavlink_signed(command(), KEY, 0, T0 + 10))
    frame[12] ^= 0xFF  # a payload byte: the CRC fails before the signature is looked at
    parser = FrameParser(frame_check=verifier.accept)
    assert parser.feed(bytes(frame)) == [] and parser.flush() == []
    assert parser.bad_frames == 1 and parser.refused_frames == 0 and not verifier.rejections


def test_without_a_check_signed_and_unsigned_frames_parse_as_before():
    stream = pymavlink_signed(command(), KEY, 0, T0) + pymavlink_unsigned(command())
    out = FrameParser().feed(stream)
    assert len(out) == 2 and all(m.get_type() == "COMMAND_LONG" for m in out)


def test_signature_is_sha256_of_key_frame_and_stamp():
    """The 6 signature bytes are the first 6 of SHA-256(key + frame up to the timestamp)."""
    frame = Signer(KEY, 4, T0).sign(pymavlink_unsigned(heartbeat(), 1, 191))
    assert frame[-6:] == hashlib.sha256(KEY + frame[:-6]).digest()[:6]
    assert frame[-13] == 4 and int.from_bytes(frame[-12:-6], "little") == T0 + 1


# ----------------------------------------------------------------------------- udpin peer


def test_a_udpin_link_that_does_not_follow_senders_replies_only_to_the_adopted_one():
    async def main() -> None:
        server = await open_link("udpin:127.0.0.1:0")
        assert isinstance(server, UdpLink)
        server.reply_to_any_sender = False
        gcs = await open_link(f"udpout:127.0.0.1:{server.local_port}")
        stranger = await open_link(f"udpout:127.0.0.1:{server.local_port}")
        try:
            await gcs.send(b"signed")
            assert await asyncio.wait_for(server.recv(), 5.0) == b"signed"
            await server.send(b"nobody adopted yet")
            assert server.send_failures == 1
            server.adopt_sender()  # the chunk from the ground station was accepted
            await stranger.send(b"unsigned")
            assert await asyncio.wait_for(server.recv(), 5.0) == b"unsigned"  # not adopted
            await server.send(b"reply")
            assert await asyncio.wait_for(gcs.recv(), 5.0) == b"reply"
            with pytest.raises(asyncio.TimeoutError):
                await asyncio.wait_for(stranger.recv(), 0.2)
        finally:
            for link in (gcs, stranger, server):
                await link.close()

    asyncio.run(main())

"""MAVLink 2 message signing on a link: our frames signed, the peer's checked.

The pipeline packs unsigned frames once for every link; signing happens at the
edge, per link, as the service sends and receives:

* :class:`Signer` appends the 13-byte signature (link id, 48-bit timestamp, the
  first 6 bytes of ``SHA-256(key + frame + link id + timestamp)``) to a packed
  MAVLink 2 frame and sets the SIGNED incompatibility flag. The CRC covers that
  flag byte, so it changes with it: the CRC-16/MCRF4XX of the frame is affine in
  its bytes, and flipping one header bit changes it by a fixed amount that depends
  only on the frame length (:func:`_flag_crc_delta`). No CRC_EXTRA, hence no
  dialect, is needed; the result is byte for byte what pymavlink packs with
  ``mav.signing.sign_outgoing`` (tests/mavlink/test_signing.py).
* :class:`Verifier` checks every frame received on a link (after the framing has
  checked its CRC): a valid signature under the link's key, then a timestamp newer
  than the last one accepted from the same ``(system, component, link id)`` stream;
  a stream seen for the first time may not be more than a minute behind our own
  timestamp. In ``require`` mode unsigned frames (MAVLink 1 included) are refused
  too. A refused frame is dropped, counted by reason (:data:`REJECTION_REASONS`)
  and logged on its 1st, 10th, 100th ... occurrence.

The timestamp is in 10 µs units since 2015-01-01 00:00 UTC. It never goes back:
each frame signed uses ``max(last + 1, wall clock)``, an accepted frame with a
later timestamp moves ours forward (the MAVLink rule for systems whose clock may be
wrong), and the service stores it in its state directory and starts from
``max(stored, wall clock)``. Nothing here reads a clock: the caller passes the
wall-clock time.

Keys: 32 bytes from a file (raw, or 64 hexadecimal digits), or a passphrase
hashed with SHA-256 as MAVProxy's ``signing setup <passphrase>`` does, so that a
ground station set up with MAVProxy's command shares the key.

References
----------
MAVLink message signing: https://mavlink.io/en/guide/message_signing.html;
pymavlink's ``MAVLink_message.sign_packet`` and ``MAVLink.check_signature``;
MAVProxy ``modules/mavproxy_signing.py`` (``passphrase_to_key``).
"""

from __future__ import annotations

import collections
import dataclasses
import hashlib
import logging
from dataclasses import dataclass
from pathlib import Path

from companion.mavlink.ids import (
    CRC_LEN,
    HEADER_LEN_V2,
    IFLAG_SIGNED,
    SIGNATURE_LEN,
    STX_V2,
)
from companion.ranges import check_ranges, ranged

logger = logging.getLogger(__name__)

KEY_LEN = 32
"""A signing key is 32 bytes."""
MAVLINK_EPOCH_UNIX_S = 1_420_070_400
"""2015-01-01 00:00:00 UTC, the origin of signing timestamps, in UNIX seconds."""
TIMESTAMP_UNITS_PER_S = 100_000
"""Signing timestamps count 10 µs units."""
TIMESTAMP_MAX = (1 << 48) - 1
"""The timestamp field has 48 bits."""
NEW_STREAM_MAX_AGE = 60 * TIMESTAMP_UNITS_PER_S
"""A stream seen for the first time may be at most a minute behind our timestamp (as
pymavlink and the MAVLink C library accept it)."""

MODES = ("off", "sign", "require")
"""``off``: frames as without signing; ``sign``: ours signed, the peer's signed frames
checked and its unsigned ones accepted; ``require``: ours signed, only valid signed
frames accepted."""

UNSIGNED = "unsigned_frame"
BAD_SIGNATURE = "bad_signature"
REPLAYED = "replayed_frame"
STALE = "stale_timestamp"
REJECTION_REASONS = (UNSIGNED, BAD_SIGNATURE, REPLAYED, STALE)
"""Why a received frame was refused: unsigned on a link that requires signing; a
signature that does not verify under the link's key (a wrong or unknown key, or altered
bytes: the protocol cannot tell them apart); a timestamp not newer than the last one
accepted from its stream (a replay); a new stream more than a minute behind ours."""


# ----------------------------------------------------------------------------- config


@dataclass(frozen=True, slots=True)
class LinkSigningConfig:
    """MAVLink 2 signing on this link."""

    mode: str = ranged("off", choices=MODES)
    """off | sign (our frames signed, the peer's signed frames checked, unsigned accepted)
    | require (our frames signed, only valid signed frames accepted)."""
    key_file: str = ""
    """File holding the 32-byte key: the raw bytes, or 64 hexadecimal digits."""
    passphrase: str = dataclasses.field(default="", repr=False)
    """Or a passphrase (ASCII), hashed with SHA-256 as MAVProxy's `signing setup` does."""
    link_id: int = ranged(0, ge=0, le=255)
    """Link id carried in our signatures (the receiver keeps one timestamp per system,
    component and link id)."""

    def __post_init__(self) -> None:
        check_ranges(self)
        if self.key_file and self.passphrase:
            raise ValueError("give key_file or passphrase, not both")
        if self.mode != "off" and not (self.key_file or self.passphrase):
            raise ValueError(f"mode {self.mode!r} needs a key_file or a passphrase")
        if not self.passphrase.isascii():
            raise ValueError("passphrase must be ASCII (as MAVProxy hashes it)")

    @property
    def enabled(self) -> bool:
        """Whether the link signs at all."""
        return self.mode != "off"


@dataclass(frozen=True, slots=True)
class SigningConfig:
    """MAVLink 2 message signing, per link (off by default)."""

    autopilot: LinkSigningConfig = dataclasses.field(default_factory=LinkSigningConfig)
    """The autopilot link (link.master)."""
    gcs: LinkSigningConfig = dataclasses.field(default_factory=LinkSigningConfig)
    """The ground-station link (link.gcs)."""


# ----------------------------------------------------------------------------- keys


def passphrase_key(passphrase: str) -> bytes:
    """The 32-byte key of a passphrase: SHA-256 of its ASCII bytes (MAVProxy's
    ``passphrase_to_key``)."""
    return hashlib.sha256(passphrase.encode("ascii")).digest()


def key_from_bytes(data: bytes) -> bytes:
    """A key file's content: exactly 32 raw bytes, or 64 hexadecimal digits (surrounding
    whitespace ignored). Raises ``ValueError`` otherwise."""
    if len(data) == KEY_LEN:
        return bytes(data)
    text = data.strip()
    if len(text) == 2 * KEY_LEN:
        try:
            return bytes.fromhex(text.decode("ascii"))
        except (UnicodeDecodeError, ValueError):
            pass
    raise ValueError(
        f"not a signing key: {len(data)} bytes; expected 32 raw bytes or 64 hex digits"
    )


def load_key(cfg: LinkSigningConfig) -> bytes:
    """The key ``cfg`` names (its file read now). Raises ``ValueError`` naming the file."""
    if cfg.passphrase:
        return passphrase_key(cfg.passphrase)
    try:
        data = Path(cfg.key_file).read_bytes()
    except OSError as exc:
        raise ValueError(f"signing key_file {cfg.key_file}: {exc.strerror or exc}") from None
    try:
        return key_from_bytes(data)
    except ValueError as exc:
        raise ValueError(f"signing key_file {cfg.key_file}: {exc}") from None


# ----------------------------------------------------------------------------- time


def timestamp_at(t_unix_s: float) -> int:
    """The signing timestamp (10 µs units since 2015-01-01 UTC) of a UNIX time; 0 for
    any time before 2015 (a clock not set yet)."""
    units = int((t_unix_s - MAVLINK_EPOCH_UNIX_S) * TIMESTAMP_UNITS_PER_S)
    return min(max(units, 0), TIMESTAMP_MAX)


# ----------------------------------------------------------------------------- CRC


def _mcrf4xx(data: bytes, crc: int) -> int:
    """CRC-16/MCRF4XX (MAVLink's X.25 checksum) of ``data`` from ``crc``."""
    for byte in data:
        tmp = byte ^ (crc & 0xFF)
        tmp = (tmp ^ (tmp << 4)) & 0xFF
        crc = ((crc >> 8) ^ (tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)) & 0xFFFF
    return crc


_DELTAS: dict[int, int] = {}


def _flag_crc_delta(payload_len: int) -> int:
    """What setting the SIGNED flag XORs into the CRC of a frame with ``payload_len``
    payload bytes.

    The checksum runs over ``frame[1:-2] + CRC_EXTRA``; without a final XOR the CRC of
    a message of fixed length is affine in its bits, so two messages differing in one
    bit differ in CRC by the CRC, from 0, of that bit followed by as many zero bytes as
    follow it (here: the compat flags, sequence, system, component, the 3 id bytes, the
    payload and CRC_EXTRA).
    """
    delta = _DELTAS.get(payload_len)
    if delta is None:
        following = HEADER_LEN_V2 - 3 + payload_len + 1
        delta = _DELTAS[payload_len] = _mcrf4xx(bytes((IFLAG_SIGNED,)) + bytes(following), 0)
    return delta


# ----------------------------------------------------------------------------- signing


class Signer:
    """Signs our packed MAVLink 2 frames for one link.

    Parameters
    ----------
    key
        The 32-byte secret key.
    link_id
        Our link id (0-255), carried in every signature.
    timestamp
        The last timestamp used (10 µs units since 2015): the next frame gets a later one.

    Attributes
    ----------
    timestamp : int
        The last timestamp used or accepted from the peer (it only grows).
    signed : int
        Frames signed.
    unsignable : int
        Frames passed on unsigned: MAVLink 1, already signed or malformed (never ours).
    """

    __slots__ = ("_key", "_link_id", "timestamp", "signed", "unsignable")

    def __init__(self, key: bytes, link_id: int, timestamp: int = 0) -> None:
        if len(key) != KEY_LEN:
            raise ValueError(f"a signing key is {KEY_LEN} bytes, got {len(key)}")
        if not 0 <= link_id <= 255:
            raise ValueError(f"link_id must be in [0, 255], got {link_id}")
        self._key = bytes(key)
        self._link_id = link_id
        self.timestamp = min(max(int(timestamp), 0), TIMESTAMP_MAX)
        self.signed = 0
        self.unsignable = 0

    def advance_to(self, timestamp: int) -> None:
        """Never sign below ``timestamp`` again (the wall clock, a stored or a received
        timestamp); the timestamp never goes back."""
        if timestamp > self.timestamp:
            self.timestamp = min(timestamp, TIMESTAMP_MAX)

    def sign(self, frame: bytes, now: int = 0) -> bytes:
        """``frame`` signed, with timestamp ``max(last + 1, now)`` (``now``: the wall clock
        as :func:`timestamp_at` gives it). Anything but an unsigned MAVLink 2 frame is
        returned unchanged (and counted in :attr:`unsignable`)."""
        n = len(frame)
        if (
            n < HEADER_LEN_V2 + CRC_LEN
            or frame[0] != STX_V2
            or frame[2] != 0
            or n != HEADER_LEN_V2 + frame[1] + CRC_LEN
        ):
            self.unsignable += 1
            return frame
        ts = max(self.timestamp + 1, now)
        if ts > TIMESTAMP_MAX:  # 2.8e9 s after 2015: not in this service's lifetime
            self.unsignable += 1
            return frame
        self.timestamp = ts
        out = bytearray(frame)
        out[2] = IFLAG_SIGNED
        crc = (out[-2] | (out[-1] << 8)) ^ _flag_crc_delta(frame[1])
        out[-2] = crc & 0xFF
        out[-1] = crc >> 8
        out.append(self._link_id)
        out += ts.to_bytes(6, "little")
        out += hashlib.sha256(self._key + out).digest()[:6]
        self.signed += 1
        return bytes(out)


class Verifier:
    """Checks the frames received on one link (see the module docstring).

    Parameters
    ----------
    key
        The link's 32-byte key.
    require
        Refuse unsigned frames (``require`` mode); otherwise only signed frames are
        checked.
    signer
        The same link's :class:`Signer`: a new stream is compared with its timestamp, and
        an accepted timestamp later than its own moves it forward.
    name
        The link's name, for the log.

    Attributes
    ----------
    rejections : collections.Counter[str]
        Refused frames by reason (:data:`REJECTION_REASONS`).
    accepted_signed : int
        Signed frames accepted.
    accepted_unsigned : int
        Unsigned frames accepted (``sign`` mode).
    """

    __slots__ = (
        "_key",
        "_require",
        "_signer",
        "_name",
        "_streams",
        "rejections",
        "accepted_signed",
        "accepted_unsigned",
    )

    def __init__(self, key: bytes, require: bool, signer: Signer, name: str = "") -> None:
        if len(key) != KEY_LEN:
            raise ValueError(f"a signing key is {KEY_LEN} bytes, got {len(key)}")
        self._key = bytes(key)
        self._require = require
        self._signer = signer
        self._name = name
        self._streams: dict[tuple[int, int, int], int] = {}
        """Last accepted timestamp per (system, component, link id)."""
        self.rejections: collections.Counter[str] = collections.Counter()
        self.accepted_signed = 0
        self.accepted_unsigned = 0

    def accept(self, frame: bytes | bytearray) -> bool:
        """Whether to pass on ``frame``, one complete frame whose CRC the framing has
        checked (STX to CRC, and the signature if flagged). A refused frame is counted
        and logged."""
        reason = self._check(frame)
        if reason is None:
            return True
        self._reject(reason, frame)
        return False

    def _check(self, frame: bytes | bytearray) -> str | None:
        """The reason to refuse ``frame``, or None."""
        if frame[0] != STX_V2 or not frame[2] & IFLAG_SIGNED:
            if self._require:
                return UNSIGNED
            self.accepted_unsigned += 1
            return None
        if len(frame) < HEADER_LEN_V2 + CRC_LEN + SIGNATURE_LEN:
            return BAD_SIGNATURE
        if hashlib.sha256(self._key + frame[:-6]).digest()[:6] != frame[-6:]:
            return BAD_SIGNATURE
        link_id = frame[-SIGNATURE_LEN]
        ts = int.from_bytes(frame[-12:-6], "little")
        stream = (frame[5], frame[6], link_id)
        last = self._streams.get(stream)
        if last is not None:
            if ts <= last:
                return REPLAYED
        elif ts + NEW_STREAM_MAX_AGE < self._signer.timestamp:
            return STALE
        self._streams[stream] = ts
        self._signer.advance_to(ts)
        self.accepted_signed += 1
        return None

    def _reject(self, reason: str, frame: bytes | bytearray) -> None:
        """Count a refusal; log it on the 1st, 10th, 100th ... of its reason."""
        before = self.rejections[reason]
        after = before + 1
        self.rejections[reason] = after
        if before == 0 or len(str(after)) != len(str(before)):
            src = f"{frame[5]}/{frame[6]}" if frame[0] == STX_V2 else f"{frame[3]}/{frame[4]}"
            logger.warning(
                "%s link: MAVLink frame refused: %s (from %s; %d so far)",
                self._name or "a",
                reason,
                src,
                after,
            )


class LinkSigning:
    """One link's signing: a :class:`Signer` for what goes out, a :class:`Verifier` for
    what comes in.

    Parameters
    ----------
    cfg
        The link's configuration (``mode`` not ``off``).
    key
        Its key (:func:`load_key`).
    timestamp
        Where the timestamp starts: at least the stored one and the wall clock's.
    name
        The link's name, for the log.
    """

    __slots__ = ("config", "signer", "verifier")

    def __init__(self, cfg: LinkSigningConfig, key: bytes, timestamp: int, name: str) -> None:
        if not cfg.enabled:
            raise ValueError("signing is off on this link")
        self.config = cfg
        self.signer = Signer(key, cfg.link_id, timestamp)
        self.verifier = Verifier(key, cfg.mode == "require", self.signer, name)

    def sign(self, frame: bytes, now: int) -> bytes:
        """:meth:`Signer.sign`."""
        return self.signer.sign(frame, now)

    def accept(self, frame: bytes | bytearray) -> bool:
        """:meth:`Verifier.accept`."""
        return self.verifier.accept(frame)

    @property
    def timestamp(self) -> int:
        """The link's signing timestamp (the last used or accepted)."""
        return self.signer.timestamp

"""The MAVLink numbers written out in companion.mavlink.ids are pymavlink's."""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega, development

from companion.mavlink import ids
from companion.types import Severity


def test_every_name_a_dialect_defines_has_its_value() -> None:
    names = [n for n in vars(ids) if n.isupper()]
    checked = 0
    for name in names:
        for dialect in (ardupilotmega, development):
            if hasattr(dialect, name):
                assert getattr(ids, name) == getattr(dialect, name), name
                checked += 1
    assert checked >= 40


def test_frame_layout_and_text_lengths() -> None:
    assert ids.STX_V2 == ardupilotmega.PROTOCOL_MARKER_V2
    assert ids.STX_V1 == ardupilotmega.PROTOCOL_MARKER_V1
    assert ids.HEADER_LEN_V2 == ardupilotmega.HEADER_LEN_V2
    assert ids.HEADER_LEN_V1 == ardupilotmega.HEADER_LEN_V1
    assert ids.SIGNATURE_LEN == ardupilotmega.MAVLINK_SIGNATURE_BLOCK_LEN
    assert ids.IFLAG_SIGNED == ardupilotmega.MAVLINK_IFLAG_SIGNED
    statustext = ardupilotmega.MAVLink_statustext_message
    text_len = statustext.array_lengths[statustext.ordered_fieldnames.index("text")]
    assert text_len == ids.STATUSTEXT_MAX_CHARS
    named = ardupilotmega.MAVLink_named_value_float_message
    assert named.array_lengths[named.ordered_fieldnames.index("name")] == ids.NAMED_VALUE_MAX_CHARS


def test_severity_is_mav_severity() -> None:
    for s in Severity:
        assert getattr(ardupilotmega, f"MAV_SEVERITY_{s.name}") == s.value

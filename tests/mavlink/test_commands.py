"""The command protocol's pieces: reading a request, addressing, retransmissions."""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as apm

from companion.mavlink.commands import (
    RETRANSMISSION_WINDOW_S,
    Retransmissions,
    addressed_to,
    heading_action,
    read_command,
)
from companion.mavlink.ids import MAV_RESULT_ACCEPTED, MAV_RESULT_DENIED
from companion.types import HeadingAction
from tests.mavlink._util import Packer

GCS = Packer(255, 190)


def request(param1: float = 1.0, confirmation: int = 0, sender: Packer = GCS, command=31010):
    msg = apm.MAVLink_command_long_message(1, 191, command, confirmation, param1, 0, 0, 0, 0, 0, 0)
    return read_command(sender.parsed(msg))


def test_read_command_long_and_int() -> None:
    r = request(2.0, confirmation=3)
    assert (r.message, r.command, r.params[0], r.confirmation) == ("COMMAND_LONG", 31010, 2.0, 3)
    assert (r.source_system, r.source_component, r.target_system, r.target_component) == (
        255,
        190,
        1,
        191,
    )
    mi = apm.MAVLink_command_int_message(0, 0, 6, 512, 0, 0, 1.5, 0, 0, 0, 473977420, -5, 12.5)
    ri = read_command(GCS.parsed(mi))
    assert ri.message == "COMMAND_INT" and ri.confirmation == 0
    assert ri.params == (1.5, 0.0, 0.0, 0.0, 473977420.0, -5.0, 12.5)


def test_addressing_and_heading_actions() -> None:
    r = request()
    assert addressed_to(r, 1, 191) and not addressed_to(r, 2, 191) and not addressed_to(r, 1, 1)
    assert not addressed_to(r, None, 191)  # our system id unknown: only 0 is ours
    assert [heading_action(v) for v in (0.0, 1.0, 2.0)] == [
        HeadingAction.REFUSE,
        HeadingAction.CONFIRM,
        HeadingAction.UNDO,
    ]
    assert all(heading_action(v) is None for v in (0.5, 3.0, -1.0, math.nan, math.inf))


def test_retransmissions_repeat_only_an_accepted_command() -> None:
    memory = Retransmissions()
    first = request(2.0)
    assert memory.repeat(first, 10.0) is None  # confirmation 0: a new command
    memory.remember(first, MAV_RESULT_ACCEPTED, 10.0)
    again = request(2.0, confirmation=1)
    assert memory.repeat(again, 11.0) == MAV_RESULT_ACCEPTED
    assert memory.repeat(request(1.0, confirmation=1), 11.0) is None  # other parameters
    assert memory.repeat(request(2.0, confirmation=1, command=31011), 11.0) is None
    other_sender = request(2.0, confirmation=1, sender=Packer(255, 191))
    assert memory.repeat(other_sender, 11.0) is None
    assert memory.repeat(again, 10.0 + RETRANSMISSION_WINDOW_S + 0.1) is None  # too late
    assert memory.repeat(again, 9.0) is None  # before it: not a retransmission
    # a command not accepted changed nothing: its retransmission is carried out again
    memory.remember(request(2.0), MAV_RESULT_DENIED, 12.0)
    assert memory.repeat(request(2.0, confirmation=1), 12.5) is None
    assert memory.repeated == 1

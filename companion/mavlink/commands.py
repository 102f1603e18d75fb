"""The MAVLink command protocol at our component: what a command asks, and retransmissions.

A ground station sends a command in COMMAND_LONG or COMMAND_INT and waits for one
COMMAND_ACK; without it, it sends the command again, COMMAND_LONG with
``confirmation`` counting up (https://mavlink.io/en/services/command.html). The
service answers every command addressed to component 191 exactly once
(``Pipeline``): this module reads the request (:func:`read_command`), says whether
it is addressed to us (:func:`addressed_to`), maps the heading command's ``param1``
(:data:`HEADING_ACTIONS`) and remembers the last answer to each sender so that a
retransmission is answered as the original was, without doing it twice
(:class:`Retransmissions`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from companion.mavlink.ids import MAV_RESULT_ACCEPTED, MAVLINK_MSG_ID_COMMAND_INT
from companion.types import HeadingAction

HEADING_ACTIONS: dict[float, HeadingAction] = {
    0.0: HeadingAction.REFUSE,
    1.0: HeadingAction.CONFIRM,
    2.0: HeadingAction.UNDO,
}
"""``param1`` of the heading command (MAV_CMD_USER_1) -> what it asks."""

RETRANSMISSION_WINDOW_S = 10.0
"""A COMMAND_LONG with ``confirmation`` > 0 repeating the last command of the same sender,
accepted within this (receive time, s), is a retransmission: its ACK was lost."""


@dataclass(frozen=True, slots=True)
class CommandRequest:
    """A COMMAND_LONG or COMMAND_INT, as the command protocol sees it.

    ``params`` are param1..param7; COMMAND_INT's ``x``, ``y`` (integers) and ``z`` stand
    as param5..7. ``confirmation`` is COMMAND_LONG's (COMMAND_INT has none: 0).
    """

    message: str
    command: int
    params: tuple[float, ...]
    confirmation: int
    source_system: int
    source_component: int
    target_system: int
    target_component: int


@dataclass(frozen=True, slots=True)
class DecodedCommand:
    """A command addressed to us, which the caller answers with exactly one COMMAND_ACK.

    ``result`` (a MAV_RESULT) when decoding already decided it (unsupported command,
    invalid parameter, no autopilot clock yet), with ``reason`` for the operator (empty:
    none); ``None`` when the sample decoded from it decides (the engine's
    :class:`~companion.types.CommandResult`).
    """

    request: CommandRequest
    result: int | None = None
    reason: str = ""


def read_command(msg: Any) -> CommandRequest:
    """The request of a COMMAND_LONG or COMMAND_INT message (pymavlink object).

    Raises
    ------
    AttributeError, TypeError, ValueError
        If a field is missing or not a number (a corrupt message).
    """
    header = msg._header
    if header.msgId == MAVLINK_MSG_ID_COMMAND_INT:
        message = "COMMAND_INT"
        params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.x, msg.y, msg.z)
        confirmation = 0
    else:
        message = "COMMAND_LONG"
        params = (
            msg.param1,
            msg.param2,
            msg.param3,
            msg.param4,
            msg.param5,
            msg.param6,
            msg.param7,
        )
        confirmation = int(msg.confirmation)
    return CommandRequest(
        message=message,
        command=int(msg.command),
        params=tuple(float(p) for p in params),
        confirmation=confirmation,
        source_system=int(header.srcSystem),
        source_component=int(header.srcComponent),
        target_system=int(msg.target_system),
        target_component=int(msg.target_component),
    )


def addressed_to(request: CommandRequest, system_id: int | None, component_id: int) -> bool:
    """For us: to our system (or to every system, 0) and our component (or to every
    component, 0). Before the system id is known only system 0 is ours."""
    return request.target_system in (0, system_id) and request.target_component in (
        0,
        component_id,
    )


def heading_action(param1: float) -> HeadingAction | None:
    """What ``param1`` of the heading command asks; ``None`` for any other value."""
    if not math.isfinite(param1):
        return None
    return HEADING_ACTIONS.get(param1)


def _same(a: CommandRequest, b: CommandRequest) -> bool:
    """The same command and parameters (NaN equal to NaN: a parameter left unset)."""
    if a.message != b.message or a.command != b.command:
        return False
    pairs = zip(a.params, b.params, strict=True)
    return all(x == y or (math.isnan(x) and math.isnan(y)) for x, y in pairs)


class Retransmissions:
    """Each sender's (system, component) last command if it was ACCEPTED, to answer its
    retransmission.

    A COMMAND_LONG with ``confirmation`` > 0, the same command and parameters as the
    sender's last one, ACCEPTED within :data:`RETRANSMISSION_WINDOW_S` before, is that
    command again (its ACK was lost): ACCEPTED again and not carried out a second time
    (undo twice would otherwise be DENIED the second time). A command not accepted
    changed nothing: carried out again, it gets the answer of the moment.
    """

    def __init__(self, window_s: float = RETRANSMISSION_WINDOW_S) -> None:
        self._window_s = window_s
        self._last: dict[tuple[int, int], tuple[CommandRequest, int, float]] = {}
        self.repeated = 0
        """Retransmissions answered from memory."""

    def repeat(self, request: CommandRequest, t_rx_s: float) -> int | None:
        """The result to send again if ``request`` is a retransmission, else ``None``."""
        if request.confirmation <= 0:
            return None
        last = self._last.get((request.source_system, request.source_component))
        if last is None:
            return None
        previous, result, t_prev_s = last
        if not 0.0 <= t_rx_s - t_prev_s <= self._window_s or not _same(request, previous):
            return None
        self.repeated += 1
        return result

    def remember(self, request: CommandRequest, result: int, t_rx_s: float) -> None:
        """``request`` was answered ``result`` (a MAV_RESULT) at receive time ``t_rx_s``:
        kept if ACCEPTED, else the sender's last command is forgotten."""
        sender = (request.source_system, request.source_component)
        if result == MAV_RESULT_ACCEPTED:
            self._last[sender] = (request, result, t_rx_s)
        else:
            self._last.pop(sender, None)

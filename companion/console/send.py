"""What the console sends to the service (component 191): encoded frames, no I/O.

The heading command (MAV_CMD_USER_1, ``param1`` 1 confirm, 0 refuse, 2 undo;
docs/mavlink.md) and the parameter protocol's list request and set. The console
speaks as a ground station: system 255, component 190 (MAV_COMP_ID_MISSIONPLANNER).
"""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from companion.mavlink.ids import MAV_CMD_USER_1, MAV_COMP_ID_ONBOARD_COMPUTER

GCS_SYSTEM = 255
GCS_COMPONENT = 190
MAV_PARAM_TYPE_REAL32 = 9


class Sender:
    """Encodes the console's requests (one MAVLink 2 encoder, its own sequence)."""

    def __init__(self) -> None:
        self.mav = mavlink.MAVLink(None, srcSystem=GCS_SYSTEM, srcComponent=GCS_COMPONENT)
        self.mav.robust_parsing = True

    def heading_command(self, target_system: int, action: float) -> bytes:
        """COMMAND_LONG MAV_CMD_USER_1 with ``param1`` = action (1 confirm, 0 refuse, 2 undo)."""
        msg = self.mav.command_long_encode(
            target_system,
            MAV_COMP_ID_ONBOARD_COMPUTER,
            MAV_CMD_USER_1,
            0,
            action,
            0,
            0,
            0,
            0,
            0,
            0,
        )
        return bytes(msg.pack(self.mav))

    def param_request_list(self, target_system: int) -> bytes:
        msg = self.mav.param_request_list_encode(target_system, MAV_COMP_ID_ONBOARD_COMPUTER)
        return bytes(msg.pack(self.mav))

    def param_request_read(self, target_system: int, index: int) -> bytes:
        """PARAM_REQUEST_READ by index (a value lost from the list is asked for again)."""
        msg = self.mav.param_request_read_encode(
            target_system, MAV_COMP_ID_ONBOARD_COMPUTER, b"", index
        )
        return bytes(msg.pack(self.mav))

    def param_set(
        self, target_system: int, name: str, value: float, param_type: int | None = None
    ) -> bytes:
        """PARAM_SET (the service types the value from its own table; docs/params.md)."""
        msg = self.mav.param_set_encode(
            target_system,
            MAV_COMP_ID_ONBOARD_COMPUTER,
            name.encode("ascii"),
            float(value),
            MAV_PARAM_TYPE_REAL32 if param_type is None else param_type,
        )
        return bytes(msg.pack(self.mav))

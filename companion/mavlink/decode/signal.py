"""GNSS_INTEGRITY (441, MAVLink's development set) -> :class:`GnssSignalReport`: the
receiver's own jamming and spoofing flags as the autopilot relays them.

* **Which receiver.** PX4 sends the GNSS_INTEGRITY of its first GPS (``sensor_gps``
  instance 0) with that receiver's *device id* in ``id`` (the low byte of a 32-bit id,
  PX4 ``mavlink/streams/GNSS_INTEGRITY.hpp``): from a PX4 autopilot it is receiver 0.
  From any other autopilot ``id`` 0 or 1 is that receiver (GPS_RAW_INT, GPS2_RAW), as the
  message's definition asks; another id is rejected (``unknown_receiver``).
* **Time.** The message has none: the latest autopilot time.
* **States.** ``jamming_state`` and ``spoofing_state`` (GPS_JAMMING_STATE,
  GPS_SPOOFING_STATE: 0 unknown, 1 none, 2 mitigated, 3 detected) become
  :class:`~companion.types.InterferenceState`; any other value is rejected
  (``bad_enum``). PX4 sends 3 for u-blox's "spoofing indicated" as well as "multiple
  indications", and for "jamming warning" as well as "critical"; with no GPS it sends
  the message with its states 0 (unknown) once a second.

The report's ``source`` is ``"autopilot"``: the receiver's own verdict
(:mod:`companion.integrity.signal`). ArduPilot's dialect does not carry message 441: an
ArduPilot never sends it. The service reads it only when the dialect it parses with
(``[encoder] dialect``) knows it (``development``, ``all``); a PX4 log (.ulg) carries the
same flags whatever the dialect (:mod:`companion.mavlink.logs.ulog`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from companion.mavlink.decode.clock import BootClock
from companion.mavlink.decode.rejections import Rejected
from companion.types import AutopilotFlavour, GnssSignalReport, InterferenceState

STATES = (
    InterferenceState.UNKNOWN,
    InterferenceState.CLEAN,
    InterferenceState.MITIGATED,
    InterferenceState.DETECTED,
)
"""GPS_JAMMING_STATE / GPS_SPOOFING_STATE 0..3 (the two enums share their values)."""
SOURCE = "autopilot"


def _state(value: int) -> InterferenceState:
    if not 0 <= value < len(STATES):
        raise Rejected("bad_enum")
    return STATES[value]


class SignalDecoder:
    """The GNSS_INTEGRITY handler (``(msg, t_rx_s) -> sample``, raising :class:`Rejected`)."""

    def __init__(self, clock: BootClock, flavour: Callable[[], AutopilotFlavour]) -> None:
        self._now = clock.now
        self._flavour = flavour

    def gnss_integrity(self, msg: Any, t_rx_s: float) -> GnssSignalReport:
        """GNSS_INTEGRITY: the receiver's own jamming and spoofing states."""
        jamming = _state(int(msg.jamming_state))
        spoofing = _state(int(msg.spoofing_state))
        if self._flavour() is AutopilotFlavour.PX4:
            receiver = 0
        else:
            receiver = int(msg.id)
            if receiver not in (0, 1):
                raise Rejected("unknown_receiver")
        jam_text: tuple[str, ...] = ()
        spoof_text: tuple[str, ...] = ()
        if jamming in (InterferenceState.MITIGATED, InterferenceState.DETECTED):
            jam_text = (f"receiver jamming {jamming.value} (GNSS_INTEGRITY)",)
        if spoofing in (InterferenceState.MITIGATED, InterferenceState.DETECTED):
            spoof_text = (f"receiver spoofing {spoofing.value} (GNSS_INTEGRITY)",)
        return GnssSignalReport(
            t_s=self._now(),
            receiver_id=receiver,
            source=SOURCE,
            jamming=jamming,
            spoofing=spoofing,
            evidence=jam_text + spoof_text,
            spoofing_evidence=spoof_text,
        )

"""What fault detection keeps of each GNSS receiver between its fixes."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from companion.nav.navigator import GnssMeasurement


@dataclass(slots=True)
class ReceiverState:
    """One receiver's latest fix, exclusion and innovation, for the tests of later fixes."""

    last_meas: GnssMeasurement | None = None
    """Its latest fix (local NED frame): the other receivers are separated from it."""
    excluded_until_s: float = -math.inf
    """Excluded (its fixes not fused) until this time, s."""
    alerted: bool = False
    """Its FAULT alert was sent for the current fault (one alert per fault, not per fix)."""
    last_fail_t_s: float = -math.inf
    """Time of its last failed test, s."""
    last_nis: float = 0.0
    """The navigator's last NIS for this receiver, per degree of freedom."""
    last_nis_t_s: float = -math.inf
    """Time of that NIS, s."""
    shown_wrong_until_s: float = -math.inf
    """A separation test (against another receiver or a reference) blamed it: until this
    time its exclusion rests on independent evidence, not on the innovation alone."""


def is_excluded(
    receivers: Mapping[int, ReceiverState], receiver_id: int, now_s: float | None
) -> bool:
    """True when ``receiver_id`` is excluded at ``now_s`` (None: no time yet, nothing is)."""
    rx = receivers.get(receiver_id)
    if rx is None or now_s is None:
        return False
    return now_s < rx.excluded_until_s

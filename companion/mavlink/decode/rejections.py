"""Why a message gave no sample: the exception the checks raise, and the counting.

Each rejection reason is counted; it is logged at WARNING on its 1st, 10th,
100th, 1000th... occurrence (a deterministic rate limit, no clock read), except
the benign reasons (:data:`BENIGN_REASONS`), logged at DEBUG the same way.
"""

from __future__ import annotations

import collections
import logging

logger = logging.getLogger(__name__)

BENIGN_REASONS = frozenset(
    {
        "unhandled_type",
        "own_message",
        "not_autopilot",
        "wrong_sysid",
        "repeated_fix",
        "unused_imu_stream",
        "own_injection",
    }
)
"""Reasons that are the normal traffic of a shared link, not a fault."""


class Rejected(Exception):
    """A message failed a check (the argument is the reason)."""


def count_rejection(rejections: collections.Counter[str], reason: str, count: int = 1) -> None:
    """Add ``count`` to ``rejections[reason]`` and log on each new power of ten."""
    before = rejections[reason]
    after = before + count
    rejections[reason] = after
    # log on the 1st, 10th, 100th... occurrence
    if before == 0 or len(str(after)) != len(str(before)):
        level = logging.DEBUG if reason in BENIGN_REASONS else logging.WARNING
        logger.log(level, "MAVLink input rejected: %s (%d so far)", reason, after)

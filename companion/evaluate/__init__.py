"""Scoring a replay against truth (``companion evaluate``).

Reads what the service published (the replay output ``.tlog``: only messages from
component 191, MAV_COMP_ID_ONBOARD_COMPUTER), the simulator's truth CSV and its JSON
sidecar of scheduled events, and computes:

* the position error of the published solution against the truth interpolated at the
  solution's time of validity (``GLOBAL_POSITION_INT.time_boot_ms``), horizontal and
  vertical, for the "normal" part of the flight (outside every event window) and for each
  event window separately, with the honesty check of the published 95 % accuracy;
* for each scheduled event the time from its start to the first matching alert, or "missed",
  and for faults the size of the fault at detection;
* alerts with no event behind them (false alerts);
* the taxi heading correction (``CMP HDG_READY``) against the injected heading error.

Rules (written once, here):

Time alignment
    A published solution is compared with the truth at ``t_s = time_boot_ms / 1000``
    (autopilot time of validity), never at its tlog time. Truth is interpolated linearly in
    time (longitude unwrapped, yaw unwrapped). Solutions outside the truth's time span are
    counted and left out. An autopilot reboot inside the log (``time_boot_ms`` going back
    by more than a second) is undone: the new boot's times continue the first boot's by
    the tlog time of the silence, as the simulator's truth is on the first boot's clock.
Error
    ``published - truth`` expressed in the local NED frame of the truth point itself
    (pymap3d), so long routes do not mix vertical into horizontal. Horizontal error is the
    2-D norm; vertical error is positive when the solution is above the truth.
Alert time
    STATUSTEXT has no time field. An alert's autopilot time is its tlog time minus the offset
    ``tlog_time - time_boot_ms/1000`` of the nearest *preceding* published
    GLOBAL_POSITION_INT in the log (the first one for alerts before any solution). Its error
    is the service's publication latency (one output cycle in a replay).
Honesty check
    Published 95 % horizontal accuracy = ``sqrt(chi2.ppf(0.95, 2))`` (2.45) x the 1-sigma
    ``GPS_INPUT.horiz_accuracy``; vertical = ``norm.ppf(0.975)`` (1.96) x ``vert_accuracy``.
    When the log has no GPS_INPUT (PX4), ``CMP_HACC``/``CMP_VACC`` are used. A solution takes
    the latest accuracy at or before its time, no older than :data:`ACCURACY_MAX_AGE_S`.
    Coverage is the fraction of solutions (published at a steady rate, so of time) whose
    true error is within the published 95 % figure.
Detection
    An event is detected by the first alert whose code is in :data:`EVENT_ALERT_CODES` for
    its kind, timed within ``[t_start - ALERT_EARLY_TOLERANCE_S, t_end + RECOVERY_GRACE_S]``.
    Latency is measured from ``t_start``. The fault size at detection comes from the event's
    params (step: size; ramp: rate x elapsed time; dither: amplitude).
False alerts
    An alert whose code is in :data:`FALSE_ALERT_CODES` (GNSS_LOST, RTK_LOST, GNSS_STALE,
    FAULT, INTEGRITY) is false when it lies outside every event window extended by the same
    tolerance and grace, whatever the event's kind (a protection level may legitimately
    exceed its limit during an outage). GNSS_BACK, RTK_BACK, CAT and HDG_* (and BRIDGING of
    older replays) are status reports, never false alerts.
Heading
    ``HDG_READY`` carries the mismatch ``INS heading - GNSS track`` (Markelov et al.), the
    value the service subtracts from its INS heading. With the sidecar's ``heading_error_deg`` (INS
    heading - true heading) and ``crab_deg`` (true heading - ground track), the expected value
    is ``heading_error_deg + crab_deg``; the error is the published value minus that, wrapped
    to +-180 deg. Both are read from the sidecar's top level or, failing that, from its
    ``parameters`` object (where the simulator writes them).

Modules
-------
:mod:`.run` (:func:`evaluate`), :mod:`.truth` (truth CSV, sidecar events), :mod:`.published`
(the service's messages over the flight, via :mod:`companion.mavlink.readback`),
:mod:`.score` (the rules above), :mod:`.results` (:class:`Evaluation` and its parts, JSON),
:mod:`.text` (the text report), :mod:`.plot` (the report picture, matplotlib).

References
----------
Kim, Walter and Powell, "Standalone GPS-based flight inspection system": ramp and dither
faults and their detection; Markelov et al., "INS course correction from satellite
navigation before take-off": the heading mismatch and its accuracy. ``docs/replay.md``:
the replay and evaluation contract.
"""

from companion.evaluate.published import ACCURACY_MAX_AGE_S
from companion.evaluate.results import (
    AlertRecord,
    ErrorStats,
    Evaluation,
    EvaluationError,
    EvaluationSeries,
    EventResult,
    HeadingResult,
    TlogStats,
)
from companion.evaluate.run import evaluate
from companion.evaluate.score import (
    ALERT_EARLY_TOLERANCE_S,
    EVENT_ALERT_CODES,
    FALSE_ALERT_CODES,
    H95_PER_SIGMA,
    MISMATCH_MEDIAN_DISTANCE_M,
    RECOVERY_GRACE_S,
    V95_PER_SIGMA,
)
from companion.evaluate.truth import TRUTH_COLUMNS

__all__ = [
    "ACCURACY_MAX_AGE_S",
    "ALERT_EARLY_TOLERANCE_S",
    "EVENT_ALERT_CODES",
    "FALSE_ALERT_CODES",
    "H95_PER_SIGMA",
    "MISMATCH_MEDIAN_DISTANCE_M",
    "RECOVERY_GRACE_S",
    "TRUTH_COLUMNS",
    "V95_PER_SIGMA",
    "AlertRecord",
    "ErrorStats",
    "Evaluation",
    "EvaluationError",
    "EvaluationSeries",
    "EventResult",
    "HeadingResult",
    "TlogStats",
    "evaluate",
]

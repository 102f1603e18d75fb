"""Taxi heading correction from the GNSS track (Markelov et al.).

A fast INS alignment leaves an azimuth error of about a degree. On the ground,
on straight taxi sections, the track angle of the GNSS velocity equals the
true heading (up to an airframe constant), so the mean mismatch between the
INS heading and the GNSS track over many cycles is the heading error. The
corrected heading is ``psi_ins - mean``.

A ground crab angle (heading minus track on a straight taxi: nose-wheel toe, an
antenna/IMU installation offset) is an airframe constant. Unless it is given as
``ground_crab_deg`` it is *included* in the correction, and the corrected
heading is then the track direction, not the fuselage axis.

When all acceptance criteria hold: ``CMP HDG_READY <value> ±<eps> n=<cycles>``;
the correction is applied on confirmation (:meth:`HeadingCorrector.on_command`) or
automatically (``auto_apply``), announced with ``HDG_APPLIED``, and may be undone
(``HDG_UNDONE``: READY again). When one fails: ``CMP HDG_REJECT <reason>`` and the
accumulation starts over. Its state for a ground station is
:class:`HeadingStatus` (``CMP_HDGS``).

Accuracy: with the Doppler track the cycles needed for ``eps`` grow as
``(1.96 vel_noise / (speed eps))^2`` (``bench/heading.py`` measures it);
``track_source="position"`` (the displacement over ``pos_baseline_s`` of RTK
fixed positions) removes that limit. Either way the correction is the INS
heading error *averaged over the cycles*: if the autopilot's own heading
wanders, the corrected heading inherits the wander.

Modules:

* :mod:`.config`: :class:`HeadingConfig`, the ``[heading]`` block;
* :mod:`.attitude`: the INS heading at a fix's time and the straight-section test;
* :mod:`.ground`: on the ground? (landed state or fallback inference);
* :mod:`.track`: the track angle from RTK positions;
* :mod:`.stats`: the running statistics and the cycles of the current sample;
* :mod:`.criteria`: the acceptance criteria and the parked bias test;
* :mod:`.park`: the parked GNSS velocity check;
* :mod:`.corrector`: :class:`HeadingCorrector`, the state machine;
* :mod:`.state`: the persisted state (survives a service restart).

Method notes: ``docs/methods.md``.

References
----------
Markelov et al., "INS course correction from satellite navigation before
take-off": the mismatch, the recursive mean, variance and accuracy, the
straight-section rules and the acceptance criteria. The position track, the
trend and leg tests and the standardised normality test are this package's
additions.
"""

from companion.nav.heading.attitude import RATE_BASELINE_S, yaw_rate_radps
from companion.nav.heading.config import TRACK_SOURCES, HeadingConfig
from companion.nav.heading.corrector import HeadingCorrector
from companion.nav.heading.criteria import Verdict
from companion.nav.heading.state import STATE_VERSION, HeadingPhase, HeadingStatus
from companion.nav.heading.stats import HeadingEstimate, RunningStats

__all__ = [
    "RATE_BASELINE_S",
    "STATE_VERSION",
    "TRACK_SOURCES",
    "HeadingConfig",
    "HeadingCorrector",
    "HeadingEstimate",
    "HeadingPhase",
    "HeadingStatus",
    "RunningStats",
    "Verdict",
    "yaw_rate_radps",
]

"""The service's changes to itself: what each one invalidates, re-seeded, never blamed on a
receiver.

The service adapts itself in flight: the lag it places a receiver's fixes with (measured,
:mod:`companion.engine.gnss_lag`, carried in by :mod:`companion.engine.lag_ramp`), the IMU
stamps' offset inside that measurement, the IMU noise the blend measures, the IMU grade
widened (:meth:`Engine._widen_grade`), the navigator reset or re-initialised to a receiver
(:meth:`Engine._reset_to`). Each is right on its own, but the tests that watch the
receivers remember the service as it was before: an innovation history, separation series,
inertial references anchored from the navigator, rejection clocks. Left alone, the
integrity monitor sees the service's own change as the receiver's fault.

:meth:`Engine.self_change` is the one way to say "the service changed itself at ``t``";
:data:`RESEEDS` says, per kind, what that invalidates, and :func:`reseed` re-seeds it:

* the separation series of the receiver concerned (all, for a change of the whole
  navigation) start again and forget their latest results, its innovation memory is
  cleared, and for one separation window its fix-level failures (the navigator's
  innovation, the potential filter's ellipsoid) are counted and logged, not attributed
  (:meth:`IntegrityMonitor.service_changed`);
* the outage monitor's rejection clocks start again, and after a change that moved a
  receiver's fixes a reset within that window is not alerted
  (:meth:`OutageMonitor.service_changed`);
* the inertial references, anchored from the navigator as it was, are dropped (they
  re-anchor from the next trusted state);
* the gap-bridge probes straddling the change are dropped.

A change of the measured IMU noise invalidates nothing: the blend's covariance, its gate
and its innovations' covariance follow it at once (counted and logged, as the IMU stamps'
offset, which enters only the lag measurement).

Pure: no I/O, no clock.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from companion.nav.blend import BlendNavigator

if TYPE_CHECKING:
    from companion.engine.core import Engine

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class Reseed:
    """What one kind of self-change invalidates."""

    series: bool
    """The separation series of the receiver concerned (every receiver when none is)."""
    excuse: bool
    """Its innovation memory, and its fix-level failures within the horizon are the
    service's own doing."""
    references: bool
    """The inertial references anchored from the navigator before the change."""
    rejections: bool
    """The outage monitor's rejection clocks."""
    quiet_resets: bool
    """A reset of the navigator within the horizon is the change's doing (a receiver's
    fixes moved): not alerted. Not after a reset: a second one says the navigator is
    still off, which is worth an alert."""
    probes: bool
    """The gap-bridge probes straddling the change (:mod:`.bridge_choice`)."""


_NOTHING = Reseed(
    series=False, excuse=False, references=False, rejections=False, quiet_resets=False, probes=False
)
RESEEDS: dict[str, Reseed] = {
    # the receiver's fixes placed at other times: everything that compared them before
    "lag": Reseed(
        series=True, excuse=True, references=True, rejections=True, quiet_resets=True, probes=True
    ),
    # inside the lag measurement only (added to the lag it hands out): nothing else uses it
    "stamp": _NOTHING,
    # the blend's covariance follows it at once, and with it its gate and its innovations'
    # covariance: the innovations judged before were judged with what was in use then
    "noise": _NOTHING,
    # the navigation restarted (its own restart re-seeds the rest)
    "grade": Reseed(
        series=True, excuse=True, references=True, rejections=True, quiet_resets=True, probes=True
    ),
    # the navigator moved to a receiver's fix: what compared the receivers with it (not
    # the grade check's innovations: the prediction's errors before it are evidence about
    # the IMU)
    "reset": Reseed(
        series=False,
        excuse=True,
        references=True,
        rejections=True,
        quiet_resets=False,
        probes=True,
    ),
}
"""Per kind of self-change, what it invalidates (module docstring)."""


def reseed(engine: Engine, t_s: float, kind: str, text: str, receiver_id: int | None) -> None:
    """Re-seed what a ``kind`` change at ``t_s`` invalidates (:data:`RESEEDS`); ``text``
    says what changed (logged), ``receiver_id`` which receiver's fixes it concerns (None:
    the whole navigation). Raises ValueError for an unknown kind."""
    what = RESEEDS.get(kind)
    if what is None:
        raise ValueError(f"unknown self-change {kind!r} (known: {', '.join(RESEEDS)})")
    integrity = engine.integrity
    integrity.stats[f"self_change_{kind}"] += 1
    log.info("t=%.2f s self-change (%s): %s", t_s, kind, text)
    horizon_s = integrity.config.separation_window_s
    receivers = None if receiver_id is None else [receiver_id]
    if what.series or what.excuse:
        integrity.service_changed(
            t_s,
            f"{kind}: {text}",
            receivers,
            horizon_s if what.excuse else 0.0,
            series=what.series,
        )
    if what.rejections:
        engine.outage.service_changed(t_s, receiver_id, horizon_s if what.quiet_resets else 0.0)
    if what.references and engine.coast is not None:
        engine.coast.drop_slots(f"self_change_{kind}")
    if what.probes:
        engine.bridge_evidence.reset()


class NoiseWatch:
    """Says when the blend's measured IMU noise has moved by more than ``ratio`` (either
    way) since it last said so (``ratio``: the grade check's own margin, ``min_ratio``:
    a change its innovations could see)."""

    def __init__(self, ratio: float) -> None:
        self.ratio = ratio
        self._seen: tuple[float, float] | None = None

    def moved(self, blend: object) -> str:
        """'' when not; otherwise what moved (for the log)."""
        if not isinstance(blend, BlendNavigator):
            return ""
        accel = float(max(blend.diag.accel_psd_ned))
        gyro = blend.diag.gyro_psd
        now = (accel, gyro if math.isfinite(gyro) else 0.0)
        seen, self._seen = self._seen, now
        if seen is None:
            return ""
        for name, old, new in zip(("accelerometer", "gyro"), seen, now, strict=True):
            if old > 0.0 and new > 0.0 and max(new / old, old / new) > self.ratio:
                return f"{name} noise PSD {old:.3g} -> {new:.3g}"
        self._seen = seen  # announce against the last announced, not a creeping one
        return ""

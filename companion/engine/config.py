"""The ``[engine]`` configuration block: publication rates, the local frame, the navigator.

Each field's range is declared beside it (:mod:`companion.ranges`); the one check that
relates two fields (``status_rate_hz <= publish_rate_hz``) is written out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from companion.ranges import check_ranges, ranged

NAVIGATORS = ("blend", "singer", "passthrough")
"""The navigators :attr:`EngineConfig.navigator` chooses from."""
GAP_ATTITUDES = ("auto", "autopilot", "rates")
"""The choices of :attr:`EngineConfig.gap_attitude`."""


@dataclass(frozen=True, slots=True)
class EngineConfig:
    """Publication and frame handling of the engine."""

    publish_rate_hz: float = ranged(10.0, gt=0.0, le=50.0)
    """GLOBAL_POSITION_INT / GPS_INPUT rate on the autopilot clock (5-10 Hz for GPS_INPUT).
    With ``publish_on_fix``, the rate of the publications made while no fix is fused
    (holding, bridging, a receiver slower than this)."""
    publish_on_fix: bool = True
    """Publish as soon as a fix has been fused (the GPS_INPUT built on it leaves within the
    service's own processing time of the fix's arrival), not at the next tick of
    ``publish_rate_hz``. While no fix is fused (a gap, or between the fixes of a receiver
    slower than ``publish_rate_hz``) every ``1/publish_rate_hz``; a fix expected within
    half a period is waited for until it is half a fix interval late, at most ``0.2`` s
    after the last publication (ArduPilot counts a GPS unhealthy when no message comes
    for 245 ms)."""
    min_publish_interval_s: float = ranged(0.08, ge=0.0, le=0.2)
    """With ``publish_on_fix``, two publications are never closer than this (autopilot
    clock): ArduPilot's EKF takes a GPS message only more than 70 ms after the last one it
    took, so a closer one would be dropped. A fix fused sooner is published when this has
    passed."""
    status_rate_hz: float = ranged(1.0, gt=0.0)
    """Rate of the CMP_* NAMED_VALUE_FLOAT status values."""
    reanchor_distance_m: float = ranged(20_000.0, ge=1000.0, finite=False)
    """Re-anchor the local NED frame when the solution is this far from its anchor."""
    navigator: str = ranged("blend", choices=NAVIGATORS)
    """Which navigator carries the position: 'blend' (GNSS/INS, El-Mowafy 2005; with the
    pass-through taking over while no IMU stream arrives), 'singer' (Singer's manoeuvre
    model, no IMU) or 'passthrough' (GNSS with constant-velocity extrapolation)."""
    imu_timeout_s: float = ranged(0.5, gt=0.0, le=5.0)
    """The blend carries the solution only while an IMU sample is at most this old."""
    min_imu_rate_hz: float = ranged(20.0, ge=0.0)
    """... and while the IMU's measured rate is at least this: below it the IMU cannot
    dead-reckon (a 10 Hz log, or 1 Hz through a telemetry radio) and the pass-through's
    constant velocity carries the solution instead. 0 disables the check."""
    imu_rate_hold_s: float = ranged(5.0, ge=0.0)
    """The IMU counts as usable again only after its rate has held this long (and after
    an IMU timeout): no flapping between navigators."""
    gap_attitude: str = ranged("auto", choices=GAP_ATTITUDES)
    """What carries the blend's attitude through a GNSS gap: 'autopilot' (its attitude,
    as outside gaps), 'rates' (from the gap's start, the autopilot's body rates: its
    gyros less its own bias estimate, not its attitude's corrections) or 'auto': the rates
    while the autopilot may fuse what the service publishes (a GPS of type MAV taking our
    GPS_INPUT), whose attitude through the gap is then corrected by our own output (also
    after ``gap_feed_max_h_acc_m``: what it fused stays in it), else its attitude."""
    gap_feed_max_h_acc_m: float = ranged(3.0, gt=0.0, finite=False)
    """When the autopilot may fuse what the service publishes: through a GNSS gap the
    solution is published as "no fix" (GPS_INPUT ``fix_type`` 1; GLOBAL_POSITION_INT is
    unchanged) once its horizontal accuracy (1-sigma) exceeds this, m, until GNSS is
    trusted again. Fed to the end, the autopilot follows a slowly drifting solution with
    its own attitude and wind; from there its own dead reckoning serves it better.
    ``inf``: the whole gap is fed."""
    gap_feed_no_airspeed_max_h_acc_m: float = ranged(math.inf, gt=0.0, finite=False)
    """The same limit when the autopilot's airframe has no airspeed (HEARTBEAT: a
    multirotor or a helicopter). Its filter cannot dead-reckon without a position source:
    ArduCopter's EKF3, the fix withdrawn, declared an EKF failsafe (LAND) 8 s later and
    stopped aiding 7 s after that, its position held still while the copter flew on; fed
    to the end of a 30 s gap it stayed on our solution. ``inf`` (default): fed throughout."""
    primary_receiver: int = ranged(0, choices=(0, 1))
    """The receiver fused normally; the other is fused only while this one is unusable
    (and is always the integrity monitor's independent solution)."""
    potential_bridge: bool = True
    """Without an IMU stream, carry the solution through GNSS gaps (BRIDGING) with the
    position-potential filter (Grzegorzewski 2005) instead of the pass-through's constant
    velocity."""
    potential_combine: bool = False
    """With an IMU stream, publish through gaps the INS and potential predictions combined
    by their covariances (their shared last-fix error as cross-covariance) while the two
    agree (:func:`companion.nav.potential.combine_with_ins`). Better than either alone on
    simulated RTK-fixed approaches and cruises, worse than the INS alone on a MEMS flight
    with a minute of turns (``python bench/potential.py`` measures both): off by default."""
    vertical_prior: bool = True
    """Through gaps, publish the height's change since the gap's start as the INS's (or
    the constant-velocity bridge's) combined with no change, whose variance is the spread
    of the vehicle's height changes over the gap's length in the last minute of fused
    fixes, while the two agree; after the first disagreement the INS alone to the gap's
    end (:mod:`companion.nav.vertical_prior`). Without a barometer nothing else bounds the
    INS's vertical drift (``python bench/walk_0827.py`` measures it)."""
    inertial_reference: bool = False
    """With the blend, keep free-inertial solutions coasting from staggered anchors
    (:mod:`companion.integrity.coast`, the ``[coast]`` block) as the integrity monitor's
    references: they do not contain the receivers' recent fixes, so a slow vertical ramp or
    a sub-metre dither shows against them even with one receiver (the separation set of
    Kim, Walter and Powell). Worth its cost with a tactical IMU; a MEMS IMU drifts too fast
    to catch anything the innovation test misses (``python bench/integrity.py`` measures
    both)."""
    potential_fix_test: bool = False
    """Test each fix of the fused receiver against the potential prediction's ellipsoid
    (Grzegorzewski 2005) in the integrity monitor. Off by default: the prediction has no
    acceleration, so the test trips at manoeuvre onsets (turns, rotation) where the blend's
    innovation test, with the IMU, does not."""

    silence_timeout_s: float = ranged(2.0, gt=0.0, le=60.0)
    """No IMU, attitude or GNSS sample from the autopilot for this long is a silence:
    ``NO_DATA``, no position published, and the navigation restarts from the first fix
    after it (``DATA_BACK``). Far above the gaps of a live stream (10-50 Hz), twice those
    of a 1 Hz telemetry recording. Sooner when the GNSS loss falls due while every stream
    is stalled (:mod:`companion.engine.silence`): ``NO_DATA`` then says the loss."""
    silence_intervals: float = ranged(2.0, ge=1.0)
    """A link whose data samples come with longer pauses (a ground station's 1 Hz
    telemetry) is silent only after this many times the longest of its recent pauses
    that were no silence (:mod:`companion.engine.silence`) ..."""
    silence_timeout_max_s: float = ranged(5.0, gt=0.0, le=60.0)
    """... at most this long (s); at or below ``silence_timeout_s`` the timeout is fixed."""
    no_gnss_alert_s: float = ranged(3.0, gt=0.0, le=60.0)
    """No usable fix this long after the autopilot's first sample (or after a silence):
    ``NO_GNSS``, the service is not navigating."""
    no_gnss_repeat_s: float = ranged(30.0, gt=0.0)
    """``NO_GNSS`` is repeated at this interval while no usable fix arrives."""
    baro_in_blend: bool = True
    """Through a GNSS gap, fuse the barometer's height (calibrated against trusted GNSS
    before the gap, :mod:`companion.nav.baro`) into the blend as a down-position
    measurement: height is what an IMU loses first (El-Mowafy 2005)."""
    imu_grade_check: bool = True
    """Compare the IMU's measured white noise with the blend's configured grade when that
    grade is narrower than a MEMS autopilot IMU's; when it is noisier, ``IMU_GRADE``, the
    MEMS grade and a restart from the next fix (no receiver blamed)."""

    def __post_init__(self) -> None:
        check_ranges(self)
        if self.status_rate_hz > self.publish_rate_hz:
            raise ValueError(
                f"status_rate_hz must be <= publish_rate_hz ({self.publish_rate_hz:g}), "
                f"got {self.status_rate_hz!r}"
            )

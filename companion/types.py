"""Typed samples (into the core) and outputs (out of it).

Conventions (docs/architecture.md):

* SI units and radians everywhere; every name carries frame and unit
  (``acc_b_mps2`` is specific force in the body frame, ``vel_ned_mps`` velocity
  in the local North-East-Down frame).
* ``t_s`` is the one estimation clock: the autopilot's own time since its boot,
  reconstructed by :mod:`companion.mavlink.decode` (wrap, epoch-stamped GNSS and
  reboots handled there). ``t_rx_s`` is when the message was received (wall time
  live, log time in a replay): for latency figures only, never for estimation.
* Vectors are 1-D ``numpy`` arrays of float64, never (n, 1) columns.
* Every dataclass is frozen and slotted: a sample is a fact, not a workspace.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
"""A float64 array; its shape is stated where it is used."""


def largest_eigenvalue_2x2(a: float, b: float, c: float) -> float:
    """Largest eigenvalue of the symmetric 2x2 matrix [[a, b], [b, c]] (closed form)."""
    h = 0.5 * (a - c)
    return 0.5 * (a + c) + math.sqrt(h * h + b * b)


def largest_eigenvalue_3x3(m: list[list[float]]) -> float:
    """Largest eigenvalue of a symmetric 3x3 matrix (trigonometric closed form).

    Same value as ``numpy.linalg.eigvalsh(m)[-1]`` to rounding, at a small fraction
    of the cost (``tests/test_types.py``).

    References
    ----------
    O. K. Smith, "Eigenvalues of a symmetric 3x3 matrix", Comm. ACM 4(4), 1961.
    """
    a00, a01, a02 = m[0]
    a11, a12 = m[1][1], m[1][2]
    a22 = m[2][2]
    p1 = a01 * a01 + a02 * a02 + a12 * a12
    if p1 == 0.0:
        return max(a00, a11, a22)
    q = (a00 + a11 + a22) / 3.0
    b00, b11, b22 = a00 - q, a11 - q, a22 - q
    p = math.sqrt((b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * p1) / 6.0)
    det = (
        b00 * (b11 * b22 - a12 * a12)
        - a01 * (a01 * b22 - a12 * a02)
        + a02 * (a01 * a12 - b11 * a02)
    )
    r = det / (2.0 * p * p * p)
    r = -1.0 if r < -1.0 else 1.0 if r > 1.0 else r
    return q + 2.0 * p * math.cos(math.acos(r) / 3.0)


class FixType(enum.IntEnum):
    """GNSS fix type as MAVLink's GPS_FIX_TYPE."""

    NO_GPS = 0
    NO_FIX = 1
    FIX_2D = 2
    FIX_3D = 3
    DGPS = 4
    RTK_FLOAT = 5
    RTK_FIXED = 6
    STATIC = 7
    PPP = 8


class LandedState(enum.IntEnum):
    """MAV_LANDED_STATE from EXTENDED_SYS_STATE."""

    UNDEFINED = 0
    ON_GROUND = 1
    IN_AIR = 2
    TAKEOFF = 3
    LANDING = 4


class AutopilotFlavour(enum.Enum):
    """Which autopilot family is on the other end; decides GPS_INPUT vs GLOBAL_POSITION_SENSOR."""

    ARDUPILOT = "ardupilot"
    PX4 = "px4"
    UNKNOWN = "unknown"


class NavMode(enum.Enum):
    """Mode of the navigation, set by the outage management (:mod:`companion.nav.outage`)."""

    INIT = "init"  # no trusted fix yet
    NORMAL = "normal"  # fusing good GNSS
    DEGRADED = "degraded"  # GNSS present but downgraded (RTK lost, accuracy jump)
    BRIDGING = "bridging"  # no usable GNSS: carried by the motion model
    REACQUIRING = "reacquiring"  # GNSS back, not yet trusted (gate)
    LOST = "lost"  # bridging too long: no position worth publishing


class Severity(enum.IntEnum):
    """MAV_SEVERITY."""

    EMERGENCY = 0
    ALERT = 1
    CRITICAL = 2
    ERROR = 3
    WARNING = 4
    NOTICE = 5
    INFO = 6
    DEBUG = 7


class AlertCode(enum.Enum):
    """First word after ``CMP `` in a STATUSTEXT (the alert catalogue: docs/mavlink.md)."""

    GNSS_LOST = "GNSS_LOST"
    RTK_LOST = "RTK_LOST"
    RTK_BACK = "RTK_BACK"
    GNSS_STALE = "GNSS_STALE"
    GNSS_BACK = "GNSS_BACK"
    GNSS_SLOW = "GNSS_SLOW"
    GNSS_STEADY = "GNSS_STEADY"
    FAULT = "FAULT"
    INTEGRITY = "INTEGRITY"
    CAT = "CAT"
    HDG_READY = "HDG_READY"
    HDG_APPLIED = "HDG_APPLIED"
    HDG_REJECT = "HDG_REJECT"
    HDG_ACCUM = "HDG_ACCUM"
    HDG_IDLE = "HDG_IDLE"
    HDG_UNDONE = "HDG_UNDONE"
    HDG_RESTORED = "HDG_RESTORED"
    HDG_CMD = "HDG_CMD"
    NO_DATA = "NO_DATA"
    DATA_BACK = "DATA_BACK"
    NO_GNSS = "NO_GNSS"
    AP_CONFIG = "AP_CONFIG"
    IMU_GRADE = "IMU_GRADE"
    RAW_FAULT = "RAW_FAULT"
    RAW_LOST = "RAW_LOST"
    RAW_BACK = "RAW_BACK"
    SPOOF = "SPOOF"
    """A receiver suspected of lying consistently (its motion against the IMU's, the
    barometer's, another receiver's or the carrier phase's; its own or the autopilot's
    spoofing flag), with the evidence."""
    SPOOF_END = "SPOOF_END"
    """The receiver agrees with the independent references again (or they were shown
    wrong)."""
    JAM = "JAM"
    """Jamming suspected or reported (C/N0 down, the receiver's own jamming state)."""
    JAM_END = "JAM_END"
    """No jamming any more."""


class InterferenceState(enum.Enum):
    """A receiver's (or the service's) verdict on jamming or spoofing, as MAVLink's
    GPS_JAMMING_STATE / GPS_SPOOFING_STATE say it (the encoder maps it)."""

    UNKNOWN = "unknown"  # not monitored, or no verdict yet
    CLEAN = "clean"  # monitored: none
    MITIGATED = "mitigated"  # present, and mitigated (e.g. the receiver excluded)
    DETECTED = "detected"  # present


class HeadingAction(enum.Enum):
    """What the ground station asks of the taxi heading correction (docs/mavlink.md)."""

    REFUSE = "refuse"  # drop the READY candidate: the accumulation starts over
    CONFIRM = "confirm"  # apply the READY candidate
    UNDO = "undo"  # remove the applied correction: back to the uncorrected heading


class CommandOutcome(enum.Enum):
    """The engine's answer to an operator command (the pipeline sends it as COMMAND_ACK)."""

    ACCEPTED = "accepted"  # done, or already so (a repeated command changes nothing)
    TEMPORARILY_REJECTED = "temporarily_rejected"  # not now: may succeed later
    DENIED = "denied"  # not in this state, or not a valid request: retrying will not help
    FAILED = "failed"  # valid, but carrying it out failed


# --------------------------------------------------------------------------- samples in


@dataclass(frozen=True, slots=True)
class ImuSample:
    """One IMU reading (RAW_IMU / SCALED_IMU[2,3] / HIGHRES_IMU).

    ``acc_b_mps2`` is specific force (what an accelerometer measures: at rest
    level it reads about (0, 0, -9.81) in FRD body axes), shape (3,).
    ``gyro_b_radps`` is angular rate in body axes, shape (3,).
    """

    t_s: float
    t_rx_s: float
    acc_b_mps2: FloatArray
    gyro_b_radps: FloatArray
    imu_id: int = 0
    source: str = ""


@dataclass(frozen=True, slots=True)
class AttitudeSample:
    """The autopilot's attitude (ATTITUDE or ATTITUDE_QUATERNION), body FRD to NED.

    ``rate_b_radps`` is the body angular rate the autopilot reports, shape (3,).
    """

    t_s: float
    t_rx_s: float
    roll_rad: float
    pitch_rad: float
    yaw_rad: float
    rate_b_radps: FloatArray


@dataclass(frozen=True, slots=True)
class BaroSample:
    """One barometer reading (SCALED_PRESSURE / SCALED_PRESSURE2, HIGHRES_IMU's abs_pressure).

    ``pressure_pa`` is the static (absolute) pressure, Pa; ``temperature_c`` the sensor's
    temperature, deg C (``None`` when not reported); ``baro_id`` 0 for SCALED_PRESSURE and
    HIGHRES_IMU, 1 for SCALED_PRESSURE2.
    """

    t_s: float
    t_rx_s: float
    pressure_pa: float
    temperature_c: float | None
    baro_id: int = 0
    source: str = ""


@dataclass(frozen=True, slots=True)
class GnssFix:
    """One GNSS fix (GPS_RAW_INT: receiver 0, GPS2_RAW: receiver 1).

    MAVLink's GPS_RAW_INT carries ground speed and course, not a vertical
    velocity: ``vel_ne_mps`` (shape (2,)) is derived from them and is ``None``
    when the course is unknown. Accuracies are 1-sigma and ``None`` when the
    receiver did not report them (MAVLink's 0 / UINT16_MAX "unknown").
    ``t_s`` is the time of validity of the fix on the autopilot clock: its stamp less
    ``placed_s``, the lag the service placed it with (changed only by the service: a lag
    measured and carried in, a parameter read).
    """

    t_s: float
    t_rx_s: float
    receiver_id: int
    fix_type: FixType
    lat_rad: float
    lon_rad: float
    alt_msl_m: float
    alt_hae_m: float | None
    vel_ne_mps: FloatArray | None
    ground_speed_mps: float
    course_rad: float | None
    h_acc_m: float | None
    v_acc_m: float | None
    vel_acc_mps: float | None
    hdop: float | None
    vdop: float | None
    satellites: int | None
    dgps_age_s: float | None = None
    placed_s: float = 0.0


@dataclass(frozen=True, slots=True)
class RtkStatus:
    """GPS_RTK / GPS2_RTK: health and baseline of the RTK solution (receiver 0 / 1).

    ``health`` and ``accuracy`` are the receiver's own figures as MAVLink carries
    them; ``rate_hz`` is the rate of the corrections received; ``baseline_m``
    (shape (3,)) is the baseline to the base station in the frame MAVLink's
    ``baseline_coords_type`` gives (ECEF or NED); ``iar_num_hypotheses`` is the
    number of integer-ambiguity hypotheses still open.
    """

    t_s: float
    t_rx_s: float
    receiver_id: int
    health: int
    rate_hz: float
    satellites: int
    baseline_m: FloatArray
    accuracy: int
    iar_num_hypotheses: int


@dataclass(frozen=True, slots=True)
class HeartbeatSample:
    """The autopilot's HEARTBEAT (carries no time of its own: ``t_s`` is the last known)."""

    t_s: float
    t_rx_s: float
    system_id: int
    autopilot: int  # MAV_AUTOPILOT
    vehicle_type: int  # MAV_TYPE
    armed: bool
    system_status: int  # MAV_STATE


@dataclass(frozen=True, slots=True)
class LandedStateSample:
    """EXTENDED_SYS_STATE (no time of its own: ``t_s`` is the last known)."""

    t_s: float
    t_rx_s: float
    landed_state: LandedState


@dataclass(frozen=True, slots=True)
class VfrHudSample:
    """VFR_HUD (no time of its own: ``t_s`` is the last known)."""

    t_s: float
    t_rx_s: float
    airspeed_mps: float
    ground_speed_mps: float
    heading_rad: float
    alt_msl_m: float
    climb_mps: float


@dataclass(frozen=True, slots=True)
class AutopilotSolution:
    """The autopilot's own GLOBAL_POSITION_INT: kept for comparison only."""

    t_s: float
    t_rx_s: float
    lat_rad: float
    lon_rad: float
    alt_msl_m: float
    vel_ned_mps: FloatArray
    yaw_rad: float | None


@dataclass(frozen=True, slots=True)
class RebootEvent:
    """The autopilot rebooted (its boot clock restarted). ``t_s`` is on the new clock."""

    t_s: float
    t_rx_s: float
    previous_t_s: float


@dataclass(frozen=True, slots=True)
class HeadingCommand:
    """The ground station confirmed, refused or undid the heading correction."""

    t_s: float
    t_rx_s: float
    action: HeadingAction


@dataclass(frozen=True, slots=True)
class RawSolution:
    """A position from the raw receiver's carrier phase (T-D PRP, Kim, Walter and Powell)
    with its own integrity verdict (FIS-RAIM), on the autopilot clock.

    ``t_s`` is the receiver epoch's GPS time mapped onto the autopilot's time (the
    raw-link edge does it: :mod:`companion.raw.link`). ``pos_cov_ned_m2`` and
    ``vel_cov_ned_m2ps2`` are (3, 3) in the NED axes at the position; the position's
    covariance includes the error of the epoch-0 position the solution is anchored
    at. ``anchor_t_s`` is when the solution's error last changed character (its epoch
    0, or trust regained after a fault): a separation series against it starts there.
    ``fis_available`` is False where a subset's predicted separation is too noisy to
    test (no verdict); ``slope_alert`` / ``residual_alert`` are FIS-RAIM's tests at this
    epoch; ``fault`` stands from an alert until FIS-RAIM has passed long enough again.
    """

    t_s: float
    t_rx_s: float
    lat_rad: float
    lon_rad: float
    alt_msl_m: float
    vel_ned_mps: FloatArray
    pos_cov_ned_m2: FloatArray
    vel_cov_ned_m2ps2: FloatArray
    anchor_t_s: float
    satellites: int
    fis_available: bool
    slope_alert: bool
    residual_alert: bool
    fault: bool

    @property
    def trusted(self) -> bool:
        """FIS-RAIM tested the solution and no fault stands: it may judge a receiver."""
        return self.fis_available and not (self.fault or self.slope_alert or self.residual_alert)


@dataclass(frozen=True, slots=True)
class GnssSignalReport:
    """Signal-level evidence about one receiver at autopilot time ``t_s``: what the
    receiver itself, the autopilot (GNSS_INTEGRITY, PX4's GPS flags) or the raw link's own
    tests (C/N0, clock, Doppler) say about jamming and spoofing.

    ``source`` names who says it: ``"autopilot"`` (the receiver's own flags relayed by
    the autopilot), ``"receiver"`` (the receiver's own indicators read on the raw link),
    ``"raw"`` (the raw link's own signal tests); the first two are the receiver's own
    verdict (:mod:`companion.integrity.signal`). ``jam_indicator`` is the receiver's
    jamming indicator scaled to 0..1 (None: not given); ``evidence`` short
    human-readable reasons (``"C/N0 spread 0.6 dB-Hz over 9 sats"``) for the alert text,
    of which ``spoofing_evidence`` are those about spoofing (the rest are about jamming).
    """

    t_s: float
    receiver_id: int
    source: str
    jamming: InterferenceState = InterferenceState.UNKNOWN
    spoofing: InterferenceState = InterferenceState.UNKNOWN
    jam_indicator: float | None = None
    evidence: tuple[str, ...] = ()
    spoofing_evidence: tuple[str, ...] = ()


Sample = (
    ImuSample
    | AttitudeSample
    | BaroSample
    | GnssFix
    | RtkStatus
    | HeartbeatSample
    | LandedStateSample
    | VfrHudSample
    | AutopilotSolution
    | RebootEvent
    | HeadingCommand
    | RawSolution
    | GnssSignalReport
)
"""Anything the decoder gives the engine (:meth:`companion.engine.Engine.handle`)."""


# --------------------------------------------------------------------------- outputs


@dataclass(frozen=True, slots=True)
class NavSolution:
    """The published navigation solution, valid at autopilot time ``t_s``.

    ``pos_cov_ned_m2`` and ``vel_cov_ned_m2ps2`` are 3x3 covariances in the
    local NED frame. ``fix_type`` is what the solution honestly is (never RTK
    while bridging; NO_FIX when integrity is lost). ``yaw_rad`` is the
    (corrected) heading, ``None`` when unknown.
    """

    t_s: float
    lat_rad: float
    lon_rad: float
    alt_msl_m: float
    vel_ned_mps: FloatArray
    pos_cov_ned_m2: FloatArray
    vel_cov_ned_m2ps2: FloatArray
    yaw_rad: float | None
    mode: NavMode
    fix_type: FixType
    satellites: int
    alt_hae_m: float | None = None

    @property
    def h_acc_m(self) -> float:
        """Horizontal 1-sigma accuracy: sqrt of the larger eigenvalue of the N-E covariance."""
        (a, b, _), (_, c, _) = self.pos_cov_ned_m2[:2].tolist()
        return math.sqrt(max(largest_eigenvalue_2x2(a, b, c), 0.0))

    @property
    def v_acc_m(self) -> float:
        """Vertical 1-sigma accuracy."""
        return float(np.sqrt(max(self.pos_cov_ned_m2[2, 2], 0.0)))

    @property
    def vel_acc_mps(self) -> float:
        """Speed 1-sigma accuracy: sqrt of the largest velocity-covariance eigenvalue."""
        return math.sqrt(max(largest_eigenvalue_3x3(self.vel_cov_ned_m2ps2.tolist()), 0.0))


@dataclass(frozen=True, slots=True)
class Alert:
    """An alert for STATUSTEXT: published as ``CMP <code> <text>``."""

    t_s: float
    code: AlertCode
    severity: Severity
    text: str = ""


@dataclass(frozen=True, slots=True)
class NamedValue:
    """A NAMED_VALUE_FLOAT (name at most 10 characters, e.g. ``CMP_HPL``)."""

    t_s: float
    name: str
    value: float


@dataclass(frozen=True, slots=True)
class IntegrityReport:
    """Integrity summary for GNSS_INTEGRITY (where the dialect carries it)."""

    t_s: float
    hpl_m: float
    vpl_m: float
    integrity_ok: bool
    fault_detected: bool
    spoofing: InterferenceState = InterferenceState.UNKNOWN
    jamming: InterferenceState = InterferenceState.UNKNOWN


@dataclass(frozen=True, slots=True)
class CommandResult:
    """The answer to an operator command (:class:`HeadingCommand`): its outcome and, unless
    accepted, the reason for the operator (STATUSTEXT). Exactly one per command."""

    t_s: float
    outcome: CommandOutcome
    reason: str = ""


Output = NavSolution | Alert | NamedValue | IntegrityReport | CommandResult

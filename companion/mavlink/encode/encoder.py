"""The encoder: builds the service's outgoing messages from typed outputs.

What each output becomes and the field choices are described in
:mod:`companion.mavlink.encode`; packing is :class:`~.packing.Packer`'s.
"""

from __future__ import annotations

import collections
import logging
import math
from collections.abc import Callable
from typing import Any, cast

import numpy as np

from companion.mavlink import units
from companion.mavlink.dialect import load_dialect
from companion.mavlink.encode.config import LIVE_KEYS, EncoderConfig
from companion.mavlink.encode.packing import Packer
from companion.mavlink.ids import (
    ALERT_PREFIX,
    GLOBAL_POSITION_PRIMARY,
    GLOBAL_POSITION_SRC_ESTIMATOR,
    GLOBAL_POSITION_UNHEALTHY,
    GPS_JAMMING_STATE_DETECTED,
    GPS_JAMMING_STATE_MITIGATED,
    GPS_JAMMING_STATE_NOT_JAMMED,
    GPS_JAMMING_STATE_UNKNOWN,
    GPS_RAIM_STATE_FAILED,
    GPS_RAIM_STATE_OK,
    GPS_SPOOFING_STATE_DETECTED,
    GPS_SPOOFING_STATE_MITIGATED,
    GPS_SPOOFING_STATE_NOT_SPOOFED,
    GPS_SPOOFING_STATE_UNKNOWN,
    MAV_AUTOPILOT_INVALID,
    MAV_COMP_ID_AUTOPILOT1,
    MAV_COMP_ID_ONBOARD_COMPUTER,
    MAV_STATE_FLIGHT_TERMINATION,
    MAV_TYPE_ONBOARD_CONTROLLER,
    MAVLINK_VERSION,
    NAMED_VALUE_MAX_CHARS,
    STATUSTEXT_MAX_CHARS,
    STATUSTEXT_MAX_CHUNKS,
)
from companion.nav.earth import radii_of_curvature_m
from companion.types import (
    Alert,
    AlertCode,
    AutopilotFlavour,
    FixType,
    IntegrityReport,
    InterferenceState,
    NamedValue,
    NavMode,
    NavSolution,
    Output,
    largest_eigenvalue_2x2,
    largest_eigenvalue_3x3,
)

logger = logging.getLogger(__name__)

_INT16_MAX = 32767
_UINT16_CAP = 65534
_CDEG_FULL = 36000
_F64 = np.dtype(np.float64)
# plain-int and module-level copies of enum members and units, for the per-solution path
_FIX_3D = int(FixType.FIX_3D)
_RTK_FIXED = int(FixType.RTK_FIXED)
_ARDUPILOT = AutopilotFlavour.ARDUPILOT
_PX4 = AutopilotFlavour.PX4
FEEDBACK_HOLD_MODES = frozenset({NavMode.BRIDGING, NavMode.LOST, NavMode.REACQUIRING})
"""With :attr:`Encoder.feedback_guard`: modes in which PX4 gets no GLOBAL_POSITION_SENSOR
(from GNSS lost until GNSS is trusted again)."""
_NO_FIX = int(FixType.NO_FIX)
_DEGE7_PER_RAD = units.DEGE7_PER_RAD
_MM_PER_M = units.MM_PER_M
_CM_PER_M = units.CM_PER_M
_MS_PER_S = units.MS_PER_S
_US_PER_S = units.US_PER_S
_CDEG_PER_RAD = units.CDEG_PER_RAD
_TWO_PI = 2.0 * math.pi


JAMMING_STATE = {
    InterferenceState.UNKNOWN: GPS_JAMMING_STATE_UNKNOWN,
    InterferenceState.CLEAN: GPS_JAMMING_STATE_NOT_JAMMED,
    InterferenceState.MITIGATED: GPS_JAMMING_STATE_MITIGATED,
    InterferenceState.DETECTED: GPS_JAMMING_STATE_DETECTED,
}
"""GNSS_INTEGRITY ``jamming_state`` of the service's verdict."""
SPOOFING_STATE = {
    InterferenceState.UNKNOWN: GPS_SPOOFING_STATE_UNKNOWN,
    InterferenceState.CLEAN: GPS_SPOOFING_STATE_NOT_SPOOFED,
    InterferenceState.MITIGATED: GPS_SPOOFING_STATE_MITIGATED,
    InterferenceState.DETECTED: GPS_SPOOFING_STATE_DETECTED,
}
"""GNSS_INTEGRITY ``spoofing_state`` of the service's verdict."""

_ASCII_SPELLING = str.maketrans({"±": "+/-", "°": "deg", "σ": "sigma", "—": "-"})


def _floats(value: Any, shape: tuple[int, ...]) -> list[Any]:
    """``value`` (a vector or a 3x3 matrix of ``shape``) as (nested) lists of Python floats.

    A float64 array of that shape, what the engine publishes, is converted in one call;
    anything else goes through the general conversion (ValueError/TypeError if it cannot
    be read as that shape).
    """
    if type(value) is np.ndarray and value.dtype == _F64 and value.shape == shape:
        return value.tolist()  # type: ignore[no-any-return]
    if shape == (3,):
        vn, ve, vd = (float(v) for v in value)
        return [vn, ve, vd]
    # cast: numpy's stubs type tolist() by the array's static shape, which reshape(shape)
    # does not give (under Python 3.10 they infer a scalar)
    return cast("list[Any]", np.asarray(value, dtype=np.float64).reshape(shape).tolist())


def _clamp_int(v: float, lo: int, hi: int) -> int:
    return lo if v < lo else hi if v > hi else int(round(v))


def _carried_forward(
    lat_rad: float, lon_rad: float, alt_m: float, vn_mps: float, ve_mps: float, dt_s: float
) -> tuple[int, int]:
    """Latitude and longitude (degE7) ``dt_s`` later at the horizontal velocity (NED)."""
    m_m, n_m = radii_of_curvature_m(lat_rad)
    lat = lat_rad + vn_mps * dt_s / (m_m + alt_m)
    lon = lon_rad + ve_mps * dt_s / ((n_m + alt_m) * math.cos(lat_rad))
    return (
        _clamp_int(lat * _DEGE7_PER_RAD, -900_000_000, 900_000_000),
        _clamp_int(lon * _DEGE7_PER_RAD, -1_800_000_000, 1_800_000_000),
    )


ALERT_FAMILIES: dict[AlertCode, str] = {
    AlertCode.NO_GNSS: "gnss",
    AlertCode.GNSS_LOST: "gnss",
    AlertCode.GNSS_BACK: "gnss",
    AlertCode.RTK_LOST: "rtk",
    AlertCode.RTK_BACK: "rtk",
    AlertCode.NO_DATA: "data",
    AlertCode.DATA_BACK: "data",
    AlertCode.RAW_FAULT: "raw",
    AlertCode.RAW_LOST: "raw",
    AlertCode.RAW_BACK: "raw",
    AlertCode.GNSS_SLOW: "rate",
    AlertCode.GNSS_STEADY: "rate",
    AlertCode.SPOOF: "spoof",
    AlertCode.SPOOF_END: "spoof",
    AlertCode.JAM: "jam",
    AlertCode.JAM_END: "jam",
}
"""Alerts that say one state (GNSS, RTK, the data streams, the raw receiver, the fix
rate, spoofing, jamming): a change of it is always sent, whatever
``statustext_min_interval_s``; only repeats of the state last sent are thinned."""

STATE_OF_ALERT: dict[AlertCode, Callable[[Alert], object]] = {
    AlertCode.INTEGRITY: lambda alert: alert.severity,
    AlertCode.CAT: lambda alert: alert.text,
}
"""Codes each of whose alerts says a state, and what the state is: INTEGRITY's severity
(lost CRITICAL, restored NOTICE), CAT's text (the new category). A change of it is always
sent, as a change of code within a family of :data:`ALERT_FAMILIES`: a restoration, or
a category, thinned away would leave the ground with an older state than the service's."""


class Encoder:
    """Builds and packs the service's outgoing MAVLink messages.

    Parameters
    ----------
    config
        Output choice, floors, rate limits, dialect.
    system_id
        Our MAVLink system id (set it to the autopilot's once known).

    Attributes
    ----------
    suppressed : collections.Counter[str]
        Alert code -> STATUSTEXTs suppressed by the rate limit.
    dropped : collections.Counter[str]
        Reason -> outputs not encoded.
    """

    def __init__(self, config: EncoderConfig | None = None, system_id: int = 1) -> None:
        self.config = config if config is not None else EncoderConfig()
        self.gps_id_override: int | None = None
        """The id the autopilot's parameters call for (``gps_id_from_autopilot``), set by
        the pipeline; None: ``config.gps_id``."""
        self._mod = load_dialect(self.config.dialect)
        self._packer = Packer(self._mod, MAV_COMP_ID_ONBOARD_COMPUTER)
        self._pack_args = self._packer.pack_args
        self.system_id = system_id
        self._has_integrity = hasattr(self._mod, "MAVLink_gnss_integrity_message")
        self._first_alt_mm: int | None = None
        self._last_alert_t: dict[AlertCode, float] = {}
        self._family_state: dict[str, object] = {}
        """The last state sent of each family of :data:`ALERT_FAMILIES` (its code) and of
        each code of :data:`STATE_OF_ALERT`."""
        self._text_id = 0
        """Id of the last chunked STATUSTEXT (1..65535, wrapping)."""
        self._intervals = {
            AlertCode(code): interval
            for code, interval in self.config.statustext_interval_overrides
        }
        self.suppressed: collections.Counter[str] = collections.Counter()
        self.dropped: collections.Counter[str] = collections.Counter()
        self.held: collections.Counter[str] = collections.Counter()
        """GLOBAL_POSITION_SENSORs held back from PX4, by reason (``agp_id_unknown``,
        ``feedback_guard``, ``no_fix``)."""
        self._gpi_cls = self._mod.MAVLink_global_position_int_message
        self._gps_input_cls = self._mod.MAVLink_gps_input_message
        self.agp_id: int | None = None
        """GLOBAL_POSITION_SENSOR ``id`` read from PX4 (``EKF2_AGP0_ID``,
        :mod:`companion.mavlink.px4_agp`); None: ``config.gps_id``."""
        self.agp_hold = False
        """PX4's id is not known yet (being read, or no autopilot yet): no
        GLOBAL_POSITION_SENSOR (one of another id would keep PX4 from fusing the right
        one). The pipeline holds from its start until it has read the id, or given up."""
        self.feedback_guard = False
        """PX4 fuses what we send (``EKF2_AGP0_CTRL``): no GLOBAL_POSITION_SENSOR from a GNSS
        gap's start until GNSS is trusted again (:data:`FEEDBACK_HOLD_MODES`): bridged, our
        solution rests on PX4's attitude and IMU, which PX4 would then correct with it."""

    @property
    def system_id(self) -> int:
        """Source system id of packed messages (the autopilot's, once known)."""
        return int(self._packer.mav.srcSystem)

    @system_id.setter
    def system_id(self, value: int) -> None:
        if not 1 <= int(value) <= 255:
            raise ValueError(f"system_id must be in 1..255, got {value}")
        self._packer.mav.srcSystem = int(value)

    @property
    def gps_id(self) -> int:
        """The id sent in GPS_INPUT, GLOBAL_POSITION_SENSOR and GNSS_INTEGRITY."""
        override = self.gps_id_override
        return self.config.gps_id if override is None else override

    def reconfigure(self, config: EncoderConfig) -> None:
        """Encode with ``config`` from the next message on; only the keys of
        :data:`~companion.mavlink.encode.config.LIVE_KEYS` may differ from the running
        configuration (ValueError otherwise, and nothing changes)."""
        fixed = {
            name
            for name in EncoderConfig.__dataclass_fields__
            if name not in LIVE_KEYS and getattr(config, name) != getattr(self.config, name)
        }
        if fixed:
            raise ValueError(f"[encoder] {', '.join(sorted(fixed))}: only at a restart")
        self.config = config

    @property
    def dialect_module(self) -> Any:
        """The pymavlink dialect module the messages are built from."""
        return self._mod

    @property
    def has_gnss_integrity(self) -> bool:
        """True when the dialect carries GNSS_INTEGRITY."""
        return self._has_integrity

    # ------------------------------------------------------------------ public

    def encode(self, out: Output, flavour: AutopilotFlavour) -> list[Any]:
        """MAVLink messages for one output (possibly none).

        Parameters
        ----------
        out
            A NavSolution, Alert, NamedValue or IntegrityReport.
        flavour
            The autopilot family (chooses GPS_INPUT vs GLOBAL_POSITION_SENSOR in ``auto``).

        Raises
        ------
        ValueError
            If ``out`` is not an output type (a CommandResult is the pipeline's to answer:
            it knows the sender).
        """
        if isinstance(out, NavSolution):
            return self._solution(out, flavour)
        if isinstance(out, Alert):
            return self._alert(out)
        if isinstance(out, NamedValue):
            return self._named_value(out)
        if isinstance(out, IntegrityReport):
            return self._integrity(out)
        raise ValueError(f"not an output: {type(out).__name__}")

    def heartbeat(self, system_status: int, custom_mode: int = 0) -> Any:
        """Our HEARTBEAT (MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID).

        ``system_status`` is a MAV_STATE (0..8); ``custom_mode`` the navigation state
        (docs/mavlink.md).
        """
        if not 0 <= system_status <= MAV_STATE_FLIGHT_TERMINATION:
            raise ValueError(f"system_status must be a MAV_STATE (0..8), got {system_status}")
        return self._mod.MAVLink_heartbeat_message(
            MAV_TYPE_ONBOARD_CONTROLLER,
            MAV_AUTOPILOT_INVALID,
            0,
            custom_mode,
            system_status,
            MAVLINK_VERSION,
        )

    def command_ack(
        self, command: int, result: int, target_system: int, target_component: int
    ) -> Any:
        """COMMAND_ACK for a command we handled (e.g. the heading confirmation, MAV_CMD_USER_1)."""
        return self._mod.MAVLink_command_ack_message(
            command, result, 0, 0, target_system, target_component
        )

    def allow_next(self, code: AlertCode) -> None:
        """Let the next STATUSTEXT of ``code`` through whatever the rate limit: it answers
        an operator's command (one per command, not the flood the limit is for)."""
        self._last_alert_t.pop(code, None)

    def pack(self, msg: Any) -> bytes:
        """Serialise ``msg`` with our system id, component 191 and the next sequence number,
        byte for byte as pymavlink's ``msg.pack`` (:meth:`.packing.Packer.pack`)."""
        return self._packer.pack(msg)

    def encode_frames(self, out: Output, flavour: AutopilotFlavour) -> list[tuple[str, bytes]]:
        """``(message name, frame)`` of each message :meth:`encode` gives for ``out``, packed
        as :meth:`pack` packs them one after the other (the same bytes, the same sequence
        numbers). Solutions and named values, the frequent outputs, are packed straight
        from the values, without building pymavlink message objects.

        Raises
        ------
        ValueError
            If ``out`` is not an output type.
        """
        kind = type(out)
        if kind is NavSolution:
            messages = self._solution_args(out, flavour)  # type: ignore[arg-type]
        elif kind is NamedValue:
            messages = self._named_value_args(out)  # type: ignore[arg-type]
        else:
            return [(m._type, self.pack(m)) for m in self.encode(out, flavour)]
        return [self._pack_args(cls, args) for cls, args in messages]

    # ------------------------------------------------------------------ outputs

    def _solution(self, sol: NavSolution, flavour: AutopilotFlavour) -> list[Any]:
        return [cls(*args) for cls, args in self._solution_args(sol, flavour)]

    def _solution_args(
        self, sol: NavSolution, flavour: AutopilotFlavour
    ) -> list[tuple[type, tuple[Any, ...]]]:
        """``(message class, constructor arguments)`` of the solution's messages."""
        try:
            vn, ve, vd = _floats(sol.vel_ned_mps, (3,))
            pc = _floats(sol.pos_cov_ned_m2, (3, 3))
            vc = _floats(sol.vel_cov_ned_m2ps2, (3, 3))
        except (TypeError, ValueError):
            self.dropped["malformed_solution"] += 1
            logger.warning("not encoding a malformed navigation solution at t=%s", sol.t_s)
            return []
        total = sol.lat_rad + sol.lon_rad + sol.alt_msl_m + sol.t_s + vn + ve + vd
        total += sum(pc[0]) + sum(pc[1]) + sum(pc[2]) + sum(vc[0]) + sum(vc[1]) + sum(vc[2])
        if not math.isfinite(total) or sol.t_s < 0.0:
            self.dropped["nonfinite_solution"] += 1
            logger.warning("not encoding a non-finite navigation solution at t=%s", sol.t_s)
            return []
        lat = _clamp_int(sol.lat_rad * _DEGE7_PER_RAD, -900_000_000, 900_000_000)
        lon = _clamp_int(sol.lon_rad * _DEGE7_PER_RAD, -1_800_000_000, 1_800_000_000)
        alt_mm = _clamp_int(sol.alt_msl_m * _MM_PER_M, -(2**31), 2**31 - 1)
        if self._first_alt_mm is None:
            self._first_alt_mm = alt_mm
        yaw_cd: int | None = None
        yaw_rad = sol.yaw_rad
        if yaw_rad is not None and math.isfinite(yaw_rad):
            yaw_cd = int(round((yaw_rad % _TWO_PI) * _CDEG_PER_RAD)) % _CDEG_FULL
        # the engine publishes at whole milliseconds; round, never truncate (a truncated
        # millisecond is 3 cm along-track at approach speed)
        time_boot_ms = round(sol.t_s * _MS_PER_S) % (1 << 32)
        k = _CM_PER_M
        gpi = (
            self._gpi_cls,
            (
                time_boot_ms,
                lat,
                lon,
                alt_mm,
                _clamp_int(alt_mm - self._first_alt_mm, -(2**31), 2**31 - 1),
                _clamp_int(vn * k, -_INT16_MAX, _INT16_MAX),
                _clamp_int(ve * k, -_INT16_MAX, _INT16_MAX),
                _clamp_int(vd * k, -_INT16_MAX, _INT16_MAX),
                units.UINT16_UNKNOWN if yaw_cd is None else yaw_cd,
            ),
        )
        out: list[tuple[type, tuple[Any, ...]]] = [gpi]
        cfg = self.config
        kind = cfg.output
        if kind == "auto":
            if flavour is _ARDUPILOT:
                kind = "gps_input"
            elif flavour is _PX4:
                kind = "global_position_sensor"
            else:
                return out
        # the same quantities as NavSolution.h_acc_m / v_acc_m / vel_acc_mps, in closed form
        h_lmax = largest_eigenvalue_2x2(pc[0][0], pc[0][1], pc[1][1])
        h_acc = max(math.sqrt(max(h_lmax, 0.0)), cfg.min_h_acc_m)
        v_acc = max(math.sqrt(max(pc[2][2], 0.0)), cfg.min_v_acc_m)
        if kind == "gps_input":
            s_acc = max(math.sqrt(max(largest_eigenvalue_3x3(vc), 0.0)), cfg.min_vel_acc_mps)
            if yaw_cd is None or not cfg.gps_input_yaw:
                yaw_field = 0
            else:
                yaw_field = yaw_cd if yaw_cd != 0 else _CDEG_FULL
            out.append(
                (
                    self._gps_input_cls,
                    (
                        round(sol.t_s * _US_PER_S),
                        self.gps_id,
                        0,  # ignore_flags: every field is provided
                        0,  # time_week_ms: no GPS time
                        0,  # time_week: 0 disables ArduPilot's jitter correction
                        # ArduPilot's GPS_Status stops at RTK fixed (6): STATIC/PPP go as 3D
                        int(sol.fix_type) if sol.fix_type <= _RTK_FIXED else _FIX_3D,
                        lat,
                        lon,
                        float(sol.alt_msl_m),
                        h_acc / cfg.uere_m,
                        v_acc / cfg.uere_m,
                        vn,
                        ve,
                        vd,
                        s_acc,
                        h_acc,
                        v_acc,
                        _clamp_int(sol.satellites, 0, 254),
                        yaw_field,
                    ),
                )
            )
        elif self.agp_hold:
            self.held["agp_id_unknown"] += 1
            return out
        elif self.feedback_guard and sol.mode in FEEDBACK_HOLD_MODES:
            self.held["feedback_guard"] += 1
            return out
        elif sol.fix_type <= _NO_FIX:
            # PX4 ignores the message's flags and fuses whatever position comes: a solution
            # without a fix (integrity lost, navigation lost) is not sent
            self.held["no_fix"] += 1
            return out
        else:
            healthy = sol.fix_type >= _FIX_3D
            alt_hae = sol.alt_hae_m
            lead_s = cfg.px4_agp_lead_s
            if lead_s > 0.0:
                lat, lon = _carried_forward(sol.lat_rad, sol.lon_rad, sol.alt_msl_m, vn, ve, lead_s)
            out.append(
                (
                    self._mod.MAVLink_global_position_sensor_message,
                    (
                        self.system_id,
                        MAV_COMP_ID_AUTOPILOT1,
                        self.gps_id if self.agp_id is None else self.agp_id,
                        round((sol.t_s + lead_s) * units.US_PER_S),
                        0,
                        GLOBAL_POSITION_SRC_ESTIMATOR,
                        GLOBAL_POSITION_PRIMARY if healthy else GLOBAL_POSITION_UNHEALTHY,
                        lat,
                        lon,
                        math.nan if alt_hae is None else float(alt_hae),
                        float(sol.alt_msl_m),
                        h_acc,
                        v_acc,
                    ),
                )
            )
        return out

    def _alert(self, alert: Alert) -> list[Any]:
        code = alert.code
        family = ALERT_FAMILIES.get(code)
        state: object = code
        state_of = STATE_OF_ALERT.get(code)
        if state_of is not None:
            family, state = code.value, state_of(alert)
        # a change of state within a family (GNSS lost -> back -> lost) is always sent: the
        # interval only thins repeats of the state last sent, so the ground never keeps an
        # older state than the service's
        change = family is not None and self._family_state.get(family, state) != state
        last = self._last_alert_t.get(code)
        interval = self._intervals.get(code, self.config.statustext_min_interval_s)
        if not change and last is not None and last <= alert.t_s < last + interval:
            self.suppressed[code.value] += 1
            return []
        self._last_alert_t[code] = alert.t_s
        if family is not None:
            self._family_state[family] = state
        # STATUSTEXT is read as ASCII by most ground stations (pymavlink among them):
        # spell the few non-ASCII signs the alerts use, drop anything else
        plain = alert.text.translate(_ASCII_SPELLING)
        text = f"{ALERT_PREFIX}{code.value} {plain}".rstrip()
        data = text.encode("ascii", "replace")[: STATUSTEXT_MAX_CHARS * STATUSTEXT_MAX_CHUNKS]
        severity = int(alert.severity)
        if len(data) <= STATUSTEXT_MAX_CHARS:
            return [self._mod.MAVLink_statustext_message(severity, data, 0, 0)]
        # MAVLink 2 chunking: one non-zero id, chunk_seq from 0; a chunk shorter than the
        # field (an empty one after an exact multiple) ends the text
        self._text_id = self._text_id % 0xFFFF + 1
        chunks = [
            data[i : i + STATUSTEXT_MAX_CHARS] for i in range(0, len(data), STATUSTEXT_MAX_CHARS)
        ]
        if len(chunks[-1]) == STATUSTEXT_MAX_CHARS:
            chunks.append(b"")
        return [
            self._mod.MAVLink_statustext_message(severity, chunk, self._text_id, seq)
            for seq, chunk in enumerate(chunks)
        ]

    def _named_value(self, nv: NamedValue) -> list[Any]:
        return [cls(*args) for cls, args in self._named_value_args(nv)]

    def _named_value_args(self, nv: NamedValue) -> list[tuple[type, tuple[Any, ...]]]:
        """``(NAMED_VALUE_FLOAT class, constructor arguments)``, or nothing if dropped."""
        if len(nv.name) > NAMED_VALUE_MAX_CHARS or not nv.name.isascii():
            self.dropped["bad_name"] += 1
            logger.warning("NAMED_VALUE_FLOAT name %r is not 1..10 ASCII chars; dropped", nv.name)
            return []
        if not math.isfinite(nv.value) or not math.isfinite(nv.t_s) or nv.t_s < 0.0:
            self.dropped["nonfinite_value"] += 1
            return []
        return [
            (
                self._mod.MAVLink_named_value_float_message,
                (
                    round(nv.t_s * _MS_PER_S) % (1 << 32),
                    nv.name.encode("ascii"),
                    float(nv.value),
                ),
            )
        ]

    def _integrity(self, rep: IntegrityReport) -> list[Any]:
        if not self._has_integrity:
            return []

        def cm(v: float) -> int:
            if not math.isfinite(v) or v < 0.0:
                return units.UINT16_UNKNOWN
            return _clamp_int(v * units.CM_PER_M, 0, _UINT16_CAP)

        ok = rep.integrity_ok and not rep.fault_detected
        return [
            self._mod.MAVLink_gnss_integrity_message(
                self.gps_id,
                0,  # system_errors
                0,  # authentication_state: unknown
                JAMMING_STATE[rep.jamming],
                SPOOFING_STATE[rep.spoofing],
                GPS_RAIM_STATE_OK if ok else GPS_RAIM_STATE_FAILED,
                cm(rep.hpl_m),
                cm(rep.vpl_m),
                units.UINT8_UNKNOWN,
                units.UINT8_UNKNOWN,
                units.UINT8_UNKNOWN,
                units.UINT8_UNKNOWN,
            )
        ]

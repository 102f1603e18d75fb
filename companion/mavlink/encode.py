"""Typed outputs in, MAVLink messages out (the output edge of the service).

What each output becomes
------------------------
:class:`NavSolution`
    GLOBAL_POSITION_INT, plus the solution for the autopilot: GPS_INPUT for
    ArduPilot (GPS_TYPE=14), GLOBAL_POSITION_SENSOR for PX4. With
    ``EncoderConfig.output = "auto"`` the choice follows the autopilot flavour;
    an UNKNOWN flavour gets GLOBAL_POSITION_INT only (we never feed a position
    to an autopilot we have not identified).
:class:`Alert`
    STATUSTEXT ``"CMP <CODE> <text>"`` truncated to 50 characters, severity
    from the alert; at most one per code per ``statustext_min_interval_s`` of
    the outputs' own ``t_s`` (suppressed ones are counted in
    :attr:`Encoder.suppressed`). A ``t_s`` earlier than the last sent one (a
    reboot) re-arms the code.
:class:`NamedValue`
    NAMED_VALUE_FLOAT (name at most 10 characters, else dropped and counted).
:class:`IntegrityReport`
    GNSS_INTEGRITY when the configured dialect carries it (``development``,
    ``all``), else nothing. ``raim_hfom``/``raim_vfom`` carry the horizontal and
    vertical protection levels in cm (65534 cap); ``raim_state`` is OK or FAILED.

Field choices (documented here because MAVLink leaves them open)
----------------------------------------------------------------
* GLOBAL_POSITION_INT: ``time_boot_ms = int(t_s * 1000)`` (the autopilot time
  at which the solution is valid); ``relative_alt`` is relative to the first
  altitude this encoder published (0 at the first message); ``hdg`` 0..35999
  cdeg, 65535 when the yaw is unknown. Velocities saturate at the int16 range.
* GPS_INPUT: ``time_usec`` = ``t_s`` in microseconds (boot clock). ArduPilot's
  AP_GPS_MAV ignores ``time_usec`` and only uses ``time_week``/``time_week_ms``
  for its jitter correction when ``time_week > 0``; we have no GPS time, so
  both are 0 and ArduPilot stamps the fix on arrival. All fields are
  provided, so ``ignore_flags = 0`` (accuracies, velocities and DOPs are always
  filled). ``horiz_accuracy``, ``vert_accuracy`` and ``speed_accuracy`` are
  the 1-sigma values of the solution's covariance, floored by the config (never
  claim better than ``min_h_acc_m`` ...). HDOP/VDOP are derived from them as
  ``hdop = h_acc / uere_m`` and ``vdop = v_acc / uere_m`` with a nominal
  user-equivalent range error ``uere_m`` (ArduPilot's arming check compares
  HDOP with GPS_HDOP_GOOD). ``yaw`` is 1..36000 cdeg (36000 = north) or 0 when
  unknown or when ``gps_input_yaw`` is off.
* GLOBAL_POSITION_SENSOR: target = the autopilot (``system_id``, component 1),
  ``source = GLOBAL_POSITION_SRC_ESTIMATOR``, ``flags = PRIMARY`` or
  ``UNHEALTHY`` when the fix is below 3D, ``alt_ellipsoid`` NaN when unknown,
  ``eph``/``epv`` the floored 1-sigma accuracies, ``processing_time = 0``.

Solutions with a non-finite position or covariance are not encoded (counted
``nonfinite_solution`` in :attr:`Encoder.dropped`).

References
----------
MAVLink common.xml (GLOBAL_POSITION_INT, GPS_INPUT, GLOBAL_POSITION_SENSOR,
STATUSTEXT, NAMED_VALUE_FLOAT); ArduPilot libraries/AP_GPS/AP_GPS_MAV.cpp
(GPS_INPUT handling).
"""

from __future__ import annotations

import collections
import logging
import math
import operator
import struct
from dataclasses import dataclass
from typing import Any

import numpy as np

from companion.mavlink import units
from companion.mavlink.frames import load_dialect
from companion.types import (
    Alert,
    AlertCode,
    AutopilotFlavour,
    FixType,
    IntegrityReport,
    NamedValue,
    NavSolution,
    Output,
    largest_eigenvalue_2x2,
    largest_eigenvalue_3x3,
)

logger = logging.getLogger(__name__)

MAV_TYPE_ONBOARD_CONTROLLER = 18
MAV_AUTOPILOT_INVALID = 8
MAVLINK_VERSION = 3
GLOBAL_POSITION_SRC_ESTIMATOR = 6
GLOBAL_POSITION_UNHEALTHY = 1
GLOBAL_POSITION_PRIMARY = 2
GPS_RAIM_STATE_OK = 2
GPS_RAIM_STATE_FAILED = 3
STATUSTEXT_MAX_CHARS = 50
NAMED_VALUE_MAX_CHARS = 10
UINT8_NOT_AVAILABLE = 255
_INT16_MAX = 32767
_UINT16_CAP = 65534
_CDEG_FULL = 36000
_OUTPUTS = ("auto", "gps_input", "global_position_sensor")
_F64 = np.dtype(np.float64)
# plain-int and module-level copies of enum members and units, for the per-solution path
_FIX_3D = int(FixType.FIX_3D)
_RTK_FIXED = int(FixType.RTK_FIXED)
_ARDUPILOT = AutopilotFlavour.ARDUPILOT
_PX4 = AutopilotFlavour.PX4
_DEGE7_PER_RAD = units.DEGE7_PER_RAD
_MM_PER_M = units.MM_PER_M
_CM_PER_M = units.CM_PER_M
_MS_PER_S = units.MS_PER_S
_US_PER_S = units.US_PER_S
_CDEG_PER_RAD = units.CDEG_PER_RAD
_TWO_PI = 2.0 * math.pi


_ASCII_SPELLING = str.maketrans({"±": "+/-", "°": "deg", "σ": "sigma", "—": "-"})


@dataclass(frozen=True, slots=True)
class EncoderConfig:
    """Encoder settings.

    Attributes
    ----------
    output
        ``"auto"`` (by autopilot flavour), ``"gps_input"`` or ``"global_position_sensor"``.
    gps_id
        GPS_INPUT ``gps_id`` / GLOBAL_POSITION_SENSOR ``id``.
    min_h_acc_m, min_v_acc_m
        Floors of the published 1-sigma horizontal / vertical accuracy, m.
    min_vel_acc_mps
        Floor of the published speed accuracy, m/s.
    uere_m
        Nominal user-equivalent range error used to derive HDOP/VDOP, m.
    gps_input_yaw
        Send the solution's (taxi-corrected) yaw in GPS_INPUT.yaw. Off by default: the
        autopilot then fuses it as a GNSS heading (ArduPilot EK3_SRC1_YAW = 2), which must
        be a deliberate choice.
    statustext_min_interval_s
        Least time between two STATUSTEXTs of the same alert code, s.
    statustext_interval_overrides
        ``((code, interval_s), ...)`` per-code exceptions.
    dialect
        pymavlink v2.0 dialect module used to build and pack messages.
    """

    output: str = "auto"
    gps_id: int = 0
    min_h_acc_m: float = 0.01
    min_v_acc_m: float = 0.01
    min_vel_acc_mps: float = 0.01
    uere_m: float = 1.0
    gps_input_yaw: bool = False
    statustext_min_interval_s: float = 5.0
    statustext_interval_overrides: tuple[tuple[str, float], ...] = ()
    dialect: str = "ardupilotmega"

    def __post_init__(self) -> None:
        if self.output not in _OUTPUTS:
            raise ValueError(f"output must be one of {_OUTPUTS}, got {self.output!r}")
        if not 0 <= self.gps_id <= 255:
            raise ValueError("gps_id must be in 0..255")
        for name in ("min_h_acc_m", "min_v_acc_m", "min_vel_acc_mps", "uere_m"):
            v = getattr(self, name)
            if not (v > 0.0 and math.isfinite(v)):
                raise ValueError(f"{name} must be finite and > 0, got {v!r}")
        if not self.statustext_min_interval_s >= 0.0:
            raise ValueError("statustext_min_interval_s must be >= 0")
        codes = {c.value for c in AlertCode}
        for code, interval in self.statustext_interval_overrides:
            if code not in codes:
                raise ValueError(f"unknown alert code {code!r} in statustext_interval_overrides")
            if not interval >= 0.0:
                raise ValueError(f"interval for {code} must be >= 0")
        load_dialect(self.dialect)


STX_V2 = 0xFD
HEADER_LEN_V2 = 10
CRC_LEN = 2
_HEADER_V2 = struct.Struct("<7B3s")
"""STX, payload length, incompat and compat flags, seq, system, component, 24-bit id."""
_CRC = struct.Struct("<H")


def _pack_plan(mod: Any, cls: type) -> Any:
    """``(field getter, payload packer, id, id bytes, CRC_EXTRA byte)`` for a message class
    :meth:`Encoder.pack` packs itself, or False (arrays, strings, MAVLink 1 or no fast CRC:
    pymavlink packs those)."""
    try:
        fields = list(cls.ordered_fieldnames)  # type: ignore[attr-defined]
        lengths = list(cls.lengths)  # type: ignore[attr-defined]
        fmt = cls.unpacker.format  # type: ignore[attr-defined]
        msg_id = int(cls.id)  # type: ignore[attr-defined]
        extra = bytes((int(cls.crc_extra),))  # type: ignore[attr-defined]
    except (AttributeError, TypeError, ValueError):
        return False
    fmt = fmt.decode() if isinstance(fmt, bytes) else fmt
    if (
        getattr(mod, "mcrf4xx", None) is None
        or float(mod.WIRE_PROTOCOL_VERSION) != 2.0
        or sum(lengths) != len(lengths)
        or "s" in fmt
        or "c" in fmt
        or not fields
    ):
        return False
    get = operator.attrgetter(*fields)
    getter = get if len(fields) > 1 else (lambda m, _g=get: (_g(m),))
    id_bytes = bytes((msg_id & 0xFF, (msg_id >> 8) & 0xFF, msg_id >> 16))
    return getter, cls.unpacker.pack, msg_id, id_bytes, extra  # type: ignore[attr-defined]


def _args_pack_plan(mod: Any, cls: type) -> Any:
    """``(wire-order picker, payload packer, id bytes, CRC_EXTRA byte)`` to pack a message of
    class ``cls`` straight from its constructor arguments, or False (MAVLink 1, arrays, no
    fast CRC: those are built and packed by pymavlink).

    pymavlink's ``pack`` packs the attributes its constructor stored, in wire order
    (``ordered_fieldnames``); a ``char[]`` field is packed from the raw bytes given to the
    constructor. So the payload is the constructor arguments permuted to wire order.
    """
    try:
        fields = list(cls.fieldnames)  # type: ignore[attr-defined]
        ordered = list(cls.ordered_fieldnames)  # type: ignore[attr-defined]
        lengths = list(cls.lengths)  # type: ignore[attr-defined]
        msg_id = int(cls.id)  # type: ignore[attr-defined]
        extra = bytes((int(cls.crc_extra),))  # type: ignore[attr-defined]
        pack_payload = cls.unpacker.pack  # type: ignore[attr-defined]
    except (AttributeError, TypeError, ValueError):
        return False
    if (
        getattr(mod, "mcrf4xx", None) is None
        or float(mod.WIRE_PROTOCOL_VERSION) != 2.0
        or sum(lengths) != len(lengths)
        or len(fields) < 2
        or sorted(fields) != sorted(ordered)
    ):
        return False
    pick = operator.itemgetter(*(fields.index(name) for name in ordered))
    id_bytes = bytes((msg_id & 0xFF, (msg_id >> 8) & 0xFF, msg_id >> 16))
    return pick, pack_payload, id_bytes, extra


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
    return np.asarray(value, dtype=np.float64).reshape(shape).tolist()  # type: ignore[no-any-return]


def _clamp_int(v: float, lo: int, hi: int) -> int:
    return lo if v < lo else hi if v > hi else int(round(v))


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
        self._mod = load_dialect(self.config.dialect)
        self._mav = self._mod.MAVLink(None, srcSystem=0, srcComponent=0)
        self.system_id = system_id
        self._mav.srcComponent = units.MAV_COMP_ID_ONBOARD_COMPUTER
        self._has_integrity = hasattr(self._mod, "MAVLink_gnss_integrity_message")
        self._first_alt_mm: int | None = None
        self._last_alert_t: dict[AlertCode, float] = {}
        self._intervals = {
            AlertCode(code): interval
            for code, interval in self.config.statustext_interval_overrides
        }
        self.suppressed: collections.Counter[str] = collections.Counter()
        self.dropped: collections.Counter[str] = collections.Counter()
        self._pack_plans: dict[type, Any] = {}
        self._args_plans: dict[type, Any] = {}
        self._gpi_cls = self._mod.MAVLink_global_position_int_message
        self._gps_input_cls = self._mod.MAVLink_gps_input_message
        self._crc: Any = getattr(self._mod, "mcrf4xx", None)

    @property
    def system_id(self) -> int:
        """Source system id of packed messages (the autopilot's, once known)."""
        return int(self._mav.srcSystem)

    @system_id.setter
    def system_id(self, value: int) -> None:
        if not 1 <= int(value) <= 255:
            raise ValueError(f"system_id must be in 1..255, got {value}")
        self._mav.srcSystem = int(value)

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
            If ``out`` is not an output type.
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

    def heartbeat(self, system_status: int) -> Any:
        """Our HEARTBEAT (MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID).

        ``system_status`` is a MAV_STATE (0..8).
        """
        if not 0 <= system_status <= 8:
            raise ValueError(f"system_status must be a MAV_STATE (0..8), got {system_status}")
        return self._mod.MAVLink_heartbeat_message(
            MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID, 0, 0, system_status, MAVLINK_VERSION
        )

    def command_ack(
        self, command: int, result: int, target_system: int, target_component: int
    ) -> Any:
        """COMMAND_ACK for a command we handled (e.g. the heading confirmation, MAV_CMD_USER_1)."""
        return self._mod.MAVLink_command_ack_message(
            command, result, 0, 0, target_system, target_component
        )

    def pack(self, msg: Any) -> bytes:
        """Serialise ``msg`` with our system id, component 191 and the next sequence number.

        Messages without arrays or strings are packed here with the message class's own
        struct, the MAVLink 2 trailing-zero truncation and CRC_EXTRA, byte for byte what
        pymavlink's ``msg.pack`` gives (and the same ``_msgbuf``, ``_payload``, ``_crc``
        and ``_header`` are left on the message); anything else goes to pymavlink.
        """
        mav = self._mav
        plan = self._pack_plans.get(type(msg))
        if plan is None:
            plan = self._pack_plans[type(msg)] = _pack_plan(self._mod, type(msg))
        if plan is False or mav.signing.sign_outgoing:
            data = bytes(msg.pack(mav))
        else:
            get, pack_payload, msg_id, id_bytes, extra = plan
            data = self._frame(pack_payload(*get(msg)), id_bytes, extra)
            msg._payload = data[HEADER_LEN_V2:-CRC_LEN]
            msg._header = self._mod.MAVLink_header(
                msg_id, 0, 0, data[1], mav.seq, mav.srcSystem, mav.srcComponent
            )
            msg._msgbuf = bytearray(data)
            msg._crc = data[-2] | (data[-1] << 8)
        mav.seq = (mav.seq + 1) % 256
        return data

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

    def _pack_args(self, cls: type, args: tuple[Any, ...]) -> tuple[str, bytes]:
        """``(name, frame)`` of ``cls(*args)`` as :meth:`pack` would pack it."""
        plan = self._args_plans.get(cls)
        if plan is None:
            plan = self._args_plans[cls] = _args_pack_plan(self._mod, cls)
        mav = self._mav
        if plan is False or mav.signing.sign_outgoing:
            msg = cls(*args)
            return msg._type, self.pack(msg)
        pick, pack_payload, id_bytes, extra = plan
        data = self._frame(pack_payload(*pick(args)), id_bytes, extra)
        mav.seq = (mav.seq + 1) % 256
        return cls.msgname, data  # type: ignore[attr-defined]

    def _frame(self, payload: bytes, id_bytes: bytes, extra: bytes) -> bytes:
        """The unsigned MAVLink 2 frame of ``payload`` with the current sequence number
        (not advanced here), as pymavlink frames it (trailing zeros truncated)."""
        mav = self._mav
        stripped = payload.rstrip(b"\x00") or payload[:1]
        buf = _HEADER_V2.pack(
            STX_V2, len(stripped), 0, 0, mav.seq, mav.srcSystem, mav.srcComponent, id_bytes
        )
        buf += stripped
        return buf + _CRC.pack(self._crc(extra, self._crc(buf[1:], 0xFFFF)))

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
                        cfg.gps_id,
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
        else:
            healthy = sol.fix_type >= _FIX_3D
            alt_hae = sol.alt_hae_m
            out.append(
                (
                    self._mod.MAVLink_global_position_sensor_message,
                    (
                        self.system_id,
                        units.MAV_COMP_ID_AUTOPILOT1,
                        cfg.gps_id,
                        round(sol.t_s * units.US_PER_S),
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
        last = self._last_alert_t.get(code)
        interval = self._intervals.get(code, self.config.statustext_min_interval_s)
        if last is not None and last <= alert.t_s < last + interval:
            self.suppressed[code.value] += 1
            return []
        self._last_alert_t[code] = alert.t_s
        # STATUSTEXT is read as ASCII by most ground stations (pymavlink among them):
        # spell the few non-ASCII signs the alerts use, drop anything else
        plain = alert.text.translate(_ASCII_SPELLING)
        text = f"CMP {code.value} {plain}".rstrip()[:STATUSTEXT_MAX_CHARS]
        return [
            self._mod.MAVLink_statustext_message(
                int(alert.severity), text.encode("ascii", "replace"), 0, 0
            )
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
                self.config.gps_id,
                0,
                0,
                0,
                0,
                GPS_RAIM_STATE_OK if ok else GPS_RAIM_STATE_FAILED,
                cm(rep.hpl_m),
                cm(rep.vpl_m),
                UINT8_NOT_AVAILABLE,
                UINT8_NOT_AVAILABLE,
                UINT8_NOT_AVAILABLE,
                UINT8_NOT_AVAILABLE,
            )
        ]

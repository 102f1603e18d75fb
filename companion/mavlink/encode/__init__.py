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
    STATUSTEXT ``"CMP <CODE> <text>"``, severity from the alert; a text longer
    than 50 characters is sent in MAVLink 2 chunks (one non-zero ``id``,
    ``chunk_seq`` from 0, at most 4 chunks); at most one per code per
    ``statustext_min_interval_s`` of the outputs' own ``t_s`` (suppressed ones are counted in
    :attr:`Encoder.suppressed`). A ``t_s`` earlier than the last sent one (a
    reboot) re-arms the code.
:class:`NamedValue`
    NAMED_VALUE_FLOAT (name at most 10 characters, else dropped and counted).
:class:`IntegrityReport`
    GNSS_INTEGRITY when the configured dialect carries it (``development``,
    ``all``), else nothing. ``raim_hfom``/``raim_vfom`` carry the horizontal and
    vertical protection levels in cm (65534 cap); ``raim_state`` is OK or FAILED;
    ``jamming_state`` and ``spoofing_state`` the service's verdicts
    (:meth:`companion.integrity.signal.SignalMonitor.stamp`: unknown, none, mitigated,
    detected).

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

Modules: :mod:`.encoder` (:class:`Encoder`, the messages), :mod:`.packing`
(frames, byte for byte as pymavlink packs them), :mod:`.config`
(:class:`EncoderConfig`). See ``docs/mavlink.md`` for the messages in and out.

References
----------
MAVLink common.xml (GLOBAL_POSITION_INT, GPS_INPUT, GLOBAL_POSITION_SENSOR,
STATUSTEXT, NAMED_VALUE_FLOAT); ArduPilot libraries/AP_GPS/AP_GPS_MAV.cpp
(GPS_INPUT handling).
"""

from companion.mavlink.encode.config import LIVE_KEYS, EncoderConfig
from companion.mavlink.encode.encoder import Encoder

__all__ = ["LIVE_KEYS", "Encoder", "EncoderConfig"]

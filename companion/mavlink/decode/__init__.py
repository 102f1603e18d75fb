"""MAVLink messages in, typed SI samples out (the input edge of the service).

Every MAVLink scaling is undone here, with the constants of
:mod:`companion.mavlink.units`; the core only ever sees :mod:`companion.types`.

=====================  ===========================================================
:mod:`.decoder`        :class:`Decoder`: dispatch, the system id filter, the heading
                       command, counting (``accepted`` / ``rejections``)
:mod:`.gnss`           GPS_RAW_INT, GPS2_RAW -> GnssFix; GPS_RTK, GPS2_RTK -> RtkStatus
:mod:`.inertial`       RAW_IMU, SCALED_IMU/2/3, HIGHRES_IMU -> ImuSample;
                       ATTITUDE, ATTITUDE_QUATERNION -> AttitudeSample
:mod:`.vehicle`        HEARTBEAT (the autopilot's identity and flavour) ->
                       HeartbeatSample; GLOBAL_POSITION_INT -> AutopilotSolution;
                       VFR_HUD, EXTENDED_SYS_STATE
:mod:`.signal`         GNSS_INTEGRITY -> GnssSignalReport (the receiver's own jamming
                       and spoofing flags, as the autopilot relays them)
:mod:`.clock`          the one clock (autopilot time since boot): wraps, epoch
                       stamps, SYSTEM_TIME, reboots -> RebootEvent
:mod:`.rejections`     the rejection reasons' counting and rate-limited log
:mod:`.config`         :class:`DecoderConfig`
=====================  ===========================================================

Every check that fails names a reason (``nan_field``, ``lat_out_of_range``,
``time_backwards`` ...: see each module) and the message yields no sample.
See ``docs/mavlink.md`` for the messages in and out.

References
----------
MAVLink common message set (field units and sentinels):
https://mavlink.io/en/messages/common.html
"""

from companion.mavlink.decode.config import DecoderConfig
from companion.mavlink.decode.decoder import LIGHT_MESSAGE_IDS, Decoder

__all__ = ["LIGHT_MESSAGE_IDS", "Decoder", "DecoderConfig"]

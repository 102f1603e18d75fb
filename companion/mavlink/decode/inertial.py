"""Inertial messages: IMUs -> :class:`ImuSample`, attitude -> :class:`AttitudeSample`.

* RAW_IMU, SCALED_IMU, SCALED_IMU2/3 (mG, mrad/s) and HIGHRES_IMU (m/s^2,
  rad/s) -> :class:`ImuSample` (``imu_id`` = the message's ``id`` or 0/1/2 for
  SCALED_IMU/2/3; ``source`` = message name).
* ATTITUDE, ATTITUDE_QUATERNION -> :class:`AttitudeSample` (yaw wrapped to
  [-pi, pi]).

One IMU stream is used (:class:`ImuStreamChoice`): the autopilot may send several
(ArduPilot RAW_IMU and SCALED_IMU2/3, each its own sensor); mixing them would feed the
navigator two sensors' biases in turn. The others are rejected as ``unused_imu_stream``.

Checks: non-finite values (``nan_field``), IMU beyond ``max_acc_mps2`` /
``max_gyro_radps`` (``imu_out_of_range``), attitude angles out of range or
rates too large (``attitude_out_of_range``), quaternion norm far from 1
(``bad_quaternion``).
"""

from __future__ import annotations

import collections
import math
from typing import Any

import numpy as np

from companion.mavlink import units
from companion.mavlink.decode.clock import BootClock
from companion.mavlink.decode.config import DecoderConfig
from companion.mavlink.decode.rejections import Rejected
from companion.nav.rotations import quat_to_euler
from companion.types import AttitudeSample, ImuSample

_MPS2_PER_MG = 1.0 / units.MG_PER_MPS2
_RADPS_PER_MRADPS = 1.0 / units.MRAD_PER_RAD
_US_PER_S = units.US_PER_S
_EPOCH_USEC = units.EPOCH_USEC_THRESHOLD
_TWO_PI = 2.0 * math.pi
_ROLL_MAX = math.pi + 1e-3
_PITCH_MAX = 0.5 * math.pi + 1e-3
_YAW_MAX = 2.0 * _ROLL_MAX
"""Largest plausible ATTITUDE angles, rad (a wrapped yaw may span two turns)."""


class ImuStreamChoice:
    """Which IMU stream (message name, sensor id) is used: the busiest over the last
    ``window_s`` of autopilot time; another takes over only when the chosen one stops
    (``stop_s``) or another delivers clearly more (``switch_ratio``)."""

    def __init__(self, window_s: float = 2.0, stop_s: float = 0.5, switch_ratio: float = 1.5):
        self.window_s = window_s
        self.stop_s = stop_s
        self.switch_ratio = switch_ratio
        self.chosen: tuple[str, int] | None = None
        self._times: dict[tuple[str, int], collections.deque[float]] = {}

    def accept(self, key: tuple[str, int], t_s: float) -> bool:
        q = self._times.get(key)
        if q is None:
            q = self._times[key] = collections.deque()
        elif q and q[-1] > t_s:  # the clock went back (a reboot): start this stream afresh
            q.clear()
        q.append(t_s)
        lo = t_s - self.window_s
        while q[0] < lo:
            q.popleft()
        chosen = self.chosen
        if chosen == key:
            return True
        if chosen is None:
            self.chosen = key
            return True
        cq = self._times[chosen]
        if (
            not cq
            or cq[-1] < t_s - self.stop_s
            or cq[-1] > t_s + self.window_s  # the clock went back: a reboot
            or len(q) > self.switch_ratio * sum(1 for t in cq if t >= lo) + 2
        ):
            self.chosen = key
            return True
        return False

    def reset(self) -> None:
        self.chosen = None
        self._times.clear()


class InertialDecoder:
    """The IMU and attitude handlers (``(msg, t_rx_s) -> sample``, raising :class:`Rejected`)."""

    def __init__(self, config: DecoderConfig, clock: BootClock) -> None:
        self._boot_time = clock.boot_time
        self._time_ms = clock.time_ms
        self._time_us = clock.time_us
        self._max_acc2 = config.max_acc_mps2**2
        self._max_gyro2 = config.max_gyro_radps**2
        self.imu_choice = ImuStreamChoice()

    def _imu(
        self,
        t_s: float,
        t_rx_s: float,
        ax: float,
        ay: float,
        az: float,
        gx: float,
        gy: float,
        gz: float,
        imu_id: int,
        src: str,
    ) -> ImuSample:
        """Validate SI specific force (m/s^2) and rate (rad/s) and build the sample."""
        a2 = ax * ax + ay * ay + az * az
        g2 = gx * gx + gy * gy + gz * gz
        if not math.isfinite(a2 + g2):
            raise Rejected("nan_field")
        if a2 > self._max_acc2 or g2 > self._max_gyro2:
            raise Rejected("imu_out_of_range")
        if not self.imu_choice.accept((src, imu_id), t_s):
            raise Rejected("unused_imu_stream")
        # positional, cheaper than keywords at 50 Hz (t_s, t_rx_s, acc, gyro, id, source)
        return ImuSample(t_s, t_rx_s, np.array((ax, ay, az)), np.array((gx, gy, gz)), imu_id, src)

    def raw_imu(self, msg: Any, t_rx_s: float) -> ImuSample:
        """RAW_IMU, the most frequent message: the common boot-clock case of
        :meth:`BootClock.time_us` written out here (the same result)."""
        imu_id = msg.id
        raw_us = msg.time_usec
        if 0 < raw_us <= _EPOCH_USEC:
            t_s = self._boot_time(raw_us / _US_PER_S, ("RAW_IMU", imu_id), t_rx_s)
        else:
            t_s = self._time_us(raw_us, ("RAW_IMU", imu_id), t_rx_s)
        k = _MPS2_PER_MG
        r = _RADPS_PER_MRADPS
        return self._imu(
            t_s, t_rx_s, msg.xacc * k, msg.yacc * k, msg.zacc * k,
            msg.xgyro * r, msg.ygyro * r, msg.zgyro * r, imu_id, "RAW_IMU",
        )  # fmt: skip

    def scaled_imu(self, msg: Any, t_rx_s: float) -> ImuSample:
        """SCALED_IMU, SCALED_IMU2, SCALED_IMU3 (imu_id 0, 1, 2)."""
        name = msg.get_type()
        imu_id = 0 if name == "SCALED_IMU" else (1 if name == "SCALED_IMU2" else 2)
        t_s = self._time_ms(msg.time_boot_ms, name, t_rx_s)
        k = _MPS2_PER_MG
        r = _RADPS_PER_MRADPS
        return self._imu(
            t_s, t_rx_s, msg.xacc * k, msg.yacc * k, msg.zacc * k,
            msg.xgyro * r, msg.ygyro * r, msg.zgyro * r, imu_id, name,
        )  # fmt: skip

    def highres_imu(self, msg: Any, t_rx_s: float) -> ImuSample:
        """HIGHRES_IMU (already SI)."""
        imu_id = msg.id
        ax, ay, az = msg.xacc, msg.yacc, msg.zacc
        gx, gy, gz = msg.xgyro, msg.ygyro, msg.zgyro
        if not math.isfinite(ax + ay + az + gx + gy + gz):
            raise Rejected("nan_field")
        t_s = self._time_us(msg.time_usec, ("HIGHRES_IMU", imu_id), t_rx_s)
        return self._imu(t_s, t_rx_s, ax, ay, az, gx, gy, gz, imu_id, "HIGHRES_IMU")

    def _rates(self, msg: Any) -> np.ndarray:
        p, q, r = msg.rollspeed, msg.pitchspeed, msg.yawspeed
        r2 = p * p + q * q + r * r
        if not math.isfinite(r2):
            raise Rejected("nan_field")
        if r2 > self._max_gyro2:
            raise Rejected("attitude_out_of_range")
        return np.array((p, q, r))

    def attitude(self, msg: Any, t_rx_s: float) -> AttitudeSample:
        """ATTITUDE (Euler angles)."""
        roll, pitch, yaw = msg.roll, msg.pitch, msg.yaw
        if not math.isfinite(roll + pitch + yaw):
            raise Rejected("nan_field")
        if abs(roll) > _ROLL_MAX or abs(pitch) > _PITCH_MAX or abs(yaw) > _YAW_MAX:
            raise Rejected("attitude_out_of_range")
        rate = self._rates(msg)
        t_s = self._time_ms(msg.time_boot_ms, "ATTITUDE", t_rx_s)
        if yaw > math.pi:
            yaw -= _TWO_PI
        elif yaw < -math.pi:
            yaw += _TWO_PI
        # positional (25 Hz): t_s, t_rx_s, roll, pitch, yaw, rate
        return AttitudeSample(t_s, t_rx_s, roll, pitch, yaw, rate)

    def attitude_quaternion(self, msg: Any, t_rx_s: float) -> AttitudeSample:
        """ATTITUDE_QUATERNION (normalised, then Euler angles)."""
        q = np.array([msg.q1, msg.q2, msg.q3, msg.q4], dtype=np.float64)
        n2 = float(q @ q)
        if not math.isfinite(n2):
            raise Rejected("nan_field")
        if abs(n2 - 1.0) > 0.1:
            raise Rejected("bad_quaternion")
        rate = self._rates(msg)
        t_s = self._time_ms(msg.time_boot_ms, "ATTITUDE_QUATERNION", t_rx_s)
        roll, pitch, yaw = quat_to_euler(q / math.sqrt(n2))
        return AttitudeSample(
            t_s=t_s, t_rx_s=t_rx_s, roll_rad=roll, pitch_rad=pitch, yaw_rad=yaw, rate_b_radps=rate
        )

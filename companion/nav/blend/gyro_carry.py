"""The rotation the IMU's gyro integrates between two attitude samples.

The autopilot's attitude messages carry its body rates at the attitude's rate (ATTITUDE,
25 Hz on PX4 and ArduPilot); its IMU stream comes faster (HIGHRES_IMU about 50 Hz on PX4,
RAW_IMU 40-50 Hz on ArduPilot). A vehicle that rolls and yaws at once (PX4 SIH's airplane
swings its yaw rate by +-50 deg/s about once a second in its loiter) is carried wrongly
by rates sampled every 40 ms: rotations do not commute, and the sum of the missed terms
grows like a coning error (Savage, "Strapdown inertial navigation integration algorithm
design part 1", JGCD 21(1), 1998, eq. 26). Measured on two 20 s windows of that flight,
the rates at 25 Hz departed 2-4.5 deg in heading from the autopilot's attitude, the
IMU's gyro at 50 Hz 0.3-0.6 deg, which is what the autopilot's heading error against the
truth did.

:class:`GyroCarry` integrates every IMU gyro sample (trapezoidal) and hands over, at each
attitude time, the rotation since the previous one: the ends are carried from the nearest
IMU sample by its rate (at most :data:`MAX_EXTRAP_S`).
"""

from __future__ import annotations

from companion.nav.rotations import Quat, quat_from_rotvec, quat_mul

MAX_STEP_S = 0.1
"""IMU samples further apart than this break the carry (a gap in the IMU stream)."""
MAX_EXTRAP_S = 0.05
"""An attitude time further than this from the newest IMU sample gets no increment."""


class GyroCarry:
    """The body-frame rotation of the IMU's gyro from one :meth:`take` to the next."""

    def __init__(self) -> None:
        self._last: tuple[float, list[float]] | None = None
        """The newest IMU sample ``(t_s, gyro rad/s)``."""
        self._acc: Quat | None = None
        """The rotation from the previous take's time to the newest IMU sample; None:
        broken since (no increment at the next take)."""
        self.breaks = 0
        """Times the carry broke (a gap or a step back in the IMU stream)."""

    def on_imu(self, t_s: float, gyro_b_radps: list[float]) -> None:
        last = self._last
        self._last = (t_s, gyro_b_radps)
        if last is None:
            return
        dt = t_s - last[0]
        if not 0.0 < dt <= MAX_STEP_S:
            if self._acc is not None:
                self.breaks += 1
            self._acc = None
            return
        if self._acc is None:
            return
        h = 0.5 * dt
        w0 = last[1]
        self._acc = quat_mul(
            self._acc,
            quat_from_rotvec(
                (w0[0] + gyro_b_radps[0]) * h,
                (w0[1] + gyro_b_radps[1]) * h,
                (w0[2] + gyro_b_radps[2]) * h,
            ),
        )

    def take(self, t_s: float) -> Quat | None:
        """The rotation from the previous take's time to ``t_s`` (None: not covered by
        the IMU); the carry starts again from ``t_s``."""
        last = self._last
        if last is None:
            return None
        t_imu, w = last
        ahead = t_s - t_imu
        if abs(ahead) > MAX_EXTRAP_S:
            self._acc = None
            return None
        acc = self._acc
        out = None
        if acc is not None:
            out = quat_mul(acc, quat_from_rotvec(w[0] * ahead, w[1] * ahead, w[2] * ahead))
        # from t_s to the newest IMU sample
        self._acc = quat_from_rotvec(-w[0] * ahead, -w[1] * ahead, -w[2] * ahead)
        return out

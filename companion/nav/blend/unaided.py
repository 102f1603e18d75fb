"""How far the autopilot's heading departs from its own body rates through a GNSS gap.

The rates are the IMU's gyro where its samples cover the attitude's (:mod:`.gyro_carry`:
faster than the attitude messages' own rates, which a rolling and yawing vehicle outruns),
else the attitude messages' rates.

In a gap the autopilot shares (its GNSS is ours), its heading is no longer aided by the
GNSS velocity: what still moves it besides its body rates (its gyros less its own bias
estimate) is its remaining aiding (a compass, airspeed), which may pull it toward the
truth or away from it, and the service cannot tell which. Its rates are integrated from
the gap's start (trapezoidal, as :mod:`.rate_drift`), corrected by the mean rate at which
its attitude strayed from them while aided (:meth:`.RateDrift.mean_rate`: what its aiding
corrected them by, taken as their bias); the rotation from that carried attitude to the
autopilot's, about down, is the heading departure ``D`` (rad). Aiding that carries on as
before departs from the corrected rates by little; aiding that stops departs by the
rates' bias, and aiding that does something new (a compass pulling the heading in a
turn) by that. The blend counts the largest ``D`` seen as heading-error variance
(:meth:`~companion.nav.blend.BlendNavigator.attitude_unaided`): a correction of unknown
quality is as likely an error of its size.

``D`` is smoothed over :data:`SMOOTH_S` first: the autopilot's rates trail its attitude
by a few tens of milliseconds (its gyro filter), so a roll into a turn departs for the
length of the roll and the roll out takes it back; a heading pulled by the aiding stays.

A departure is seen as it grows, smoothed, so later than the heading error it measures
began, and a heading error turns the velocity by the velocity change it has been present
for (Titterton & Weston eq. 12.21: ``d(dv)/dt = -psi x f``). Each growth of the peak is
therefore counted as a heading error present since the gap's start
(:func:`heading_sensitivity`): on the heading, and on the velocity and position it would
have turned since. Counted only on the heading, the turn it happened in is lost: beside
ArduPlane SITL, a departure of 0.75 deg seen in the gap's first turn (33 m/s of velocity
change) left the velocity 1 m/s off while its claim had grown by 0.4 m/s.
"""

from __future__ import annotations

import math

from companion.nav.blend.rate_drift import MAX_STEP_S
from companion.nav.rotations import (
    Quat,
    quat_from_rotvec,
    quat_mul,
    quat_to_mat_values,
    rotvec_between,
)

SMOOTH_S = 2.0
"""Time constant of the exponential smoothing of the departure, s: longer than a roll
into or out of a turn (about a second at 30 deg/s)."""


def heading_sensitivity(
    dv_ned_mps: tuple[float, float], dq_ned_m: tuple[float, float]
) -> tuple[float, float, float, float]:
    """The position and velocity errors (N, E) per radian of a heading error present since
    the gap's start, when the velocity has changed by ``dv_ned_mps`` (N, E) since and the
    position has moved ``dq_ned_m`` (N, E) beyond the start's velocity carried on: the
    psi-angle model's ``d(dv)/dt = -psi x f`` about down (``dv_N' = f_E psi_D``,
    ``dv_E' = -f_N psi_D``) integrated once and twice. Returns (pos N, pos E, vel N,
    vel E)."""
    return (dq_ned_m[1], -dq_ned_m[0], dv_ned_mps[1], -dv_ned_mps[0])


class UnaidedDeparture:
    """The autopilot's heading against its corrected rates integrated since :meth:`start`."""

    def __init__(self) -> None:
        self._carried: Quat | None = None
        self._corr = [0.0, 0.0, 0.0]
        self._last: tuple[float, list[float]] | None = None
        self._smooth_rad = 0.0
        self.peak_sq_rad2 = 0.0
        """Largest squared smoothed departure seen since the start, rad^2."""
        self.restarts = 0
        """Times the carried attitude restarted from the autopilot's (a gap in the
        attitude stream longer than :data:`MAX_STEP_S`)."""

    def start(self, rate_correction_b_radps: list[float] | None = None) -> None:
        """A gap begins: the next sample is the reference; ``rate_correction_b_radps``
        (body axes) is added to every rate carried."""
        self._carried = None
        self._last = None
        self._smooth_rad = 0.0
        self.peak_sq_rad2 = 0.0
        self._corr = list(rate_correction_b_radps or (0.0, 0.0, 0.0))

    def on_sample(self, t_s: float, q_nb: Quat, rate_b_radps: list[float]) -> float:
        """One attitude sample with its body rates; returns the increase of
        :attr:`peak_sq_rad2` it caused (rad^2, 0 when none)."""
        last = self._last
        carried = self._carried
        if last is not None and carried is not None and t_s == last[0]:
            return 0.0  # the same sample again (a repeated message)
        self._last = (t_s, rate_b_radps)
        if last is None or carried is None or not 0.0 < t_s - last[0] <= MAX_STEP_S:
            if carried is not None:
                self.restarts += 1
            # (re)start from the autopilot's attitude, keeping the peak already seen: the
            # departure restarts from where the smoothed one was
            self._carried = q_nb
            return 0.0
        dt = t_s - last[0]
        h = 0.5 * dt
        w0 = last[1]
        k = self._corr
        carried = quat_mul(
            carried,
            quat_from_rotvec(
                (w0[0] + rate_b_radps[0]) * h + k[0] * dt,
                (w0[1] + rate_b_radps[1]) * h + k[1] * dt,
                (w0[2] + rate_b_radps[2]) * h + k[2] * dt,
            ),
        )
        return self._compare(dt, carried, q_nb)

    def on_increment(self, t_s: float, q_nb: Quat, dq_b: Quat | None) -> float:
        """As :meth:`on_sample`, the attitude carried from the previous sample by the
        rotation ``dq_b`` (body frame: the IMU's gyro, :mod:`.gyro_carry`) instead of the
        sample's rates; None (not covered by the IMU) restarts the carry from ``q_nb``."""
        last = self._last
        carried = self._carried
        if last is not None and carried is not None and t_s == last[0]:
            return 0.0
        self._last = (t_s, [])
        if dq_b is None or last is None or carried is None or not 0.0 < t_s - last[0] <= MAX_STEP_S:
            if carried is not None:
                self.restarts += 1
            self._carried = q_nb
            return 0.0
        dt = t_s - last[0]
        k = self._corr
        carried = quat_mul(
            quat_mul(carried, dq_b), quat_from_rotvec(k[0] * dt, k[1] * dt, k[2] * dt)
        )
        return self._compare(dt, carried, q_nb)

    def _compare(self, dt: float, carried: Quat, q_nb: Quat) -> float:
        """The carried attitude against the autopilot's: the smoothed departure about down
        and the growth of its peak."""
        self._carried = carried
        r = rotvec_between(carried, q_nb)  # in the carried body frame
        c = quat_to_mat_values(carried)
        d_down = c[6] * r[0] + c[7] * r[1] + c[8] * r[2]
        a = math.exp(-dt / SMOOTH_S)
        self._smooth_rad = a * self._smooth_rad + (1.0 - a) * d_down
        sq = self._smooth_rad * self._smooth_rad
        if sq > self.peak_sq_rad2 and math.isfinite(sq):
            grown = sq - self.peak_sq_rad2
            self.peak_sq_rad2 = sq
            return grown
        return 0.0

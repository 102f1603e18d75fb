"""Rotations: quaternions, rotation matrices, Euler angles, rotation vectors, angle wrapping.

Conventions:

* quaternions are Hamilton products of (w, x, y, z); ``q_nb`` rotates a body (FRD)
  vector into NED;
* ``mat_nb`` is the body-to-NED rotation matrix, ``vec_n = mat_nb @ vec_b``;
* Euler angles are the aerospace ZYX sequence (yaw, then pitch, then roll), radians;
* a rotation vector is the axis times the angle (rad); ``skew(a) @ b == cross(a, b)``.

Two forms side by side: the numpy API (arrays in and out) and the float-tuple form
(:data:`Quat`, :data:`Mat3Values`) of the per-sample paths, where a numpy call costs more
than the arithmetic. Where a function has both forms, the array is built from the tuple's
values (the same operations, so the same values).

References
----------
Titterton & Weston, Strapdown Inertial Navigation Technology, 2nd ed., ch. 3
(quaternions, direction cosines, Euler angles and their relations); Shepperd,
"Quaternion from rotation matrix", J. Guidance and Control 1(3), 1978.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from companion.types import FloatArray

Quat = tuple[float, float, float, float]
"""A quaternion (w, x, y, z) as 4 floats."""
Vec3 = tuple[float, float, float]
"""A 3-vector as 3 floats."""
Mat3Values = tuple[float, float, float, float, float, float, float, float, float]
"""A 3x3 matrix as 9 floats, row-major (:func:`quat_to_mat_values`)."""


# ---------------------------------------------------------------------------- angles


def wrap_pi(angle_rad: float) -> float:
    """Wrap an angle to [-pi, pi)."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


def wrap_2pi(angle_rad: float) -> float:
    """Wrap an angle to [0, 2 pi)."""
    return angle_rad % (2.0 * math.pi)


def skew(v: FloatArray) -> FloatArray:
    """Cross-product matrix: ``skew(a) @ b == cross(a, b)``, shape (3, 3)."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


# ---------------------------------------------------------------------------- quaternions


def quat_mul(a: Quat, b: Quat) -> Quat:
    """Hamilton product ``a * b`` of (w, x, y, z) quaternions."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def quat_normalise(q: Quat) -> Quat:
    """Unit quaternion with non-negative scalar part."""
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    if q[0] < 0.0:
        n = -n
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


def quat_from_rotvec(rx: float, ry: float, rz: float) -> Quat:
    """Quaternion of a rotation vector (rad); second order in the angle below 1e-8 rad."""
    ang = math.sqrt(rx * rx + ry * ry + rz * rz)
    if ang < 1e-8:
        return (1.0 - ang * ang / 8.0, 0.5 * rx, 0.5 * ry, 0.5 * rz)
    s = math.sin(0.5 * ang) / ang
    return (math.cos(0.5 * ang), rx * s, ry * s, rz * s)


def quat_rotate(q: Quat, vx: float, vy: float, vz: float) -> Vec3:
    """Rotate a vector by unit quaternion ``q`` (body to NED for ``q_nb``)."""
    w, x, y, z = q
    # t = 2 q_vec x v ; v' = v + w t + q_vec x t
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    return (
        vx + w * tx + (y * tz - z * ty),
        vy + w * ty + (z * tx - x * tz),
        vz + w * tz + (x * ty - y * tx),
    )


def rotate_by_rotvec(q: Quat, rx: float, ry: float, rz: float) -> Quat:
    """``q`` turned by the rotation vector (rx, ry, rz) (rad) on its left, i.e. in the
    reference frame (NED for ``q_nb``), normalised.

    ``quat_normalise(quat_mul(quat_from_rotvec(rx, ry, rz), q))`` written out in one body
    (the same operations; it runs several times per GNSS fix).
    """
    ang = math.sqrt(rx * rx + ry * ry + rz * rz)
    if ang < 1e-8:
        aw, ax, ay, az = 1.0 - ang * ang / 8.0, 0.5 * rx, 0.5 * ry, 0.5 * rz
    else:
        s = math.sin(0.5 * ang) / ang
        aw, ax, ay, az = math.cos(0.5 * ang), rx * s, ry * s, rz * s
    bw, bx, by, bz = q
    w = aw * bw - ax * bx - ay * by - az * bz
    x = aw * bx + ax * bw + ay * bz - az * by
    y = aw * by - ax * bz + ay * bw + az * bx
    z = aw * bz + ax * by - ay * bx + az * bw
    n = math.sqrt(w * w + x * x + y * y + z * z)
    if w < 0.0:
        n = -n
    return (w / n, x / n, y / n, z / n)


def rotvec_between(q_from: Quat, q_to: Quat) -> Vec3:
    """The rotation vector (rad) of ``conj(q_from) * q_to``: the turn, in ``q_from``'s own
    frame (the body for ``q_nb``), that takes ``q_from`` to ``q_to`` (the shorter way)."""
    aw, ax, ay, az = q_from
    bw, bx, by, bz = q_to
    w = aw * bw + ax * bx + ay * by + az * bz
    x = aw * bx - ax * bw - ay * bz + az * by
    y = aw * by + ax * bz - ay * bw - az * bx
    z = aw * bz - ax * by + ay * bx - az * bw
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    s = math.sqrt(x * x + y * y + z * z)
    if s < 1e-12:
        return (2.0 * x, 2.0 * y, 2.0 * z)
    k = 2.0 * math.atan2(s, w) / s
    return (k * x, k * y, k * z)


# ---------------------------------------------------------------------------- matrices


def quat_to_mat_values(q: Quat | FloatArray) -> Mat3Values:
    """The rotation matrix of a unit quaternion (``mat_nb`` for ``q_nb``), row-major, as
    9 floats."""
    w, x, y, z = q
    return (
        1 - 2 * (y * y + z * z),
        2 * (x * y - w * z),
        2 * (x * z + w * y),
        2 * (x * y + w * z),
        1 - 2 * (x * x + z * z),
        2 * (y * z - w * x),
        2 * (x * z - w * y),
        2 * (y * z + w * x),
        1 - 2 * (x * x + y * y),
    )


def quat_to_mat(q: Quat | FloatArray) -> FloatArray:
    """Rotation matrix (3, 3) of a unit quaternion (``mat_nb`` for ``q_nb``)."""
    return np.array(quat_to_mat_values(q)).reshape(3, 3)


def mat_to_quat(mat: FloatArray) -> Quat:
    """Unit quaternion (w, x, y, z), w >= 0, of a rotation matrix (3, 3) (Shepperd's method:
    the branch of the largest of the trace and the diagonal entries)."""
    tr = float(np.trace(mat))
    if tr > 0.0:
        s = math.sqrt(tr + 1.0) * 2.0
        return quat_normalise(
            (
                0.25 * s,
                (mat[2, 1] - mat[1, 2]) / s,
                (mat[0, 2] - mat[2, 0]) / s,
                (mat[1, 0] - mat[0, 1]) / s,
            )
        )
    i = int(np.argmax(np.diag(mat)))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = math.sqrt(1.0 + mat[i, i] - mat[j, j] - mat[k, k]) * 2.0
    q = [0.0, 0.0, 0.0, 0.0]
    q[0] = (mat[k, j] - mat[j, k]) / s
    q[1 + i] = 0.25 * s
    q[1 + j] = (mat[j, i] + mat[i, j]) / s
    q[1 + k] = (mat[k, i] + mat[i, k]) / s
    return quat_normalise((q[0], q[1], q[2], q[3]))


# ---------------------------------------------------------------------------- Euler angles


def euler_to_mat_nb(roll_rad: float, pitch_rad: float, yaw_rad: float) -> FloatArray:
    """Body-to-NED rotation matrix from ZYX Euler angles, shape (3, 3)."""
    cr, sr = math.cos(roll_rad), math.sin(roll_rad)
    cp, sp = math.cos(pitch_rad), math.sin(pitch_rad)
    cy, sy = math.cos(yaw_rad), math.sin(yaw_rad)
    return np.array(
        [
            [cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy],
            [cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy],
            [-sp, sr * cp, cr * cp],
        ]
    )


def mat_nb_to_euler(mat_nb: FloatArray) -> tuple[float, float, float]:
    """ZYX Euler angles (roll, pitch, yaw) in radians from a body-to-NED matrix."""
    roll = math.atan2(mat_nb[2, 1], mat_nb[2, 2])
    pitch = -math.asin(max(-1.0, min(1.0, mat_nb[2, 0])))
    yaw = math.atan2(mat_nb[1, 0], mat_nb[0, 0])
    return roll, pitch, yaw


def euler_to_quat_values(roll_rad: float, pitch_rad: float, yaw_rad: float) -> Quat:
    """Body-to-NED quaternion (w, x, y, z) from ZYX Euler angles, as 4 floats."""
    cr, sr = math.cos(roll_rad / 2), math.sin(roll_rad / 2)
    cp, sp = math.cos(pitch_rad / 2), math.sin(pitch_rad / 2)
    cy, sy = math.cos(yaw_rad / 2), math.sin(yaw_rad / 2)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


def euler_to_quat(roll_rad: float, pitch_rad: float, yaw_rad: float) -> FloatArray:
    """Body-to-NED quaternion (w, x, y, z) from ZYX Euler angles, shape (4,)."""
    return np.array(euler_to_quat_values(roll_rad, pitch_rad, yaw_rad))


def quat_to_euler(q_nb: FloatArray | Sequence[float]) -> tuple[float, float, float]:
    """ZYX Euler angles (roll, pitch, yaw) in radians from a body-to-NED quaternion
    (w, x, y, z), an array (4,) or 4 floats."""
    w, x, y, z = (float(c) for c in q_nb)
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    return roll, pitch, quat_to_yaw(w, x, y, z)


def quat_to_yaw(w: float, x: float, y: float, z: float) -> float:
    """The yaw (ZYX Euler) of a body-to-NED quaternion's 4 components, rad."""
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))

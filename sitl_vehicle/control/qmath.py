"""Small float-tuple math for the controllers (the shape of PX4's ``ControlMath`` / matrix::Quatf).

Quaternions are ``(w, x, y, z)`` tuples rotating body (FRD) -> world (NED). Vectors are 3-tuples.
Plain floats on purpose: these run every physics step and small NumPy arrays are ~10x slower.
"""

from __future__ import annotations

import math

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]


def isfinite3(v) -> bool:
    return math.isfinite(v[0]) and math.isfinite(v[1]) and math.isfinite(v[2])


def qmul(a: Quat, b: Quat) -> Quat:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw)


def qconj(q: Quat) -> Quat:
    return (q[0], -q[1], -q[2], -q[3])


def qnormalize(q: Quat) -> Quat:
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    if n <= 0.0:
        return (1.0, 0.0, 0.0, 0.0)
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


def qcanonical(q: Quat) -> Quat:
    """Same rotation with non-negative w (PX4 ``canonical()``)."""
    return q if q[0] >= 0.0 else (-q[0], -q[1], -q[2], -q[3])


def qrotate(q: Quat, v: Vec3) -> Vec3:
    """Rotate ``v`` from body to world: ``R(q) v``."""
    w, x, y, z = q
    vx, vy, vz = v
    # t = 2 * (q_vec x v)
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    return (vx + w * tx + (y * tz - z * ty),
            vy + w * ty + (z * tx - x * tz),
            vz + w * tz + (x * ty - y * tx))


def qrotate_inv(q: Quat, v: Vec3) -> Vec3:
    """Rotate ``v`` from world to body: ``R(q)^T v``."""
    return qrotate((q[0], -q[1], -q[2], -q[3]), v)


def dcm_z(q: Quat) -> Vec3:
    """Third column of R(q): the body z axis expressed in the world frame."""
    w, x, y, z = q
    return (2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y))


def quat_from_euler(roll: float, pitch: float, yaw: float) -> Quat:
    """ZYX (yaw, pitch, roll) Euler angles to quaternion."""
    cr, sr = math.cos(0.5 * roll), math.sin(0.5 * roll)
    cp, sp = math.cos(0.5 * pitch), math.sin(0.5 * pitch)
    cy, sy = math.cos(0.5 * yaw), math.sin(0.5 * yaw)
    return (cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy)


def euler_from_quat(q: Quat) -> Vec3:
    """Quaternion to ZYX Euler angles ``(roll, pitch, yaw)`` in radians."""
    w, x, y, z = q
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    s = 2.0 * (w * y - z * x)
    pitch = math.asin(max(-1.0, min(1.0, s)))
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return roll, pitch, yaw


def yaw_from_quat(q: Quat) -> float:
    w, x, y, z = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def wrap_pi(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def quat_between(src: Vec3, dst: Vec3, eps: float = 1e-5) -> Quat:
    """Shortest rotation taking direction ``src`` to ``dst`` (PX4 ``Quatf(src, dst)``)."""
    cx = src[1] * dst[2] - src[2] * dst[1]
    cy = src[2] * dst[0] - src[0] * dst[2]
    cz = src[0] * dst[1] - src[1] * dst[0]
    d = src[0] * dst[0] + src[1] * dst[1] + src[2] * dst[2]
    if math.sqrt(cx * cx + cy * cy + cz * cz) < eps and d < 0.0:
        ax, ay, az = abs(src[0]), abs(src[1]), abs(src[2])
        if ax < ay:
            o = (1.0, 0.0, 0.0) if ax < az else (0.0, 0.0, 1.0)
        else:
            o = (0.0, 1.0, 0.0) if ay < az else (0.0, 0.0, 1.0)
        cx = src[1] * o[2] - src[2] * o[1]
        cy = src[2] * o[0] - src[0] * o[2]
        cz = src[0] * o[1] - src[1] * o[0]
        w = 0.0
    else:
        n2s = src[0] * src[0] + src[1] * src[1] + src[2] * src[2]
        n2d = dst[0] * dst[0] + dst[1] * dst[1] + dst[2] * dst[2]
        w = d + math.sqrt(n2s * n2d)
    return qnormalize((w, cx, cy, cz))


def bodyz_to_attitude(body_z: Vec3, yaw_sp: float) -> Quat:
    """Attitude whose body z axis is ``body_z`` (world) with heading ``yaw_sp`` (PX4 ``bodyzToAttitude``)."""
    bx, by, bz = body_z
    n = math.sqrt(bx * bx + by * by + bz * bz)
    if n < 1e-7:
        bx, by, bz, n = 0.0, 0.0, 1.0, 1.0
    bx, by, bz = bx / n, by / n, bz / n
    yc = (-math.sin(yaw_sp), math.cos(yaw_sp), 0.0)
    # body_x = y_C x body_z
    xx = yc[1] * bz - yc[2] * by
    xy = yc[2] * bx - yc[0] * bz
    xz = yc[0] * by - yc[1] * bx
    if bz < 0.0:
        xx, xy, xz = -xx, -xy, -xz
    if abs(bz) < 1e-6:
        xx, xy, xz = 0.0, 0.0, 1.0
    nx = math.sqrt(xx * xx + xy * xy + xz * xz)
    xx, xy, xz = xx / nx, xy / nx, xz / nx
    # body_y = body_z x body_x
    yx = by * xz - bz * xy
    yy = bz * xx - bx * xz
    yz = bx * xy - by * xx
    return quat_from_dcm(((xx, yx, bx), (xy, yy, by), (xz, yz, bz)))


def quat_from_dcm(r) -> Quat:
    """Rotation matrix (rows) to quaternion, Shepperd's method."""
    tr = r[0][0] + r[1][1] + r[2][2]
    if tr > 0.0:
        s = math.sqrt(tr + 1.0) * 2.0
        return qnormalize((0.25 * s, (r[2][1] - r[1][2]) / s, (r[0][2] - r[2][0]) / s, (r[1][0] - r[0][1]) / s))
    if r[0][0] > r[1][1] and r[0][0] > r[2][2]:
        s = math.sqrt(1.0 + r[0][0] - r[1][1] - r[2][2]) * 2.0
        return qnormalize(((r[2][1] - r[1][2]) / s, 0.25 * s, (r[0][1] + r[1][0]) / s, (r[0][2] + r[2][0]) / s))
    if r[1][1] > r[2][2]:
        s = math.sqrt(1.0 + r[1][1] - r[0][0] - r[2][2]) * 2.0
        return qnormalize(((r[0][2] - r[2][0]) / s, (r[0][1] + r[1][0]) / s, 0.25 * s, (r[1][2] + r[2][1]) / s))
    s = math.sqrt(1.0 + r[2][2] - r[0][0] - r[1][1]) * 2.0
    return qnormalize(((r[1][0] - r[0][1]) / s, (r[0][2] + r[2][0]) / s, (r[1][2] + r[2][1]) / s, 0.25 * s))

"""Quaternion attitude P controller with yaw weighting (the shape of PX4's ``AttitudeControl``).

Reduced attitude first: the rotation that aligns the current thrust axis with the desired one is
computed alone (roll/pitch), then the remaining yaw rotation is added scaled by ``yaw_weight`` so a
large heading error never steals authority from tilt. The yaw gain is divided by the weight to keep
the small-error yaw response equal to ``att_p[2]`` (as PX4 does).
"""

from __future__ import annotations

import math

from sitl_vehicle.control.qmath import dcm_z, qcanonical, qconj, qmul, qrotate_inv, quat_between


class AttitudeControl:
    """Pure P controller: ``update(q, q_sp, yaw_rate_sp) -> body rate setpoint`` (rad/s, FRD)."""

    def __init__(self, p=(6.5, 6.5, 2.8), yaw_weight: float = 0.4, rate_limit=(3.8, 3.8, 3.5)):
        self.set_proportional_gain(p, yaw_weight)
        self.set_rate_limit(rate_limit)

    def set_proportional_gain(self, p, yaw_weight: float) -> None:
        self._yaw_w = min(max(yaw_weight, 0.0), 1.0)
        gx, gy, gz = p
        if self._yaw_w > 1e-4:
            gz /= self._yaw_w
        self._gain = (gx, gy, gz)

    def set_rate_limit(self, rate_limit) -> None:
        self._rate_limit = tuple(rate_limit)

    def update(self, q, qd, yaw_rate_sp: float = float("nan")) -> tuple[float, float, float]:
        e_z = dcm_z(q)
        e_z_d = dcm_z(qd)
        qd_red = quat_between(e_z, e_z_d)
        if abs(qd_red[1]) > 1.0 - 1e-5 or abs(qd_red[2]) > 1.0 - 1e-5:
            qd_red = qd  # vehicle upside down relative to the setpoint: full attitude control
        else:
            qd_red = qmul(qd_red, q)
        q_mix = qcanonical(qmul(qconj(qd_red), qd))
        w = min(max(q_mix[0], -1.0), 1.0)
        z = min(max(q_mix[3], -1.0), 1.0)
        yw = self._yaw_w
        qd = qmul(qd_red, (math.cos(yw * math.acos(w)), 0.0, 0.0, math.sin(yw * math.asin(z))))
        qe = qcanonical(qmul(qconj(q), qd))
        gx, gy, gz = self._gain
        rx, ry, rz = 2.0 * qe[1] * gx, 2.0 * qe[2] * gy, 2.0 * qe[3] * gz
        if yaw_rate_sp == yaw_rate_sp and abs(yaw_rate_sp) != math.inf:
            zb = qrotate_inv(q, (0.0, 0.0, 1.0))
            rx += zb[0] * yaw_rate_sp
            ry += zb[1] * yaw_rate_sp
            rz += zb[2] * yaw_rate_sp
        lx, ly, lz = self._rate_limit
        return (min(max(rx, -lx), lx), min(max(ry, -ly), ly), min(max(rz, -lz), lz))

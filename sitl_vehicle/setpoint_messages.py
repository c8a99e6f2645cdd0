"""Offboard setpoints as MAVLink sends them: SET_POSITION_TARGET_LOCAL_NED read into a ``Setpoint``.

Pure: the type_mask's ignore bits become NaN axes (:class:`sitl_vehicle.sim.Setpoint`), BODY_NED velocities and
accelerations are turned by the current yaw, and a message that cannot be flown raises :class:`SetpointError`
saying how to fix it. Apart from the protocol (``sitl_vehicle.mavlink_io``, which counts and reports the
refusals) because it is the one message whose fields need reading axis by axis.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.sim import Setpoint

TYPE_MASK_POSITION = 0b111
TYPE_MASK_VELOCITY = 0b111 << 3
TYPE_MASK_ACCEL = 0b111 << 6
TYPE_MASK_FORCE = 1 << 9
TYPE_MASK_YAW = 1 << 10
TYPE_MASK_YAW_RATE = 1 << 11
SUPPORTED_FRAMES = {mavlink.MAV_FRAME_LOCAL_NED: "LOCAL_NED", mavlink.MAV_FRAME_BODY_NED: "BODY_NED"}


class SetpointError(ValueError):
    """A SET_POSITION_TARGET_LOCAL_NED that cannot be flown; the message says why and how to fix it."""


def setpoint_from_message(msg, yaw_now: float) -> Setpoint:
    """SET_POSITION_TARGET_LOCAL_NED → Setpoint with full type_mask semantics (ignored field = NaN).

    MAV_FRAME_BODY_NED follows the MAVLink definition: positions as in LOCAL_NED, velocities and
    accelerations in the vehicle's heading frame (rotated by the current yaw).
    """
    if msg.coordinate_frame not in SUPPORTED_FRAMES:
        raise SetpointError(f"setpoint frame {msg.coordinate_frame} not supported: use MAV_FRAME_LOCAL_NED (1) "
                            f"or MAV_FRAME_BODY_NED (8)")
    mask = msg.type_mask
    if mask & TYPE_MASK_FORCE and (mask & TYPE_MASK_ACCEL) != TYPE_MASK_ACCEL:
        # The force flag only changes what afx..afz mean; with accelerations ignored it is harmless.
        raise SetpointError("force setpoints (type_mask bit 10) are not supported: send accelerations")

    def axes(bits_offset: int, values: tuple[float, float, float]) -> tuple[float, float, float]:
        return tuple(math.nan if mask & (1 << (bits_offset + i)) else float(v) for i, v in enumerate(values))

    position = axes(0, (msg.x, msg.y, msg.z))
    velocity = axes(3, (msg.vx, msg.vy, msg.vz))
    acceleration = axes(6, (msg.afx, msg.afy, msg.afz))
    yaw = math.nan if mask & TYPE_MASK_YAW else float(msg.yaw)
    yaw_rate = math.nan if mask & TYPE_MASK_YAW_RATE else float(msg.yaw_rate)
    for label, values, offset in (("position", position, 0), ("velocity", velocity, 3),
                                  ("acceleration", acceleration, 6)):
        for i, v in enumerate(values):
            if not (mask & (1 << (offset + i))) and not math.isfinite(v):
                raise SetpointError(f"setpoint {label} {'xyz'[i]} is {v}: set type_mask bit {offset + i} "
                                    f"to leave that axis uncontrolled instead of sending NaN")
    for label, v, bit in (("yaw", yaw, TYPE_MASK_YAW), ("yaw_rate", yaw_rate, TYPE_MASK_YAW_RATE)):
        if not (mask & bit) and not math.isfinite(v):
            raise SetpointError(f"setpoint {label} is {v}: set type_mask bit {bit.bit_length()} to ignore it")
    if all(math.isnan(v) for v in position + velocity + acceleration):
        raise SetpointError("setpoint ignores every position, velocity and acceleration axis: nothing to fly")
    if msg.coordinate_frame == mavlink.MAV_FRAME_BODY_NED:
        c, s = math.cos(yaw_now), math.sin(yaw_now)
        velocity = (c * velocity[0] - s * velocity[1], s * velocity[0] + c * velocity[1], velocity[2])
        acceleration = (c * acceleration[0] - s * acceleration[1], s * acceleration[0] + c * acceleration[1],
                        acceleration[2])
    return Setpoint(position=position, velocity=velocity, acceleration=acceleration, yaw=yaw, yaw_rate=yaw_rate)

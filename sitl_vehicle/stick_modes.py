"""The stick modes' setpoints: Position, Altitude, Stabilized, Manual and Acro flown from MANUAL_CONTROL.

:class:`StickModes` is a mixin of :class:`sitl_vehicle.commander.Commander` (it reads the commander's sticks,
parameters and mode and keeps what centred sticks hold): the sticks shaped by the MPC_* parameters
(:mod:`sitl_vehicle.manual`) become a velocity, acceleration, attitude or (Acro, by the MC_ACRO_* parameters)
body-rate setpoint, and a centred stick holds
the altitude, heading or position where the vehicle stops (:func:`stopping_point`, which Hold uses too). Apart
from the commander because it is what the pilot flies, not what the commander decides.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from sitl_vehicle.manual import (
    AcroShape,
    ShapedSticks,
    Sticks,
    StickShape,
    acro_rates,
    shape_sticks,
    stick_acceleration,
    stick_climb_velocity,
    stick_velocity,
)
from sitl_vehicle.modes import FlightMode
from sitl_vehicle.sim import AttitudeSetpoint, ManualSetpoint, RateSetpoint, Setpoint

if TYPE_CHECKING:
    from sitl_vehicle.commander import VehicleStatus

NAN = math.nan


class StickModes:
    """The stick modes' setpoints, mixed into ``Commander``."""

    def _stick_shape(self) -> StickShape:
        p = self.params
        optional = {field: p[name] for name, field in (("MPC_Z_VEL_MAX_UP", "vel_up_max"),
                                                       ("MPC_Z_VEL_MAX_DN", "vel_down_max")) if name in p}
        return StickShape(deadzone=p["MPC_HOLD_DZ"], xy_expo=p["MPC_XY_MAN_EXPO"], z_expo=p["MPC_Z_MAN_EXPO"],
                          yaw_expo=p["MPC_YAW_EXPO"], vel_xy_max=p["MPC_VEL_MANUAL"],
                          yaw_rate_max=math.radians(p["MPC_MAN_Y_MAX"]), tilt_max=math.radians(p["MPC_MAN_TILT_MAX"]),
                          **optional)

    def _acro_shape(self) -> AcroShape:
        p = self.params
        return AcroShape(roll_rate_max=math.radians(p["MC_ACRO_R_MAX"]),
                         pitch_rate_max=math.radians(p["MC_ACRO_P_MAX"]),
                         yaw_rate_max=math.radians(p["MC_ACRO_Y_MAX"]), expo=p["MC_ACRO_EXPO"],
                         expo_yaw=p["MC_ACRO_EXPO_Y"], superexpo=p["MC_ACRO_SUPEXPO"],
                         superexpo_yaw=p["MC_ACRO_SUPEXPOY"])

    def _shaped_sticks(self) -> ShapedSticks:
        return shape_sticks(self._sticks or Sticks(), self._stick_shape())

    def _stick_setpoint(self, status: VehicleStatus) -> Setpoint | ManualSetpoint:
        """The sticks' setpoint. Acro: body rates up to MC_ACRO_*_MAX and the throttle as the thrust.
        Stabilized/Manual: roll and pitch angles up to MPC_MAN_TILT_MAX, a yaw rate and the throttle as they are.
        Position/Altitude: a centred stick holds what it controls: the altitude (throttle), the heading (yaw)
        and, in Position mode, the position where the vehicle stops."""
        if self.mode.rates_from_sticks:
            roll_rate, pitch_rate, yaw_rate = acro_rates(self._sticks, self._acro_shape())
            return RateSetpoint(roll_rate, pitch_rate, yaw_rate, thrust=self._sticks.throttle)
        shape = self._stick_shape()
        sticks = shape_sticks(self._sticks, shape)
        if self.mode.attitude_from_sticks:  # forward stick pitches the nose down (negative pitch, FRD)
            return AttitudeSetpoint(roll=sticks.right * shape.tilt_max, pitch=-sticks.forward * shape.tilt_max,
                                    yaw_rate=sticks.yaw * shape.yaw_rate_max, throttle=self._sticks.throttle)
        if sticks.yaw != 0.0:
            self._stick_yawing = True
            yaw, yaw_rate = NAN, sticks.yaw * shape.yaw_rate_max
        else:
            if self._stick_yawing:
                self._stick_yawing = False
                self._hold_yaw = status.yaw
            yaw, yaw_rate = self._hold_yaw, NAN
        stop = None
        if sticks.up != 0.0:
            self._stick_hold_z = None
            z, vd = NAN, stick_climb_velocity(sticks, shape)
        else:
            if self._stick_hold_z is None:
                stop = stopping_point(status.position, status.velocity)
                self._stick_hold_z = stop[2]
            z, vd = self._stick_hold_z, NAN
        if self.mode is FlightMode.ALTCTL:
            an, ae = stick_acceleration(sticks, shape, status.yaw)
            return Setpoint(position=(NAN, NAN, z), velocity=(NAN, NAN, vd), acceleration=(an, ae, NAN), yaw=yaw,
                            yaw_rate=yaw_rate)
        if not sticks.horizontal_centred:
            self._stick_hold_xy = None
            vn, ve = stick_velocity(sticks, shape, status.yaw)
            return Setpoint(position=(NAN, NAN, z), velocity=(vn, ve, vd), yaw=yaw, yaw_rate=yaw_rate)
        if self._stick_hold_xy is None:
            stop = stop or stopping_point(status.position, status.velocity)
            self._stick_hold_xy = (stop[0], stop[1])
        return Setpoint(position=(*self._stick_hold_xy, z), velocity=(NAN, NAN, vd), yaw=yaw, yaw_rate=yaw_rate)


def stopping_point(position, velocity, decel: float = 2.0) -> tuple[float, float, float]:
    """Where the vehicle comes to rest braking at ``decel`` m/s² — PX4's Hold stops, it does not go back."""
    return tuple(p + v * abs(v) / (2.0 * decel) for p, v in zip(position, velocity, strict=True))

"""What the vehicle core is asked to fly: :class:`Setpoint` (position, velocity, acceleration and yaw, NaN = axis not
controlled), :class:`AttitudeSetpoint` (Stabilized) and :class:`RateSetpoint` (Acro), and PX4's manual throttle curve.

Plain values, apart from :mod:`sitl_vehicle.sim` (which re-exports them) because the commander, the MAVLink edge and
the stick modes make them without needing the vehicle itself.
"""

from __future__ import annotations

from dataclasses import dataclass

NAN = float("nan")
NAN3 = (NAN, NAN, NAN)


@dataclass(frozen=True)
class Setpoint:
    """NaN component = axis not controlled."""

    position: tuple[float, float, float] = NAN3  # m, NED
    velocity: tuple[float, float, float] = NAN3  # m/s, NED
    acceleration: tuple[float, float, float] = NAN3  # m/s^2, NED
    yaw: float = NAN  # rad
    yaw_rate: float = NAN  # rad/s
    cruise_speed: float = NAN  # m/s, the horizontal speed of the planned move to ``position`` (NaN: MPC_XY_CRUISE;
                               # at most MPC_XY_VEL_MAX), as a mission's DO_CHANGE_SPEED sets it


@dataclass(frozen=True)
class AttitudeSetpoint:
    """Stabilized flight: roll and pitch (rad), yaw rate (rad/s) and throttle (0..1, 0.5 = hover thrust)."""

    roll: float = 0.0
    pitch: float = 0.0
    yaw_rate: float = 0.0
    throttle: float = 0.0


@dataclass(frozen=True)
class RateSetpoint:
    """Acro flight: body rates (rad/s, FRD) and the collective thrust (0..1 of full), as PX4's rate controller
    takes them from the sticks (the throttle is the thrust: no hover centre)."""

    roll_rate: float = 0.0
    pitch_rate: float = 0.0
    yaw_rate: float = 0.0
    thrust: float = 0.0


ManualSetpoint = AttitudeSetpoint | RateSetpoint


def throttle_to_thrust(throttle: float, hover: float, thrust_min: float, thrust_max: float) -> float:
    """PX4's manual throttle curve (MPC_THR_CURVE 0): 0 -> thrust_min, 0.5 -> hover, 1 -> thrust_max, linear
    in between, so that a centred stick hovers."""
    t = min(max(throttle, 0.0), 1.0)
    if t <= 0.5:
        return thrust_min + (hover - thrust_min) * t / 0.5
    return hover + (thrust_max - hover) * (t - 0.5) / 0.5

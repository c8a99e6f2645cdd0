"""Manual control (a joystick or RC through MAVLink MANUAL_CONTROL) for PX4's stick modes: Position, Altitude,
Stabilized, Manual and Acro.

Pure functions: the MAVLink edge turns MANUAL_CONTROL into :class:`Sticks`, the commander turns sticks into
velocity or acceleration setpoints with :func:`shape_sticks`, :func:`stick_velocity`, :func:`stick_climb_velocity`
and :func:`stick_acceleration`, and into Acro's body rates with :func:`acro_rates`. Conventions are
PX4's ``manual_control_setpoint``: pitch stick forward +, roll stick right +, yaw stick right (clockwise
seen from above) +, throttle 0..1 with 0.5 the centre, where Position and Altitude mode hold altitude.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sitl_vehicle.airframes import GRAVITY

INT16_MAX = 32767  # MANUAL_CONTROL: an axis sent as INT16_MAX is invalid (unused)


class ManualControlError(ValueError):
    """A MANUAL_CONTROL that cannot be used; the message says why and how to fix it."""


@dataclass(frozen=True)
class Sticks:
    """Normalised sticks: pitch, roll, yaw in -1..1, throttle in 0..1 (0.5 = centre)."""

    pitch: float = 0.0
    roll: float = 0.0
    throttle: float = 0.5
    yaw: float = 0.0


def sticks_from_manual_control(x: int, y: int, z: int, r: int) -> Sticks:
    """MANUAL_CONTROL axes -> Sticks, as PX4 reads a ground station's joystick.

    x (pitch), y (roll) and r (yaw) are -1000..1000, z (throttle) 0..1000 with 500 the centre (what
    QGroundControl's virtual joystick and MAVSDK's ManualControl send). An axis sent as INT16_MAX is unused
    and reads as centred.
    """
    def axis(name: str, value: int, low: int, centre: int) -> float:
        if value == INT16_MAX:
            return centre / 1000.0
        if not low <= value <= 1000:
            raise ManualControlError(f"MANUAL_CONTROL {name}={value} is outside {low}..1000: send {name} in that "
                                     f"range (INT16_MAX marks an unused axis)")
        return value / 1000.0

    return Sticks(pitch=axis("x", x, -1000, 0), roll=axis("y", y, -1000, 0), throttle=axis("z", z, 0, 500),
                  yaw=axis("r", r, -1000, 0))


def expo_deadzone(value: float, expo: float, deadzone: float) -> float:
    """PX4's stick shaping: zero inside ±deadzone, rescaled to reach ±1 at full stick, then the cubic expo
    curve (1 - e)·v + e·v³ (e = 0 linear, e = 1 cubic)."""
    v = max(-1.0, min(1.0, value))
    if abs(v) <= deadzone:
        return 0.0
    v = (v - math.copysign(deadzone, v)) / (1.0 - deadzone)
    return (1.0 - expo) * v + expo * v * v * v


@dataclass(frozen=True)
class StickShape:
    """Parameters of the stick mapping (PX4 names in the comments)."""

    deadzone: float = 0.1            # MPC_HOLD_DZ
    xy_expo: float = 0.6             # MPC_XY_MAN_EXPO
    z_expo: float = 0.6              # MPC_Z_MAN_EXPO
    yaw_expo: float = 0.6            # MPC_YAW_EXPO
    vel_xy_max: float = 10.0         # MPC_VEL_MANUAL, m/s at full stick in Position mode
    vel_up_max: float = 3.0          # MPC_Z_VEL_MAX_UP, m/s at full throttle
    vel_down_max: float = 1.5        # MPC_Z_VEL_MAX_DN, m/s at zero throttle
    yaw_rate_max: float = math.radians(150.0)  # MPC_MAN_Y_MAX, rad/s at full yaw stick
    tilt_max: float = math.radians(35.0)       # MPC_MAN_TILT_MAX, tilt at full stick (Altitude, Stabilized)


@dataclass(frozen=True)
class ShapedSticks:
    """Sticks after dead zone and expo: forward, right, up and yaw in -1..1 (0 = centred)."""

    forward: float
    right: float
    up: float
    yaw: float

    @property
    def horizontal_centred(self) -> bool:
        return self.forward == 0.0 and self.right == 0.0


def shape_sticks(sticks: Sticks, shape: StickShape) -> ShapedSticks:
    return ShapedSticks(forward=expo_deadzone(sticks.pitch, shape.xy_expo, shape.deadzone),
                        right=expo_deadzone(sticks.roll, shape.xy_expo, shape.deadzone),
                        up=expo_deadzone(2.0 * sticks.throttle - 1.0, shape.z_expo, shape.deadzone),
                        yaw=expo_deadzone(sticks.yaw, shape.yaw_expo, shape.deadzone))


def heading_to_ned(forward: float, right: float, yaw: float) -> tuple[float, float]:
    """A (forward, right) vector in the heading frame -> (north, east)."""
    c, s = math.cos(yaw), math.sin(yaw)
    return c * forward - s * right, s * forward + c * right


def _horizontal(shaped: ShapedSticks, yaw: float, full_stick: float) -> tuple[float, float]:
    """The horizontal sticks as a NED vector, ``full_stick`` long at full deflection (a diagonal full stick
    is as long as a straight one)."""
    f, r = shaped.forward, shaped.right
    norm = math.hypot(f, r)
    if norm > 1.0:
        f, r = f / norm, r / norm
    return heading_to_ned(f * full_stick, r * full_stick, yaw)


def stick_velocity(shaped: ShapedSticks, shape: StickShape, yaw: float) -> tuple[float, float]:
    """Position mode: the horizontal NED velocity the sticks ask for (speed up to vel_xy_max)."""
    return _horizontal(shaped, yaw, shape.vel_xy_max)


def stick_climb_velocity(shaped: ShapedSticks, shape: StickShape) -> float:
    """NED vertical velocity (down +) from the throttle stick: up to vel_up_max up, vel_down_max down."""
    return -shaped.up * (shape.vel_up_max if shaped.up > 0 else shape.vel_down_max)


def stick_acceleration(shaped: ShapedSticks, shape: StickShape, yaw: float) -> tuple[float, float]:
    """Altitude mode: the horizontal NED acceleration of a tilt proportional to the sticks (no position or
    velocity hold: centred sticks level the vehicle and it drifts, as PX4's Altitude mode does)."""
    return _horizontal(shaped, yaw, GRAVITY * math.tan(shape.tilt_max))


def superexpo(value: float, expo: float, superexpo_factor: float) -> float:
    """PX4's Acro stick curve: the expo curve (1 - e)·v + e·v³ times (1 - g)/(1 - |v|·g), which keeps 0 and ±1
    and, as g grows, leaves the centre finer and the full stick steeper (v clamped to ±1, e to 0..1, g to
    0..0.99)."""
    v = max(-1.0, min(1.0, value))
    e = max(0.0, min(1.0, expo))
    g = max(0.0, min(0.99, superexpo_factor))
    return ((1.0 - e) * v + e * v * v * v) * (1.0 - g) / (1.0 - abs(v) * g)


@dataclass(frozen=True)
class AcroShape:
    """Acro's stick mapping (PX4 names in the comments): full stick is the rate maximum on each axis."""

    roll_rate_max: float = math.radians(720.0)    # MC_ACRO_R_MAX
    pitch_rate_max: float = math.radians(720.0)   # MC_ACRO_P_MAX
    yaw_rate_max: float = math.radians(540.0)     # MC_ACRO_Y_MAX
    expo: float = 0.69                            # MC_ACRO_EXPO, roll and pitch
    expo_yaw: float = 0.69                        # MC_ACRO_EXPO_Y
    superexpo: float = 0.7                        # MC_ACRO_SUPEXPO, roll and pitch
    superexpo_yaw: float = 0.7                    # MC_ACRO_SUPEXPOY


def acro_rates(sticks: Sticks, shape: AcroShape) -> tuple[float, float, float]:
    """Acro: the body rates (roll, pitch, yaw; rad/s, FRD) the sticks ask for, through :func:`superexpo` and no
    dead zone, as PX4's rate controller reads them: roll stick right rolls right, pitch stick forward pitches
    the nose down, yaw stick right turns clockwise seen from above."""
    return (superexpo(sticks.roll, shape.expo, shape.superexpo) * shape.roll_rate_max,
            superexpo(-sticks.pitch, shape.expo, shape.superexpo) * shape.pitch_rate_max,
            superexpo(sticks.yaw, shape.expo_yaw, shape.superexpo_yaw) * shape.yaw_rate_max)

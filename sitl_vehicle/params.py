"""The vehicle's parameters, by their PX4 names.

Every parameter here is read by the code that flies the vehicle: commander parameters are read on each
update, and controller/planner parameters are pushed into the vehicle core's config objects through the
``on_change`` hook, so a PARAM_SET from a ground station changes behaviour at once, as on PX4. Values
travel as PX4 sends them: MAV_PARAM_TYPE_REAL32, or MAV_PARAM_TYPE_INT32 for the ones PX4 keeps as integers
(enumerations, bitmasks and a few counts), their bytes in the message's float field (PX4's bytewise encoding,
done at the MAVLink edge, :mod:`sitl_vehicle.mavlink_io`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace

INTEGER_UNITS = ("enum", "bitmask")  # parameters with these units are INT32 in PX4


@dataclass(frozen=True)
class ParamSpec:
    name: str  # PX4 name, ≤ 16 characters (MAVLink param_id)
    default: float
    minimum: float
    maximum: float
    unit: str
    description: str
    whole: bool = False  # INT32 in PX4 though neither an enumeration nor a bitmask (an id, whole seconds)

    @property
    def integer(self) -> bool:
        """Kept as an integer, as PX4 keeps it (INT32 over MAVLink)."""
        return self.whole or self.unit in INTEGER_UNITS


class ParameterError(ValueError):
    """A parameter name or value that the vehicle cannot accept."""


class ParameterStore:
    """An ordered set of named float parameters with range checks and change notification."""

    def __init__(self, specs: Iterable[ParamSpec]):
        self._specs: dict[str, ParamSpec] = {}
        for spec in specs:
            if len(spec.name) > 16:
                raise ValueError(f"parameter name {spec.name!r} is longer than MAVLink's 16 characters")
            self._specs[spec.name] = spec
        self._values = {name: spec.default for name, spec in self._specs.items()}
        self._listeners: list[Callable[[str, float], None]] = []

    def __contains__(self, name: str) -> bool:
        return name in self._specs

    def __getitem__(self, name: str) -> float:
        return self._values[name]

    def __len__(self) -> int:
        return len(self._specs)

    def names(self) -> list[str]:
        return list(self._specs)

    def index(self, name: str) -> int:
        return list(self._specs).index(name)

    def spec(self, name: str) -> ParamSpec:
        return self._specs[name]

    def on_change(self, listener: Callable[[str, float], None]) -> None:
        self._listeners.append(listener)

    def set(self, name: str, value: float) -> float:
        """Set a parameter; raises ParameterError naming the problem. Returns the stored value."""
        if name not in self._specs:
            raise ParameterError(f"unknown parameter {name!r}")
        spec = self._specs[name]
        value = float(value)
        if not math.isfinite(value):
            raise ParameterError(f"{name}: value must be finite, got {value}")
        if spec.integer and value != int(value):
            raise ParameterError(f"{name}: {value:g} is not a whole number; it is an integer parameter")
        if not spec.minimum <= value <= spec.maximum:
            raise ParameterError(f"{name}: {value:g} is outside [{spec.minimum:g}, {spec.maximum:g}] {spec.unit}")
        self._values[name] = value
        for listener in self._listeners:
            listener(name, value)
        return value

    def as_dict(self) -> dict[str, float]:
        return dict(self._values)


# Commander and navigator parameters (PX4 names and defaults).
COMMANDER_PARAMS = [
    ParamSpec("MIS_TAKEOFF_ALT", 2.5, 0.5, 100.0, "m", "Takeoff altitude above home: the default, and the "
              "minimum a takeoff command is raised to"),
    ParamSpec("COM_OF_LOSS_T", 1.0, 0.05, 60.0, "s", "Offboard setpoint timeout before failsafe"),
    ParamSpec("COM_OBL_RC_ACT", 5.0, 0.0, 7.0, "enum",
              "Offboard loss action: 3 = Return, 4 = Land, 5 = Hold (other PX4 values fall back to Hold)"),
    ParamSpec("COM_DISARM_LAND", 2.0, -1.0, 20.0, "s", "Auto-disarm this long after landing (<0: off)"),
    ParamSpec("COM_DISARM_PRFLT", 10.0, -1.0, 60.0, "s", "Auto-disarm if no takeoff this long after arming"),
    ParamSpec("MPC_LAND_SPEED", 0.7, 0.2, 2.0, "m/s", "Landing descent speed"),
    ParamSpec("NAV_ACC_RAD", 0.1, 0.02, 5.0, "m", "Acceptance radius of Takeoff and Return waypoints"),
    ParamSpec("NAV_DLL_ACT", 0.0, 0.0, 6.0, "enum", "Ground-station link loss action: 0 = none, 1 = Hold, "
              "2 = Return, 3 = Land, 5/6 = stop the motors (terminate/disarm)"),
    ParamSpec("COM_DL_LOSS_T", 10.0, 1.0, 300.0, "s", "Ground-station heartbeat timeout before the link is lost",
              whole=True),
    ParamSpec("GF_ACTION", 2.0, 0.0, 5.0, "enum", "Geofence breach action: 0 = none, 1 = warning, 2 = Hold, "
              "3 = Return, 4 = terminate (motors stopped), 5 = Land"),
    ParamSpec("GF_MAX_HOR_DIST", 0.0, 0.0, 10000.0, "m", "Geofence: largest distance from home (0: no limit)"),
    ParamSpec("GF_MAX_VER_DIST", 0.0, 0.0, 10000.0, "m", "Geofence: largest height above home (0: no limit)"),
    ParamSpec("COM_DLL_EXCEPT", 0.0, 0.0, 7.0, "bitmask", "Modes where ground-station link loss is only "
              "reported: 1 Mission, 2 Hold/Takeoff/Land/Return, 4 Offboard (it never acts in Land)"),
    ParamSpec("RTL_TYPE", 0.0, 0.0, 3.0, "enum", "Return to: 0 = home or the nearest rally point, 1 = the nearest "
              "rally point or mission landing (home only with neither), 2 = along the mission to its landing (or back "
              "along it to home), 3 = the nearest of home, a rally point and the mission landing"),
    ParamSpec("MC_ORBIT_RAD_MAX", 1000.0, 1.0, 10000.0, "m", "Orbit: largest radius a DO_ORBIT may ask for"),
    ParamSpec("NAV_MC_ALT_RAD", 0.8, 0.05, 200.0, "m", "Orbit: within this of the circle's altitude (and 2 m of "
              "the circle) the vehicle circles; farther, it first flies to the circle"),
    ParamSpec("RTL_RETURN_ALT", 60.0, 0.0, 150.0, "m", "Return: climb to at least this altitude above home"),
    ParamSpec("RTL_DESCEND_ALT", 30.0, 0.5, 100.0, "m", "Return: descend to this altitude above home, then land"),
    ParamSpec("RTL_LAND_DELAY", 0.0, -1.0, 300.0, "s", "Return: hover this long above home before landing "
              "(<0: hover until told otherwise)"),
    # the stick modes (MANUAL_CONTROL from a joystick), sitl_vehicle.manual
    ParamSpec("COM_RC_LOSS_T", 0.5, 0.0, 35.0, "s", "Manual control timeout before the manual-control-loss "
              "failsafe"),
    ParamSpec("NAV_RCL_ACT", 2.0, 0.0, 6.0, "enum", "Manual control loss action (once sticks were heard, "
              "armed with them): 1 = Hold, 2 = Return, 3 = Land, 5/6 = stop the motors (terminate/disarm); "
              "others: Hold"),
    ParamSpec("COM_RCL_EXCEPT", 0.0, 0.0, 7.0, "bitmask", "Modes where manual control loss is only reported: "
              "1 Mission, 2 Hold/Takeoff/Land/Return, 4 Offboard (the stick modes always act on it)"),
    ParamSpec("COM_FAIL_ACT_T", 5.0, 0.0, 25.0, "s", "Manual control or data link lost: hold this long before "
              "the failsafe action, for the pilot to choose a mode instead (<= 0.1: act at once; stopping the "
              "motors and offboard loss never wait)"),
    ParamSpec("COM_RC_OVERRIDE", 1.0, 0.0, 3.0, "bitmask", "Moving the sticks switches to Position mode in: "
              "1 the auto modes (Hold, Takeoff, Land, Return, Mission), 2 Offboard"),
    ParamSpec("COM_RC_STICK_OV", 30.0, 5.0, 80.0, "%", "How far a stick must move (within 1 s) to take over "
              "(throttle counts double)"),
    ParamSpec("MPC_HOLD_DZ", 0.1, 0.0, 1.0, "-", "Stick dead zone of the stick modes"),
    ParamSpec("MPC_XY_MAN_EXPO", 0.6, 0.0, 1.0, "-", "Horizontal stick expo (0 linear, 1 cubic)"),
    ParamSpec("MPC_Z_MAN_EXPO", 0.6, 0.0, 1.0, "-", "Throttle stick expo (0 linear, 1 cubic)"),
    ParamSpec("MPC_YAW_EXPO", 0.6, 0.0, 1.0, "-", "Yaw stick expo (0 linear, 1 cubic)"),
    ParamSpec("MPC_VEL_MANUAL", 10.0, 1.0, 20.0, "m/s", "Position mode: horizontal speed at full stick"),
    ParamSpec("MPC_MAN_Y_MAX", 150.0, 0.0, 400.0, "deg/s", "Yaw rate at full yaw stick"),
    ParamSpec("MPC_MAN_TILT_MAX", 35.0, 1.0, 85.0, "deg", "Altitude and Stabilized modes: tilt at full stick"),
    ParamSpec("MC_ACRO_R_MAX", 720.0, 0.0, 1800.0, "deg/s", "Acro: roll rate at full stick"),
    ParamSpec("MC_ACRO_P_MAX", 720.0, 0.0, 1800.0, "deg/s", "Acro: pitch rate at full stick"),
    ParamSpec("MC_ACRO_Y_MAX", 540.0, 0.0, 1800.0, "deg/s", "Acro: yaw rate at full stick"),
    ParamSpec("MC_ACRO_EXPO", 0.69, 0.0, 1.0, "-", "Acro: roll and pitch stick expo (0 linear, 1 cubic)"),
    ParamSpec("MC_ACRO_EXPO_Y", 0.69, 0.0, 1.0, "-", "Acro: yaw stick expo (0 linear, 1 cubic)"),
    ParamSpec("MC_ACRO_SUPEXPO", 0.7, 0.0, 0.95, "-", "Acro: roll and pitch SuperExpo (0 plain expo)"),
    ParamSpec("MC_ACRO_SUPEXPOY", 0.7, 0.0, 0.95, "-", "Acro: yaw SuperExpo (0 plain expo)"),
    ParamSpec("SYS_AUTOSTART", 4001.0, 0.0, 1e6, "", "Airframe id (4001: generic quadrotor X)", whole=True),
]


@dataclass(frozen=True)
class ConfigBinding:
    """A PX4 parameter that lives in one field (or one element of a tuple field) of the core's configs."""

    spec: ParamSpec
    config: str  # "control" or "planner": which VehicleConfig member holds it
    field: str
    index: int | None = None  # element of a (roll, pitch, yaw) tuple field
    scale: float = 1.0  # config value = parameter value × scale (PX4 gives angles in degrees)


_DEG = math.pi / 180.0


def _b(name, config, field_name, lo, hi, unit, text, index=None, scale=1.0) -> ConfigBinding:
    return ConfigBinding(ParamSpec(name, math.nan, lo, hi, unit, text), config, field_name, index, scale)


# Controller and planner parameters; their defaults are read from the vehicle's configs at boot.
CONFIG_BINDINGS = [
    _b("MPC_XY_P", "control", "pos_p_xy", 0.0, 10.0, "1/s", "Horizontal position gain"),
    _b("MPC_Z_P", "control", "pos_p_z", 0.0, 10.0, "1/s", "Vertical position gain"),
    _b("MPC_XY_VEL_P_ACC", "control", "vel_p_xy", 0.0, 30.0, "1/s", "Horizontal velocity P gain"),
    _b("MPC_XY_VEL_I_ACC", "control", "vel_i_xy", 0.0, 30.0, "1/s^2", "Horizontal velocity I gain"),
    _b("MPC_XY_VEL_D_ACC", "control", "vel_d_xy", 0.0, 5.0, "-", "Horizontal velocity D gain"),
    _b("MPC_Z_VEL_P_ACC", "control", "vel_p_z", 0.0, 30.0, "1/s", "Vertical velocity P gain"),
    _b("MPC_Z_VEL_I_ACC", "control", "vel_i_z", 0.0, 30.0, "1/s^2", "Vertical velocity I gain"),
    _b("MPC_Z_VEL_D_ACC", "control", "vel_d_z", 0.0, 5.0, "-", "Vertical velocity D gain"),
    _b("MPC_XY_VEL_MAX", "control", "vel_max_xy", 0.1, 30.0, "m/s", "Horizontal velocity limit"),
    _b("MPC_Z_VEL_MAX_UP", "control", "vel_max_up", 0.1, 10.0, "m/s", "Climb velocity limit"),
    _b("MPC_Z_VEL_MAX_DN", "control", "vel_max_down", 0.1, 10.0, "m/s", "Descent velocity limit"),
    _b("MPC_TILTMAX_AIR", "control", "tilt_max_rad", 5.0, 89.0, "deg", "Tilt limit", scale=_DEG),
    _b("MPC_THR_MIN", "control", "thrust_min", 0.0, 0.5, "-", "Minimum collective thrust"),
    _b("MPC_THR_MAX", "control", "thrust_max", 0.5, 1.0, "-", "Maximum collective thrust"),
    _b("MC_ROLL_P", "control", "att_p", 0.0, 20.0, "1/s", "Roll attitude gain", index=0),
    _b("MC_PITCH_P", "control", "att_p", 0.0, 20.0, "1/s", "Pitch attitude gain", index=1),
    _b("MC_YAW_P", "control", "att_p", 0.0, 20.0, "1/s", "Yaw attitude gain", index=2),
    _b("MC_YAW_WEIGHT", "control", "yaw_weight", 0.0, 1.0, "-", "Yaw weight in the attitude error"),
    _b("MC_ROLLRATE_MAX", "control", "rate_max", 1.0, 1800.0, "deg/s", "Roll rate limit", index=0, scale=_DEG),
    _b("MC_PITCHRATE_MAX", "control", "rate_max", 1.0, 1800.0, "deg/s", "Pitch rate limit", index=1, scale=_DEG),
    _b("MC_YAWRATE_MAX", "control", "rate_max", 1.0, 1800.0, "deg/s", "Yaw rate limit", index=2, scale=_DEG),
    _b("MC_ROLLRATE_P", "control", "rate_p", 0.0, 100.0, "1/s", "Roll rate P gain", index=0),
    _b("MC_PITCHRATE_P", "control", "rate_p", 0.0, 100.0, "1/s", "Pitch rate P gain", index=1),
    _b("MC_YAWRATE_P", "control", "rate_p", 0.0, 100.0, "1/s", "Yaw rate P gain", index=2),
    _b("MC_ROLLRATE_I", "control", "rate_i", 0.0, 100.0, "1/s^2", "Roll rate I gain", index=0),
    _b("MC_PITCHRATE_I", "control", "rate_i", 0.0, 100.0, "1/s^2", "Pitch rate I gain", index=1),
    _b("MC_YAWRATE_I", "control", "rate_i", 0.0, 100.0, "1/s^2", "Yaw rate I gain", index=2),
    _b("MC_ROLLRATE_D", "control", "rate_d", 0.0, 5.0, "-", "Roll rate D gain", index=0),
    _b("MC_PITCHRATE_D", "control", "rate_d", 0.0, 5.0, "-", "Pitch rate D gain", index=1),
    _b("MC_YAWRATE_D", "control", "rate_d", 0.0, 5.0, "-", "Yaw rate D gain", index=2),
    _b("MPC_XY_CRUISE", "planner", "v_max_xy", 0.1, 20.0, "m/s", "Planned horizontal speed"),
    _b("MPC_Z_V_AUTO_UP", "planner", "v_max_up", 0.1, 10.0, "m/s", "Planned climb speed"),
    _b("MPC_Z_V_AUTO_DN", "planner", "v_max_down", 0.1, 10.0, "m/s", "Planned descent speed"),
    _b("MPC_ACC_HOR", "planner", "a_max_xy", 0.1, 20.0, "m/s^2", "Planned horizontal acceleration"),
    _b("MPC_ACC_UP_MAX", "planner", "a_max_z", 0.1, 20.0, "m/s^2", "Planned vertical acceleration"),
]


def _config_value(configs: dict, binding: ConfigBinding) -> float:
    value = getattr(configs[binding.config], binding.field)
    if binding.index is not None:
        value = value[binding.index]
    return float(value) / binding.scale


def bound_specs(configs: dict) -> list[ParamSpec]:
    """The bound parameters' specs with defaults read from ``configs`` ({"control": ..., "planner": ...})."""
    return [replace(b.spec, default=_config_value(configs, b)) for b in CONFIG_BINDINGS]


def apply_binding(configs: dict, name: str, value: float) -> dict:
    """Return new configs with parameter ``name`` set to ``value`` (unchanged configs if it is not bound)."""
    binding = next((b for b in CONFIG_BINDINGS if b.spec.name == name), None)
    if binding is None:
        return configs
    target = configs[binding.config]
    new_value = value * binding.scale
    if binding.index is not None:
        items = list(getattr(target, binding.field))
        items[binding.index] = new_value
        new_value = tuple(items)
    return {**configs, binding.config: replace(target, **{binding.field: new_value})}

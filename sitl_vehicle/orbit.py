"""Orbit mode (MAV_CMD_DO_ORBIT, MAVSDK's ``do_orbit``) as PX4's multicopter flight task flies it (pure).

A circle of ``radius`` round a centre at an altitude, flown at a tangential ``speed`` (positive: clockwise seen from
above, the sign of the command's radius).  Entered without a circle (DO_SET_MODE), or before a command names one,
PX4 starts a 1 m circle round where the vehicle is at 1 m/s.  A command changes what it names and keeps the rest
(NaN: keep); the radius is held to 1 m-``MC_ORBIT_RAD_MAX`` and the speed to 10 m/s, and a speed whose centripetal
acceleration would reach 2 m/s² is lowered to the one that does not (PX4 keeps the radius: a small circle flown
slowly is the safe one).  Off the circle (more than 2 m from it, or ``NAV_MC_ALT_RAD`` from its altitude) the
vehicle flies straight to its nearest point facing the centre; on it, it flies the tangent with a pull back to the
radius, facing as the yaw behaviour says.  Live sticks (MANUAL_CONTROL) change the circle as PX4's do
(:func:`stick_adjusted`): the radius and the speed, and the throttle climbs or descends with the circle, centred
holding its altitude.  The functions are the geometry; :class:`OrbitMode` is the commander's part (mixed into
:class:`sitl_vehicle.commander.Commander`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.commander_types import ACCEPTED, Reply, VehicleStatus
from sitl_vehicle.manual import stick_climb_velocity
from sitl_vehicle.modes import FlightMode
from sitl_vehicle.sim import Setpoint
from sitl_vehicle.trajectory import PlannerConfig

NAN = math.nan

# PX4's FlightTaskOrbit limits and acceptance (constants there, as here)
RADIUS_MIN_M = 1.0
SPEED_MAX_MPS = 10.0
ACCELERATION_MAX_MPS2 = 2.0
ON_CIRCLE_M = 2.0
START_SPEED_MPS = 1.0
STICK_STEP_MAX_S = 0.5   # the longest step the sticks act over (PX4's flight task time-out)
PLANNER_DEFAULTS = PlannerConfig()   # MPC_XY_CRUISE and MPC_ACC_HOR where the vehicle's parameters are not bound

# MAVLink ORBIT_YAW_BEHAVIOUR
YAW_FRONT_TO_CENTER = 0
YAW_HOLD_INITIAL_HEADING = 1
YAW_UNCONTROLLED = 2
YAW_FRONT_TANGENT = 3
YAW_RC_CONTROLLED = 4
YAW_BEHAVIOURS = (YAW_FRONT_TO_CENTER, YAW_HOLD_INITIAL_HEADING, YAW_UNCONTROLLED, YAW_FRONT_TANGENT,
                  YAW_RC_CONTROLLED)


@dataclass(frozen=True)
class Orbit:
    """One circle: ``centre`` (local north, east and down, m), ``radius`` (m), ``speed`` (m/s, + clockwise),
    ``yaw_behaviour`` (ORBIT_YAW_BEHAVIOUR), the heading it was commanded at (for HOLD_INITIAL_HEADING), the
    direction it was commanded in (the sense of the sticks with the nose along the tangent: PX4 keeps it while the
    sticks turn the circle round) and when the sticks last acted on it (s; None: not yet)."""

    centre: tuple[float, float, float]
    radius: float
    speed: float
    yaw_behaviour: int = YAW_FRONT_TO_CENTER
    initial_yaw: float = 0.0
    started_clockwise: bool = True
    sticks_at_s: float | None = field(default=None, compare=False)   # bookkeeping, not the circle


def feasible(radius: float, speed: float, radius_max: float) -> tuple[float, float]:
    """The radius held to its range, and the speed to its limit and to the centripetal acceleration limit."""
    radius = min(max(radius, RADIUS_MIN_M), radius_max)
    speed = min(max(speed, -SPEED_MAX_MPS), SPEED_MAX_MPS)
    if speed * speed >= ACCELERATION_MAX_MPS2 * radius:
        speed = math.copysign(math.sqrt(ACCELERATION_MAX_MPS2 * radius), speed)
    return radius, speed


def starting_orbit(position: tuple[float, float, float], yaw: float, radius_max: float) -> Orbit:
    """The circle PX4's Orbit starts with: 1 m round where the vehicle is, clockwise at 1 m/s."""
    radius, speed = feasible(RADIUS_MIN_M, START_SPEED_MPS, radius_max)
    return Orbit(tuple(position), radius, speed, YAW_FRONT_TO_CENTER, yaw)


def commanded_orbit(orbit: Orbit, yaw: float, radius_max: float, radius: float = NAN, speed: float = NAN,
                    yaw_behaviour: float = NAN, centre_ne: tuple[float, float] = (NAN, NAN),
                    down: float = NAN) -> Orbit:
    """``orbit`` changed by a DO_ORBIT's parameters (NaN: keep): the radius's sign is the direction, the speed its
    magnitude; ``yaw`` is the heading now, the one HOLD_INITIAL_HEADING keeps.  The caller has checked
    ``yaw_behaviour`` against :data:`YAW_BEHAVIOURS`."""
    clockwise = orbit.speed > 0
    new_radius, magnitude = orbit.radius, abs(orbit.speed)
    if math.isfinite(radius):
        clockwise = radius > 0
        new_radius = abs(radius)
    if math.isfinite(speed):
        magnitude = speed
    new_radius, new_speed = feasible(new_radius, magnitude if clockwise else -magnitude, radius_max)
    north, east, centre_down = orbit.centre
    if math.isfinite(centre_ne[0]) and math.isfinite(centre_ne[1]):
        north, east = centre_ne
    if math.isfinite(down):
        centre_down = down
    behaviour = int(yaw_behaviour) if math.isfinite(yaw_behaviour) else orbit.yaw_behaviour
    return replace(orbit, centre=(north, east, centre_down), radius=new_radius, speed=new_speed,
                   yaw_behaviour=behaviour, initial_yaw=yaw, started_clockwise=clockwise)


def stick_adjusted(orbit: Orbit, forward: float, right: float, dt: float, radius_max: float, radius_rate: float,
                   speed_rate: float) -> Orbit:
    """``orbit`` as PX4's sticks change it over ``dt`` s (``forward``, ``right``: the shaped pitch and roll sticks,
    -1..1).  Facing the centre (any yaw behaviour but FRONT_TANGENT), the pitch stick forward draws the circle in at
    ``radius_rate`` (MPC_XY_CRUISE, m/s at full stick) and the roll stick right speeds it up clockwise at
    ``speed_rate`` (MPC_ACC_HOR, m/s² at full stick; left: counter-clockwise, through a stop).  With the nose along
    the tangent the two swap, in the sense the circle was commanded in: roll towards the centre draws it in, pitch
    forward speeds it along.  The result is held to :func:`feasible`."""
    radius_stick, speed_stick = forward, right
    if orbit.yaw_behaviour == YAW_FRONT_TANGENT:
        sense = 1.0 if orbit.started_clockwise else -1.0
        radius_stick, speed_stick = sense * right, sense * forward
    radius, speed = feasible(orbit.radius - radius_stick * dt * radius_rate,
                             orbit.speed + speed_stick * dt * speed_rate, radius_max)
    return replace(orbit, radius=radius, speed=speed)


def on_circle(orbit: Orbit, position: tuple[float, float, float], altitude_acceptance_m: float) -> bool:
    """Within 2 m of the circle and ``altitude_acceptance_m`` (NAV_MC_ALT_RAD) of its altitude."""
    north, east, down = orbit.centre
    off = math.hypot(position[0] - north, position[1] - east) - orbit.radius
    return abs(off) < ON_CIRCLE_M and abs(position[2] - down) < altitude_acceptance_m


def approach_point(orbit: Orbit, position: tuple[float, float, float]) -> tuple[float, float, float]:
    """The circle's point nearest ``position``, at its altitude (from its centre: the point due north)."""
    north, east, down = orbit.centre
    dn, de = position[0] - north, position[1] - east
    distance = math.hypot(dn, de)
    un, ue = (dn / distance, de / distance) if distance > 1e-9 else (1.0, 0.0)
    return north + un * orbit.radius, east + ue * orbit.radius, down


def facing_centre(orbit: Orbit, position: tuple[float, float, float]) -> float:
    """The heading from ``position`` to the centre (the one held at the centre itself: north)."""
    dn, de = orbit.centre[0] - position[0], orbit.centre[1] - position[1]
    return math.atan2(de, dn) if math.hypot(dn, de) > 1e-9 else 0.0


def circle_setpoint(orbit: Orbit, position: tuple[float, float, float]) -> Setpoint:
    """On the circle: the tangent at ``speed`` plus the radial error as a velocity back to it, the centripetal
    acceleration as feed-forward, the circle's altitude, and the heading of the yaw behaviour."""
    north, east, down = orbit.centre
    dn, de = position[0] - north, position[1] - east
    distance = math.hypot(dn, de)
    un, ue = (dn / distance, de / distance) if distance > 1e-9 else (0.0, 0.0)
    v, r = orbit.speed, orbit.radius
    velocity = (-ue * v + (r - distance) * un, un * v + (r - distance) * ue, NAN)
    acceleration = (-un * v * v / r, -ue * v * v / r, NAN)
    yaw, yaw_rate = NAN, NAN
    if orbit.yaw_behaviour == YAW_HOLD_INITIAL_HEADING:
        yaw = orbit.initial_yaw
    elif orbit.yaw_behaviour == YAW_FRONT_TANGENT:
        ahead = math.copysign(1.0, v)
        yaw, yaw_rate = math.atan2(ahead * un, -ahead * ue), v / r
    elif orbit.yaw_behaviour == YAW_FRONT_TO_CENTER:
        yaw, yaw_rate = math.atan2(-ue, -un), v / r
    # YAW_UNCONTROLLED and YAW_RC_CONTROLLED (the yaw stick is not flown in Orbit here): the heading it has is held
    return Setpoint(position=(NAN, NAN, down), velocity=velocity, acceleration=acceleration, yaw=yaw,
                    yaw_rate=yaw_rate)


class OrbitMode:
    """The commander's Orbit mode, mixed into :class:`sitl_vehicle.commander.Commander` (whose state it uses)."""

    def orbit(self, status: VehicleStatus, radius: float = NAN, speed: float = NAN, yaw_behaviour: float = NAN,
              centre_ne: tuple[float, float] = (NAN, NAN), down: float = NAN) -> Reply:
        """MAV_CMD_DO_ORBIT (MAVSDK's do_orbit): Orbit mode, on the circle the parameters name (NaN: keep the
        circle flown, or the one Orbit starts with; see :mod:`sitl_vehicle.orbit`)."""
        refused = self._refused_unless_flying(status, "Orbit denied: not flying (take off first)")
        if refused is not None:
            return refused
        if self.mode is not FlightMode.ORBIT:
            self._enter(FlightMode.ORBIT, status)
        self._orbit = commanded_orbit(self._orbit, status.yaw, self.params["MC_ORBIT_RAD_MAX"], radius, speed,
                                      yaw_behaviour, centre_ne, down)
        self._orbit_approach = None         # a new circle is approached afresh
        o = self._orbit
        self._say(mavlink.MAV_SEVERITY_INFO, f"Orbit: {o.radius:.1f} m round {o.centre[0]:.1f} m north, "
                                             f"{o.centre[1]:.1f} m east, {self.home[2] - o.centre[2]:.1f} m above "
                                             f"home, {abs(o.speed):.1f} m/s {'' if o.speed > 0 else 'counter-'}"
                                             "clockwise")
        return ACCEPTED

    @property
    def orbit_flown(self) -> Orbit | None:
        """The circle Orbit mode flies (None in any other mode): ORBIT_EXECUTION_STATUS reports it."""
        return self._orbit if self.mode is FlightMode.ORBIT else None

    def _orbit_setpoint(self, status: VehicleStatus) -> Setpoint:
        """On the circle, round it; off it, straight to its nearest point as it was when the approach began,
        facing the centre.  The sticks act first; a throttle off centre climbs or descends at its speed."""
        climb = self._orbit_sticks(status)
        if on_circle(self._orbit, status.position, self.params["NAV_MC_ALT_RAD"]):
            self._orbit_approach = None
            setpoint = circle_setpoint(self._orbit, status.position)
        else:
            if self._orbit_approach is None:
                self._orbit_approach = approach_point(self._orbit, status.position)
            setpoint = Setpoint(position=self._orbit_approach, yaw=facing_centre(self._orbit, status.position))
        if climb == 0.0:
            return setpoint
        return replace(setpoint, position=(*setpoint.position[:2], NAN), velocity=(*setpoint.velocity[:2], climb))

    def _orbit_sticks(self, status: VehicleStatus) -> float:
        """The circle changed by live sticks since they last acted (:func:`stick_adjusted`, over at most
        :data:`STICK_STEP_MAX_S`); returns the throttle's climb velocity (NED down, m/s; 0 centred or without
        sticks).  Climbing, the circle's altitude follows the vehicle's, so a centred throttle holds where it is;
        a circle changed is approached afresh."""
        orbit, now = self._orbit, status.time_s
        self._orbit = replace(orbit, sticks_at_s=now)
        if orbit.sticks_at_s is None or not self._manual_alive(now):
            return 0.0
        p, sticks = self.params, self._shaped_sticks()
        cruise = p["MPC_XY_CRUISE"] if "MPC_XY_CRUISE" in p else PLANNER_DEFAULTS.v_max_xy
        acceleration = p["MPC_ACC_HOR"] if "MPC_ACC_HOR" in p else PLANNER_DEFAULTS.a_max_xy
        adjusted = stick_adjusted(orbit, sticks.forward, sticks.right,
                                  min(max(now - orbit.sticks_at_s, 0.0), STICK_STEP_MAX_S),
                                  p["MC_ORBIT_RAD_MAX"], cruise, acceleration)
        climb = stick_climb_velocity(sticks, self._stick_shape())
        if climb != 0.0:
            adjusted = replace(adjusted, centre=(*orbit.centre[:2], status.position[2]))
        if (adjusted.radius, adjusted.centre) != (orbit.radius, orbit.centre):
            self._orbit_approach = None
        self._orbit = replace(adjusted, sticks_at_s=now)
        return climb

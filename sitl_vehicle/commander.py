"""Commander: flight modes, arming and failsafes with PX4 semantics, as a pure state machine.

The commander owns no clock and no sockets. The MAVLink edge calls its request methods when commands
arrive and ``update`` once per control tick with the vehicle's status; it answers with a ``Reply``
(a MAV_RESULT plus the reason PX4 would print) and, from ``update``, the armed state and setpoint the
vehicle core must fly. STATUSTEXT lines it wants sent are queued in ``messages``.

Four parts have modules of their own, mixed into :class:`Commander`: the link-loss failsafes and the
pilot's stick takeover (``sitl_vehicle.failsafes``), Return's legs, a mission's items and the requests that load
and start one (``sitl_vehicle.navigator``), Orbit mode's circle (``sitl_vehicle.orbit``) and the stick modes'
setpoints (``sitl_vehicle.stick_modes``). Their constants, and the types in ``sitl_vehicle.commander_types``, are
importable from here too, as before the split.
"""

from __future__ import annotations

import logging
import math
from collections import deque

from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.commander_types import ACCEPTED, CommanderOutput, Reply, VehicleStatus
from sitl_vehicle.failsafes import (
    AUTO_MODES,
    DLL_ACTIONS,
    DLL_STOP_MOTORS,
    FAIL_ACT_T_MIN,
    FAILSAFE_SEVERITY,
    GF_NONE,
    LOSS_EXCEPTION_BIT,
    OBL_ACTION_LAND,
    OBL_ACTION_RETURN,
    RC_OVERRIDE_AUTO,
    RC_OVERRIDE_OFFBOARD,
    STICK_MOVE_WINDOW_S,
    Failsafes,
)
from sitl_vehicle.geofence import Geofence, RallyItem
from sitl_vehicle.manual import Sticks
from sitl_vehicle.mission import MissionItem
from sitl_vehicle.modes import FlightMode
from sitl_vehicle.navigator import (
    MIS_CLIMB,
    MIS_DONE,
    MIS_FLY,
    MIS_HOLD,
    MIS_LAND,
    RTL_CLIMB,
    RTL_DESCEND,
    RTL_LAND,
    RTL_LOITER,
    RTL_RETURN,
    Navigator,
)
from sitl_vehicle.orbit import Orbit, OrbitMode, starting_orbit
from sitl_vehicle.params import ParameterStore
from sitl_vehicle.return_plan import ReturnPlan
from sitl_vehicle.sim import ManualSetpoint, Setpoint
from sitl_vehicle.stick_modes import StickModes, stopping_point

__all__ = [
    "ACCEPTED", "ARM_THROTTLE_LOW", "ARM_THROTTLE_MAX", "AUTO_MODES", "DLL_ACTIONS", "DLL_STOP_MOTORS",
    "FAIL_ACT_T_MIN", "FAILSAFE_SEVERITY", "LOSS_EXCEPTION_BIT", "MIS_CLIMB", "MIS_DONE", "MIS_FLY", "MIS_HOLD",
    "MIS_LAND", "NAN", "OBL_ACTION_LAND", "OBL_ACTION_RETURN", "RC_OVERRIDE_AUTO", "RC_OVERRIDE_OFFBOARD", "RTL_CLIMB",
    "RTL_DESCEND", "RTL_LAND", "RTL_LOITER", "RTL_RETURN", "STICK_MOVE_WINDOW_S", "TAKEOFF_ALT_SILENT_MARGIN",
    "Commander", "CommanderOutput", "Reply", "VehicleStatus",
]

log = logging.getLogger(__name__)
NAN = math.nan

# PX4 raises a takeoff altitude below MIS_TAKEOFF_ALT silently when it is short by less than this (Navigator:
# "don't complain if difference is smaller than 10cm")
TAKEOFF_ALT_SILENT_MARGIN = 0.1
# PX4 refuses to arm in Position or Altitude mode with the throttle stick above this (0.5 = centre), and in
# Stabilized or Manual mode unless the throttle is low
ARM_THROTTLE_MAX = 0.6
ARM_THROTTLE_LOW = 0.2


class Commander(Failsafes, Navigator, OrbitMode, StickModes):
    """PX4-like commander/navigator for Takeoff, Hold, Land, Return, Mission (``set_mission``), Offboard, Orbit
    (``orbit``), and the stick modes Position, Altitude, Stabilized, Manual and Acro (``manual_control``).

    ``home`` (local NED) is where the vehicle last armed on the ground, as PX4 sets it (or a place DO_SET_HOME
    sent, which arming keeps); Takeoff altitudes and Return are relative to it.
    """

    def __init__(self, params: ParameterStore, home: tuple[float, float, float] = (0.0, 0.0, 0.0)):
        self.params = params
        self.home = home
        self._home_set_manually = False  # by DO_SET_HOME to a place: arming then keeps it, as PX4 does
        self.mode = FlightMode.AUTO_LOITER
        self.armed = False
        self.failsafe = False
        self.messages: deque[tuple[int, str]] = deque(maxlen=64)
        self._armed_at = 0.0
        self._has_flown = False
        self._landed_since: float | None = None
        self._hold_target: tuple[float, float, float] | None = None
        self._hold_yaw = 0.0
        self._takeoff_target: tuple[float, float, float] | None = None
        self._takeoff_has_xy = False  # the takeoff flies to a horizontal target too (else: climbs where it is)
        self._land_xy: tuple[float, float] | None = None
        self._offboard_setpoint: Setpoint | None = None
        self._offboard_time = -math.inf
        self._gcs_time: float | None = None  # last ground-station heartbeat (None: never connected)
        self._gcs_lost = False
        self._gcs_failsafe_done = False  # the data-link failsafe acted on this loss already
        # a link-loss action waiting out COM_FAIL_ACT_T in Hold: (the mode it switches to, when)
        self._delayed_failsafe: tuple[FlightMode, float] | None = None
        self._failsafe_stick_takeover = False  # whether moving the sticks may end the current failsafe
        self._rtl_leg: str | None = None
        self._rtl_start_xy = (0.0, 0.0)
        self._rtl_z = 0.0
        self._rtl_loiter_since = 0.0
        self._sticks: Sticks | None = None
        self._sticks_time = -math.inf
        self._recent_sticks: deque[tuple[float, Sticks]] = deque()  # the last STICK_MOVE_WINDOW_S of input
        self._sticks_moved = False  # moved since the last update: a takeover request
        self._manual_lost = False
        self._manual_lost_at_arming = False  # armed without sticks: their loss is ignored until they return
        self._manual_failsafe_done = False  # the manual-control failsafe acted on this loss already
        self._stick_hold_xy: tuple[float, float] | None = None  # where centred sticks hold (Position mode)
        self._stick_hold_z: float | None = None  # the altitude a centred throttle holds
        self._stick_yawing = False
        self.mission: tuple[MissionItem, ...] = ()
        self.mission_seq = 0  # the current item
        self.mission_reached: deque[int] = deque(maxlen=64)  # items reached, for MISSION_ITEM_REACHED
        self._mission_phase = MIS_DONE
        self._mission_target: tuple[float, float, float] = (NAN, NAN, NAN)
        self._mission_speed = NAN  # the horizontal speed a DO_CHANGE_SPEED set (NaN: MPC_XY_CRUISE)
        self._jumps_done: dict[int, int] = {}  # DO_JUMP item -> the jumps it made in this run of the mission
        self._mission_since = 0.0
        self._mission_complete = False
        self.geofence = Geofence()
        self._geofence_breached = False  # the geofence failsafe acted on this breach already
        self.rally_points: tuple[RallyItem, ...] = ()
        self._rtl_plan: ReturnPlan | None = None  # where and how Return flies (set as it begins)
        self._rtl_path_index = 0  # the point of its path being flown to
        self._reposition: tuple[tuple[float, float, float], float] | None = None  # its target and speed
        self._orbit: Orbit | None = None  # the circle Orbit mode flies
        self._orbit_approach: tuple[float, float, float] | None = None  # where it flies to reach the circle

    # ----------------------------------------------------------------------------------- requests
    def arm(self, status: VehicleStatus, force: bool = False) -> Reply:
        if self.armed:
            return ACCEPTED
        if not force:
            reason = self._arming_denied_reason(status)
            if reason:
                return self._refuse(mavlink.MAV_RESULT_TEMPORARILY_REJECTED, f"Arming denied: {reason}")
        self.armed = True
        if status.landed and not self._home_set_manually:
            self.home = status.position
        self._armed_at = status.time_s
        self._has_flown = False
        self._landed_since = status.time_s if status.landed else None
        self.failsafe = False
        self._delayed_failsafe = None
        self._manual_lost_at_arming = self._manual_lost
        self._manual_failsafe_done = self._gcs_failsafe_done = False
        self._enter(self.mode, status)
        self._say(mavlink.MAV_SEVERITY_INFO, "Armed by external command")
        return ACCEPTED

    def disarm(self, status: VehicleStatus, force: bool = False) -> Reply:
        if not self.armed:
            return ACCEPTED
        if not status.landed and not force:
            return self._refuse(mavlink.MAV_RESULT_DENIED, "Disarming denied: not landed")
        self._disarm("Disarmed by external command")
        return ACCEPTED

    def set_mode(self, mode: FlightMode, status: VehicleStatus) -> Reply:
        if mode is FlightMode.OFFBOARD and not self._offboard_alive(status.time_s):
            return self._refuse(mavlink.MAV_RESULT_TEMPORARILY_REJECTED,
                                "Switching to Offboard is currently not possible: no setpoint stream")
        if mode is FlightMode.AUTO_TAKEOFF:
            return self.takeoff(status, NAN)
        if mode is FlightMode.AUTO_RTL:
            return self.return_to_launch(status)
        if mode is FlightMode.AUTO_MISSION and not self.mission:
            return self._refuse(mavlink.MAV_RESULT_TEMPORARILY_REJECTED,
                                "Switching to Mission is currently not possible: no mission (upload one first)")
        if mode is FlightMode.ORBIT and (not self.armed or status.landed):
            return self._refuse(mavlink.MAV_RESULT_TEMPORARILY_REJECTED,
                                "Switching to Orbit is currently not possible: not flying (take off first)")
        if mode.manual and not self._manual_alive(status.time_s):
            return self._refuse(mavlink.MAV_RESULT_TEMPORARILY_REJECTED,
                                f"Switching to {mode.label} is currently not possible: no manual control input "
                                "(send MANUAL_CONTROL)")
        self._pilot_takes_over()
        self._enter(mode, status)
        return ACCEPTED

    def takeoff(self, status: VehicleStatus, altitude_above_home: float = NAN,
                target_xy: tuple[float, float] | None = None) -> Reply:
        """Takeoff as PX4's Navigator does it: climb to ``altitude_above_home`` (local NED, home = where the
        vehicle armed), never below the minimum ``MIS_TAKEOFF_ALT`` above home and never down, then Hold.

        A finite altitude below the minimum is raised to it ("Using minimum takeoff altitude", critical when it
        was short by more than ``TAKEOFF_ALT_SILENT_MARGIN``); a NaN altitude flies the minimum and only says so
        (info). ``target_xy`` (local north, east) is where to climb to; None climbs where the vehicle is. The
        heading is kept: PX4 ignores a takeoff yaw on multicopters.
        """
        if not self.armed:
            return self._refuse(mavlink.MAV_RESULT_TEMPORARILY_REJECTED, "Takeoff denied: arm first")
        minimum = self.params["MIS_TAKEOFF_ALT"]
        if not math.isfinite(altitude_above_home):
            self._say(mavlink.MAV_SEVERITY_INFO, f"Using minimum takeoff altitude: {minimum:.2f} m")
            altitude_above_home = minimum
        elif altitude_above_home < minimum:
            if altitude_above_home < minimum - TAKEOFF_ALT_SILENT_MARGIN:
                self._say(mavlink.MAV_SEVERITY_CRITICAL, f"Using minimum takeoff altitude: {minimum:.2f} m")
            altitude_above_home = minimum
        target_down = self.home[2] - altitude_above_home
        if target_down > status.position[2]:  # NED: the target is below the vehicle, and takeoff never descends
            target_down = status.position[2]
            self._say(mavlink.MAV_SEVERITY_CRITICAL, "Already higher than takeoff altitude")
        north, east = target_xy if target_xy is not None else status.position[:2]
        self._delayed_failsafe = None
        self._takeoff_target = (north, east, target_down)
        self._takeoff_has_xy = target_xy is not None
        self._enter(FlightMode.AUTO_TAKEOFF, status)
        self._say(mavlink.MAV_SEVERITY_INFO, f"Takeoff to {self.home[2] - target_down:.1f} m above home")
        return ACCEPTED

    def land(self, status: VehicleStatus) -> Reply:
        self._delayed_failsafe = None
        self._enter(FlightMode.AUTO_LAND, status)
        return ACCEPTED

    def return_to_launch(self, status: VehicleStatus) -> Reply:
        """Return mode: climb to RTL_RETURN_ALT above home (never down), fly home, descend to
        RTL_DESCEND_ALT, hover RTL_LAND_DELAY s, land."""
        refused = self._refused_unless_flying(status, "Return denied: not flying")
        if refused is not None:
            return refused
        self._enter(FlightMode.AUTO_RTL, status)
        return ACCEPTED

    def reposition(self, status: VehicleStatus, target: tuple[float, float, float], yaw: float = NAN,
                   speed: float = NAN) -> Reply:
        """MAV_CMD_DO_REPOSITION (MAVSDK's goto_location), as PX4 flies it: Hold mode, flying to ``target`` (local
        NED; a NaN component keeps the vehicle's own) at ``speed`` (m/s; NaN or not above 0: MPC_XY_CRUISE), facing
        ``yaw`` (rad; NaN: the heading it has), then holding there."""
        refused = self._refused_unless_flying(status, "Reposition denied: not flying (take off first)")
        if refused is not None:
            return refused
        self._enter(FlightMode.AUTO_LOITER, status)
        goal = tuple(t if math.isfinite(t) else here for t, here in zip(target, status.position, strict=True))
        self._hold_target = goal
        if math.isfinite(yaw):
            self._hold_yaw = yaw
        self._reposition = (goal, speed if speed > 0 else NAN)   # (NaN > 0 is False)
        self._say(mavlink.MAV_SEVERITY_INFO, f"Reposition: flying to {goal[0]:.1f} m north, {goal[1]:.1f} m east, "
                                             f"{self.home[2] - goal[2]:.1f} m above home")
        return ACCEPTED

    def change_speed(self, speed: float) -> Reply:
        """MAV_CMD_DO_CHANGE_SPEED as a command (MAVSDK's set_current_speed): the horizontal speed (m/s; NaN: back to
        MPC_XY_CRUISE) of the mission from here, and of a reposition under way."""
        self._mission_speed = speed
        if self._reposition is not None:
            self._reposition = (self._reposition[0], speed)
        return ACCEPTED

    def terminate(self) -> Reply:
        """MAV_CMD_DO_FLIGHTTERMINATION (MAVSDK's terminate): the motors stop at once, in the air too, as PX4's
        flight termination does; the vehicle falls."""
        self._disarm("Flight terminated: motors stopped")
        return ACCEPTED

    def set_home(self, place: tuple[float, float, float], manually: bool = True) -> Reply:
        """MAV_CMD_DO_SET_HOME: home (local NED) moves to ``place``; Return and relative altitudes follow it. As on
        PX4, a place sent (``manually``) stays home when the vehicle next arms; home set where the vehicle is moves
        there again."""
        self.home = place
        self._home_set_manually = manually
        return ACCEPTED

    def gcs_heartbeat(self, time_s: float) -> None:
        """A ground station's HEARTBEAT arrived (the data link whose loss NAV_DLL_ACT acts on)."""
        self._gcs_time = time_s
        if self._gcs_lost:
            self._gcs_lost = self._gcs_failsafe_done = False
            self._say(mavlink.MAV_SEVERITY_INFO, "Data link regained")

    def offboard_setpoint(self, setpoint: Setpoint, time_s: float) -> None:
        """A valid offboard setpoint arrived (the MAVLink edge has already rejected malformed ones)."""
        self._offboard_setpoint = setpoint
        self._offboard_time = time_s

    def manual_control(self, sticks: Sticks, time_s: float) -> None:
        """Stick input arrived (MANUAL_CONTROL; the MAVLink edge has already rejected malformed ones)."""
        self._sticks = sticks
        self._sticks_time = time_s
        self._note_stick_movement(sticks, time_s)
        if self._manual_lost:
            self._manual_lost = self._manual_lost_at_arming = self._manual_failsafe_done = False
            self._say(mavlink.MAV_SEVERITY_INFO, "Manual control regained")

    # ------------------------------------------------------------------------------------ update
    def update(self, status: VehicleStatus) -> CommanderOutput:
        now = status.time_s
        if status.crashed and self.armed:
            self._disarm("Crash detected: motors stopped")
        if self.armed:
            self._update_land_detector(status)
        if self.mode is FlightMode.OFFBOARD and not self._offboard_alive(now):
            self._offboard_lost(status)
        if self._sticks is not None and not self._manual_lost and not self._manual_alive(now):
            self._manual_lost = True
            self._say(mavlink.MAV_SEVERITY_CRITICAL, "Manual control lost")
        if self._manual_lost and self.armed and not (self._manual_failsafe_done or self._manual_lost_at_arming
                                                     or self._loss_excepted("COM_RCL_EXCEPT")):
            self._manual_control_failsafe(status)
        if self._gcs_time is not None and not self._gcs_lost and now - self._gcs_time > self.params["COM_DL_LOSS_T"]:
            self._gcs_lost = True
            self._say(mavlink.MAV_SEVERITY_CRITICAL, "Connection to ground station lost")
        if self._gcs_lost and self.armed and not status.landed and not (
                self._gcs_failsafe_done or self.mode is FlightMode.AUTO_LAND or self._loss_excepted("COM_DLL_EXCEPT")):
            self._data_link_failsafe(status)
        if int(self.params["GF_ACTION"]) != GF_NONE:
            self._check_geofence(status)
        if self._delayed_failsafe is not None and self.armed and now >= self._delayed_failsafe[1]:
            self._delayed_failsafe_due(status)
        if self._sticks_moved:
            self._sticks_moved = False
            if self.armed and self._manual_alive(now) and self._stick_takeover_allowed():
                self._say(mavlink.MAV_SEVERITY_INFO, f"Sticks moved: pilot takes over from {self.mode.label}, "
                                                     "switching to Position")
                self.failsafe = False
                self._enter(FlightMode.POSCTL, status)
        if self.mode is FlightMode.AUTO_TAKEOFF and self._takeoff_target is not None:
            if self._takeoff_reached(status):
                self._say(mavlink.MAV_SEVERITY_INFO, "Takeoff complete: holding")
                self._hold_target, self._hold_yaw = self._takeoff_target, status.yaw
                self.mode = FlightMode.AUTO_LOITER
        if self.mode is FlightMode.AUTO_RTL and self.armed:
            self._advance_return(status)
        if self.mode is FlightMode.AUTO_MISSION and self.armed:
            self._advance_mission(status)
        return CommanderOutput(self.armed, self._setpoint(status), self.mode)

    @property
    def landing(self) -> bool:
        """Descending to land (Land mode, Return's last leg, or a mission's Land item)."""
        return (self.mode is FlightMode.AUTO_LAND or (self.mode is FlightMode.AUTO_RTL and self._rtl_leg == RTL_LAND)
                or (self.mode is FlightMode.AUTO_MISSION and self._mission_phase == MIS_LAND))

    # ---------------------------------------------------------------------------------- internals
    def _setpoint(self, status: VehicleStatus) -> Setpoint | ManualSetpoint:
        if self.mode is FlightMode.OFFBOARD and self._offboard_setpoint is not None:
            return self._offboard_setpoint
        if self.mode is FlightMode.AUTO_TAKEOFF and self._takeoff_target is not None:
            return Setpoint(position=self._takeoff_target, yaw=self._hold_yaw)
        if self.mode is FlightMode.AUTO_RTL and not self.landing:
            return Setpoint(position=self._return_target(), yaw=self._hold_yaw)
        if self.mode is FlightMode.AUTO_MISSION and not self.landing and self._climb_requested():
            return Setpoint(position=self._mission_target, yaw=self._mission_yaw(status),
                            cruise_speed=self._mission_speed)
        if self.mode is FlightMode.ORBIT and self._orbit is not None:
            return self._orbit_setpoint(status)
        if self.mode.manual and self._sticks is not None and (not status.landed or self._climb_requested()
                                                              or self.mode.thrust_from_throttle):
            return self._stick_setpoint(status)
        if self.landing or (status.landed and not self._climb_requested()):
            # Descend (on the ground: keep pressing down, so the thrust winds down to idle).
            x, y = self._land_xy or status.position[:2]
            return Setpoint(position=(x, y, NAN), velocity=(NAN, NAN, self.params["MPC_LAND_SPEED"]),
                            yaw=self._hold_yaw)
        target = self._hold_target or status.position
        # a reposition's speed holds for its own target only: Hold entered any other way flies at MPC_XY_CRUISE
        speed = self._reposition[1] if self._reposition is not None and self._reposition[0] == target else NAN
        return Setpoint(position=target, yaw=self._hold_yaw, cruise_speed=speed)

    def _takeoff_reached(self, status: VehicleStatus) -> bool:
        """At the takeoff altitude within NAV_ACC_RAD, and at its horizontal target if it has one (a vertical
        climb is judged on altitude alone, so estimate drift sideways does not hold it up)."""
        reach = self.params["NAV_ACC_RAD"]
        north, east, down = self._takeoff_target
        x, y, z = status.position
        return abs(z - down) <= reach and (not self._takeoff_has_xy or math.hypot(x - north, y - east) <= reach)

    def _climb_requested(self) -> bool:
        if self.mode.manual:
            return self._sticks is not None and self._shaped_sticks().up > 0.0  # throttle above centre
        if self.mode is FlightMode.AUTO_MISSION:
            return self._mission_phase != MIS_LAND
        return self.mode is FlightMode.AUTO_LOITER and self._hold_target is not None and self._has_flown

    def _enter(self, mode: FlightMode, status: VehicleStatus) -> None:
        if mode is not self.mode:
            log.info("mode %s -> %s", self.mode.label, mode.label)
        from_mission = self.mode is FlightMode.AUTO_MISSION
        self.mode = mode
        self._hold_yaw = status.yaw
        if mode is FlightMode.AUTO_LOITER:
            self._hold_target = stopping_point(status.position, status.velocity)
        elif mode is FlightMode.AUTO_LAND:
            self._land_xy = status.position[:2]
        elif mode is FlightMode.AUTO_MISSION:
            if self._mission_complete:
                self.mission_seq = 0  # a finished mission starts again from its first item, at the default speed
                self._mission_complete = False
                self._mission_speed = NAN
                self._jumps_done = {}
            self._mission_target = (NAN, NAN, NAN)  # nothing flown to yet in this mode
            self._begin_mission_item(status)
        elif mode.manual:
            self._stick_hold_xy = self._stick_hold_z = None  # set from the state when the sticks are centred
            self._stick_yawing = False
        elif mode is FlightMode.AUTO_RTL:
            self._begin_return(status, self.mission_seq if from_mission else None)
        elif mode is FlightMode.ORBIT:
            self._orbit = starting_orbit(status.position, status.yaw, self.params["MC_ORBIT_RAD_MAX"])
            self._orbit_approach = None

    def _mission_item_reached(self, status: VehicleStatus) -> None:
        self.mission_reached.append(self.mission_seq)
        log.info("mission item %d reached at t=%.2f s", self.mission_seq, status.time_s)

    def _update_land_detector(self, status: VehicleStatus) -> None:
        now = status.time_s
        if not status.landed:
            self._has_flown = True
            self._landed_since = None
            return
        if self._landed_since is None:
            self._landed_since = now
            if self._has_flown:
                self._say(mavlink.MAV_SEVERITY_INFO, "Landing detected")
        landed_for = now - self._landed_since
        if self._has_flown:
            delay = self.params["COM_DISARM_LAND"]
            if delay >= 0 and landed_for >= delay:
                self._disarm("Disarmed by landing")
        else:
            delay = self.params["COM_DISARM_PRFLT"]
            if delay >= 0 and now - self._armed_at >= delay and self.mode is not FlightMode.AUTO_TAKEOFF:
                self._disarm("Disarmed: no takeoff after arming")

    def _offboard_alive(self, now: float) -> bool:
        return now - self._offboard_time <= self.params["COM_OF_LOSS_T"]

    def _manual_alive(self, now: float) -> bool:
        return self._sticks is not None and now - self._sticks_time <= self.params["COM_RC_LOSS_T"]

    def _arming_denied_reason(self, status: VehicleStatus) -> str | None:
        if status.crashed:
            return "vehicle crashed; restart the simulation"
        if not status.position_valid:
            return "position estimate not valid yet"
        if not status.landed:
            return "vehicle is not landed"
        if self.mode in (FlightMode.AUTO_LAND, FlightMode.AUTO_RTL, FlightMode.ORBIT):
            return f"{self.mode.label} mode is not armable; switch to Hold or Offboard"
        outside = self._geofence_breach(status, home=status.position)    # home is set where it arms
        if outside and int(self.params["GF_ACTION"]) != GF_NONE:
            return f"vehicle outside the geofence ({outside})"
        if self.mode is FlightMode.AUTO_MISSION and not self.mission:
            return "no mission"
        if self.mode is FlightMode.OFFBOARD and not self._offboard_alive(status.time_s):
            return "no offboard setpoint stream"
        if self.mode.manual and not self._manual_alive(status.time_s):
            return f"manual control lost; {self.mode.label} mode needs MANUAL_CONTROL"
        if self.mode.thrust_from_throttle and self._sticks.throttle > ARM_THROTTLE_LOW:
            return "throttle not low; pull it down to arm"
        if self.mode.manual and self._sticks.throttle > ARM_THROTTLE_MAX:
            return "throttle above center"
        return None

    def _disarm(self, text: str) -> None:
        self.armed = False
        self._delayed_failsafe = None
        self._has_flown = False
        self._landed_since = None
        self._say(mavlink.MAV_SEVERITY_INFO, text)

    def _pilot_takes_over(self) -> None:
        """A mode or a place the pilot chose ends a failsafe and a failsafe's delay, as PX4's takeover does."""
        self.failsafe = False
        self._delayed_failsafe = None

    def _refused_unless_flying(self, status: VehicleStatus, text: str) -> Reply | None:
        """A command that flies somewhere (Return, a reposition, an orbit) is refused with ``text`` unless the vehicle
        is armed in the air; in the air the pilot takes over (:meth:`_pilot_takes_over`) and None is returned."""
        if not self.armed or status.landed:
            return self._refuse(mavlink.MAV_RESULT_TEMPORARILY_REJECTED, text)
        self._pilot_takes_over()
        return None

    def _refuse(self, result: int, text: str) -> Reply:
        self._say(mavlink.MAV_SEVERITY_CRITICAL, text)
        return Reply(result, text, announced=True)

    def _say(self, severity: int, text: str) -> None:
        log.info("%s", text)
        self.messages.append((severity, text))

"""Navigator: how Return and Mission mode fly, leg by leg and item by item, as PX4's navigator does, and the
requests that load and start a mission.

:class:`Navigator` is a mixin of :class:`sitl_vehicle.commander.Commander` (it reads and sets the commander's
state and calls its ``_enter``, ``set_mode``, ``_say`` and ``_mission_item_reached``): Return's legs (climb, the
plan's path, fly to the destination, descend, wait, land; :mod:`sitl_vehicle.return_plan` says where) and a
mission's items (climb, fly, hold, land, and the items with nothing to fly to) with the targets the commander's
setpoint flies. Apart from the commander because the commander chooses the mode and this flies it: it changes mode
only to hand a mission's Return item to Return mode, to hold when a mission is replaced in flight, and to start
Mission mode when asked to (MISSION_START, DO_LAND_START).
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.commander_types import ACCEPTED, Reply, VehicleStatus
from sitl_vehicle.mission import (
    DO_COMMANDS,
    DO_JUMP,
    DO_SET_ROI_LOCATION,
    DO_SET_ROI_NONE,
    NAV_DELAY,
    NAV_LAND,
    NAV_RETURN_TO_LAUNCH,
    NAV_TAKEOFF,
    MissionItem,
    mission_landing,
)
from sitl_vehicle.modes import FlightMode
from sitl_vehicle.return_plan import plan_return

# Return mode's legs, in order (PX4's RTL: climb, the plan's path (a mission's items), fly to the destination at
# the altitude reached, descend, wait, land; a mission's landing lands straight after the flight there)
RTL_CLIMB, RTL_PATH, RTL_RETURN = "climb", "path", "return"
RTL_DESCEND, RTL_LOITER, RTL_LAND = "descend", "loiter", "land"
# Mission mode's phases within an item: climb (a Takeoff item, or the climb PX4 adds before a first waypoint
# when started on the ground), fly to the item, hold there, land; done: holding at the last item
MIS_CLIMB, MIS_FLY, MIS_HOLD, MIS_LAND, MIS_DONE = "climb", "fly", "hold", "land", "done"
ROI_NEAR_M = 0.5   # nearer than this to its region of interest (horizontally) the vehicle keeps the heading it has


class Navigator:
    """Return's legs and a mission's items, mixed into ``Commander``."""

    _mission_roi: tuple[float, float] | None = None    # the place a DO_SET_ROI_LOCATION set (local north, east)

    def set_mission(self, items: list[MissionItem], status: VehicleStatus) -> None:
        """A new mission (uploaded whole; empty clears it). Flying the old one, the vehicle holds instead."""
        self.mission = tuple(items)
        self.mission_seq = 0
        self._mission_speed = math.nan  # MPC_XY_CRUISE until a DO_CHANGE_SPEED
        self._jumps_done = {}           # DO_JUMP item -> the jumps it made
        self._mission_roi = None
        self._mission_phase = MIS_DONE
        self._mission_complete = False
        if self.mode is FlightMode.AUTO_MISSION:
            self._say(mavlink.MAV_SEVERITY_WARNING, "Mission changed in flight: switching to Hold")
            self._enter(FlightMode.AUTO_LOITER, status)

    def set_mission_current(self, seq: int, status: VehicleStatus) -> Reply:
        """MISSION_SET_CURRENT: continue from item ``seq`` (at once when flying the mission)."""
        if not 0 <= seq < len(self.mission):
            return self._refuse(mavlink.MAV_RESULT_DENIED, f"Mission item {seq} does not exist (the mission has "
                                                           f"{len(self.mission)} items)")
        self.mission_seq = seq
        self._mission_complete = False  # entering Mission mode continues from here rather than from item 0
        if self.mode is FlightMode.AUTO_MISSION:
            self._mission_target = (math.nan, math.nan, math.nan)   # a jump: what was flown to before is behind
            self._begin_mission_item(status)
        return ACCEPTED

    def start_mission(self, status: VehicleStatus, first: int = 0) -> Reply:
        """MAV_CMD_MISSION_START: Mission mode from item ``first``."""
        if self.mission and not 0 <= first < len(self.mission):
            return self._refuse(mavlink.MAV_RESULT_DENIED, f"Mission start denied: no item {first}")
        if self.mission:
            self.mission_seq = first
            self._mission_complete = False  # start from `first` rather than from the beginning
        return self.set_mode(FlightMode.AUTO_MISSION, status)

    def start_mission_landing(self, status: VehicleStatus) -> Reply:
        """MAV_CMD_DO_LAND_START: Mission mode from where the mission's landing starts, as PX4 jumps to it."""
        landing = mission_landing(self.mission)
        if landing is None:
            return self._refuse(mavlink.MAV_RESULT_DENIED, "Landing sequence denied: the mission has no landing "
                                                           "(upload one with DO_LAND_START or NAV_LAND)")
        return self.start_mission(status, landing[0])

    @property
    def mission_finished(self) -> bool:
        return bool(self.mission) and self._mission_complete

    def _begin_return(self, status: VehicleStatus, mission_seq: int | None = None) -> None:
        """Return's first leg: climb where the vehicle is to RTL_RETURN_ALT above home (never down), and no higher
        than a metre under the geofence's ceiling (GF_MAX_VER_DIST), as PX4's Return keeps inside the fence; the
        legs after go where and how RTL_TYPE says (:func:`sitl_vehicle.return_plan.plan_return`; ``mission_seq``:
        the item being flown, when Return began in Mission mode)."""
        plan = plan_return(int(self.params["RTL_TYPE"]), status.position, self.home, self.rally_points,
                           self.mission, mission_seq)
        self._rtl_plan, self._rtl_path_index = plan, 0
        self._rtl_start_xy = status.position[:2]
        climb = self.params["RTL_RETURN_ALT"]
        if self.params["GF_MAX_VER_DIST"] > 0:
            climb = min(climb, max(self.params["GF_MAX_VER_DIST"] - 1.0, 0.0))
        self._rtl_z = status.position[2]
        if plan.climb:
            self._rtl_leg = RTL_CLIMB
            self._rtl_z = min(status.position[2], self.home[2] - climb)  # NED: up is -z
            self._say(mavlink.MAV_SEVERITY_INFO, f"Return: {plan.flying} at {self.home[2] - self._rtl_z:.1f} m "
                                                 "above home")
        else:
            self._rtl_leg = RTL_PATH if plan.path else RTL_RETURN
            self._say(mavlink.MAV_SEVERITY_INFO, f"Return: {plan.flying}")

    def _mission_yaw(self, status: VehicleStatus) -> float:
        """The heading Mission mode flies: towards the region of interest while one is set (as PX4's navigator
        turns a multicopter to it; within :data:`ROI_NEAR_M` the heading it had), else the items' own."""
        if self._mission_roi is not None:
            north, east = self._mission_roi[0] - status.position[0], self._mission_roi[1] - status.position[1]
            if math.hypot(north, east) > ROI_NEAR_M:
                self._hold_yaw = math.atan2(east, north)
        return self._hold_yaw

    def _descend_z(self) -> float:
        return max(self._rtl_z, self.home[2] - self.params["RTL_DESCEND_ALT"])  # descending never climbs

    def _return_target(self) -> tuple[float, float, float]:
        hx, hy = self._rtl_plan.destination
        if self._rtl_leg == RTL_CLIMB:
            return (*self._rtl_start_xy, self._rtl_z)
        if self._rtl_leg == RTL_PATH:
            north, east, down = self._rtl_plan.path[self._rtl_path_index]
            return (north, east, down if math.isfinite(down) else self._rtl_z)
        if self._rtl_leg == RTL_RETURN:
            return (hx, hy, self._rtl_z)
        return (hx, hy, self._descend_z())

    def _advance_return(self, status: VehicleStatus) -> None:
        """Move to Return's next leg once the current one's target is reached (within NAV_ACC_RAD)."""
        x, y, z = status.position
        reached = self.params["NAV_ACC_RAD"]
        plan = self._rtl_plan
        hx, hy = plan.destination
        if self._rtl_leg == RTL_CLIMB and abs(z - self._rtl_z) <= reached:
            self._rtl_leg = RTL_PATH if plan.path else RTL_RETURN
        if self._rtl_leg == RTL_PATH and math.dist(status.position, self._return_target()) <= reached:
            self._rtl_z = self._return_target()[2]       # what follows is flown at this altitude
            self._rtl_path_index += 1
            if self._rtl_path_index == len(plan.path):
                self._rtl_leg = RTL_RETURN
        if self._rtl_leg == RTL_RETURN and math.hypot(x - hx, y - hy) <= reached:
            if plan.mission_landing:
                self._return_lands()
            else:
                self._rtl_leg = RTL_DESCEND
        if self._rtl_leg == RTL_DESCEND and abs(z - self._descend_z()) <= reached:
            self._rtl_leg = RTL_LOITER
            self._rtl_loiter_since = status.time_s
        if self._rtl_leg == RTL_LOITER:
            delay = self.params["RTL_LAND_DELAY"]
            if delay >= 0 and status.time_s - self._rtl_loiter_since >= delay:
                self._return_lands()

    def _return_lands(self) -> None:
        self._rtl_leg = RTL_LAND
        self._land_xy = self._rtl_plan.destination
        self._say(mavlink.MAV_SEVERITY_INFO, f"Return: {self._rtl_plan.landing}")

    def _begin_mission_item(self, status: VehicleStatus) -> None:
        item = self.mission[self.mission_seq]
        x, y, z = status.position
        if item.command in DO_COMMANDS or item.command == NAV_DELAY:
            # nothing to fly to: the vehicle keeps to the item flown to before (where it is, if none), as PX4 does
            if not all(map(math.isfinite, self._mission_target)):
                self._mission_target = status.position
        if item.command in DO_COMMANDS:         # act, then on to the next (the last: the mission is finished)
            if item.speed is not None:
                self._mission_speed = item.speed
            if item.command in (DO_SET_ROI_LOCATION, DO_SET_ROI_NONE):
                self._mission_roi = (item.north, item.east) if item.command == DO_SET_ROI_LOCATION else None
            if item.command == DO_JUMP and self._jumps_done.get(self.mission_seq, 0) < item.jump[1]:
                self._jumps_done[self.mission_seq] = self._jumps_done.get(self.mission_seq, 0) + 1
                self._mission_item_reached(status)
                self.mission_seq = item.jump[0]
                self._begin_mission_item(status)
                return
            self._next_mission_item(status, reached=True)
            return
        if item.command == NAV_DELAY:           # hold for param1 s
            self._mission_item_reached(status)
            self._mission_phase, self._mission_since = MIS_HOLD, status.time_s
            return
        if item.command == NAV_RETURN_TO_LAUNCH:
            self._mission_item_reached(status)
            if status.landed:  # nothing to return from: the mission ends here
                self._mission_phase, self._mission_complete = MIS_LAND, True
            elif self.mode is FlightMode.AUTO_MISSION:  # unless the mission changed mode already
                self._enter(FlightMode.AUTO_RTL, status)
            return
        if math.isfinite(item.yaw):
            self._hold_yaw = item.yaw
        has_xy = math.isfinite(item.north)
        tx, ty = (item.north, item.east) if has_xy else (x, y)
        self._mission_since = status.time_s
        if item.command == NAV_LAND:
            self._mission_target = (tx, ty, z)
            self._mission_phase = MIS_FLY if has_xy else MIS_LAND
            self._land_xy = (tx, ty)
            return
        tz = item.down(self.home[2])
        if item.command == NAV_TAKEOFF or status.landed:
            # PX4 climbs where it is first: a Takeoff item, or any first item flown from the ground
            self._mission_target = (x, y, tz)
            self._mission_phase = MIS_CLIMB
            return
        self._mission_target = (tx, ty, tz)
        self._mission_phase = MIS_FLY

    def _advance_mission(self, status: VehicleStatus) -> None:
        """Move through the mission's items as PX4's navigator does (see MIS_* phases)."""
        if not self.mission:
            return
        item = self.mission[self.mission_seq]
        phase = self._mission_phase
        now = status.time_s
        reach = self.params["NAV_ACC_RAD"]
        if phase == MIS_CLIMB and abs(status.position[2] - self._mission_target[2]) <= reach:
            if item.command == NAV_TAKEOFF:
                self._next_mission_item(status)
            else:  # the climb before a waypoint: now fly to it
                self._mission_target = (item.north, item.east, self._mission_target[2])
                self._mission_phase = MIS_FLY
        elif phase == MIS_FLY and math.dist(status.position, self._mission_target) <= max(reach,
                                                                                          item.acceptance_radius):
            if item.command == NAV_LAND:
                self._mission_phase = MIS_LAND
            elif item.hold_s > 0:
                self._mission_item_reached(status)
                self._mission_phase, self._mission_since = MIS_HOLD, now
            else:
                self._next_mission_item(status, reached=True)
        elif phase == MIS_HOLD and now - self._mission_since >= item.hold_s:
            self._next_mission_item(status)
        elif phase == MIS_LAND and status.landed and not self._mission_complete:
            self._mission_item_reached(status)
            self._mission_complete = True  # still landing: the thrust winds down and the vehicle disarms
            self._say(mavlink.MAV_SEVERITY_INFO, "Mission finished, landed")

    def _next_mission_item(self, status: VehicleStatus, reached: bool = False) -> None:
        item = self.mission[self.mission_seq]
        if reached or item.command == NAV_TAKEOFF:
            self._mission_item_reached(status)
        if self.mission_seq + 1 < len(self.mission):
            self.mission_seq += 1
            self._begin_mission_item(status)
        else:
            self._mission_phase = MIS_DONE  # PX4 holds at the last item, still in Mission mode
            self._mission_complete = True
            self._say(mavlink.MAV_SEVERITY_INFO, "Mission finished, loitering")

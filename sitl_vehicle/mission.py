"""Missions: the items PX4's Mission mode flies, checked and converted to the local frame at upload.

Pure: the MAVLink edge turns each MISSION_ITEM_INT into a :class:`MissionItem` with
:func:`mission_item_from_message` (which raises :class:`MissionError` carrying the MAV_MISSION_RESULT and the
reason), and the commander flies the list. Horizontal positions are converted to local NED at upload (the
local frame's geodetic origin never moves); altitudes stay as sent, because a relative altitude is measured
from home, which is set again at each arming, as PX4 does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

# the MAV_CMDs a mission may hold, with PX4's names
NAV_WAYPOINT = mavlink.MAV_CMD_NAV_WAYPOINT
NAV_LOITER_UNLIM = mavlink.MAV_CMD_NAV_LOITER_UNLIM  # a multicopter holds at its place until told otherwise
NAV_LOITER_TIME = mavlink.MAV_CMD_NAV_LOITER_TIME  # a multicopter holds at its place for param1 s
NAV_DELAY = mavlink.MAV_CMD_NAV_DELAY  # holds where the vehicle is for param1 s (MAVSDK's loiter_time_s)
NAV_RETURN_TO_LAUNCH = mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH
NAV_LAND = mavlink.MAV_CMD_NAV_LAND
NAV_TAKEOFF = mavlink.MAV_CMD_NAV_TAKEOFF
DO_LAND_START = mavlink.MAV_CMD_DO_LAND_START  # marks where the mission's landing begins (flown past in Mission)
DO_CHANGE_SPEED = mavlink.MAV_CMD_DO_CHANGE_SPEED  # param2: the horizontal speed of the items after it (m/s)
DO_JUMP = mavlink.MAV_CMD_DO_JUMP  # go on from item param1, param2 times (then on past the jump)
DO_SET_ROI_LOCATION = mavlink.MAV_CMD_DO_SET_ROI_LOCATION  # face its place from here on (a gimbal would point at it)
DO_SET_ROI_NONE = mavlink.MAV_CMD_DO_SET_ROI_NONE  # stop facing a region of interest
SPEED_NO_CHANGE, SPEED_DEFAULT = -1.0, -2.0        # DO_CHANGE_SPEED's param2 for "no change" and "back to default"
SPEED_TYPES_HORIZONTAL = (0.0, 1.0)                # param1: air speed or ground speed (a multicopter's the same)
# camera and gimbal items (as MAVSDK's Mission plugin and QGroundControl add them): PX4 hands them to a payload;
# the simulated vehicle carries none, so Mission mode flies past them, and the upload says so
PAYLOAD_COMMANDS = {mavlink.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW: "DO_GIMBAL_MANAGER_PITCHYAW",
                    mavlink.MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE: "DO_GIMBAL_MANAGER_CONFIGURE",
                    mavlink.MAV_CMD_DO_MOUNT_CONTROL: "DO_MOUNT_CONTROL",
                    mavlink.MAV_CMD_DO_MOUNT_CONFIGURE: "DO_MOUNT_CONFIGURE",
                    mavlink.MAV_CMD_IMAGE_START_CAPTURE: "IMAGE_START_CAPTURE",
                    mavlink.MAV_CMD_IMAGE_STOP_CAPTURE: "IMAGE_STOP_CAPTURE",
                    mavlink.MAV_CMD_VIDEO_START_CAPTURE: "VIDEO_START_CAPTURE",
                    mavlink.MAV_CMD_VIDEO_STOP_CAPTURE: "VIDEO_STOP_CAPTURE",
                    mavlink.MAV_CMD_DO_SET_CAM_TRIGG_DIST: "DO_SET_CAM_TRIGG_DIST",
                    mavlink.MAV_CMD_SET_CAMERA_MODE: "SET_CAMERA_MODE",
                    mavlink.MAV_CMD_SET_CAMERA_ZOOM: "SET_CAMERA_ZOOM",
                    mavlink.MAV_CMD_SET_CAMERA_FOCUS: "SET_CAMERA_FOCUS",
                    mavlink.MAV_CMD_DO_TRIGGER_CONTROL: "DO_TRIGGER_CONTROL",
                    mavlink.MAV_CMD_DO_DIGICAM_CONTROL: "DO_DIGICAM_CONTROL"}
SUPPORTED_COMMANDS = {NAV_WAYPOINT: "NAV_WAYPOINT", NAV_LOITER_UNLIM: "NAV_LOITER_UNLIM",
                      NAV_LOITER_TIME: "NAV_LOITER_TIME", NAV_DELAY: "NAV_DELAY",
                      NAV_RETURN_TO_LAUNCH: "NAV_RETURN_TO_LAUNCH", NAV_LAND: "NAV_LAND", NAV_TAKEOFF: "NAV_TAKEOFF",
                      DO_JUMP: "DO_JUMP", DO_LAND_START: "DO_LAND_START", DO_CHANGE_SPEED: "DO_CHANGE_SPEED",
                      DO_SET_ROI_LOCATION: "DO_SET_ROI_LOCATION", DO_SET_ROI_NONE: "DO_SET_ROI_NONE",
                      **PAYLOAD_COMMANDS}
# items with nothing to fly to: Mission mode acts on them (or not) and goes on at once
DO_COMMANDS = (DO_JUMP, DO_LAND_START, DO_CHANGE_SPEED, DO_SET_ROI_LOCATION, DO_SET_ROI_NONE, *PAYLOAD_COMMANDS)
# items that take the vehicle somewhere (a jump back must pass one, or it would loop without flying)
FLOWN_COMMANDS = (NAV_WAYPOINT, NAV_LOITER_UNLIM, NAV_LOITER_TIME, NAV_DELAY, NAV_LAND, NAV_TAKEOFF,
                  NAV_RETURN_TO_LAUNCH)
# items with no place of their own: they may come in MAV_FRAME_MISSION, the frame of commands, and without altitude
# (a region of interest is a place, though nothing to fly to)
PLACELESS_COMMANDS = (NAV_DELAY, *(command for command in DO_COMMANDS if command != DO_SET_ROI_LOCATION))
# items that may leave out a place: "here" for a Takeoff or Land, and the placeless ones
UNPLACED_COMMANDS = (NAV_TAKEOFF, NAV_LAND, NAV_RETURN_TO_LAUNCH, *PLACELESS_COMMANDS)
# frames: altitude relative to home, or above mean sea level
RELATIVE_FRAMES = (mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)
AMSL_FRAMES = (mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_INT)
FLOAT_FRAMES = {mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT: mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
                mavlink.MAV_FRAME_GLOBAL_INT: mavlink.MAV_FRAME_GLOBAL}
MAX_ITEMS = 500
MAX_DISTANCE_M = 10_000.0  # a waypoint farther than this from the local origin is a mistake (e.g. lat/lon 0)


class MissionError(ValueError):
    """An item that cannot be flown: ``result`` is the MAV_MISSION_RESULT to answer with."""

    def __init__(self, result: int, text: str):
        super().__init__(text)
        self.result = result


@dataclass(frozen=True)
class PlanItem:
    """One checked item of an uploaded plan (a mission's, a geofence's). ``lat``/``lon`` (deg) and ``alt`` (m)
    are as sent, for download; ``north``/``east`` are the local position."""

    seq: int
    command: int
    frame: int
    params: tuple[float, float, float, float]
    lat: float
    lon: float
    alt: float
    north: float
    east: float

    def item_message(self, target_system: int, target_component: int, int_form: bool, mission_type: int,
                     current: bool = False, autocontinue: bool = True):
        """MISSION_ITEM_INT (lat/lon in 1e-7 degrees), or with ``int_form`` false the older float MISSION_ITEM
        (degrees, and the frame's non-_INT name), as the MAVLink mission protocol answers MISSION_REQUEST."""
        if int_form:
            return mavlink.MAVLink_mission_item_int_message(
                target_system, target_component, self.seq, self.frame, self.command, int(current), int(autocontinue),
                *self.params, int(round(self.lat * 1e7)), int(round(self.lon * 1e7)), self.alt, mission_type)
        return mavlink.MAVLink_mission_item_message(
            target_system, target_component, self.seq, FLOAT_FRAMES.get(self.frame, self.frame), self.command,
            int(current), int(autocontinue), *self.params, self.lat, self.lon, self.alt, mission_type)


@dataclass(frozen=True)
class MissionItem(PlanItem):
    """One checked mission item (``north``/``east`` NaN: where the vehicle is, for a Takeoff or Land without
    coordinates, or nowhere, for an item with nothing to fly to); ``alt_relative`` says whether ``alt`` is above
    home (else above mean sea level, ``amsl_down`` locally)."""

    alt_relative: bool
    amsl_down: float  # for an altitude above mean sea level: its local down coordinate
    autocontinue: bool = True

    @property
    def name(self) -> str:
        return SUPPORTED_COMMANDS[self.command]

    @property
    def hold_s(self) -> float:
        """Seconds to hold at the item: NAV_WAYPOINT's, NAV_LOITER_TIME's and NAV_DELAY's param1, and for ever at a
        NAV_LOITER_UNLIM."""
        if self.command == NAV_LOITER_UNLIM:
            return math.inf
        return (self.params[0] if self.command in (NAV_WAYPOINT, NAV_LOITER_TIME, NAV_DELAY) and self.params[0] > 0
                else 0.0)

    @property
    def speed(self) -> float | None:
        """DO_CHANGE_SPEED: the horizontal speed (m/s) of the items after it, NaN for the default, None for no
        change (or a climb or descent speed, which the vehicle does not model)."""
        return speed_change(self.params[0], self.params[1]) if self.command == DO_CHANGE_SPEED else None

    @property
    def jump(self) -> tuple[int, int]:
        """DO_JUMP: the item to go on from and how many times."""
        return int(self.params[0]), int(self.params[1])

    @property
    def acceptance_radius(self) -> float:
        """NAV_WAYPOINT param2 (m; 0: the NAV_ACC_RAD default)."""
        return self.params[1] if self.command == NAV_WAYPOINT and self.params[1] > 0 else 0.0

    @property
    def yaw(self) -> float:
        """param4, the heading to fly (rad; NaN: keep the heading), for the items whose param4 is one."""
        yaw = self.params[3] if self.command in (NAV_WAYPOINT, NAV_LOITER_UNLIM, NAV_TAKEOFF, NAV_LAND) else math.nan
        return math.radians(yaw) if math.isfinite(yaw) else math.nan

    def down(self, home_down: float) -> float:
        """The item's local NED down coordinate, given home's."""
        return home_down - self.alt if self.alt_relative else self.amsl_down

    def to_message(self, current: bool, target_system: int, target_component: int, int_form: bool = True):
        """The item as the mission protocol sends it back (see :meth:`PlanItem.item_message`)."""
        return self.item_message(target_system, target_component, int_form, mavlink.MAV_MISSION_TYPE_MISSION,
                                 current, self.autocontinue)


def mission_item_from_message(msg, to_local) -> MissionItem:
    """MISSION_ITEM_INT (or the older float MISSION_ITEM) -> MissionItem; ``to_local(lat, lon, alt_amsl)`` ->
    local (north, east, down).

    Raises MissionError naming the item, what is wrong and what to send instead."""
    seq = msg.seq
    where = f"mission item {seq}"
    if msg.command not in SUPPORTED_COMMANDS:
        raise MissionError(mavlink.MAV_MISSION_UNSUPPORTED,
                           f"{where}: command {msg.command} is not supported; use "
                           + ", ".join(f"{name} ({cmd})" for cmd, name in SUPPORTED_COMMANDS.items()))
    if msg.command in PLACELESS_COMMANDS and msg.frame == mavlink.MAV_FRAME_MISSION:
        # no place: param5 and param6 are the command's own (a gimbal's flags, say), kept to be sent back as they came
        scale = 1e-7 if msg.get_type() == "MISSION_ITEM_INT" else 1.0
        lat, lon, placed = msg.x * scale, msg.y * scale, False
    else:
        lat, lon, placed = global_position(msg, where)
    alt = float(msg.z)
    params = (float(msg.param1), float(msg.param2), float(msg.param3), float(msg.param4))  # NaN: the default
    if not math.isfinite(alt) and msg.command not in PLACELESS_COMMANDS:
        raise MissionError(mavlink.MAV_MISSION_INVALID_PARAM7, f"{where}: altitude is {alt}; send metres")
    if msg.command == DO_JUMP and not all(math.isfinite(p) and p >= 0 and p == int(p) for p in params[:2]):
        raise MissionError(mavlink.MAV_MISSION_INVALID_PARAM1,
                           f"{where}: DO_JUMP's item (param1) and repeat count (param2) are {params[0]} and "
                           f"{params[1]}; send whole numbers, 0 or more")
    if msg.command == NAV_DELAY and not (math.isfinite(params[0]) and params[0] >= 0):
        raise MissionError(mavlink.MAV_MISSION_INVALID_PARAM1,
                           f"{where}: NAV_DELAY's delay (param1) is {params[0]}; send seconds, 0 or more (a time of "
                           "day to wait for is not supported)")
    if msg.command == DO_CHANGE_SPEED and not valid_speed(params[1]):
        raise MissionError(mavlink.MAV_MISSION_INVALID_PARAM2,
                           f"{where}: DO_CHANGE_SPEED's speed (param2) is {params[1]}; send m/s above 0, -1 (no "
                           "change) or -2 (the default)")
    amsl_down = to_local(0.0, 0.0, alt)[2] if msg.frame in AMSL_FRAMES else math.nan
    if not placed and msg.command in UNPLACED_COMMANDS:
        north = east = math.nan  # "here", as PX4 reads a Takeoff or Land without coordinates
    elif not placed:
        raise MissionError(mavlink.MAV_MISSION_INVALID_PARAM5_X,
                           f"{where}: {SUPPORTED_COMMANDS[msg.command]} needs a latitude and longitude")
    else:
        north, east = local_near_home(where, lat, lon, alt, to_local)
    return MissionItem(seq=seq, command=msg.command, frame=msg.frame, params=params, lat=lat, lon=lon, alt=alt,
                       north=north, east=east, alt_relative=msg.frame in RELATIVE_FRAMES, amsl_down=amsl_down,
                       autocontinue=bool(msg.autocontinue))


def global_position(msg, where: str) -> tuple[float, float, bool]:
    """An uploaded item's latitude and longitude in degrees, and whether they name a place (finite, not 0, 0);
    raises MissionError for an item not in a global frame (altitude above home or above mean sea level)."""
    if msg.frame not in RELATIVE_FRAMES + AMSL_FRAMES:
        raise MissionError(mavlink.MAV_MISSION_UNSUPPORTED_FRAME,
                           f"{where}: frame {msg.frame} is not supported; use MAV_FRAME_GLOBAL_RELATIVE_ALT_INT (6) "
                           "or MAV_FRAME_GLOBAL_INT (5)")
    scale = 1e-7 if msg.get_type() == "MISSION_ITEM_INT" else 1.0
    lat, lon = msg.x * scale, msg.y * scale
    return lat, lon, math.isfinite(lat) and math.isfinite(lon) and not (lat == 0.0 and lon == 0.0)


def local_near_home(where: str, lat: float, lon: float, alt: float, to_local) -> tuple[float, float]:
    """The local (north, east) of a place; raises MissionError for one farther than MAX_DISTANCE_M from the local
    origin (coordinates sent wrong, say as 0 or in another unit)."""
    north, east, _ = to_local(lat, lon, alt)
    distance = math.hypot(north, east)
    if distance > MAX_DISTANCE_M:
        raise MissionError(mavlink.MAV_MISSION_INVALID_PARAM5_X,
                           f"{where}: {lat:.7f}, {lon:.7f} is {distance / 1000:.0f} km from home; send coordinates "
                           "near home")
    return north, east


def valid_speed(speed: float) -> bool:
    """DO_CHANGE_SPEED's param2, as a mission item or a command: m/s above 0, or -1 (no change), or -2 (default)."""
    return speed > 0 or speed in (SPEED_NO_CHANGE, SPEED_DEFAULT)


def speed_change(kind: float, speed: float) -> float | None:
    """What a valid DO_CHANGE_SPEED of type ``kind`` (param1) and ``speed`` (param2) sets: the horizontal speed
    (m/s), NaN for the default, None for no change (or a climb or descent speed, which the vehicle does not model)."""
    if speed == SPEED_NO_CHANGE or kind not in SPEED_TYPES_HORIZONTAL:
        return None
    return math.nan if speed == SPEED_DEFAULT else speed


def mission_landing(items) -> tuple[int, int] | None:
    """The mission's landing as PX4 marks it: (where it starts, its Land item), the start being the first
    DO_LAND_START followed by a Land item, or with no such marker the first Land item itself; None: no landing."""
    lands = [i for i, item in enumerate(items) if item.command == NAV_LAND]
    for start, item in enumerate(items):
        if item.command == DO_LAND_START:
            after = [i for i in lands if i > start]
            if after:
                return start, after[0]
    return (lands[0], lands[0]) if lands else None


def passed_items_note(items) -> str | None:
    """A line saying which items of an accepted mission the vehicle flies past without acting on them (a camera's,
    a gimbal's, a climb or descent speed), or None: an upload never drops what it cannot do in silence."""
    passed = [item for item in items if item.command in PAYLOAD_COMMANDS
              or (item.command == DO_CHANGE_SPEED and item.params[0] not in SPEED_TYPES_HORIZONTAL)]
    if not passed:
        return None
    names = sorted({item.name if item.command != DO_CHANGE_SPEED else "DO_CHANGE_SPEED of a climb or descent speed"
                    for item in passed})
    return (f"Mission: {len(passed)} item{'s' if len(passed) > 1 else ''} with nothing to act on here (no camera, "
            f"gimbal or climb speed model), flown past: {', '.join(names)}")


def check_mission(items) -> None:
    """What no single item shows: every DO_JUMP goes to an item of the mission other than itself, and one that
    jumps back passes an item that flies (else Mission mode would loop in place).  Raises MissionError."""
    for seq, item in enumerate(items):
        if item.command != DO_JUMP:
            continue
        target, _ = item.jump
        if target >= len(items) or target == seq:
            raise MissionError(mavlink.MAV_MISSION_INVALID_SEQUENCE,
                               f"mission item {seq}: DO_JUMP to item {target}, which "
                               + ("is the jump itself" if target == seq else f"the {len(items)}-item mission lacks")
                               + "; send the index of another item")
        if target < seq and not any(items[i].command in FLOWN_COMMANDS for i in range(target, seq)):
            raise MissionError(mavlink.MAV_MISSION_INVALID_SEQUENCE,
                               f"mission item {seq}: DO_JUMP back to item {target} passes no item that flies "
                               "(it would loop in place); jump to a waypoint")

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
NAV_RETURN_TO_LAUNCH = mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH
NAV_LAND = mavlink.MAV_CMD_NAV_LAND
NAV_TAKEOFF = mavlink.MAV_CMD_NAV_TAKEOFF
DO_LAND_START = mavlink.MAV_CMD_DO_LAND_START  # marks where the mission's landing begins (flown past in Mission)
SUPPORTED_COMMANDS = {NAV_WAYPOINT: "NAV_WAYPOINT", NAV_RETURN_TO_LAUNCH: "NAV_RETURN_TO_LAUNCH",
                      NAV_LAND: "NAV_LAND", NAV_TAKEOFF: "NAV_TAKEOFF", DO_LAND_START: "DO_LAND_START"}
# items that may leave out a place: "here" for a Takeoff or Land, and a marker with nowhere of its own
UNPLACED_COMMANDS = (NAV_TAKEOFF, NAV_LAND, NAV_RETURN_TO_LAUNCH, DO_LAND_START)
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
    coordinates); ``alt_relative`` says whether ``alt`` is above home (else above mean sea level, ``amsl_down``
    locally)."""

    alt_relative: bool
    amsl_down: float  # for an altitude above mean sea level: its local down coordinate
    autocontinue: bool = True

    @property
    def name(self) -> str:
        return SUPPORTED_COMMANDS[self.command]

    @property
    def hold_s(self) -> float:
        """NAV_WAYPOINT param1: seconds to hold at the waypoint."""
        return self.params[0] if self.command == NAV_WAYPOINT and self.params[0] > 0 else 0.0

    @property
    def acceptance_radius(self) -> float:
        """NAV_WAYPOINT param2 (m; 0: the NAV_ACC_RAD default)."""
        return self.params[1] if self.command == NAV_WAYPOINT and self.params[1] > 0 else 0.0

    @property
    def yaw(self) -> float:
        """param4, the heading to fly (rad; NaN: keep the heading)."""
        yaw = self.params[3]
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
    if msg.command == DO_LAND_START and msg.frame == mavlink.MAV_FRAME_MISSION:
        lat, lon, placed = 0.0, 0.0, False   # a marker with no place of its own, in the frame of commands
    else:
        lat, lon, placed = global_position(msg, where)
    alt = float(msg.z)
    params = (float(msg.param1), float(msg.param2), float(msg.param3), float(msg.param4))  # NaN: the default
    if not math.isfinite(alt):
        raise MissionError(mavlink.MAV_MISSION_INVALID_PARAM7, f"{where}: altitude is {alt}; send metres")
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

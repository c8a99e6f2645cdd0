"""Geofence and rally points: PX4's inclusion and exclusion zones and its limits from home, checked against where
the vehicle is, and the safe points a Return may fly to instead of home.

Pure: the MAVLink edge turns each item of a plan of type FENCE (MISSION_ITEM_INT with ``mission_type`` 1, as
MAVSDK's Geofence plugin and QGroundControl upload it) into a :class:`FenceItem` with :func:`fence_item_from_message`
(which raises :class:`sitl_vehicle.mission.MissionError` carrying the MAV_MISSION_RESULT and the reason), and
:func:`geofence_from_items` groups the items into zones: polygons (``MAV_CMD_NAV_FENCE_POLYGON_VERTEX_*``, one item
per vertex, param1 the vertex count) and circles (``MAV_CMD_NAV_FENCE_CIRCLE_*``, param1 the radius), each inclusion
or exclusion, and PX4's return point (``MAV_CMD_NAV_FENCE_RETURN_POINT``, kept for download). Positions are
converted to local NED at upload. As PX4 reads a fence, the vehicle is inside when it is in at least one inclusion
zone (if there are any) and in no exclusion zone; GF_MAX_HOR_DIST and GF_MAX_VER_DIST (0: off) bound its distance
from home and its height above home. Rally points (``MAV_CMD_NAV_RALLY_POINT`` items of a plan of type RALLY) are
read by :func:`rally_item_from_message`; :func:`nearest_safe_point` picks where a Return goes, as PX4's default
RTL_TYPE 0 does: home or the nearest rally point, whichever is nearer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.mission import MAX_ITEMS, MissionError, PlanItem, global_position, local_near_home

POLYGON_INCLUSION = mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
POLYGON_EXCLUSION = mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION
CIRCLE_INCLUSION = mavlink.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION
CIRCLE_EXCLUSION = mavlink.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION
RETURN_POINT = mavlink.MAV_CMD_NAV_FENCE_RETURN_POINT
FENCE_COMMANDS = {POLYGON_INCLUSION: "NAV_FENCE_POLYGON_VERTEX_INCLUSION",
                  POLYGON_EXCLUSION: "NAV_FENCE_POLYGON_VERTEX_EXCLUSION",
                  CIRCLE_INCLUSION: "NAV_FENCE_CIRCLE_INCLUSION", CIRCLE_EXCLUSION: "NAV_FENCE_CIRCLE_EXCLUSION",
                  RETURN_POINT: "NAV_FENCE_RETURN_POINT"}
FENCE = mavlink.MAV_MISSION_TYPE_FENCE
RALLY = mavlink.MAV_MISSION_TYPE_RALLY
RALLY_POINT = mavlink.MAV_CMD_NAV_RALLY_POINT


@dataclass(frozen=True)
class PlacedItem(PlanItem):
    """An item of a plan of places (a fence's, the rally points'), sent back as it came in."""

    MISSION_TYPE: ClassVar[int]

    def to_message(self, target_system: int, target_component: int, int_form: bool = True):
        """MISSION_ITEM_INT of the item's plan (or the older float MISSION_ITEM): :meth:`PlanItem.item_message`."""
        return self.item_message(target_system, target_component, int_form, self.MISSION_TYPE)


@dataclass(frozen=True)
class FenceItem(PlacedItem):
    """One checked fence item: as sent (for download) and its local position."""

    MISSION_TYPE: ClassVar[int] = FENCE


@dataclass(frozen=True)
class RallyItem(PlacedItem):
    """One checked rally point: as sent (for download) and its local position."""

    MISSION_TYPE: ClassVar[int] = RALLY


def _placed(msg, where: str, to_local) -> tuple[float, float, float, float]:
    """(lat, lon, north, east) of an item that must have a place near home, in a global frame; raises MissionError
    naming the item, what is wrong and what to send instead."""
    lat, lon, placed = global_position(msg, where)
    if not placed:
        raise MissionError(mavlink.MAV_MISSION_INVALID_PARAM5_X, f"{where}: needs a latitude and longitude")
    north, east = local_near_home(where, lat, lon, 0.0, to_local)
    return lat, lon, north, east


def rally_item_from_message(msg, to_local) -> RallyItem:
    """MISSION_ITEM_INT (or MISSION_ITEM) of a RALLY plan -> RallyItem; raises MissionError with the reason."""
    where = f"rally point {msg.seq}"
    if msg.command != RALLY_POINT:
        raise MissionError(mavlink.MAV_MISSION_UNSUPPORTED,
                           f"{where}: command {msg.command} is no rally point; use NAV_RALLY_POINT ({RALLY_POINT})")
    lat, lon, north, east = _placed(msg, where, to_local)
    params = (float(msg.param1), float(msg.param2), float(msg.param3), float(msg.param4))
    return RallyItem(msg.seq, msg.command, msg.frame, params, lat, lon, float(msg.z), north, east)


def nearest_safe_point(position: tuple[float, float, float], home: tuple[float, float, float] | None,
                       rally: tuple[RallyItem, ...]) -> tuple[tuple[float, float], int | None]:
    """Where (north, east) a Return goes from ``position``: home or the rally point nearest to it, whichever is
    nearer (PX4's RTL_TYPE 0), and the rally point's index (None: home); ``home`` None: the nearest rally point
    (``rally`` not empty)."""
    places = [] if home is None else [((home[0], home[1]), None)]
    places += [((r.north, r.east), i) for i, r in enumerate(rally)]
    return min(places, key=lambda p: math.hypot(p[0][0] - position[0], p[0][1] - position[1]))


def fence_item_from_message(msg, to_local) -> FenceItem:
    """MISSION_ITEM_INT (or MISSION_ITEM) of a FENCE plan -> FenceItem; ``to_local(lat, lon, alt_amsl)`` -> local
    (north, east, down).  Raises MissionError naming the item, what is wrong and what to send instead."""
    where = f"fence item {msg.seq}"
    if msg.command not in FENCE_COMMANDS:
        raise MissionError(mavlink.MAV_MISSION_UNSUPPORTED,
                           f"{where}: command {msg.command} is no fence item; use "
                           + ", ".join(f"{name} ({cmd})" for cmd, name in FENCE_COMMANDS.items()))
    lat, lon, north, east = _placed(msg, where, to_local)
    params = (float(msg.param1), float(msg.param2), float(msg.param3), float(msg.param4))
    if msg.command in (CIRCLE_INCLUSION, CIRCLE_EXCLUSION) and not (math.isfinite(params[0]) and params[0] > 0):
        raise MissionError(mavlink.MAV_MISSION_INVALID_PARAM1,
                           f"{where}: a circle's radius (param1) is {params[0]}; send it in metres, above 0")
    if msg.command in (POLYGON_INCLUSION, POLYGON_EXCLUSION) and not (
            math.isfinite(params[0]) and params[0] >= 3 and params[0] == int(params[0])):
        raise MissionError(mavlink.MAV_MISSION_INVALID_PARAM1,
                           f"{where}: a polygon's vertex count (param1) is {params[0]}; send 3 or more")
    return FenceItem(msg.seq, msg.command, msg.frame, params, lat, lon, float(msg.z), north, east)


@dataclass(frozen=True)
class Zone:
    """An inclusion or exclusion zone in local NED: a polygon's (north, east) vertices, or a circle."""

    inclusion: bool
    vertices: tuple[tuple[float, float], ...] = ()
    centre: tuple[float, float] = (0.0, 0.0)
    radius: float = 0.0

    def contains(self, north: float, east: float) -> bool:
        if not self.vertices:
            return math.hypot(north - self.centre[0], east - self.centre[1]) <= self.radius
        inside = False      # even-odd rule: a ray east from the point crosses the outline an odd number of times
        n = len(self.vertices)
        for i in range(n):
            (n0, e0), (n1, e1) = self.vertices[i], self.vertices[(i + 1) % n]
            if (n0 > north) != (n1 > north) and east < e0 + (north - n0) * (e1 - e0) / (n1 - n0):
                inside = not inside
        return inside


@dataclass(frozen=True)
class Geofence:
    """The uploaded fence: its items as sent and the zones they make."""

    items: tuple[FenceItem, ...] = ()
    zones: tuple[Zone, ...] = ()

    def breach(self, position: tuple[float, float, float], home: tuple[float, float, float],
               max_horizontal_m: float = 0.0, max_vertical_m: float = 0.0) -> str | None:
        """Why ``position`` (local NED) is outside the fence, or None: more than ``max_horizontal_m`` from
        ``home`` or ``max_vertical_m`` above it (0: no limit), outside every inclusion zone, or in an exclusion
        zone."""
        north, east, down = position
        away = math.hypot(north - home[0], east - home[1])
        if max_horizontal_m > 0 and away > max_horizontal_m:
            return f"{away:.0f} m from home, over GF_MAX_HOR_DIST {max_horizontal_m:g} m"
        height = home[2] - down
        if max_vertical_m > 0 and height > max_vertical_m:
            return f"{height:.0f} m above home, over GF_MAX_VER_DIST {max_vertical_m:g} m"
        inclusions = [z for z in self.zones if z.inclusion]
        if inclusions and not any(z.contains(north, east) for z in inclusions):
            return "outside the geofence's inclusion zones"
        if any(z.contains(north, east) for z in self.zones if not z.inclusion):
            return "inside a geofence exclusion zone"
        return None


def geofence_from_items(items: list[FenceItem]) -> Geofence:
    """The zones of a FENCE plan's items, in order: each polygon is as many consecutive vertex items of one kind as
    their param1 says.  Raises MissionError for a polygon cut short or a plan over MAX_ITEMS items."""
    if len(items) > MAX_ITEMS:
        raise MissionError(mavlink.MAV_MISSION_NO_SPACE, f"a fence of {len(items)} items: at most {MAX_ITEMS}")
    zones, i = [], 0
    while i < len(items):
        item = items[i]
        if item.command in (CIRCLE_INCLUSION, CIRCLE_EXCLUSION):
            zones.append(Zone(item.command == CIRCLE_INCLUSION, centre=(item.north, item.east), radius=item.params[0]))
            i += 1
        elif item.command in (POLYGON_INCLUSION, POLYGON_EXCLUSION):
            count = int(item.params[0])
            vertices = items[i:i + count]
            if len(vertices) < count or any(v.command != item.command or v.params[0] != count for v in vertices):
                raise MissionError(mavlink.MAV_MISSION_INVALID_PARAM1,
                                   f"fence item {item.seq}: a polygon of {count} vertices needs {count} consecutive "
                                   f"{FENCE_COMMANDS[item.command]} items with param1 {count}")
            zones.append(Zone(item.command == POLYGON_INCLUSION, vertices=tuple((v.north, v.east) for v in vertices)))
            i += count
        else:           # the return point: kept for download, not a zone
            i += 1
    return Geofence(tuple(items), tuple(zones))

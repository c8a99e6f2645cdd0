"""Where Return goes and by which path, as PX4's ``RTL_TYPE`` chooses (pure: positions in, a plan out).

- 0, PX4's multicopter default: home or the nearest rally point, whichever is nearer, straight there;
- 1: the nearest rally point or the start of the mission's landing, home only when there is neither;
- 2: along the mission, rally points not considered: ahead through it to its landing, from the item being flown
  (in Mission mode) or else from the nearest one; a mission without a landing is flown back the other way, from
  the item before the one being flown (or the nearest), and then home;
- 3: home, a rally point or the start of the mission's landing, whichever is nearest.

A mission's landing (:func:`sitl_vehicle.mission.mission_landing`) is flown as planned, fast-forward as PX4 flies
it (each placed item in turn at its own altitude, no holds) down to its Land item. Home and rally points end as
Return always did: descend to RTL_DESCEND_ALT, wait RTL_LAND_DELAY, land. Distances are horizontal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sitl_vehicle.geofence import RallyItem, nearest_safe_point
from sitl_vehicle.mission import DO_LAND_START, MissionItem, mission_landing

Point = tuple[float, float, float]
NAN = math.nan


@dataclass(frozen=True)
class ReturnPlan:
    """A Return: climb to the return altitude (``climb``), fly ``path`` in order (a point's down NaN: at the altitude
    flown so far), then fly to ``destination`` (north, east) and land there: straight down where it is a mission's
    Land item (``mission_landing``), else by descending, waiting and landing. ``flying`` and ``landing`` say so."""

    destination: tuple[float, float]
    flying: str
    landing: str
    path: tuple[Point, ...] = ()
    climb: bool = True
    mission_landing: bool = False


def _apart(place, position: Point) -> float:
    """Horizontal distance from ``position`` to ``place`` (north, east first)."""
    return math.hypot(place[0] - position[0], place[1] - position[1])


def _placed(item: MissionItem, home_down: float) -> Point | None:
    """Where a mission item is (a marker flown at the altitude so far), or None for one without a place."""
    if not math.isfinite(item.north):
        return None
    return item.north, item.east, NAN if item.command == DO_LAND_START else item.down(home_down)


def _points(items: tuple[MissionItem, ...], indices, home_down: float) -> list[Point]:
    return [p for p in (_placed(items[i], home_down) for i in indices) if p is not None]


def _nearest_item(position: Point, items: tuple[MissionItem, ...]) -> int | None:
    placed = [i for i, item in enumerate(items) if math.isfinite(item.north)]
    if not placed:
        return None
    return min(placed, key=lambda i: _apart((items[i].north, items[i].east), position))


def _via(path: list[Point], climb: bool) -> tuple[Point, ...]:
    """A climbed Return reaches its first point at the return altitude, then goes down to it (PX4: "fly directly
    to the waypoint, descend to its altitude")."""
    if climb and path and math.isfinite(path[0][2]):
        return ((path[0][0], path[0][1], NAN),) + tuple(path)
    return tuple(path)


def _landing_plan(items: tuple[MissionItem, ...], first: int, land: int, home_down: float, position: Point,
                  flying: str, climb: bool) -> ReturnPlan:
    """Through the mission's placed items ``first`` .. ``land`` - 1, then down on its Land item (where it is
    placed, else where the path ends, else where the vehicle is)."""
    path = _points(items, range(first, land), home_down)
    end = _placed(items[land], home_down) or (path[-1] if path else position)
    return ReturnPlan((end[0], end[1]), flying, f"landing at mission item {land}", _via(path, climb), climb, True)


def _safe_point_plan(place: tuple[float, float], rally: int | None) -> ReturnPlan:
    if rally is None:
        return ReturnPlan(place, "flying home", "landing at home")
    return ReturnPlan(place, f"flying to rally point {rally}", f"landing at rally point {rally}")


def plan_return(rtl_type: int, position: Point, home: Point, rally: tuple[RallyItem, ...],
                mission: tuple[MissionItem, ...], mission_seq: int | None = None) -> ReturnPlan:
    """The Return ``RTL_TYPE`` ``rtl_type`` flies from ``position`` (local NED); ``mission_seq``: the item being
    flown when Return began in Mission mode (None: another mode)."""
    landing = mission_landing(mission)
    if rtl_type == 2:
        return _along_mission(position, home, mission, landing, mission_seq)
    # RTL_TYPE 1 goes home only with no rally point
    place, index = nearest_safe_point(position, None if rtl_type == 1 and rally else home, rally)
    entry = _points(mission, range(landing[0], landing[1] + 1), home[2]) if landing and rtl_type != 0 else []
    if not entry:             # no landing to fly to (or one with no place of its own)
        return _safe_point_plan(place, index)
    if _apart(place, position) < _apart(entry[0], position) and (rally or rtl_type == 3):
        return _safe_point_plan(place, index)      # (type 1 with no rally point: the landing, never home)
    start, land = landing
    return _landing_plan(mission, start, land, home[2], position, f"flying to the mission landing at item {start}",
                         True)


def _along_mission(position: Point, home: Point, mission: tuple[MissionItem, ...], landing: tuple[int, int] | None,
                   mission_seq: int | None) -> ReturnPlan:
    """RTL_TYPE 2 (see the module docstring)."""
    in_mission = mission_seq is not None
    nearest = _nearest_item(position, mission)
    if landing is not None:
        start, land = landing
        first = mission_seq if in_mission else nearest
        if first is None or first > land:
            first = start
        return _landing_plan(mission, first, land, home[2], position,
                             f"following the mission from item {first} to its landing", not in_mission)
    last = mission_seq - 1 if in_mission else nearest
    if last is None or last < 0:
        return _safe_point_plan((home[0], home[1]), None)
    path = _points(mission, range(last, -1, -1), home[2])
    return ReturnPlan((home[0], home[1]), f"flying the mission back from item {last}, then home", "landing at home",
                      _via(path, not in_mission), not in_mission)

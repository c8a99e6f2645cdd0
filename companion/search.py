"""Where the search looks again from, once the first look refused (pure: no clock, no I/O).

A look of the search is a servo of its own started across the start's heading; these functions say where (across
the heading) the looks start and the nearest the wall can be there, from what earlier looks saw of it.
"""

from __future__ import annotations

import math


def _wall_limit(sight: tuple, right: float, turn_rad: float, yaw_margin_rad: float, side: float) -> float:
    """Where one sight of the wall (forward, right, measured turn or None) allows its face to be at ``right``:
    the nearest (``side`` -1) or the furthest (+1), a turn of up to ``turn_rad`` either way allowed for, or, the
    turn measured, that turn give or take ``yaw_margin_rad``."""
    wall_forward, wall_right, wall_yaw = sight
    across = right - wall_right
    limit = wall_forward + side * abs(across) * math.tan(turn_rad)
    if wall_yaw is None:
        return limit
    measured = wall_forward + across * math.tan(wall_yaw) + side * abs(across) * math.tan(yaw_margin_rad)
    return max(limit, measured) if side < 0 else min(limit, measured)


def search_wall_bound(walls: list[tuple], right: float, turn_rad: float, yaw_margin_rad: float) -> float | None:
    """The nearest the wall's face can be (forward coordinate) at ``right`` across the heading, by the earlier
    looks' sights of it (forward, right, measured turn or None): a turned wall is nearer on one side (allowed for
    up to ``turn_rad``, or, its turn measured, for that give or take ``yaw_margin_rad``), and beyond the wall's
    end the flow shows only what is behind it (measured: a vehicle walked past a wall's end, then stepped
    sideways into it).  The nearest of the sights' bounds counts: one taken far across, or with a turn measured
    wrong, may put the wall too far (measured, hard world seed 41: a third look began 0.3 m from the wall), and so
    may one taken past the wall's end, of what lies behind it (seed 105: see Mission._servo_searching)."""
    return min((_wall_limit(w, right, turn_rad, yaw_margin_rad, -1.0) for w in walls), default=None)


def search_wall_ceiling(walls: list[tuple], right: float, turn_rad: float, yaw_margin_rad: float) -> float | None:
    """The furthest the wall's face can be (forward coordinate) at ``right``, by the same sights as
    :func:`search_wall_bound` (turned the other way): what a look reads beyond it is what lies behind the wall's
    end, not the wall.  The furthest of the looks' ceilings counts."""
    return max((_wall_limit(w, right, turn_rad, yaw_margin_rad, 1.0) for w in walls), default=None)


def look_places(axis: float, shift: float, side: float, alternative: float | None = None) -> list[tuple[float, str]]:
    """The looks' places across the heading (right, metres) and how to name them: ``shift`` to ``side`` (+1 right,
    -1 left: the refused opening's side) of the start's ``axis``, then to the other side; with ``alternative``
    (where another opening the first look placed is across the heading), first in front of it, then the one of
    the two sides further from it, then the nearer one too, unless it lies within half of ``shift`` of the
    alternative (that look saw it).  Measured, hard world seed 96, hard_0274582567: a 0.45 m opening 0.2 m left
    refused, then the alternative 0.4 m left (judged 0.44 m), then 1.5 m right: nothing; the 0.85 m opening 2.5 m
    left was never looked at.  A third look costs a refused flight some 20 s of its 300 (the longest hard-world flights
    of seed 96 took 78 s)."""
    places = [(axis + s * shift, f"{shift:.1f} m {'right' if s > 0 else 'left'} of the start") for s in (side, -side)]
    if alternative is None:
        return places
    across = alternative - axis
    by_distance = sorted(places, key=lambda p: abs(p[0] - alternative), reverse=True)
    looks = [(alternative, f"in front of another opening seen on the way, {abs(across):.1f} m "
                           f"{'right' if across >= 0 else 'left'} of the start"), by_distance[0]]
    if abs(by_distance[1][0] - alternative) > shift / 2:
        looks.append(by_distance[1])
    return looks

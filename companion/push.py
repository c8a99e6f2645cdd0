"""The traversal (docs/design.md step 8): how far to push, and the setpoints that carry the body through the wall.

A wall that faces the heading is crossed straight along it, in the paper's 0.05 m increments. A wall measured as
turned is crossed square to its face instead, through the point where the heading's ray meets the wall's middle
plane: the centring put that point at the middle of the corridor the heading sees, and the opening's middle
is the same point seen square on.  Along the heading, a body crosses a wall of thickness t turned by ψ through an
opening narrowed by t·tan ψ, and the sphere's own footprint on the face widens by 1/cos ψ; square to the face it
has the opening's whole width (measured, offline on the 76 pushes of hard world seed 77: the one collision,
hard_0016024713, a 0.55 m rectangle in a 0.22 m wall turned 14°, had 0.021 m to spare on its path along the
heading and 0.050-0.056 m square to the wall, with the turn off by ±3°).
"""

from __future__ import annotations

import math

import numpy as np

from companion.servo import TURN_NEGLIGIBLE_RAD, ServoConfig, heading_to_ned

Point3 = tuple[float, float, float]
DEFAULT_SERVO = ServoConfig()


def push_length(wall_distance_m: float | None, config: ServoConfig = DEFAULT_SERVO,
                far_distance_m: float | None = None) -> float:
    """How far to traverse: past the wall's back face by the margin, bounded so as not to fly on into
    whatever stands behind the opening: with the far surface's distance measured, the push ends with the
    body sphere ``far_margin_m`` short of it (but never short of the wall's front face plus the body's
    radius, which the crossing needs)."""
    if wall_distance_m is None or not math.isfinite(wall_distance_m) or wall_distance_m <= 0:
        return config.push_default_m
    beyond = min(config.push_margin_m, config.push_max_beyond_wall_m)
    length = wall_distance_m + config.wall_thickness_m + beyond
    if far_distance_m is not None and math.isfinite(far_distance_m):
        stop = far_distance_m - config.body_radius_m - config.far_margin_m
        length = max(min(length, stop), wall_distance_m + config.body_radius_m)
    return length


def push_waypoints(start: Point3, yaw: float, length_m: float, bias: tuple[float, float],
                   config: ServoConfig = DEFAULT_SERVO, wall_distance_m: float | None = None,
                   turn_rad: float | None = None) -> list[Point3]:
    """The push's position setpoints, one per increment, level flight.  Along the heading: N_f increments of
    0.05 m, spreading the last small lateral/vertical bias correction over the first half.  With the wall's
    distance and a turn beyond :data:`~companion.servo.TURN_NEGLIGIBLE_RAD` (:func:`square_crossing`): on to the
    line square to the wall through the aim, then along it, in increments of at most 0.05 m; the push ends as far
    from the wall as the straight one would."""
    return push_path(start, yaw, length_m, bias, config, wall_distance_m, turn_rad)[0]


def push_path(start: Point3, yaw: float, length_m: float, bias: tuple[float, float],
              config: ServoConfig = DEFAULT_SERVO, wall_distance_m: float | None = None,
              turn_rad: float | None = None) -> tuple[list[Point3], bool]:
    """:func:`push_waypoints`, and whether they cross the wall square to its face."""
    bias = clamped_bias(bias, config)
    path = square_crossing(length_m, bias, wall_distance_m, turn_rad, config)
    if path is None:
        return _straight_push(start, yaw, length_m, bias, config.push_increment_m), False
    return [tuple(s + d for s, d in zip(start, heading_to_ned(tuple(p), yaw), strict=True))
            for p in _resample(path, config.push_increment_m)], True


def clamped_bias(bias: tuple[float, float], config: ServoConfig = DEFAULT_SERVO) -> tuple[float, float]:
    """The push's "small" bias correction: never more than an early servo step (``lateral_clamp_far_m``)."""
    limit = config.lateral_clamp_far_m
    return float(np.clip(bias[0], -limit, limit)), float(np.clip(bias[1], -limit, limit))


def square_crossing(length_m: float, bias: tuple[float, float], wall_distance_m: float | None,
                    turn_rad: float | None, config: ServoConfig = DEFAULT_SERVO) -> list[np.ndarray] | None:
    """The corners (forward, right, down from the push's start, metres) of a push that crosses a turned wall
    square to its face: the start; where the line square to the wall through the aim (the biased heading ray's
    crossing of the wall's middle plane, the wall ``wall_thickness_m`` deep) is met, half-way to the wall and the
    sphere with its margin still before the face; and the end, as far past the wall as ``length_m`` along the
    heading goes.  None for a wall that faces the heading, without a distance, or too near to turn square."""
    if (turn_rad is None or not math.isfinite(turn_rad) or abs(turn_rad) <= TURN_NEGLIGIBLE_RAD
            or wall_distance_m is None or not math.isfinite(wall_distance_m) or wall_distance_m <= 0):
        return None
    c, s = math.cos(turn_rad), math.sin(turn_rad)
    half = config.wall_thickness_m / 2.0
    # the wall's face is at forward = distance + right·tan(turn) (its right side further for a positive turn)
    aim = np.array([wall_distance_m + bias[0] * s / c + half / c, bias[0], bias[1]])
    normal = np.array([c, -s, 0.0])                    # into the wall, square to its face
    start_depth = float(-aim @ normal)                 # from the middle plane, along the normal (< 0: before it)
    entry = -(half + config.body_radius_m + config.clearance_margin_m)
    if start_depth >= entry:
        return None
    end_depth = float((np.array([length_m, bias[0], bias[1]]) - aim) @ normal)
    if end_depth <= 0.0:
        return None
    return [np.zeros(3), aim + normal * min(start_depth / 2.0, entry), aim + normal * end_depth]


def _resample(corners: list[np.ndarray], increment_m: float) -> list[np.ndarray]:
    """Points along the polyline through ``corners`` (after the first), evenly spaced within each leg at most
    ``increment_m`` apart, each leg's end included."""
    points = []
    for a, b in zip(corners, corners[1:], strict=False):
        n = max(1, math.ceil(float(np.linalg.norm(b - a)) / increment_m))
        points += [a + (b - a) * (i / n) for i in range(1, n + 1)]
    return points


def _straight_push(start: Point3, yaw: float, length_m: float, bias: tuple[float, float],
                   increment_m: float) -> list[Point3]:
    n = max(1, int(math.ceil(length_m / increment_m)))
    half = max(1, n // 2)
    points, p = [], start
    for i in range(n):
        share = 1.0 / half if i < half else 0.0
        step = heading_to_ned((increment_m, bias[0] * share, bias[1] * share), yaw)
        p = (p[0] + step[0], p[1] + step[1], p[2] + step[2])
        points.append(p)
    return points

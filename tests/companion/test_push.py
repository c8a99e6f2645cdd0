"""The traversal's setpoints: straight along the heading through a wall that faces it, square to the face of one
measured as turned."""

import math

import numpy as np
import pytest

from companion.push import push_length, push_waypoints, square_crossing
from companion.servo import ServoConfig

CFG = ServoConfig()


def _heading_frame(points, start, yaw):
    """Setpoints back in (forward, right, down) from the start."""
    c, s = math.cos(yaw), math.sin(yaw)
    rel = np.asarray(points) - np.asarray(start)
    return np.stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1], rel[:, 2]], 1)


def _slot_clearance(path, distance, turn, width, thickness):
    """Smallest distance (m) less the body's radius between a path (forward, right) and the two jambs of a slot
    ``width`` wide in a wall ``thickness`` deep whose face is ``distance`` ahead on the axis, turned by ``turn``,
    the slot's middle where the axis meets the wall's middle plane (a top view)."""
    c, s = math.cos(turn), math.sin(turn)
    normal, along = np.array([c, -s]), np.array([s, c])
    middle = np.array([distance + thickness / 2 / c, 0.0])
    dense = np.concatenate([np.linspace(a, b, 50) for a, b in zip(path, path[1:], strict=False)])
    rel = dense - middle
    depth, side = rel @ normal, rel @ along           # across the wall's face, and along it
    best = math.inf
    for edge in (width / 2, -width / 2):             # each jamb: the rectangle depth in ±t/2, side beyond the edge
        beyond = np.maximum(0.0, np.abs(depth) - thickness / 2)
        outside = (side - edge) * np.sign(edge)        # > 0 inside the wall's solid part
        gap = np.where(outside >= 0, beyond, np.hypot(beyond, outside))
        best = min(best, float(gap.min()))
    return best - CFG.body_radius_m


@pytest.mark.parametrize("turn", [None, 0.0, 0.04, -0.04])
def test_a_wall_that_faces_the_heading_is_crossed_straight_along_it(turn):
    start, yaw = (1.0, 2.0, -1.5), 0.3
    straight = push_waypoints(start, yaw, 1.6, (0.03, -0.02), CFG)
    assert push_waypoints(start, yaw, 1.6, (0.03, -0.02), CFG, 1.0, turn) == straight
    assert square_crossing(1.6, (0.03, -0.02), 1.0, turn, CFG) is None


@pytest.mark.parametrize("turn_deg", [8.0, -14.0, 20.0])
def test_a_turned_wall_is_crossed_square_to_its_face_through_the_aim(turn_deg):
    turn, start, yaw, distance, bias = math.radians(turn_deg), (1.0, 2.0, -1.5), -0.4, 1.1, (0.04, -0.03)
    length = push_length(distance, CFG)
    points = push_waypoints(start, yaw, length, bias, CFG, distance, turn)
    rel = _heading_frame([start] + points, start, yaw)
    legs = np.diff(rel, axis=0)
    assert np.linalg.norm(legs, axis=1).max() <= CFG.push_increment_m + 1e-9
    normal = np.array([math.cos(turn), -math.sin(turn), 0.0])
    # the last leg runs square to the face, level, through the biased ray's crossing of the wall's middle plane
    _, corner, end = square_crossing(length, bias, distance, turn, CFG)
    last = rel[-1] - corner
    assert last / np.linalg.norm(last) == pytest.approx(normal, abs=1e-9)
    aim = np.array([distance + bias[0] * math.tan(turn) + CFG.wall_thickness_m / 2 / math.cos(turn), *bias])
    assert np.linalg.norm(np.cross(aim - corner, normal)) == pytest.approx(0.0, abs=1e-9)
    assert rel[-1] == pytest.approx(end) and rel[-1][2] == pytest.approx(bias[1])
    # the turn is done before the face, with the sphere and its margin clear of it ...
    face_depth = float((aim - corner) @ normal) - CFG.wall_thickness_m / 2
    assert face_depth >= CFG.body_radius_m + CFG.clearance_margin_m - 1e-9
    # ... and the push ends as far past the wall as the straight one does
    straight_end = np.array([length, *bias])
    assert float(end @ normal) == pytest.approx(float(straight_end @ normal))


@pytest.mark.parametrize("turn_deg", [10.0, -15.0, 20.0])
def test_square_to_a_turned_wall_the_body_has_the_slots_whole_width(turn_deg):
    """Lined up on the corridor the heading sees (what the centring does), a 0.55 m slot in a 0.15 m wall: straight
    along the heading the sphere keeps less than the slot's half-width less its radius, square to the wall all of
    it."""
    turn, distance, width = math.radians(turn_deg), 1.1, 0.55
    length = push_length(distance, CFG)
    for_heading = _heading_frame([(0.0, 0.0, 0.0)] + push_waypoints((0.0, 0.0, 0.0), 0.0, length, (0.0, 0.0), CFG),
                                 (0.0, 0.0, 0.0), 0.0)[:, :2]
    square = np.array([p[:2] for p in square_crossing(length, (0.0, 0.0), distance, turn, CFG)])
    whole = width / 2 - CFG.body_radius_m
    along = _slot_clearance(for_heading, distance, turn, width, CFG.wall_thickness_m)
    assert _slot_clearance(square, distance, turn, width, CFG.wall_thickness_m) == pytest.approx(whole, abs=1e-3)
    assert along < whole - CFG.wall_thickness_m * math.tan(abs(turn)) / 2 + 1e-3


def test_too_near_to_turn_square_or_without_a_distance_the_push_goes_straight():
    turn = math.radians(15.0)
    assert square_crossing(1.0, (0.0, 0.0), 0.2, turn, CFG) is None       # the face within the sphere's reach
    assert square_crossing(1.0, (0.0, 0.0), None, turn, CFG) is None
    start = (0.0, 0.0, -1.0)
    assert push_waypoints(start, 0.0, 1.0, (0.0, 0.0), CFG, None, turn) == push_waypoints(start, 0.0, 1.0, (0.0, 0.0))

"""companion.thickness: where the thickness look stands, and what it reads from two views' masks and the flow
between them; and OpeningTracker.set_wall_thickness, the estimates taken to the depth read."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from companion.opening import OpeningTracker
from companion.servo import ServoConfig
from companion.thickness import (
    ThicknessLookConfig,
    ThicknessReading,
    combined_reading,
    face_shift,
    mask_span,
    opening_at_centre,
    plan_look,
    thickness_reading,
)

FOCAL = 156.387
H, W = 240, 320


def box(u0: int, u1: int, v0: int = 100, v1: int = 140) -> np.ndarray:
    mask = np.zeros((H, W), bool)
    mask[v0:v1, u0:u1] = True
    return mask


def views(distance: float, thickness: float, step: float = 0.3, face_px: float = 30.0):
    """Masks at A and B and the flow from A to B a pinhole gives for an opening 40 px wide in a wall ``distance``
    away, ``thickness`` deep, for a step ``step`` to the right: the face shifts as a thing ``distance`` away, what
    shows through the opening as its far edges do."""
    wall = -FOCAL * step / distance
    aperture = -FOCAL * step / (distance + thickness)
    a = box(150, 190)
    shift = int(round(aperture))
    b = box(150 + shift, 190 + shift)
    flow = np.zeros((H, W, 2), np.float32)
    flow[..., 0] = wall
    flow[a] = aperture
    return a, b, flow, shift


@pytest.mark.parametrize("yaw", [0.0, 0.4, -2.5])
def test_the_look_stands_on_the_normal_through_the_clear_centre(yaw):
    centre = (3.0, -1.0, -1.2)
    config = ThicknessLookConfig()
    plan = plan_look(centre, yaw, config)
    normal = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    right = np.array([-math.sin(yaw), math.cos(yaw), 0.0])
    assert len(plan.a) == len(plan.b) == config.readings + 1
    for points, side in ((plan.a, -1), (plan.b, 1)):
        for k, point in enumerate(points):
            to_centre = np.array(centre) - np.array(point)
            assert to_centre @ normal == pytest.approx(config.distance_m - k * config.forward_m)
            assert to_centre @ right == pytest.approx(-side * config.step_m / 2)
            assert point[2] == centre[2]
    assert plan.yaw == yaw and plan.distance_m == config.distance_m


@pytest.mark.parametrize("distance, thickness", [(1.2, 0.10), (1.2, 0.25), (1.0, 0.15), (1.5, 0.20)])
def test_the_reading_recovers_the_thickness_of_a_pinhole_view(distance, thickness):
    a, b, flow, shift = views(distance, thickness)
    reading = thickness_reading(a, b, flow, distance)
    # the masks shift by whole pixels: the reading is off by what the rounding leaves
    exact = distance * (flow[0, 0, 0] / shift - 1.0)
    assert reading.thickness_m == pytest.approx(exact, abs=1e-6)
    assert reading.thickness_m == pytest.approx(thickness, abs=0.03)
    assert "deep" in reading.why


def test_the_cameras_rotation_between_the_views_is_taken_out_of_the_openings_shift():
    a, b, flow, _ = views(1.2, 0.2)
    clean = thickness_reading(a, b, flow, 1.2)
    turned = np.roll(b, -4, axis=1)                   # B's yaw 4 px further right: everything 4 px further left
    rotational = np.zeros((H, W, 2), np.float32)
    rotational[..., 0] = -4.0
    assert thickness_reading(a, turned, flow, 1.2, rotational_ab=rotational).thickness_m == pytest.approx(
        clean.thickness_m)
    assert thickness_reading(a, turned, flow, 1.2).thickness_m != pytest.approx(clean.thickness_m, abs=0.02)


def test_a_look_that_cannot_tell_says_why_and_reads_nothing():
    a, b, flow, _ = views(1.2, 0.15)
    edge = box(0, 40)
    assert thickness_reading(a, None, flow, 1.2).thickness_m is None
    assert "not seen whole from view B" in thickness_reading(a, edge, flow, 1.2).why          # cut off by the frame
    wider = box(b.nonzero()[1].min(), b.nonzero()[1].max() + 6)
    assert "px wide" in thickness_reading(a, wider, flow, 1.2).why
    far_face = flow.copy()
    far_face[~a] = flow[a][0, 0] / 2.0                 # the face moving less than the aperture: nothing behind it
    reading = thickness_reading(a, b, far_face, 1.2)
    assert reading.thickness_m is None and "outside" in reading.why
    assert "too little" in thickness_reading(a, b, None, 1.2).why
    deep = thickness_reading(*views(1.2, 0.8)[:3], 1.2)
    assert deep.thickness_m is None and "0.03-0.40 m" in deep.why


def test_mask_span_and_face_shift():
    mask = box(150, 190)
    assert mask_span(mask) == (pytest.approx(169.5), pytest.approx(35.1))     # the middle 90 % of its columns
    stray = mask.copy()
    stray[120, 200:206] = True                          # a few stray pixels: the centroid and width hardly move
    assert mask_span(stray)[1] == pytest.approx(35.1, abs=1.0) and mask_span(stray)[0] == pytest.approx(169.5, abs=0.2)
    assert mask_span(box(0, 10)) is None and mask_span(None) is None and mask_span(np.zeros((H, W), bool)) is None
    flow = np.full((H, W, 2), -30.0, np.float32)
    flow[mask] = -5.0
    assert face_shift(flow, mask) == pytest.approx(-30.0)


def test_the_opening_measured_is_the_one_at_the_centre():
    centre, aside = box(140, 180, 100, 140), box(10, 60, 20, 60)
    detection = SimpleNamespace(candidates=(SimpleNamespace(found=True, mask=aside),
                                            SimpleNamespace(found=True, mask=centre)))
    assert opening_at_centre(detection) is centre
    off = box(200, 250, 100, 140)
    detection = SimpleNamespace(candidates=(SimpleNamespace(found=True, mask=aside),
                                            SimpleNamespace(found=True, mask=off)))
    assert opening_at_centre(detection) is off
    none = SimpleNamespace(candidates=(), found=False, mask=None)
    assert opening_at_centre(none) is None


@pytest.mark.parametrize("turn", [None, math.radians(15.0)])
def test_the_trackers_estimates_go_to_the_thickness_read(turn):
    tracker = OpeningTracker(ServoConfig())
    tracker.radii, tracker.radii_at = [0.25, 0.26], [(1.4, turn), (1.2, turn)]
    tracker.close_radii, tracker.close_at = [0.26], [(1.2, turn)]
    tracker.near_radii, tracker.near_at = [0.25, 0.26], [(1.4, turn), (1.2, turn)]
    tracker.radius_trail = [0.25, 0.26]
    tracker.set_wall_thickness(0.25)
    assert tracker.servo.wall_thickness_m == 0.25
    far, near = 1.65 / 1.55, 1.45 / 1.35
    if turn is None:
        assert tracker.radii == pytest.approx([0.25 * far, 0.26 * near])
        assert tracker.close_radii == pytest.approx([0.26 * near])
        assert tracker.radius_trail == pytest.approx([0.25 * near, 0.26 * near])
    else:                                   # a deeper turned wall also stretches a little more to its plane
        assert tracker.close_radii[0] > 0.26 * near
    tracker.set_wall_thickness(0.15)
    assert tracker.radii == pytest.approx([0.25, 0.26]) and tracker.close_radii == pytest.approx([0.26])


def due(sight_changes=(), view_changes=(), **mission) -> bool:
    """companion.thickness_flight.ThicknessLook._thickness_due for a tracked opening steered by a clear radius of
    0.25 m (the need, with the estimate's allowance, 0.247 m), once seen from in front, a wall 1.2 m ahead."""
    from companion.thickness_flight import ThicknessLook

    stub = SimpleNamespace(thickness=mission.get("thickness", ThicknessLookConfig()), servo=ServoConfig(),
                           _thickness_looked=mission.get("looked", False))
    sight = SimpleNamespace(**{"judged_estimates": 1, "offset_m": (0.02, -0.01), "judged_m": None,
                               "clear_radius_m": 0.25, **dict(sight_changes)})
    view = SimpleNamespace(**{"wall_distance": 1.2, "wall_yaw": math.radians(12.0), **dict(view_changes)})
    return ThicknessLook._thickness_due(stub, sight, view)


def test_the_look_is_due_once_near_the_need_seen_from_in_front():
    assert due()
    assert due({"clear_radius_m": 0.229}) and not due({"clear_radius_m": 0.225})        # 0.02 m either way
    assert due({"clear_radius_m": 0.266}) and not due({"clear_radius_m": 0.27})
    assert not due({"judged_m": 0.30}) and due({"judged_m": 0.24, "clear_radius_m": 0.4})  # judged: what decides
    assert not due({"judged_estimates": 0}) and not due({"offset_m": None})
    assert not due(view_changes={"wall_distance": None})
    assert not due(view_changes={"wall_yaw": math.radians(35.0)}) and due(view_changes={"wall_yaw": None})
    assert not due(looked=True) and not due(thickness=ThicknessLookConfig(enabled=False))


def test_a_looks_readings_combine_by_their_median_or_not_at_all():
    def read(*values):
        return combined_reading([ThicknessReading(v, "read" if v is not None else "not seen") for v in values])

    assert read(0.20, 0.05, 0.21).thickness_m == pytest.approx(0.20)        # one outlier of three
    assert "median of 3 of 3" in read(0.20, 0.05, 0.21).why
    assert read(0.20, None, 0.23).thickness_m == pytest.approx(0.215)       # two that agree
    disagree = read(0.20, None, 0.10)
    assert disagree.thickness_m is None and "more than 0.04 m apart" in disagree.why
    alone = read(None, 0.2, None)
    assert alone.thickness_m is None and "1 of 3" in alone.why and "not seen" in alone.why

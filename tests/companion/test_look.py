"""Where a look steps next from what a frame pair showed (companion.look.next_look_step), and the heading's frame."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.look import FrameView, across_heading, along_heading, next_look_step, see_frame
from companion.opening import Sight
from companion.servo import ServoConfig

W, H = 320, 240
CFG = ServoConfig()


class _Det:
    found, area, mask, centroid, reason = True, 0.0, np.zeros((H, W), bool), None, None


def view(sight: Sight, wall_distance=None, ahead=None, area_frac=0.02) -> FrameView:
    return FrameView(sight, _Det(), [], [], None, wall_distance, ahead, None, 0.0, 0.0, None, area_frac)


def test_the_heading_frame_turns_with_the_initial_heading():
    yaw = math.radians(30.0)
    p = (math.cos(yaw) * 2.0 - math.sin(yaw) * 0.5, math.sin(yaw) * 2.0 + math.cos(yaw) * 0.5, -1.5)
    assert along_heading(p, yaw) == pytest.approx(2.0)
    assert across_heading(p, yaw) == pytest.approx((0.5, -1.5))


def test_a_blind_step_goes_straight_on_and_stops_the_hold_distance_short_of_the_wall():
    step = next_look_step(view(Sight(None, None), ahead=1.25), 3, W, H, CFG, None, False)
    assert step.delta_heading == pytest.approx((1.25 - CFG.hold_distance_m, 0.0, 0.0)) and not step.push
    far = next_look_step(view(Sight(None, None), ahead=None), 3, W, H, CFG, None, False)
    assert far.delta_heading[0] == pytest.approx(CFG.forward_step_m) and far.delta_heading[1:] == (0.0, 0.0)


def test_a_search_look_without_its_own_wall_steps_across_only_to_a_sighting_of_this_frame():
    target = (W / 2 + 60.0, H / 2)                     # right of the centre: the image law steps right
    seen = next_look_step(view(Sight(None, target), ahead=1.6), 3, W, H, CFG, wall_prior=2.5, accepted=True)
    held = next_look_step(view(Sight(None, target), ahead=1.6), 3, W, H, CFG, wall_prior=2.5, accepted=False)
    assert seen.delta_heading[1] > 0 and held.delta_heading[1:] == (0.0, 0.0)
    assert seen.delta_heading[0] <= 1.6 - CFG.hold_distance_m + 1e-9 and not seen.push
    # the first look (no prior) steers by the image law as the paper does
    free = next_look_step(view(Sight(None, target), ahead=1.6), 3, W, H, CFG, wall_prior=None, accepted=False)
    assert free.delta_heading[1] > 0


def test_a_placed_opening_is_steered_to_by_the_metric_law():
    sight = Sight(None, (W / 2, H / 2), offset_m=(0.1, -0.05), clear_radius_m=0.4, clearance_here_m=None,
                  sightings=4, close_sightings=1)
    step = next_look_step(view(sight, wall_distance=1.5, ahead=1.5), 5, W, H, CFG, None, True)
    assert step.offset_m == pytest.approx((0.1, -0.05))
    assert step.delta_heading[1] == pytest.approx(CFG.metric_gain * 0.1)
    assert step.delta_heading[2] == pytest.approx(CFG.metric_gain * -0.05)


def test_a_frame_pair_of_a_forward_step_reads_the_wall_and_places_the_opening():
    """companion.look.see_frame on synthetic forward flow: a wall at 2 m north with an opening right of the
    centre, the vehicle stepping 0.2 m on per pair along a heading of 0° (forward flow's magnitude is the
    second frame's inverse depth times the step)."""
    from companion.gap import get_detector, textured_pixels
    from companion.opening import OpeningTracker
    from companion.perception import Perception
    from companion.wall import WallTrack
    from tests.companion.synthetic import FOCAL_320x240, textured_pair, translation_flow

    K = np.array([[FOCAL_320x240, 0, (W - 1) / 2], [0, FOCAL_320x240, (H - 1) / 2], [0, 0, 1]])
    detector = get_detector("parallax")
    rgb = textured_pair(H, W, (0.0, 0.0))[0]
    openings, wall = OpeningTracker(), WallTrack()
    for k in range(4):
        ahead = 2.0 - 0.2 * (k + 1)                                    # the wall from the pair's second frame
        # a 0.25 × 0.4 m opening 0.35-0.6 m right of the heading, as the pair's first frame sees it
        opening = [((W - 1) / 2 + FOCAL_320x240 * x / (ahead + 0.2), (H - 1) / 2 + FOCAL_320x240 * y / (ahead + 0.2))
                   for x, y in ((0.35, -0.2), (0.6, -0.2), (0.6, 0.2), (0.35, 0.2))]
        flow, truth = translation_flow(H, W, (0.0, 0.0, 1.0), opening, rho_near=1 / ahead, rho_far=1 / (ahead + 3),
                                       focal=FOCAL_320x240, scale=0.2)
        seen = Perception(flow, detector(flow), None, 0.0, 0.0, textured_pixels(rgb))
        view = see_frame(seen, rgb, (0.2 * k, 0.0, -1.5), (0.2 * (k + 1), 0.0, -1.5), (0.0, 0.0, 0.0), 0.2, False,
                         K, 0.0, openings, wall)
        assert view.found and view.measured == pytest.approx(ahead, rel=0.03)
        assert view.here == pytest.approx(0.2 * (k + 1)) and view.across == pytest.approx(0.0)
        assert (view.wall_distance is None) == (k < 2)                 # three readings before a distance
    assert view.wall_distance == pytest.approx(1.2, rel=0.03) and view.ahead == pytest.approx(view.wall_distance)
    # placed where its clear centre is, 0.475 m right of the heading, give or take the detector's mask edge (its
    # clear centre came out 2-3 px left of the polygon's, 0.03 m at 1.4 m)
    assert view.sight.offset_m == pytest.approx((0.475, 0.0), abs=0.04)
    assert view.detection is view.sight.detection and view.area_frac == pytest.approx(truth.mean(), rel=0.15)


@pytest.mark.parametrize("turn_deg, off_deg", [(0.0, 3.0), (15.0, 4.5), (-18.0, -2.0), (12.0, -3.5)])
def test_a_yawed_cameras_wall_reading_is_taken_to_the_heading(turn_deg, off_deg):
    """A wall 1.3 m ahead on the heading's axis, turned by θ against the heading, read by a camera yawed δ off
    it: the plane is read along and against the camera's axis, and taken to the heading's it is the wall's."""
    from companion.look import along_heading_axis
    from companion.servo import wall_from_flow
    from tests.companion.synthetic import FOCAL_320x240 as f

    distance, theta, delta, step = 1.3, math.radians(turn_deg), math.radians(off_deg), 0.08
    xn = (np.mgrid[0:H, 0:W][1].astype(np.float64) - (W - 1) / 2) / f
    # camera point (x right, z forward) at heading-frame forward z·cos δ − x·sin δ, right z·sin δ + x·cos δ; on
    # the wall forward = distance + right·tan θ, so along the ray x = xn·z:
    inverse_depth = ((math.cos(delta) - math.sin(delta) * math.tan(theta))
                     - xn * (math.sin(delta) + math.cos(delta) * math.tan(theta))) / distance
    ys, xs = np.mgrid[0:H, 0:W].astype(np.float64)
    rho = inverse_depth * step                                             # a step along the camera's axis
    flow = np.stack([(xs - (W - 1) / 2) * rho, (ys - (H - 1) / 2) * rho], -1).astype(np.float32)
    reading, turn = wall_from_flow(flow, None, step, f)
    assert turn == pytest.approx(theta + delta, abs=0.01)                  # against the camera's axis
    assert along_heading_axis(reading, turn, delta) == pytest.approx((distance, theta), abs=2e-3)
    assert along_heading_axis(reading, turn, 0.0) == (reading, turn)
    assert along_heading_axis(reading, None, delta) == (reading, None)     # no plane: kept as read
    assert along_heading_axis(None, turn, delta) == (None, pytest.approx(theta, abs=0.01))

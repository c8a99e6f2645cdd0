"""The servo's wall readings and metric law at their edges, on hand-made inverse depths with exact answers: which
pixels read the wall (the frame's middle, between the 20th and 95th percentiles, textured, outside the openings),
how many are enough, where an opening counts as a patch of the wall, when readings agree, and how the metric law
steps, probes and pushes at its thresholds.  Flows are a lateral step of the camera, u = -ρ·f, whose inverse
depth reads back exactly."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from companion import servo
from companion.gap import ParallaxGapConfig
from companion.servo import ServoConfig, judged_tolerance, metric_step, wall_readings_agree, wall_slope
from tests.companion.synthetic import SMALL, box

H, W = SMALL
FOCAL = 100.0
# the focal length inverse_depth_from_flow takes when given none: the flowgap camera's vertical field of view
DEFAULT_F = (H / 2.0) / math.tan(math.radians(ParallaxGapConfig().vfov_deg) / 2.0)
LATERAL = (1.0, 0.0, 0.0)


def lateral_flow(rho: np.ndarray) -> np.ndarray:
    flow = np.zeros(rho.shape + (2,), np.float32)
    flow[..., 0] = -rho * DEFAULT_F
    return flow


def distinct(shape=(H, W), lo: float = 0.2, hi: float = 0.4) -> np.ndarray:
    """Positive inverse depths, every pixel's its own (a percentile then moves with any pixel added or left out)."""
    return np.linspace(lo, hi, shape[0] * shape[1]).reshape(shape)


# ------------------------------------------------------------------------------------ the wall's distance

def test_without_a_plane_the_wall_is_read_at_the_60th_percentile_of_the_frames_middle_two_thirds():
    """Rows 10-49 and columns 13-66 of a 60 × 80 frame (a sixth off each side); what lies outside is not read."""
    rho = distinct()
    middle = box(13, 10, 67, 50)
    rho[~middle] = 1e6
    d = servo._distance(rho, np.ones((H, W), bool), None, 0.2, None)
    assert d == pytest.approx(0.2 / np.percentile(rho[middle], 60), rel=1e-12)


def test_two_percent_of_the_frame_measurable_is_enough_for_the_walls_distance():
    h, w = 50, 100
    assert 0.02 * h * w == 100
    rho = distinct((h, w))
    valid = np.zeros((h, w), bool)
    valid[20:30, 30:40] = True                          # 100 px, in the middle
    assert servo._distance(rho, valid, None, 0.2, None) == pytest.approx(0.2 / np.percentile(rho[valid], 60))
    valid[20, 30] = False
    assert servo._distance(rho, valid, None, 0.2, None) is None


# ------------------------------------------------------------------------------------- the wall's plane

def plane_rho(a: float, b: float, c: float, shape=(H, W)) -> np.ndarray:
    h, w = shape
    ys, xs = np.mgrid[0:h, 0:w]
    return a * (xs - (w - 1) / 2) / FOCAL + b * (ys - (h - 1) / 2) / FOCAL + c


def test_the_plane_is_fitted_in_the_frame_less_its_edges_and_its_bottom_quarter():
    """Rows 7-44 and columns 8-71 of a 60 × 80 frame: the wall turned (a = 0.1), exact there; outside, a level
    0.3 that is off the plane but within its range (a floor, the frame's edges) is not fitted."""
    rho = np.full((H, W), 0.3)
    core = box(8, 7, 72, 45)
    rho[core] = plane_rho(0.1, 0.0, 0.3)[core]
    coef = servo._wall_plane(rho, np.ones((H, W), bool), None, FOCAL)
    assert coef == pytest.approx([0.1, 0.0, 0.3], abs=1e-12)


def test_five_percent_of_the_frame_measurable_is_enough_for_the_plane():
    h, w = 50, 100
    assert 0.05 * h * w == 250
    rho = plane_rho(0.1, 0.05, 0.4, (h, w))
    valid = np.zeros((h, w), bool)
    valid[10:20, 20:45] = True                           # 250 px, inside the fitted part
    assert servo._wall_plane(rho, valid, None, FOCAL) == pytest.approx([0.1, 0.05, 0.4], abs=1e-12)
    valid[10, 20] = False
    assert servo._wall_plane(rho, valid, None, FOCAL) is None


def test_the_plane_takes_the_wall_between_its_20th_and_95th_percentiles_both_included():
    """Of the fitted pixels, 80 % at 0.5 (the wall), 10 % at 0.25 (beyond an opening a mask missed) and 10 % at 1.0
    (something nearer): the 20th percentile is 0.5 itself and the 95th 1.0 itself, so the fit goes through the
    wall and the near block, neither alone."""
    rho = np.full((H, W), 0.5)
    rho[box(8, 7, 14, 45)] = 0.25                        # columns 8-13 of the fitted 8-71
    rho[box(66, 7, 72, 45)] = 1.0                         # columns 66-71
    kept = box(14, 7, 72, 45)
    ys, xs = np.nonzero(kept)
    a = np.stack([(xs - (W - 1) / 2) / FOCAL, (ys - (H - 1) / 2) / FOCAL, np.ones(len(xs))], axis=1)
    expected, *_ = np.linalg.lstsq(a, rho[kept], rcond=None)
    assert 0.5 < expected[2] < 1.0 and expected[0] > 0.0
    assert servo._wall_plane(rho, np.ones((H, W), bool), None, FOCAL) == pytest.approx(expected, abs=1e-12)


def test_the_planes_upper_cut_is_the_95th_percentile():
    """With the near pixels each at their own depth, the fit is that through the pixels from the 20th to the 95th
    percentile of the fitted part."""
    rho = np.full((H, W), 0.5)
    near = box(60, 7, 72, 45)
    rho[near] = np.linspace(0.9, 1.1, near.sum())
    core = box(8, 7, 72, 45)
    lo, hi = np.percentile(rho[core], (20, 95))
    kept = core & (rho >= lo) & (rho <= hi)
    ys, xs = np.nonzero(kept)
    a = np.stack([(xs - (W - 1) / 2) / FOCAL, (ys - (H - 1) / 2) / FOCAL, np.ones(len(xs))], axis=1)
    expected, *_ = np.linalg.lstsq(a, rho[kept], rcond=None)
    assert servo._wall_plane(rho, np.ones((H, W), bool), None, FOCAL) == pytest.approx(expected, abs=1e-12)


def test_a_plane_fitted_behind_the_camera_is_no_wall():
    """ρ positive only on the right of the frame, on a plane whose straight-ahead ρ is negative: no plane."""
    rho = plane_rho(0.5, 0.0, -0.01)
    assert servo._wall_plane(rho, np.ones((H, W), bool), None, FOCAL) is None


# ------------------------------------------------------------------------------ openings and the wall

OPENING = box(30, 20, 50, 40)
UNTEXTURED = box(10, 10, 25, 25)          # a plain patch, its flow filled in from around it: garbage


def wall_with_opening(untextured_rho: float = 0.9) -> np.ndarray:
    rho = np.full((H, W), 0.5)
    rho[OPENING] = 0.2
    rho[UNTEXTURED] = untextured_rho
    return rho


def test_the_untextured_pixels_are_left_out_of_the_plane_the_openings_are_judged_by():
    textured = ~UNTEXTURED
    kept, patches, distance, turn = servo.wall_and_openings(lateral_flow(wall_with_opening()), [OPENING], 0.2,
                                                            DEFAULT_F, 0.85, LATERAL, textured)
    assert kept == [0] and patches == []
    assert distance == pytest.approx(0.2 / 0.5, rel=1e-6)     # float32 flow


def test_the_untextured_pixels_are_left_out_of_the_plane_fitted_again_once_a_patch_is_set_aside():
    patch = box(55, 10, 70, 25)                           # a "gap" on the wall itself: ratio 1
    textured = ~UNTEXTURED
    kept, patches, distance, turn = servo.wall_and_openings(lateral_flow(wall_with_opening()), [OPENING, patch],
                                                            0.2, DEFAULT_F, 0.85, LATERAL, textured)
    assert kept == [0] and patches == [pytest.approx(1.0)]
    assert distance == pytest.approx(0.2 / 0.5, rel=1e-6)     # float32 flow


def test_an_opening_exactly_at_the_depth_ratio_limit_is_kept():
    flow = lateral_flow(wall_with_opening(0.5))
    textured = np.ones((H, W), bool)
    _, patches, _, _ = servo.wall_and_openings(flow, [OPENING], 0.2, DEFAULT_F, 0.3, LATERAL, textured)
    ratio = patches[0]                                     # about 0.4
    kept, patches, _, _ = servo.wall_and_openings(flow, [OPENING], 0.2, DEFAULT_F, ratio, LATERAL, textured)
    assert kept == [0] and patches == []


@pytest.mark.parametrize("translation", [0.0, 1e-3])
def test_a_step_of_a_millimetre_or_less_reads_no_distance(translation):
    flow = lateral_flow(wall_with_opening(0.5))
    kept, _, distance, _ = servo.wall_and_openings(flow, [OPENING], translation, DEFAULT_F, 0.85, LATERAL,
                                                   np.ones((H, W), bool))
    assert kept == [0] and distance is None


def test_without_a_plane_the_distance_is_read_on_the_measurable_wall_outside_the_openings():
    """Flow measurable only on a 20 × 10 patch (4 % of the frame: too little for a plane, enough for the
    percentile), part of it an opening: the distance comes from the patch's wall pixels."""
    rho = distinct()
    patch = box(15, 20, 35, 30)
    rho[OPENING] = 0.05
    flow = lateral_flow(rho)
    flow[~patch] = np.nan
    kept, _, distance, turn = servo.wall_and_openings(flow, [OPENING], 0.2, DEFAULT_F, 0.85, LATERAL, None)
    wall = patch & ~OPENING
    assert kept == [0] and turn is None
    assert distance == pytest.approx(0.2 / np.percentile(rho[wall], 60), rel=1e-6)


def test_far_distance_is_read_four_pixels_inside_the_mask():
    """The far surface's distance: the median ρ of the mask shrunk by 4 px each side (here 12 × 12 of 20 × 20),
    every pixel at its own depth, so that a row or column more or less would move it."""
    rho = np.full((H, W), 0.5)
    rho[OPENING] = distinct((20, 20), 0.1, 0.2).ravel()
    inner = box(34, 24, 46, 36)
    d = servo.far_distance_from_flow(lateral_flow(rho), OPENING, 0.2)
    assert d == pytest.approx(0.2 / np.median(rho[inner]), rel=1e-6)


def test_thirty_measurable_pixels_inside_the_mask_are_enough_for_the_far_distance():
    mask = box(30, 20, 44, 33)                             # 14 × 13: 6 × 5 = 30 px once shrunk by 4
    rho = np.where(mask, 0.2, 0.5)
    assert servo.far_distance_from_flow(lateral_flow(rho), mask, 0.2) == pytest.approx(1.0, rel=1e-6)
    smaller = box(30, 20, 44, 32)                          # 6 × 4 = 24 px
    assert servo.far_distance_from_flow(lateral_flow(np.where(smaller, 0.2, 0.5)), smaller, 0.2) is None


# ------------------------------------------------------------------------------------- readings agree

def test_readings_exactly_the_tolerance_apart_agree():
    assert wall_readings_agree([(2.0, 0.0), (2.25, 0.0)], 0.0, None, 0.0, 2, 0.25, 0.0)
    assert not wall_readings_agree([(2.0, 0.0), (2.25, 0.0)], 0.0, None, 0.0, 2, 0.125, 0.0)


def test_the_per_metre_allowance_counts_the_walls_own_distance_however_near():
    """Readings 0.54 m ahead at the median, 0.08 m apart: 0.1 per metre allows 0.054 m, so they do not agree
    (a floor of 1 m would allow 0.1)."""
    assert not wall_readings_agree([(2.5, 0.0), (2.58, 0.0)], 0.0, None, 2.0, 2, 0.0, 0.1)
    assert wall_readings_agree([(2.5, 0.0), (2.58, 0.0)], 0.0, None, 1.7, 2, 0.0, 0.1)


def test_a_turn_of_exactly_the_negligible_angle_is_no_turn():
    assert wall_slope(servo.TURN_NEGLIGIBLE_RAD) == 0.0
    assert wall_slope(2 * servo.TURN_NEGLIGIBLE_RAD) == pytest.approx(math.tan(2 * servo.TURN_NEGLIGIBLE_RAD))


# ------------------------------------------------------------------------------------------ metric law

def test_a_centring_step_goes_from_the_waypoint_down_as_across():
    """The waypoint 0.04 m below where the frame was taken, the opening 0.10 m below: 0.7 × 0.06 m down."""
    step = metric_step((0.0, 0.1), 0.5, 2.0, 0.0, 0, lag_m=(0.0, 0.04))
    assert step.delta_heading[2] == pytest.approx(0.7 * 0.06)


def test_a_step_forward_with_nothing_to_correct_is_not_a_probe():
    step = metric_step((0.0, 0.0), 0.5, 3.0, 0.0, 1)
    assert step.delta_heading == pytest.approx((0.2, 0.0, 0.0))


def test_held_in_place_the_probe_steps_right_and_left_in_turn():
    """Aligned, close, on a place too few frames placed: held (the wall nearer than the probe floor), it steps
    sideways by the probe step, right on even steps and left on odd ones."""
    sideways = [metric_step((0.0, 0.0), 0.5, 0.8, 0.3, k).delta_heading for k in range(4)]
    assert [d[1] for d in sideways] == pytest.approx([0.08, -0.08, 0.08, -0.08])
    assert all(d[0] == 0.0 for d in sideways)


def test_a_forward_step_of_two_centimetres_is_a_step_not_a_hold():
    cfg = dataclasses.replace(ServoConfig(), probe_step_m=0.02)
    step = metric_step((0.0, 0.0), 0.5, 1.2, 0.0, 1, cfg)
    assert step.delta_heading == pytest.approx((0.02, 0.0, 0.0))


def test_a_caller_that_does_not_say_how_often_the_opening_was_placed_gets_no_push():
    cfg = dataclasses.replace(ServoConfig(), push_sightings=1)
    step = metric_step((0.0, 0.0), 0.5, 1.2, 0.3, 1, cfg, clearance_here_m=0.5)
    assert step.aligned and not step.push
    assert metric_step((0.0, 0.0), 0.5, 1.2, 0.3, 1, cfg, clearance_here_m=0.5, sightings=1).push


def test_an_opening_exactly_roomy_needs_no_estimates_from_in_front():
    # sizes a float subtracts exactly, so that the tolerance is the roomy one to the last bit
    cfg = dataclasses.replace(ServoConfig(), body_radius_m=0.25, clearance_margin_m=0.125, roomy_tolerance_m=0.125,
                              size_allowance_m=0.0)
    radius = 0.5
    assert judged_tolerance(radius, cfg) == cfg.roomy_tolerance_m
    step = metric_step((0.0, 0.0), radius, 1.2, 0.3, 1, cfg, clearance_here_m=radius, sightings=3,
                       judged_estimates=0)
    assert step.judged and step.push

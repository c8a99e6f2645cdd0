"""The photometric test of two depths at an opening's edge (companion.edges), on an exact synthetic pair: a
textured wall with a round hole and a textured background behind it, the camera stepping straight ahead.  Frame 2
is built from the geometry (a wall pixel at p moves to p·Z/(Z − step)), so the truth is known to the pixel."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from companion.edges import EdgeConfig, refine_detection, refine_mask
from companion.gap import CameraMotion, ParallaxGapConfig, _inverse_depth, clear_circle, detect_gap_parallax
from tests.companion.synthetic import iou

H, W, FOCAL = 120, 160, 80.0
K = np.array([[FOCAL, 0.0, W / 2], [0.0, FOCAL, H / 2], [0.0, 0.0, 1.0]])
WALL_Z, FAR_Z, STEP = 1.2, 2.4, 0.15
CENTRE, RADIUS = (78.0, 62.0), 24.0      # the hole, in the first frame's pixels (near the focus of expansion)


def texture(seed: int, blur: float = 1.2) -> np.ndarray:
    rng = np.random.default_rng(seed)
    tex = cv2.GaussianBlur(rng.random((H, W, 3)).astype(np.float32), (0, 0), blur)
    return ((tex - tex.min()) / (tex.max() - tex.min()) * 255.0).astype(np.float32)


def scene_pair():
    """(first RGB, second RGB, exact forward flow, the truth's mask) of the wall and its hole."""
    ys, xs = np.mgrid[0:H, 0:W].astype(np.float32)
    cx, cy = (W - 1) / 2.0, (H - 1) / 2.0
    hole = np.hypot(xs - CENTRE[0], ys - CENTRE[1]) <= RADIUS
    wall, far = texture(1), texture(2)
    first = np.where(hole[..., None], far, wall)

    def seen_from(z):       # where the second frame's pixel (xs, ys) was in the first, for a surface at depth z
        k = (z - STEP) / z
        return (cx + (xs - cx) * k).astype(np.float32), (cy + (ys - cy) * k).astype(np.float32)

    wx, wy = seen_from(WALL_Z)
    through = cv2.remap(hole.astype(np.uint8), wx, wy, cv2.INTER_NEAREST).astype(bool)
    fx, fy = seen_from(FAR_Z)
    second = np.where(through[..., None], cv2.remap(far, fx, fy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT),
                      cv2.remap(wall, wx, wy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT))
    depth = np.where(hole, FAR_Z, WALL_Z)
    flow = np.stack([(xs - cx) * STEP / (depth - STEP), (ys - cy) * STEP / (depth - STEP)], -1)
    return first.astype(np.uint8), second.astype(np.uint8), flow.astype(np.float32), hole


def detector_inputs(flow):
    motion = CameraMotion(focal_px=FOCAL, principal_point=((W - 1) / 2.0, (H - 1) / 2.0))
    rho, measurable, g = _inverse_depth(flow, motion, ParallaxGapConfig())
    return rho, measurable & (rho > 0), g


def notched(truth: np.ndarray, short_px: int = 3) -> np.ndarray:
    """The truth eroded by ``short_px`` with a wedge cut into it: a blurred, notched mask as flow gives."""
    mask = cv2.erode(truth.astype(np.uint8), np.ones((3, 3), np.uint8), iterations=short_px).astype(bool)
    cv2.fillPoly(mask.view(np.uint8), [np.array([[78, 62], [104, 50], [104, 74]], np.int32)], 0)
    return mask


NO_ROTATION = np.zeros((H, W, 2), np.float32)


def test_a_short_notched_mask_is_read_back_to_the_truths_edge():
    first, second, flow, truth = scene_pair()
    rho, measurable, g = detector_inputs(flow)
    short = notched(truth)
    assert clear_circle(truth)[1] - clear_circle(short)[1] >= 3.0
    refined = refine_mask(short, first, second, rho, measurable, g, NO_ROTATION)
    assert abs(clear_circle(refined)[1] - clear_circle(truth)[1]) <= 1.0
    assert iou(refined, truth) > 0.95 > iou(short, truth)


def test_a_mask_too_large_is_cut_back_only_when_asked_to_shrink():
    first, second, flow, truth = scene_pair()
    rho, measurable, g = detector_inputs(flow)
    wide = cv2.dilate(truth.astype(np.uint8), np.ones((3, 3), np.uint8), iterations=3).astype(bool)
    cut = refine_mask(wide, first, second, rho, measurable, g, NO_ROTATION, EdgeConfig(shrink=True))
    assert iou(cut, truth) > 0.95 > iou(wide, truth)
    kept = refine_mask(wide, first, second, rho, measurable, g, NO_ROTATION)
    assert (kept >= wide).all()


def test_the_rotations_flow_is_where_the_second_frame_is_sampled():
    """The same pair with the second frame shifted by a known rotational flow: read with that flow, the same."""
    first, second, flow, truth = scene_pair()
    rho, measurable, g = detector_inputs(flow)
    shifted = cv2.warpAffine(second, np.float32([[1, 0, 3], [0, 1, -2]]), (W, H), borderMode=cv2.BORDER_REFLECT)
    rotational = np.zeros((H, W, 2), np.float32)
    rotational[..., 0], rotational[..., 1] = 3.0, -2.0
    short = notched(truth)
    plain = refine_mask(short, first, second, rho, measurable, g, NO_ROTATION)
    moved = refine_mask(short, first, shifted, rho, measurable, g, rotational)
    assert iou(moved, plain) > 0.97
    unaware = refine_mask(short, first, shifted, rho, measurable, g, NO_ROTATION)
    assert iou(unaware, truth) < iou(moved, truth) - 0.02


def test_without_a_wall_around_it_the_mask_is_left_alone():
    first, second, flow, truth = scene_pair()
    rho, measurable, g = detector_inputs(flow)
    everything = np.ones((H, W), bool)
    assert (refine_mask(everything, first, second, rho, measurable, g, NO_ROTATION) == everything).all()
    nothing_measured = np.zeros((H, W), bool)
    short = notched(truth)
    assert (refine_mask(short, first, second, rho, nothing_measured, g, NO_ROTATION) == short).all()


@pytest.mark.parametrize("window_px", [1, 3])
@pytest.mark.parametrize("shrink", [False, True])
def test_a_detection_and_its_candidates_are_read_again(shrink, window_px):
    first, second, flow, truth = scene_pair()
    detection = detect_gap_parallax(flow, ParallaxGapConfig(), CameraMotion(focal_px=FOCAL))
    assert detection.found
    refined = refine_detection(detection, first, second, flow, NO_ROTATION, K,
                               EdgeConfig(window_px=window_px, shrink=shrink))
    assert refined.found and len(refined.candidates) == len(detection.candidates)
    assert refined.candidates[0] is refined or refined.candidates[0].mask is refined.mask
    # exact flow gives the detector the truth to a pixel (IoU 0.99); read again, it stays within a pixel of it (a
    # 3 px window straddles the edge: a fraction of a pixel outward growing, inward shrinking)
    assert iou(detection.mask, truth) > 0.98 and iou(refined.mask, truth) > 0.95
    assert abs(clear_circle(refined.mask)[1] - clear_circle(truth)[1]) <= 1.1     # a pixel, and the grid's rounding
    assert refined.clear_radius_px == pytest.approx(clear_circle(refined.mask)[1])


@pytest.mark.parametrize("window_px", [1, 3, 5])
def test_a_mask_at_the_frames_edge_is_read_within_the_frame(window_px):
    """The band of a mask that reaches the frame's edge ends there (flown: 7 of the suite's first 25 flights
    stopped on a box past the frame's last row or column)."""
    first, second, flow, truth = scene_pair()
    rho, measurable, g = detector_inputs(flow)
    ys, xs = np.mgrid[0:H, 0:W]
    across, down = np.abs(ys - CENTRE[1]) <= 6, np.abs(xs - CENTRE[0]) <= 6     # bars from the hole to an edge
    for mask in (truth | (across & (xs >= CENTRE[0])), truth | (down & (ys >= CENTRE[1])),
                 truth | (across & (xs <= CENTRE[0]))):
        refined = refine_mask(mask, first, second, rho, measurable, g, NO_ROTATION, EdgeConfig(window_px=window_px))
        assert refined.shape == (H, W) and (refined >= mask).all()

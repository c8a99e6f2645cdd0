import dataclasses
import math

import numpy as np
import pytest

from companion.gap import (
    CameraMotion,
    ParallaxGapConfig,
    clear_circle,
    detect_gap_parallax,
)
from companion.gap_paper import GapDetectorConfig, detect_gap, detect_gap_in_colour
from companion.inverse_depth import estimate_translation
from tests.companion.synthetic import FOCAL_320x240, iou, translation_flow

H, W = 240, 320
QUAD = [(130, 90), (200, 95), (195, 160), (125, 150)]
CORNER_QUAD = [(40, 40), (120, 50), (110, 120), (50, 110)]
IDEAL = ParallaxGapConfig(occlusion_fill=None)   # for flows with nothing hidden: no band to fill back


@pytest.mark.parametrize("t, polygon", [
    ((1.0, 0.0, 0.2), QUAD),            # mostly sideways: the band on the side it moves to is hidden
    ((-1.0, 0.0, 0.2), QUAD),           # ... the other way
    ((0.0, 1.0, 0.3), QUAD),            # downwards
    ((0.3, 0.0, 1.0), CORNER_QUAD),     # forward, the opening off to the side of the focus of expansion
])
def test_the_band_the_wall_hides_in_the_second_frame_is_filled_back(t, polygon):
    # The far pixels that land behind the wall in the second frame take the wall's flow, as an estimator gives
    # them: read as is, the mask loses that band and its clear centre moves away from it.
    flow, truth = translation_flow(H, W, t, polygon, occlusion=True)
    cut = detect_gap_parallax(flow, IDEAL)
    filled = detect_gap_parallax(flow)                  # the default: 0.75 of the modelled band
    full = detect_gap_parallax(flow, ParallaxGapConfig(occlusion_fill=1.0))
    lost = truth & ~cut.mask
    assert lost.sum() > 0.05 * truth.sum()              # the case is real
    assert (truth & ~filled.mask).sum() < 0.5 * lost.sum()
    assert iou(full.mask, truth) > iou(filled.mask, truth) > iou(cut.mask, truth)
    assert iou(full.mask, truth) >= 0.93                 # the union leaves the corners of the cut side
    # never more than a pixel or two of wall taken for the opening
    assert (full.mask & ~truth).sum() <= 0.02 * truth.sum()
    true_centre = clear_circle(truth)[0]
    assert math.dist(full.clear_centre, true_centre) < math.dist(cut.clear_centre, true_centre)


def test_moving_toward_an_opening_around_the_focus_of_expansion_hides_nothing_and_fills_nothing():
    flow, truth = translation_flow(H, W, (0.0, 0.0, 1.0), QUAD, occlusion=True)
    assert np.array_equal(flow, translation_flow(H, W, (0.0, 0.0, 1.0), QUAD)[0])
    assert np.array_equal(detect_gap_parallax(flow).mask, detect_gap_parallax(flow, IDEAL).mask)


@pytest.mark.parametrize("detector", [detect_gap, detect_gap_parallax])
@pytest.mark.parametrize("t, polygon", [
    ((0.0, 0.0, 1.0), QUAD),            # pure forward: radial expansion about the centre
    ((0.0, 0.0, 1.0), CORNER_QUAD),
    ((1.0, 0.0, 0.2), QUAD),            # mostly lateral
    ((0.3, 0.0, 1.0), CORNER_QUAD),     # forward + lateral
])
def test_low_flow_polygon_in_expansion_field(detector, t, polygon):
    flow, truth = translation_flow(H, W, t, polygon)    # ideal: every far pixel has its true flow
    result = detector(flow) if detector is detect_gap else detector(flow, IDEAL)
    assert result.found, result.reason
    assert iou(result.mask, truth) >= 0.95
    ys, xs = np.nonzero(truth)
    assert np.hypot(result.centroid[0] - xs.mean(), result.centroid[1] - ys.mean()) < 3.0
    assert result.mask.dtype == bool and result.mask.shape == (H, W)
    assert result.area == pytest.approx(truth.sum(), rel=0.1)
    assert result.contour.shape[1] == 2


def test_parallax_detector_handles_foe_on_the_gap_edge():
    # The paper's colour pipeline loses this one (edges everywhere near the FoE); ours must not.
    flow, truth = translation_flow(H, W, (0.3, 0.0, 1.0), QUAD)
    assert iou(detect_gap_parallax(flow).mask, truth) >= 0.95


@pytest.mark.parametrize("detector", [detect_gap, detect_gap_parallax])
def test_uniform_flow_has_no_gap(detector):
    flow = np.zeros((H, W, 2), np.float32)
    flow[..., 0] = 2.0
    result = detector(flow)
    assert not result.found and result.reason
    assert result.centroid is None and not result.mask.any() and result.area == 0.0


def test_area_bounds_reject_tiny_and_accept_limits():
    img = np.full((100, 100, 3), 255, np.uint8)
    img[40:44, 40:44] = 0                   # closes to a solid 4×4 blob: contour area 9 px² < 0.001·HW = 10
    assert not detect_gap_in_colour(img).found
    img[40:50, 40:50] = 0                   # 10×10: area ≈ 81 px² is kept by the default bounds
    assert detect_gap_in_colour(img).found
    strict = GapDetectorConfig(area_min_frac=0.05)
    assert not detect_gap_in_colour(img, strict).found
    assert "area" in detect_gap_in_colour(img, strict).reason


def test_colour_detector_reads_bgr_explicitly():
    # A pure-blue square on red in BGR: grey(B=255) = 29, grey(R=255) = 76 -> edge contrast 47 > 40.
    # Read as RGB the two would swap but still differ; what must hold is that BGR→grey is the conversion.
    img = np.zeros((120, 160, 3), np.uint8)
    img[..., 2] = 255                        # red background (BGR)
    img[40:80, 60:100] = (255, 0, 0)         # blue square (BGR)
    res = detect_gap_in_colour(img)
    assert res.found
    assert res.centroid == pytest.approx((79.5, 59.5), abs=1.5)


def test_translation_is_recovered_from_flow():
    t_true = np.array([0.3, -0.1, 1.0])
    flow, _ = translation_flow(H, W, tuple(t_true), QUAD)
    t = estimate_translation(flow, FOCAL_320x240, ((W - 1) / 2, (H - 1) / 2))
    np.testing.assert_allclose(t, t_true / np.linalg.norm(t_true), atol=1e-3)


def test_parallax_detector_accepts_known_motion():
    flow, truth = translation_flow(H, W, (0.0, 0.0, 1.0), QUAD)
    res = detect_gap_parallax(flow, motion=CameraMotion(translation=(0.0, 0.0, 1.0)))
    assert iou(res.mask, truth) >= 0.95


def test_parallax_detector_sees_no_gap_on_wall_and_floor():
    # Forward+lateral motion over a wall (ρ = 0.5) with a floor in its lower quarter whose inverse depth
    # grows towards the bottom: no region is farther than the wall, so there is no gap.
    h, w = H, W
    flow, _ = translation_flow(h, w, (0.2, 0.0, 1.0), [(0, 0), (1, 0), (1, 1)], rho_far=0.5)
    ys = np.arange(h, dtype=np.float64)
    ramp = np.where(ys > 0.75 * h, 1.0 + 3.0 * (ys - 0.75 * h) / (0.25 * h), 1.0)
    flow *= ramp[:, None, None].astype(np.float32)
    res = detect_gap_parallax(flow)
    assert not res.found, res.area
    assert "enclosed" in res.reason
    # ... and with a far polygon added, it is found despite the floor
    flow2, truth = translation_flow(h, w, (0.2, 0.0, 1.0), QUAD)
    flow2 *= ramp[:, None, None].astype(np.float32)
    assert iou(detect_gap_parallax(flow2).mask, truth) >= 0.95


def test_parallax_detector_ignores_a_far_band_along_the_frame_edge():
    # Seen from 4 m, what lies beyond a wall's top edge is far too, but it is no opening: a band along the
    # frame's top edge (135×22 px, 43 % of its outline on the border; flights locked onto one like it)
    band = [(145, 0), (280, 0), (280, 22), (145, 22)]
    flow, band_mask = translation_flow(H, W, (0.1, 0.0, 1.0), band)
    res = detect_gap_parallax(flow)
    assert not res.found and "enclosed" in res.reason
    # ... while a hole in the wall below it is found
    hole, truth = translation_flow(H, W, (0.1, 0.0, 1.0), QUAD)
    both = np.where(band_mask[..., None], flow, hole)
    assert iou(detect_gap_parallax(both).mask, truth) >= 0.95


def test_inverse_depth_is_step_over_depth():
    # ρ = |T|/Z: with the synthetic field's scale 0.3 and ρ_near 0.5, the wall reads 0.15 for a unit step
    from companion.gap import inverse_depth_from_flow

    flow, truth = translation_flow(H, W, (0.3, -0.1, 1.0), QUAD, rho_near=0.5, rho_far=0.05)
    rho, valid = inverse_depth_from_flow(flow, CameraMotion(focal_px=FOCAL_320x240))
    np.testing.assert_allclose(np.nanmedian(rho[valid & ~truth]), 0.15 * np.linalg.norm((0.3, -0.1, 1.0)),
                               rtol=1e-3)
    np.testing.assert_allclose(np.nanmedian(rho[valid & truth]), 0.015 * np.linalg.norm((0.3, -0.1, 1.0)),
                               rtol=1e-3)


def test_the_clear_circle_is_the_largest_circle_inside_the_mask_not_the_centroid():
    from companion.gap import clear_circle

    mask = np.zeros((240, 320), bool)
    mask[60:180, 100:160] = True           # a 60 × 120 px slot
    centre, radius = clear_circle(mask)
    assert radius == pytest.approx(30.0, abs=0.5) and centre == pytest.approx((129.5, 119.5), abs=1.0)
    # an L: the centroid lies near the corner; the clear centre sits in the wider arm
    mask[:] = False
    mask[40:200, 40:80] = True
    mask[160:200, 40:280] = True
    (cu, cv), r = clear_circle(mask)
    assert 20.0 <= r <= 30.0 and mask[int(cv), int(cu)]                    # inside, where the arms meet
    ys, xs = np.nonzero(mask)
    assert not mask[int(round(ys.mean())), int(round(xs.mean()))]         # the centroid is not even inside
    # the frame's border is an edge: a mask running off the frame is clipped there
    mask[:] = False
    mask[100:200, 0:50] = True
    assert clear_circle(mask)[1] == pytest.approx(25.0, abs=0.6)
    assert clear_circle(np.zeros((10, 10), bool)) == (None, 0.0)


def test_a_detection_carries_its_clear_circle():
    square = [(100, 60), (220, 60), (220, 150), (100, 150)]
    flow, _ = translation_flow(240, 320, (0.0, 0.0, 1.0), square)
    det = detect_gap_parallax(flow)
    assert det.found and det.clear_radius_px == pytest.approx(45.0, abs=4.0)
    assert det.clear_centre == pytest.approx((160.0, 105.0), abs=4.0)


def test_textured_pixels_are_those_near_an_edge_of_the_image():
    from companion.gap import textured_pixels

    cfg = ParallaxGapConfig()
    rng = np.random.default_rng(3)
    wall = rng.integers(0, 256, (H, W, 1), dtype=np.uint8).repeat(3, axis=2)    # texture everywhere ...
    wall[:, 200:] = 0                                                           # ... but the empty space
    wall[100:104, 50:54] = 128                                                  # ... and a plain patch
    textured = textured_pixels(wall, cfg)
    assert textured[:, :200].all()                              # the patch too: its flow is the wall's
    assert not textured[:, 200 + cfg.texture_reach_px + 2:].any()
    assert textured[:, 200 + cfg.texture_reach_px - 1].all()    # the empty space's edge still counts
    assert not textured_pixels(np.full((H, W, 3), 90, np.uint8), cfg).any()
    # a faint gradient (under the threshold) is not texture
    ramp = np.tile(np.linspace(0, 60, W, dtype=np.float32), (H, 1)).astype(np.uint8)[..., None].repeat(3, axis=2)
    assert not textured_pixels(ramp, cfg).any()


def test_a_wide_dead_disc_at_the_focus_of_expansion_inpainted_cuts_a_notch_where_it_reaches_the_openings_edge():
    """The pixels too near the focus of expansion to read ρ one by one were filled from around them; flying at an
    opening puts the focus in it, and where the filled disc reached the edge the wall's ρ was smeared into the
    opening.  The focus 8 px inside the left edge of a 53 x 51 px opening: inpainted, a disc of 4 % of the largest
    |g| (8 px) leaves the clear circle whole, the default's 8 % (16 px) cuts 2 px off it (4 % tried, not kept:
    docs/evaluation.md); read over a window (focus_window_px, off as flown), the 8 % disc leaves it whole."""
    cx, cy = (W - 1) / 2, (H - 1) / 2
    polygon = [(cx - 8, cy - 25), (cx + 45, cy - 25), (cx + 45, cy + 25), (cx - 8, cy + 25)]
    flow, truth = translation_flow(H, W, (0.0, 0.0, 1.0), polygon, occlusion=True)
    motion = CameraMotion(focal_px=FOCAL_320x240)
    whole = clear_circle(truth)[1]
    inpainted = ParallaxGapConfig(focus_window_px=None)
    narrow = dataclasses.replace(inpainted, min_g_frac=0.04)
    assert detect_gap_parallax(flow, narrow, motion).clear_radius_px == pytest.approx(whole, abs=0.5)
    assert detect_gap_parallax(flow, inpainted, motion).clear_radius_px <= whole - 1.5
    window = dataclasses.replace(inpainted, focus_window_px=9)
    assert detect_gap_parallax(flow, window, motion).clear_radius_px == pytest.approx(whole, abs=0.5)

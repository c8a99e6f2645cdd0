"""companion.gap piece by piece: result fields, the clear circle, contour moments, the colour pipeline's steps,
Otsu splits, the far-region descent, translation and inverse depth, and each refusal of the parallax detector.

Inputs are built so that the right answer is known by construction: pure lateral motion makes the inverse depth
a per-pixel constant (ρ = -u/f), so the parallax detector's 8-bit image is exactly two levels and every threshold
can be met exactly; rectangles and triangles have their centroids and areas from geometry.
"""

from __future__ import annotations

import dataclasses
import warnings

import cv2
import numpy as np
import pytest

from companion import gap
from companion.flow.colour import flow_to_colour
from companion.gap import (
    CameraMotion,
    GapDetection,
    ParallaxGapConfig,
    _from_contour,
    clear_circle,
    get_detector,
    inverse_depth_from_flow,
)
from companion.gap_paper import GapDetectorConfig, detect_gap, detect_gap_in_colour
from companion.holes import _blend_level, _otsu_split, far_region
from companion.inverse_depth import estimate_translation
from tests.companion.synthetic import SMALL, FOCAL_320x240, box, iou, translation_flow

# Small frames keep these fast.  Pure lateral motion to the right, t = (1, 0, 0): g = (-f, 0) at every pixel,
# so the flow is u = -ρ·f, v = 0 and the inverse depth read back is exactly ρ everywhere (no focus of expansion).
(H, W), F = SMALL, 50.0
LATERAL = CameraMotion(translation=(1.0, 0.0, 0.0), focal_px=F)
# what the parallax detector does to the far class, switched off so that the mask is exactly the drawn region
RAW = dict(border_px=0, median_ksize=1, open_ksize=1, close_ksize=1)


def detect_gap_parallax(flow, config: ParallaxGapConfig | None = None, motion: CameraMotion | None = None):
    """The parallax detector on this module's idealised flows, where every far pixel has its true flow (none is
    hidden by the wall in the second frame): without the occlusion fill, which would add a band the flow never
    lost (the fill has its own tests in test_gap.py)."""
    return gap.detect_gap_parallax(flow, dataclasses.replace(config or ParallaxGapConfig(), occlusion_fill=None),
                                   motion or CameraMotion())


def lateral_flow(far: np.ndarray, rho_near: float = 0.5, rho_far: float = 0.25) -> np.ndarray:
    """Flow of the lateral step over a wall at inverse depth ``rho_near`` with ``far`` (H×W bool) at ``rho_far``."""
    rho = np.where(far, rho_far, rho_near)
    flow = np.zeros(far.shape + (2,), np.float32)
    flow[..., 0] = -rho * F
    return flow


def contour_of(*xy) -> np.ndarray:
    return np.array(xy, np.int32).reshape(-1, 1, 2)


# ----------------------------------------------------------------------------------------------------------
# result type, registry
# ----------------------------------------------------------------------------------------------------------

def test_area_fraction_is_area_over_the_frame():
    det = GapDetection(np.zeros((40, 50), bool), (1.0, 2.0), 500.0, None)
    assert det.found and det.area_fraction == pytest.approx(500.0 / 2000.0)
    assert GapDetection(np.zeros((0, 0), bool), None, 0.0, None).area_fraction == 0.0


def test_detectors_are_registered_by_name_and_an_unknown_name_is_refused_with_the_choices():
    assert get_detector("paper") is detect_gap and get_detector("parallax") is gap.detect_gap_parallax
    with pytest.raises(KeyError) as err:
        get_detector("canny")
    assert "unknown gap detector 'canny'; choose from ['paper', 'parallax']" in str(err.value)


# ----------------------------------------------------------------------------------------------------------
# clear circle
# ----------------------------------------------------------------------------------------------------------

def test_clear_circle_of_an_odd_slot_is_its_exact_middle():
    # 61 × 121 px: the pixel at distance 31 from the nearest outside pixel is the middle column x = 130, and the
    # plateau at 31 runs down it from y = 90 to 150; its middle is y = 120
    mask = box(100, 60, 161, 181, (240, 320))
    assert clear_circle(mask) == ((130.0, 120.0), 31.0)


def test_clear_circle_plateau_is_the_largest_distance_only():
    # a 61 px square (radius 31 at its centre (31, 30)) and a 59 px square (radius 30 at (101, 30)): the centre is
    # the big one's exact centre; counting the slightly smaller circles too would pull it towards the other square
    mask = box(1, 0, 62, 61, (61, 140)) | box(72, 1, 131, 60, (61, 140))
    assert clear_circle(mask) == ((31.0, 30.0), 31.0)


def test_clear_circle_of_one_pixel_in_the_last_row_and_column():
    # the frame's border counts as an edge all round, the last row and column included
    mask = np.zeros((7, 9), bool)
    mask[6, 8] = True
    assert clear_circle(mask) == ((8.0, 6.0), 1.0)
    mask[:] = False
    mask[3, 4] = True
    assert clear_circle(mask) == ((4.0, 3.0), 1.0)


def test_clear_circle_radius_is_the_euclidean_distance_to_the_nearest_outside_pixel():
    # a disc drawn by OpenCV; the radius is checked against a brute-force search over the outside pixels (the frame
    # border counting as outside), which an L1, L∞ or approximate metric would not match
    mask = np.zeros((31, 31), np.uint8)
    cv2.circle(mask, (15, 15), 12, 1, -1)
    padded = np.pad(mask, 1)
    oy, ox = np.nonzero(padded == 0)
    nearest = float(np.min(np.hypot(ox - 16, oy - 16)))
    centre, radius = clear_circle(mask.astype(bool))
    assert centre == (15.0, 15.0) and radius == pytest.approx(nearest, abs=1e-4)
    assert nearest not in (12.0, 13.0)             # the nearest outside pixel is off the axes


def test_clear_circle_reads_any_non_zero_value_as_inside():
    mask = np.zeros((30, 40), np.float64)
    mask[5:16, 10:31] = 0.4                         # 21 × 11 px
    assert clear_circle(mask) == ((20.0, 10.0), 6.0)


# ----------------------------------------------------------------------------------------------------------
# from a contour to a detection
# ----------------------------------------------------------------------------------------------------------

def test_detection_from_a_triangle_has_the_polygon_centroid_and_area():
    # a triangle's centroid is its vertices' mean; its area is half the cross product (not the pixel count)
    tri = contour_of((20, 20), (60, 20), (20, 30))
    det = _from_contour((60, 80), tri, "test")
    assert det.centroid == pytest.approx((100 / 3, 70 / 3), abs=1e-9)
    assert det.area == 200.0 and det.detector == "test" and det.reason is None
    assert det.contour.dtype == np.int32 and det.contour.tolist() == [[20, 20], [60, 20], [20, 30]]
    assert det.mask.dtype == bool and det.mask[25, 25] and not det.mask[29, 59]
    assert det.mask.sum() == np.count_nonzero(cv2.fillPoly(np.zeros((60, 80), np.uint8), [tri], 1))
    assert det.candidates == ()


def test_detection_from_a_half_pixel_triangle_keeps_the_polygon_centroid():
    # area 0.5 px²: still a polygon, centroid = vertex mean (5/3, 2/3), not that of its four drawn pixels (1.5, 0.5)
    det = _from_contour((10, 10), contour_of((0, 0), (2, 1), (3, 1)), "test")
    assert det.area == 0.5 and det.centroid == pytest.approx((5 / 3, 2 / 3), abs=1e-9)


def test_detection_from_a_degenerate_contour_uses_the_drawn_pixels():
    # a segment has no area: the centroid is that of its 11 drawn pixels, (15, 10); its clear circle is 1 px
    det = _from_contour((30, 40), contour_of((10, 10), (20, 10)), "test")
    assert det.found and det.area == 0.0 and det.centroid == (15.0, 10.0)
    assert det.mask.sum() == 11 and det.clear_centre == (15.0, 10.0) and det.clear_radius_px == 1.0
    vertical = _from_contour((30, 40), contour_of((5, 2), (5, 12)), "test")
    assert vertical.centroid == (5.0, 7.0)


def test_detection_from_a_contour_outside_the_frame_falls_back_to_the_centroid_for_its_centre():
    # nothing of it is drawn, so there is no clear circle: the centre to aim at is the polygon's centroid
    det = _from_contour((20, 20), contour_of((30, 30), (40, 30), (40, 44), (30, 44)), "test")
    assert not det.mask.any() and det.centroid == (35.0, 37.0)
    assert det.clear_centre == (35.0, 37.0) and det.clear_radius_px == 0.0


def test_detection_aims_at_the_clear_centre_not_the_centroid():
    # a right triangle: its centroid (vertex mean) is not the centre of its inscribed circle
    det = _from_contour((100, 100), contour_of((10, 10), (90, 10), (10, 90)), "test")
    assert det.centroid == pytest.approx((110 / 3, 110 / 3))
    # inscribed circle of legs a = b = 80: r = (a + b - c)/2 = 80 - 40√2 ≈ 23.4, centre (10 + r, 10 + r)
    r = 80 - 40 * np.sqrt(2)
    assert det.clear_radius_px == pytest.approx(r + 1, abs=1.0)       # distances to the first pixel outside
    assert det.clear_centre == pytest.approx((10 + r, 10 + r), abs=1.5)


# ----------------------------------------------------------------------------------------------------------
# the paper's (colour) detector
# ----------------------------------------------------------------------------------------------------------

def white(h=64, w=64) -> np.ndarray:
    return np.full((h, w, 3), 255, np.uint8)


@pytest.mark.parametrize("bad", [
    np.zeros((20, 20), np.uint8),               # grey, not colour
    np.zeros((20, 20, 4), np.uint8),            # BGRA
    np.zeros((20, 20, 3), np.float32),          # float colours
])
def test_colour_detector_refuses_anything_but_an_8_bit_three_channel_image(bad):
    with pytest.raises(ValueError, match="expected an H×W×3 uint8 BGR image, got"):
        detect_gap_in_colour(bad)


def test_colour_detector_names_itself_and_says_when_there_are_no_edges():
    res = detect_gap_in_colour(white())
    assert not res.found and res.reason == "no contours in the edge map" and res.detector == "paper"
    assert res.mask.dtype == bool and res.mask.shape == (64, 64) and not res.mask.any()
    assert res.clear_centre is None and res.clear_radius_px == 0.0 and res.contour is None
    img = white()
    img[20:34, 20:34] = 0
    found = detect_gap_in_colour(img)
    assert found.found and found.detector == "paper"
    assert detect_gap_in_colour(img, detector="mine").detector == "mine"


def test_colour_detector_says_which_area_bounds_no_contour_met():
    img = white(100, 100)
    img[40:50, 40:50] = 0
    res = detect_gap_in_colour(img, GapDetectorConfig(area_min_frac=0.05))
    assert res.reason == "no contour with 500 <= area <= 9000 px² (1 contours)" and res.detector == "paper"


def test_colour_detector_area_bounds_are_inclusive():
    # 64 × 64 = 4096 px, so a bound of A/4096 of the frame is exactly A px²
    img = white()
    img[20:34, 20:34] = 0
    area = detect_gap_in_colour(img).area
    hw = 64 * 64
    assert detect_gap_in_colour(img, GapDetectorConfig(area_min_frac=area / hw)).area == area
    assert detect_gap_in_colour(img, GapDetectorConfig(area_max_frac=area / hw)).area == area
    assert not detect_gap_in_colour(img, GapDetectorConfig(area_min_frac=(area + 1) / hw)).found


@pytest.mark.parametrize("big_first", [True, False])
def test_colour_detector_takes_the_largest_contour_wherever_it_is(big_first):
    # contours come out in an order set by their place in the image: try the big square bottom-right and top-left
    img = white()
    img[8:18, 8:18] = 0                             # 10 px square
    img[30:56, 30:56] = 0                           # 26 px square
    if not big_first:
        img = img[::-1, ::-1].copy()
    res = detect_gap_in_colour(img)
    cx, cy = (42.5, 42.5) if big_first else (63 - 42.5, 63 - 42.5)
    assert res.centroid == pytest.approx((cx, cy), abs=1.0) and res.area > 400


def test_colour_detector_takes_one_of_two_equal_contours():
    img = white()
    img[10:24, 10:24] = 0
    img[40:54, 40:54] = 0                           # the same square, far apart: two equal contours
    res = detect_gap_in_colour(img)
    assert res.found and res.centroid in (pytest.approx((16.5, 16.5), abs=1.0), pytest.approx((46.5, 46.5), abs=1.0))


def two_squares_5px_apart() -> np.ndarray:
    img = white()
    img[20:34, 10:24] = 0
    img[20:34, 29:43] = 0                           # 14 px squares, 5 px of white between them
    return img


def test_colour_detector_closing_bridges_small_gaps_with_three_iterations():
    # three closings with a 3×3 square grow each edge map by 3 px before shrinking it back: a 5 px gap is bridged
    # and the two squares read as one opening; one iteration (or a 1×1 element) leaves two separate squares
    merged = detect_gap_in_colour(two_squares_5px_apart())
    assert merged.area > 2 * 13 * 13 and merged.centroid == pytest.approx((26.0, 26.5), abs=1.0)
    for cfg in (GapDetectorConfig(close_iterations=1), GapDetectorConfig(close_ksize=1)):
        single = detect_gap_in_colour(two_squares_5px_apart(), cfg)
        assert single.area < 14 * 14
        assert single.centroid == pytest.approx((16.5, 26.5), abs=1.0) or \
            single.centroid == pytest.approx((35.5, 26.5), abs=1.0)


def test_paper_detector_passes_its_config_on_and_names_itself():
    flow, _ = translation_flow(120, 160, (0.0, 0.0, 1.0), [(65, 45), (100, 47), (97, 80), (62, 75)],
                               focal=FOCAL_320x240 / 2)
    assert detect_gap(flow).found and detect_gap(flow).detector == "paper"
    strict = detect_gap(flow, GapDetectorConfig(area_min_frac=0.5))
    assert not strict.found and strict.detector == "paper" and "area" in strict.reason


def test_paper_detector_colours_in_bgr():
    # flows of equal length at 195° and 95°: their wheel colours differ a lot in BGR grey and hardly at all when
    # the RGB image is read as BGR.  The square must be found from the BGR image.
    flow = np.zeros((64, 64, 2), np.float32)
    a, b = np.radians(195.0), np.radians(95.0)
    flow[...] = (np.cos(a), np.sin(a))
    flow[20:40, 20:40] = (np.cos(b), np.sin(b))
    grey = cv2.cvtColor(flow_to_colour(flow, bgr=True), cv2.COLOR_BGR2GRAY).astype(int)
    grey_swapped = cv2.cvtColor(flow_to_colour(flow, bgr=False), cv2.COLOR_BGR2GRAY).astype(int)
    assert abs(grey[30, 30] - grey[5, 5]) > 60 and abs(grey_swapped[30, 30] - grey_swapped[5, 5]) < 5
    res = detect_gap(flow)
    assert res.found and res.centroid == pytest.approx((29.5, 29.5), abs=1.0)


# ----------------------------------------------------------------------------------------------------------
# Otsu split and the far-region descent
# ----------------------------------------------------------------------------------------------------------

def test_otsu_split_of_two_levels_is_perfectly_separable():
    values = np.array([10] * 30 + [200] * 70, np.uint8)
    t, eta = _otsu_split(values)
    assert 10 <= t < 200 and eta == pytest.approx(1.0)
    t, eta = _otsu_split(np.array([0] * 50 + [1] * 50, np.uint8))     # a variance of only 0.25
    assert t == 0 and eta == pytest.approx(1.0)


def test_otsu_split_separability_is_between_over_total_variance():
    # levels 0 (20 %), 100 (30 %), 200 (50 %): the best split is {0, 100} | {200}
    # (w0·w1·(μ0 - μ1)² = 0.5·0.5·140² = 4900 against 0.2·0.8·162.5² = 4225), total variance 6100
    values = np.array([0] * 20 + [100] * 30 + [200] * 50, np.uint8)
    t, eta = _otsu_split(values)
    assert 100 <= t < 200 and eta == pytest.approx(4900 / 6100, rel=1e-9)
    # uneven two-level weights do not matter: still perfectly separable
    assert _otsu_split(np.array([3] * 9 + [7] * 91, np.uint8))[1] == pytest.approx(1.0)


def test_otsu_split_of_a_constant_is_not_separable():
    assert _otsu_split(np.full(50, 7, np.uint8))[1] == 0.0


def far_config(**kw) -> ParallaxGapConfig:
    return ParallaxGapConfig(area_min_frac=1 / 512, **kw)      # 8 px of a 64 × 64 image


def levels(*regions) -> np.ndarray:
    """64 × 64 8-bit image: a list of (value, mask) painted in order over 255."""
    img = np.full((64, 64), 255, np.uint8)
    for value, mask in regions:
        img[mask] = value
    return img


def test_far_region_reports_the_best_weak_split_when_none_is_significant():
    # two levels 10 apart at 0.01 per level: an inverse-depth ratio of e^0.1 = 1.105 (< 1.25), perfectly separable
    img = levels((245, box(10, 10, 30, 30, (64, 64))))
    far, reason = far_region(img, 0.01, far_config())
    assert far is None
    assert reason == "no depth contrast (best split: inverse-depth ratio 1.11, separability 1.00)"


def test_far_region_reports_the_strongest_of_several_weak_splits():
    # levels 0 (20 %), 100 (30 %), 200 (50 %) at 0.002 per level: the first split ({0, 100} | {200}) has the ratio
    # e^0.2 = 1.22 and separability 4900/6100 = 0.80; the second ({0} | {100}) e^0.2 again but separability 1.
    # Neither reaches 1.25; the second's product is the larger.
    img = np.array([0] * 820 + [100] * 1228 + [200] * 2048, np.uint8).reshape(64, 64)
    far, reason = far_region(img, 0.002, far_config())
    assert far is None and reason == "no depth contrast (best split: inverse-depth ratio 1.22, separability 1.00)"
    # 0 (30 %), 30 (20 %), 200 (50 %) at 0.001 per level: the first split ({0, 30} | {200}, medians 0 and 200) has
    # the ratio e^0.2 and separability w0·w1·(μ0 - 200)²/σ² ≈ 0.99, the second ({0} | {30}) only e^0.03 (and 1):
    # the first, stronger one is reported, not the last
    img = np.array([0] * 1228 + [30] * 820 + [200] * 2048, np.uint8).reshape(64, 64)
    far, reason = far_region(img, 0.001, far_config())
    mu0 = 30 * 820 / 2048
    eta1 = 0.5 * 0.5 * (mu0 - 200) ** 2 / np.var(img.astype(float))
    assert far is None and reason == f"no depth contrast (best split: inverse-depth ratio {np.exp(0.2):.2f}, " \
                                     f"separability {eta1:.2f})"
    assert f"{eta1:.2f}" == "0.99"


def test_far_region_of_a_constant_image_has_no_split_at_all():
    far, reason = far_region(np.full((64, 64), 90, np.uint8), 0.01, far_config())
    assert far is None and reason == "no depth contrast (best split: inverse-depth ratio 0.00, separability 0.00)"


def test_far_region_is_the_far_class_of_a_significant_split():
    gap = box(10, 10, 30, 30, (64, 64))
    far, _ = far_region(levels((0, gap)), 0.01, far_config())      # ratio e^2.55
    assert far is not None and np.array_equal(far, gap)


def test_far_region_thresholds_are_inclusive():
    # two equal halves 10 levels apart at 0.01: ratio exactly np.exp(0.1), separability exactly 1
    img = levels((245, box(0, 0, 64, 32, (64, 64))))
    ratio = float(np.exp((255.0 - 245.0) * 0.01))
    far, _ = far_region(img, 0.01, far_config(min_contrast=ratio, min_separability=1.0))
    assert far is not None and np.array_equal(far, box(0, 0, 64, 32, (64, 64)))
    far, reason = far_region(img, 0.01, far_config(min_contrast=ratio * (1 + 1e-9)))
    assert far is None and "ratio 1.11" in reason


def test_far_region_needs_both_contrast_and_separability():
    # ratio 1.105, separability 1: enough contrast for a minimum of 1.05 but not separable enough for 1.01, and
    # separable enough for 0.6 but not contrasted enough for 1.2
    img = levels((245, box(0, 0, 64, 32, (64, 64))))
    assert far_region(img, 0.01, far_config(min_contrast=1.05, min_separability=1.01))[0] is None
    assert far_region(img, 0.01, far_config(min_contrast=1.2, min_separability=0.6))[0] is None
    assert far_region(img, 0.01, far_config(min_contrast=1.05, min_separability=0.6))[0] is not None


def test_far_region_keeps_the_nearer_of_two_equally_sharp_steps():
    # 200 (50 %), 100 (30 %), 0 (20 %): both splits are steps of 100 levels (medians 200|100, then 100|0), equally
    # sharp, so the first, nearer one stands and the far region is everything below the wall
    img = np.array([0] * 820 + [100] * 1228 + [200] * 2048, np.uint8).reshape(64, 64)
    far, _ = far_region(img, 0.01, far_config())
    assert far is not None and np.array_equal(far, img < 200)


def test_far_region_takes_the_sharper_of_two_steps():
    # 255 (50 %), 215 (30 %), 0 (20 %): the second step (215 -> 0) is the sharper
    img = np.array([0] * 820 + [215] * 1228 + [255] * 2048, np.uint8).reshape(64, 64)
    far, _ = far_region(img, 0.01, far_config())
    assert far is not None and np.array_equal(far, img == 0)


def test_far_region_stops_at_a_class_smaller_than_the_minimum_area():
    # a gap (level 200 under the wall's 255) with a speck of 8 px (level 0) in it.  At a minimum of 8 px the speck
    # is a class of its own, and its step (200 levels) is sharper than the gap's (55); at 9 px the descent stops
    # at the gap.
    gap = box(10, 10, 40, 40, (64, 64))
    speck = box(20, 20, 24, 22, (64, 64))
    img = levels((200, gap), (0, speck))
    far, _ = far_region(img, 0.02, ParallaxGapConfig(area_min_frac=8 / 4096))
    assert np.array_equal(far, speck)
    far, _ = far_region(img, 0.02, ParallaxGapConfig(area_min_frac=9 / 4096))
    assert np.array_equal(far, gap)


def test_far_region_weighs_weak_splits_by_contrast_times_separability():
    # wall 255 (50 %); beyond it 100 (40 %) with 90 and 110 (5 % each) at 0.001 per level.  First split:
    # {90, 100, 110} | {255}, ratio e^0.155 = 1.17, separability ≈ 1.  Second: {90} | {100, 110}, ratio e^0.01 and
    # separability ≈ 0.56 (computed below from its definition): a product far smaller, so the first is reported
    img = np.array([90] * 205 + [100] * 1638 + [110] * 205 + [255] * 2048, np.uint8).reshape(64, 64)
    rest = img[img < 255].astype(float)
    low = rest <= 90
    w0 = low.mean()
    eta2 = w0 * (1 - w0) * (rest[low].mean() - rest[~low].mean()) ** 2 / rest.var()
    assert 0.5 < eta2 < 0.6
    far, reason = far_region(img, 0.001, far_config())
    assert far is None and reason == "no depth contrast (best split: inverse-depth ratio 1.17, separability 1.00)"


def test_far_region_without_a_minimum_area_takes_no_statistics_of_empty_classes():
    img = levels((100, box(10, 10, 30, 30, (64, 64))))
    with warnings.catch_warnings():
        warnings.simplefilter("error")              # a mean or median of an empty class warns
        far, _ = far_region(img, 0.01, ParallaxGapConfig(area_min_frac=0.0))
    assert np.array_equal(far, box(10, 10, 30, 30, (64, 64)))


# ----------------------------------------------------------------------------------------------------------
# translation and inverse depth
# ----------------------------------------------------------------------------------------------------------

SMALL_QUAD = [(60, 40), (100, 45), (97, 80), (55, 75)]


@pytest.mark.parametrize("t", [
    (1.0, 0.0, 0.0), (-1.0, 0.0, 0.0),          # sideways: g has no x' or y' term, the flow is uniform per depth
    (0.0, 1.0, 0.0), (0.0, -1.0, 0.0),
    (0.0, 0.0, 1.0), (0.0, 0.0, -1.0),          # forwards and backwards: expansion and contraction
    (0.3, -0.1, 1.0), (-0.3, 0.1, -1.0),
])
def test_translation_direction_and_sign_are_recovered(t):
    flow, _ = translation_flow(120, 160, t, SMALL_QUAD, focal=FOCAL_320x240 / 2)
    est = estimate_translation(flow, FOCAL_320x240 / 2, (79.5, 59.5))
    np.testing.assert_allclose(est, np.asarray(t) / np.linalg.norm(t), atol=1e-6)


def test_translation_is_recovered_from_a_tiny_flow():
    # 0.002 px of flow: the sign must come from the direction of the flow, whatever its size
    for t in ((0.3, -0.1, 1.0), (-0.3, 0.1, -1.0), (0.0, 1.0, 0.0)):
        flow, _ = translation_flow(120, 160, t, SMALL_QUAD, focal=FOCAL_320x240 / 2, scale=0.0001)
        est = estimate_translation(flow, FOCAL_320x240 / 2, (79.5, 59.5))
        np.testing.assert_allclose(est, np.asarray(t) / np.linalg.norm(t), atol=1e-6)


def test_translation_ignores_pixels_with_any_non_finite_component():
    flow, _ = translation_flow(120, 160, (0.3, -0.1, 1.0), SMALL_QUAD, focal=FOCAL_320x240 / 2)
    flow[::3, ::4, 0] = np.nan                     # u unknown, v known
    flow[1::5, ::2, 1] = np.inf
    est = estimate_translation(flow, FOCAL_320x240 / 2, (79.5, 59.5))
    np.testing.assert_allclose(est, np.array([0.3, -0.1, 1.0]) / np.linalg.norm((0.3, -0.1, 1.0)), atol=1e-6)


def test_translation_survives_a_flow_of_exactly_one_micro_pixel():
    # the direction normalisation adds 1e-6 px to |flow|: a vector of exactly 1e-6 px must not divide by zero
    flow, _ = translation_flow(120, 160, (0.3, -0.1, 1.0), SMALL_QUAD, focal=FOCAL_320x240 / 2)
    flow = flow.astype(np.float64)
    flow[50, 20] = (1e-6, 0.0)
    est = estimate_translation(flow, FOCAL_320x240 / 2, (79.5, 59.5))
    np.testing.assert_allclose(est, np.array([0.3, -0.1, 1.0]) / np.linalg.norm((0.3, -0.1, 1.0)), atol=1e-3)


def test_translation_down_weights_outliers():
    # 10 % of the pixels carry large random flow; an unweighted least squares is pulled far off by them
    t_true = np.array([0.3, -0.1, 1.0]) / np.linalg.norm((0.3, -0.1, 1.0))
    flow, _ = translation_flow(120, 160, tuple(t_true), SMALL_QUAD, focal=FOCAL_320x240 / 2)
    rng = np.random.default_rng(3)
    bad = rng.random((120, 160)) < 0.10
    flow[bad] = rng.normal(0.0, 20.0, (bad.sum(), 2)).astype(np.float32)
    est = estimate_translation(flow, FOCAL_320x240 / 2, (79.5, 59.5))
    plain = estimate_translation(flow, FOCAL_320x240 / 2, (79.5, 59.5), iterations=1)
    # the inliers are exact: three reweightings converge on them (to 1e-6), a single unweighted pass does not
    np.testing.assert_allclose(est, t_true, atol=1e-6)
    assert np.linalg.norm(plain - t_true) > 1e-3


def test_translation_samples_every_second_pixel_by_default():
    # even rows and columns carry a forward motion, the others a sideways one: the default stride of 2 sees only
    # the former; a stride of 3 sees both
    fwd, _ = translation_flow(120, 160, (0.0, 0.0, 1.0), SMALL_QUAD, focal=FOCAL_320x240 / 2)
    side, _ = translation_flow(120, 160, (1.0, 0.0, 0.0), SMALL_QUAD, focal=FOCAL_320x240 / 2)
    flow = side.copy()
    flow[::2, ::2] = fwd[::2, ::2]
    np.testing.assert_allclose(estimate_translation(flow, FOCAL_320x240 / 2, (79.5, 59.5)), (0, 0, 1), atol=1e-6)
    assert estimate_translation(flow, FOCAL_320x240 / 2, (79.5, 59.5), stride=3)[2] < 0.9


def test_translation_without_iterations_is_the_optical_axis():
    flow, _ = translation_flow(120, 160, (1.0, 0.0, 0.0), SMALL_QUAD, focal=FOCAL_320x240 / 2)
    np.testing.assert_array_equal(estimate_translation(flow, FOCAL_320x240 / 2, (79.5, 59.5), iterations=0),
                                  (0.0, 0.0, 1.0))


def test_inverse_depth_uses_the_default_camera_of_the_frame_size():
    # no focal length or principal point given: f from the vertical FOV and the frame height, centred principal
    # point.  A 120 × 160 frame with a 60° FOV has f = 60/tan 30° ≈ 103.9; moving forward and sideways, ρ read
    # back is the true ρ times |t| at every measurable pixel.
    f = 60.0 / np.tan(np.radians(30.0))
    t = (0.4, -0.3, 1.0)
    flow, truth = translation_flow(120, 160, t, SMALL_QUAD, focal=f, rho_near=0.5, rho_far=0.05, scale=1.0)
    cfg = ParallaxGapConfig(vfov_deg=60.0)
    rho, valid = inverse_depth_from_flow(flow, CameraMotion(translation=t), cfg)
    expected = np.where(truth, 0.05, 0.5) * np.linalg.norm(t)
    assert valid.mean() > 0.9
    np.testing.assert_allclose(rho[valid], expected[valid], rtol=1e-5)


def test_inverse_depth_depends_only_on_the_direction_of_the_given_translation():
    f = 100.0
    flow, truth = translation_flow(60, 80, (0.6, 0.0, 0.8), [(30, 20), (50, 20), (50, 40), (30, 40)], focal=f,
                                   rho_near=0.5, rho_far=0.1, scale=1.0)
    for t in ((0.6, 0.0, 0.8), (3.0, 0.0, 4.0), (0.06, 0.0, 0.08)):
        rho, valid = inverse_depth_from_flow(flow, CameraMotion(translation=t, focal_px=f))
        np.testing.assert_allclose(rho[valid], np.where(truth, 0.1, 0.5)[valid], rtol=1e-5)


def test_inverse_depth_is_exact_right_next_to_the_focus_of_expansion():
    # forward motion, principal point between pixels: the four pixels round it are √0.5 px from the FoE (|g|² =
    # 0.5 < 1) and, with a low enough min_g_frac, measurable; ρ read there is still the true ρ
    f = 100.0
    flow, _ = translation_flow(60, 80, (0.0, 0.0, 1.0), [(0, 0), (1, 0), (1, 1)], focal=f, rho_near=0.5,
                               scale=1.0)
    rho, valid = inverse_depth_from_flow(flow, CameraMotion(translation=(0, 0, 1), focal_px=f),
                                         ParallaxGapConfig(min_g_frac=0.001))
    assert valid[29:31, 39:41].all()
    np.testing.assert_allclose(rho[29:31, 39:41], 0.5, rtol=1e-6)


def test_inverse_depth_is_unmeasurable_near_the_focus_of_expansion_and_where_flow_is_not_finite():
    # principal point (0, 0), forward motion: |g| = distance to the corner pixel.  In a 9 × 7 frame the largest
    # |g|² is 8² + 6² = 100; with min_g_frac = 0.5 a pixel is measurable when x² + y² >= 25, the limit included.
    flow = np.ones((7, 9, 2), np.float32)
    flow[6, 8, 1] = np.nan                          # the farthest pixel has no flow: it is not measured either
    flow[0, 8, 0] = np.inf
    rho, valid = inverse_depth_from_flow(flow, CameraMotion(translation=(0, 0, 1), focal_px=10.0,
                                                            principal_point=(0.0, 0.0)),
                                         ParallaxGapConfig(min_g_frac=0.5))
    ys, xs = np.mgrid[0:7, 0:9]
    expected = xs ** 2 + ys ** 2 >= 25
    expected[6, 8] = expected[0, 8] = False
    np.testing.assert_array_equal(valid, expected)
    assert valid[0, 5] and valid[4, 3] and valid[3, 4] and not valid[4, 2]
    assert np.isnan(rho[~valid]).all() and np.isfinite(rho[valid]).all()
    assert rho[4, 3] == pytest.approx((3 + 4) / 25.0)


# ----------------------------------------------------------------------------------------------------------
# the parallax detector, step by step
# ----------------------------------------------------------------------------------------------------------

def test_parallax_detector_finds_a_gap_under_pure_sideways_motion():
    # v = 0 everywhere: the flow's size is all in u
    far = box(30, 20, 50, 40)
    res = detect_gap_parallax(lateral_flow(far), motion=LATERAL)
    assert res.found and res.detector == "parallax" and iou(res.mask, far) > 0.9
    assert len(res.candidates) == 1 and res.candidates[0].centroid == res.centroid
    assert res.centroid == pytest.approx((39.5, 29.5), abs=0.1)
    # the outline is simplified to within half a pixel: a handful of vertices, not every boundary pixel
    assert len(res.contour) <= 12


def test_parallax_detector_refuses_a_flow_too_small_to_measure():
    far = box(30, 20, 50, 40)
    flow = lateral_flow(far) * 0.003                 # |u| = 0.075 px on the wall: the median is 0.075 ≥ 0.05 ...
    assert detect_gap_parallax(flow, motion=LATERAL).found
    small = detect_gap_parallax(flow, ParallaxGapConfig(min_flow_px=0.08), motion=LATERAL)   # ... < 0.08
    assert small.reason == "flow too small to measure parallax" and small.detector == "parallax"
    assert small.mask.shape == (H, W) and small.mask.dtype == bool and not small.mask.any()
    nothing = detect_gap_parallax(np.full((H, W, 2), np.nan, np.float32))
    assert nothing.reason == "flow too small to measure parallax" and not nothing.mask.any()


def test_parallax_detector_measures_a_flow_exactly_at_the_minimum():
    # wall |u| = 0.0625 px (most of the frame, so the median), gap 0.03125: a minimum of exactly 0.0625 is met
    flow = lateral_flow(box(30, 20, 50, 40), rho_near=0.0625 / F, rho_far=0.03125 / F)
    assert float(np.median(np.hypot(flow[..., 0], flow[..., 1]))) == 0.0625
    assert detect_gap_parallax(flow, ParallaxGapConfig(min_flow_px=0.0625), motion=LATERAL).found


def test_parallax_detector_refuses_when_too_few_pixels_are_measurable():
    far = box(30, 20, 50, 40)
    flow = lateral_flow(far)
    res = detect_gap_parallax(flow, ParallaxGapConfig(border_px=25), motion=LATERAL)   # 10 × 30 px left
    assert res.reason == "too few pixels away from the focus of expansion" and res.detector == "parallax"
    assert res.mask.shape == (H, W) and not res.mask.any()
    # the same with most of the flow unknown
    flow[:, 17:] = np.nan
    assert detect_gap_parallax(flow, motion=LATERAL).reason == "too few pixels away from the focus of expansion"
    # and with a min_g_frac that leaves only the frame's corners (forward motion)
    fwd, _ = translation_flow(H, W, (0.0, 0.0, 1.0), [(30, 20), (50, 20), (50, 40), (30, 40)], focal=F)
    assert detect_gap_parallax(fwd, ParallaxGapConfig(min_g_frac=0.9)).reason == \
        "too few pixels away from the focus of expansion"


def test_parallax_detector_works_with_exactly_a_fifth_of_the_frame_measurable():
    # 60 × 80 = 4800 px; 960 measurable (columns 0-15 of every row) is the minimum, 0.2·H·W, and is enough
    far = np.zeros((H, W), bool)
    far[20:40, 4:12] = True
    flow = lateral_flow(far)
    flow[:, 16:] = np.nan
    res = detect_gap_parallax(flow, ParallaxGapConfig(border_px=0), motion=LATERAL)
    assert res.reason != "too few pixels away from the focus of expansion"
    flow[0, 15] = np.nan                            # 959
    assert detect_gap_parallax(flow, ParallaxGapConfig(border_px=0), motion=LATERAL).reason == \
        "too few pixels away from the focus of expansion"


def test_parallax_detector_refuses_mostly_negative_inverse_depth():
    # the camera said to move right while the scene moves right too: ρ < 0 almost everywhere
    res = detect_gap_parallax(-lateral_flow(box(30, 20, 50, 40)), motion=LATERAL)
    assert res.reason == "inverse depth mostly negative (motion not translation-like)"
    assert res.detector == "parallax" and res.mask.shape == (H, W) and not res.mask.any()


def test_parallax_detector_accepts_exactly_half_positive_inverse_depth():
    # left half: a wall with a gap; right half: negative (inpainted from the left). Half positive is enough.
    far = box(10, 20, 30, 40)
    flow = lateral_flow(far)
    flow[:, 40:] *= -1
    res = detect_gap_parallax(flow, ParallaxGapConfig(border_px=0), motion=LATERAL)
    assert res.found and iou(res.mask, far) > 0.8
    flow[0, 39] *= -1                               # one less than half
    assert detect_gap_parallax(flow, ParallaxGapConfig(border_px=0), motion=LATERAL).reason == \
        "inverse depth mostly negative (motion not translation-like)"


def test_parallax_detector_does_not_read_zero_flow_as_infinitely_far():
    # specks of exactly zero flow (ρ = 0: no measurement, e.g. textureless) scattered on the wall are filled in from
    # their neighbours; read as log 0 = -inf they would wreck the depth scale
    far = box(30, 20, 50, 40)
    flow = lateral_flow(far)
    for y in range(10, 55, 9):
        for x in range(5, 75, 11):
            if not far[y, x]:
                flow[y, x] = 0.0
    res = detect_gap_parallax(flow, motion=LATERAL)
    assert res.found and iou(res.mask, far) > 0.9


def test_parallax_detector_ignores_the_untrusted_border():
    # a wall with no opening, but the flow within 6 px of each frame edge reads far: border flow is not trusted, so
    # there is nothing but the wall
    for edge in (box(0, 0, W, 6), box(0, H - 6, W, H), box(0, 0, 6, H), box(W - 6, 0, W, H)):
        res = detect_gap_parallax(lateral_flow(edge), motion=LATERAL)
        assert res.reason == "no depth contrast (best split: inverse-depth ratio 0.00, separability 0.00)", edge
    # with border_px = 0 the whole frame is used: a far band along the top is seen, and is no opening
    res = detect_gap_parallax(lateral_flow(box(0, 0, W, 6)), ParallaxGapConfig(border_px=0), motion=LATERAL)
    assert "enclosed by a nearer surface" in res.reason
    res = detect_gap_parallax(lateral_flow(box(30, 20, 50, 40)), ParallaxGapConfig(border_px=0), motion=LATERAL)
    assert res.found


def test_parallax_detector_untrusted_border_of_one_pixel():
    # a 1 px frame of very far flow (ρ = 0.01) round a wall with a gap (ρ 0.5 and 0.25): with border_px = 1 it is
    # ignored and the gap found; read, the frame is the sharpest depth step but no hole in anything: no opening,
    # unless every step is tried with the edge at the blend's midpoint, unbounded (the frame's far side then takes
    # in the gap, a quarter of the wall's ρ), when the gap is found after it, or the frame is set aside as what
    # lies past the wall's end (past_the_end, off by default)
    far = box(30, 20, 50, 40)
    frame = ~box(1, 1, W - 1, H - 1)
    flow = lateral_flow(far)
    flow[frame] = lateral_flow(frame, rho_far=0.01)[frame]
    res = detect_gap_parallax(flow, ParallaxGapConfig(border_px=1), motion=LATERAL)
    assert res.found and iou(res.mask, far) > 0.9
    img = np.where(frame, 0, np.where(far, 120, 200)).astype(np.uint8)
    assert far_region(img, np.log(50.0) / 200, far_config())[0][0, 0]        # the frame's step is the sharpest
    assert not detect_gap_parallax(flow, ParallaxGapConfig(border_px=0, past_the_end=False), motion=LATERAL).found
    res = detect_gap_parallax(flow, ParallaxGapConfig(border_px=0, every_step=True, edge_blend=0.5,
                                                    edge_blend_reach_px=None, past_the_end=False), motion=LATERAL)
    assert res.found and iou(res.mask, far) > 0.9
    res = detect_gap_parallax(flow, ParallaxGapConfig(border_px=0, past_the_end=True), motion=LATERAL)
    assert res.found and iou(res.mask, far) > 0.9


def test_parallax_detector_contrast_is_read_on_the_true_log_scale():
    # a gap at half the wall's inverse depth (ratio 2; the log scale spans exactly ln 2 over 255 levels):
    # found with a minimum contrast just below 2, not with one just above
    far = box(30, 20, 50, 40)
    cfg = dict(border_px=0)
    assert detect_gap_parallax(lateral_flow(far), ParallaxGapConfig(min_contrast=1.997, **cfg), motion=LATERAL).found
    res = detect_gap_parallax(lateral_flow(far), ParallaxGapConfig(min_contrast=2.003, **cfg), motion=LATERAL)
    assert res.reason == "no depth contrast (best split: inverse-depth ratio 2.00, separability 1.00)"
    # the same for a ratio of 1.3 (a log span well under 1)
    near = lateral_flow(far, rho_near=0.5, rho_far=0.5 / 1.3)
    assert detect_gap_parallax(near, ParallaxGapConfig(min_contrast=1.298, **cfg), motion=LATERAL).found
    # and a ratio of 1.1 is no opening
    weak = detect_gap_parallax(lateral_flow(far, rho_far=0.5 / 1.1), motion=LATERAL)
    assert weak.reason == "no depth contrast (best split: inverse-depth ratio 1.10, separability 1.00)"


def test_parallax_detector_passes_its_config_to_inverse_depth():
    # the configured vertical FOV (150°) is the camera's: f = 30/tan 75° ≈ 8 px for a 60 px frame
    fwd, truth = translation_flow(H, W, (0.3, 0.0, 1.0), [(30, 20), (50, 20), (50, 40), (30, 40)],
                                  focal=30.0 / np.tan(np.radians(75.0)))
    cfg = ParallaxGapConfig(vfov_deg=150.0)
    res = detect_gap_parallax(fwd, cfg, CameraMotion(translation=(0.3, 0.0, 1.0)))
    assert res.found and iou(res.mask, truth) > 0.9


def test_parallax_detector_tails_beyond_the_robust_range_are_clipped():
    # 72 px of a 160 × 120 frame are a little farther than the gap and 72 px a little nearer than the wall: each
    # 0.375 %, beyond the 0.5-99.5 percentile range that sets the 8-bit scale, so they clip to its ends (the far
    # speck reads as the gap's level and is a second opening, the near one reads as wall) instead of wrapping round
    h, w = 120, 160
    motion = CameraMotion(translation=(1.0, 0.0, 0.0), focal_px=F)
    gap = box(60, 40, 100, 80, (h, w))
    rho = np.where(gap, 0.25, 0.5)
    very_far = box(10, 10, 19, 18, (h, w))          # 72 px: clipped to the gap's level, a second far region
    very_near = box(130, 90, 139, 98, (h, w))       # 72 px: clipped to the wall's level, nothing
    rho = np.where(very_far, 0.25 / 1.05, np.where(very_near, 0.5 * 1.05, rho))
    flow = np.zeros((h, w, 2), np.float32)
    flow[..., 0] = -rho * F
    res = detect_gap_parallax(flow, ParallaxGapConfig(border_px=0), motion=motion)
    assert res.found and iou(res.mask, gap) > 0.9
    assert len(res.candidates) == 2 and iou(res.candidates[1].mask, very_far) > 0.6


def test_parallax_detector_says_which_area_bounds_no_far_region_met():
    # 20 × 12 = 240 px: a far class big enough to be split off (240 px at 0.05 of the frame), but its outline
    # encloses only 19 × 11 = 209 px²
    far = box(30, 20, 50, 32)
    res = detect_gap_parallax(lateral_flow(far), ParallaxGapConfig(**RAW, area_min_frac=0.05), motion=LATERAL)
    assert res.reason == "no far region with 240 <= area <= 4320 px² enclosed by a nearer surface"
    assert res.detector == "parallax" and not res.mask.any()


def test_parallax_detector_area_bounds_are_inclusive():
    # 64 × 128 = 8192 px; the raw far mask is the drawn rectangle, whose contour area is (20-1)·(10-1) = 171 px²
    h, w = 64, 128
    far = box(40, 20, 60, 30, (h, w))
    flow = np.zeros((h, w, 2), np.float32)
    flow[..., 0] = -np.where(far, 0.25, 0.5) * F
    for bound in ("area_min_frac", "area_max_frac"):
        res = detect_gap_parallax(flow, ParallaxGapConfig(**RAW, **{bound: 171 / (h * w)}), motion=LATERAL)
        assert res.found and res.area == 171.0
    assert not detect_gap_parallax(flow, ParallaxGapConfig(**RAW, area_min_frac=172 / (h * w)), motion=LATERAL).found


def test_parallax_detector_skips_small_regions_and_keeps_looking():
    # specks of 6 × 6 px above and below a gap: too small for a minimum of 100 px; the gap is still found
    far = box(30, 22, 50, 38) | box(37, 5, 43, 11) | box(37, 49, 43, 55)
    res = detect_gap_parallax(lateral_flow(far), ParallaxGapConfig(**RAW, area_min_frac=100 / (H * W)),
                              motion=LATERAL)
    assert res.found and np.array_equal(res.mask, box(30, 22, 50, 38)) and len(res.candidates) == 1


def test_parallax_detector_skips_border_regions_and_keeps_looking():
    # bands along the top and bottom edges (more than 40 % of their outline on the border) and a gap between them
    far = box(20, 0, 60, 5) | box(20, H - 5, 60, H) | box(30, 22, 50, 38)
    res = detect_gap_parallax(lateral_flow(far), ParallaxGapConfig(**RAW), motion=LATERAL)
    assert res.found and np.array_equal(res.mask, box(30, 22, 50, 38)) and len(res.candidates) == 1


@pytest.mark.parametrize("x0, y0", [(0, 25), (0, 0), (70, 25), (70, 50), (35, 0), (35, 50), (0, 50), (70, 0)])
def test_a_small_region_on_the_frame_edge_is_no_opening(x0, y0):
    # a 10 × 10 px far square touching the frame's edge (< 2 % of the frame) is refused ...
    far = box(x0, y0, x0 + 10, y0 + 10)
    res = detect_gap_parallax(lateral_flow(far), ParallaxGapConfig(**RAW), motion=LATERAL)
    assert not res.found and "enclosed by a nearer surface" in res.reason


@pytest.mark.parametrize("x0, y0", [(1, 25), (69, 25), (35, 1), (35, 49), (1, 1), (69, 49)])
def test_a_small_region_one_pixel_inside_the_frame_is_an_opening(x0, y0):
    # ... while one a pixel inside it, wall all round, is an opening (enclosed, however small)
    far = box(x0, y0, x0 + 10, y0 + 10)
    res = detect_gap_parallax(lateral_flow(far), ParallaxGapConfig(**RAW), motion=LATERAL)
    assert res.found and np.array_equal(res.mask, far)


def test_a_region_on_the_frame_edge_at_the_limits_is_an_opening():
    # 16 px along the left edge, 6 px deep: area 15·5 = 75 px², 16 of its 40 outline points on the border
    # (exactly the 40 % allowed), border_min_frac met exactly
    far = box(0, 20, 6, 36)
    cfg = ParallaxGapConfig(**RAW, border_min_frac=75 / (H * W))
    res = detect_gap_parallax(lateral_flow(far), cfg, motion=LATERAL)
    assert res.found and np.array_equal(res.mask, far)
    # one pixel more of the minimum, or a little less of border allowed, and it is refused
    assert not detect_gap_parallax(lateral_flow(far), ParallaxGapConfig(**RAW, border_min_frac=76 / (H * W)),
                                   motion=LATERAL).found
    assert not detect_gap_parallax(lateral_flow(far), ParallaxGapConfig(**RAW, border_min_frac=75 / (H * W),
                                                                        max_border_frac=0.39),
                                   motion=LATERAL).found


def edge_and_hole(edge_rows: int, hole: tuple[int, int, int, int]):
    """A far region along the left edge (rows 5..5+edge_rows, 12 px deep; under 40 % of its outline on the border)
    and an enclosed hole."""
    edge = box(0, 5, 12, 5 + edge_rows)
    return edge, box(*hole), lateral_flow(edge | box(*hole))


def test_a_region_on_the_frame_edge_counts_half_its_area():
    # edge region 12 × 40 (contour area 11·39 = 429, counts 214.5); hole 20 × 16 (19·15 = 285): the hole first
    edge, hole, flow = edge_and_hole(40, (40, 20, 60, 36))
    res = detect_gap_parallax(flow, ParallaxGapConfig(**RAW), motion=LATERAL)
    assert np.array_equal(res.mask, hole) and len(res.candidates) == 2
    assert np.array_equal(res.candidates[1].mask, edge)
    # hole 14 × 14 (13·13 = 169): now the edge region, more than twice as large (429), comes first at 214.5
    edge, hole, flow = edge_and_hole(40, (40, 20, 54, 34))
    res = detect_gap_parallax(flow, ParallaxGapConfig(**RAW), motion=LATERAL)
    assert np.array_equal(res.mask, edge) and np.array_equal(res.candidates[1].mask, hole)


def test_candidates_are_ordered_largest_first():
    holes = [(10, 10, 20, 20), (30, 12, 50, 30), (58, 30, 72, 44), (20, 40, 34, 52)]      # 81, 323, 169, 143
    far = np.zeros((H, W), bool)
    for hole in holes:
        far |= box(*hole)
    res = detect_gap_parallax(lateral_flow(far), ParallaxGapConfig(**RAW), motion=LATERAL)
    assert [c.area for c in res.candidates] == [19 * 17, 13 * 13, 13 * 11, 9 * 9]
    assert res.candidates[0].centroid == res.centroid and np.array_equal(res.mask, box(30, 12, 50, 30))


def test_candidates_of_equal_area_are_all_kept():
    far = box(10, 20, 24, 34) | box(50, 20, 64, 34)
    res = detect_gap_parallax(lateral_flow(far), ParallaxGapConfig(**RAW), motion=LATERAL)
    assert [c.area for c in res.candidates] == [169.0, 169.0]


def test_parallax_detector_closes_over_thin_bars():
    # a 3 px near bar across the gap is closed over by the 7 px elliptic closing: one opening, not two
    gap = box(20, 15, 60, 45)
    bar = box(38, 15, 41, 45)
    cfg = ParallaxGapConfig(border_px=0, median_ksize=1)
    res = detect_gap_parallax(lateral_flow(gap & ~bar), cfg, motion=LATERAL)
    assert res.found and len(res.candidates) == 1 and iou(res.mask, gap) > 0.95
    assert len(detect_gap_parallax(lateral_flow(gap & ~bar), ParallaxGapConfig(**RAW), motion=LATERAL).candidates) == 2


def test_parallax_detector_opening_is_a_5_px_disc():
    # specks far away on the wall: one shaped like the 5 px elliptic element itself survives the opening, a 4 × 4
    # square (which a 3 × 3 square element would keep) does not, so only the gap and the disc are candidates
    gap = box(30, 15, 60, 45)
    disc = np.zeros((H, W), bool)
    disc[45:50, 5:10] = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5)).astype(bool)
    square = box(10, 10, 14, 14)
    res = detect_gap_parallax(lateral_flow(gap | disc | square),
                              ParallaxGapConfig(border_px=0, median_ksize=1, close_ksize=1), motion=LATERAL)
    assert len(res.candidates) == 2 and res.candidates[1].centroid == pytest.approx((7.0, 47.0))


def test_parallax_detector_closing_is_a_7_px_disc():
    # an L-shaped opening: a disc cannot reach into the wall's corner inside the L, so closing with it adds the few
    # wall pixels nearest that corner to the opening (a square element would fit the corner and add none)
    ell = box(20, 10, 60, 25) | box(20, 10, 35, 50)           # inner corner at (35, 25)
    res = detect_gap_parallax(lateral_flow(ell), ParallaxGapConfig(border_px=0, median_ksize=1, open_ksize=1),
                              motion=LATERAL)
    added = res.mask & ~ell
    assert res.mask[25, 35] and not ell[25, 35]
    assert 1 <= added.sum() <= 10 and added[25:30, 35:40].sum() == added.sum()
    assert res.mask[ell].all()


def test_parallax_detector_outline_has_no_redundant_vertices():
    # the closed outline is simplified as a closed curve: every vertex is a real corner (an open-curve
    # simplification would keep the tracing's start and end points, on a straight edge)
    res = detect_gap_parallax(lateral_flow(box(30, 15, 60, 45)), ParallaxGapConfig(border_px=0), motion=LATERAL)
    poly = res.contour.astype(float)
    prev, nxt = np.roll(poly, 1, axis=0), np.roll(poly, -1, axis=0)
    cross = (poly[:, 0] - prev[:, 0]) * (nxt[:, 1] - prev[:, 1]) - (poly[:, 1] - prev[:, 1]) * (nxt[:, 0] - prev[:, 0])
    assert len(poly) >= 4 and (np.abs(cross) > 0).all()


def test_parallax_detector_names_itself_when_there_is_no_depth_step():
    res = detect_gap_parallax(lateral_flow(np.zeros((H, W), bool)), motion=LATERAL)
    assert res.reason.startswith("no depth contrast") and res.detector == "parallax" and not res.mask.any()


def test_parallax_detector_refuses_an_even_median_kernel():
    # median smoothing needs an odd kernel: 2 is an error, not silently no smoothing
    with pytest.raises(cv2.error):
        detect_gap_parallax(lateral_flow(box(30, 20, 50, 40)), ParallaxGapConfig(median_ksize=2), motion=LATERAL)


def blurred_lateral_flow(far: np.ndarray, rho_near: float, rho_far: float, sigma: float) -> np.ndarray:
    """:func:`lateral_flow` as a flow estimator returns it: each surface's flow blended across the edge."""
    weight = cv2.GaussianBlur(far.astype(np.float64), (0, 0), sigma, borderType=cv2.BORDER_REPLICATE)
    flow = np.zeros(far.shape + (2,), np.float32)
    flow[..., 0] = -(weight * rho_far + (1 - weight) * rho_near) * F
    return flow


def test_parallax_detector_puts_a_blurred_edge_at_the_blend_midpoint():
    # an opening at a quarter of the wall's inverse depth, its edge blurred over a few pixels as estimated flow is:
    # split on log ρ (Otsu's), the edge lands where ρ is nearer the far side and the mask shrinks by about a pixel
    # per edge; split at the linear midpoint (edge_blend 0.5) it lands on the true edge
    far = box(20, 15, 60, 45)
    flow = blurred_lateral_flow(far, rho_near=0.8, rho_far=0.2, sigma=1.5)
    cfg = dict(RAW, area_min_frac=0.001)
    at_midpoint = detect_gap_parallax(flow, ParallaxGapConfig(edge_blend=0.5, **cfg), motion=LATERAL)
    on_log = detect_gap_parallax(flow, ParallaxGapConfig(edge_blend=None, **cfg), motion=LATERAL)
    assert abs(at_midpoint.mask.sum() - far.sum()) <= 0.02 * far.sum()
    assert on_log.mask.sum() < 0.95 * far.sum()
    assert iou(at_midpoint.mask, far) > iou(on_log.mask, far) + 0.03


def test_the_blended_edge_moves_at_most_its_reach_from_otsus():
    """ParallaxGapConfig.edge_blend_reach_px: beside the opening a surface whose inverse depth lies between Otsu's
    split and the blend level (a background close behind the wall, seen past the opening's edge) is not the
    opening; an unbounded blend takes all of it, the default reach of 1 px one column of it."""
    hole, shelf = box(20, 15, 50, 45), box(50, 15, 60, 45)
    rho = np.where(hole, 0.2, np.where(shelf, 0.45, 0.8))
    flow = np.zeros((H, W, 2), np.float32)
    flow[..., 0] = -rho * F
    cfg = dict(RAW, area_min_frac=0.001)
    otsu = detect_gap_parallax(flow, ParallaxGapConfig(edge_blend=None, **cfg), motion=LATERAL)
    unbounded = detect_gap_parallax(flow, ParallaxGapConfig(edge_blend=0.5, edge_blend_reach_px=None, **cfg),
                                    motion=LATERAL)
    default = detect_gap_parallax(flow, ParallaxGapConfig(edge_blend=0.5, **cfg), motion=LATERAL)
    assert ParallaxGapConfig().edge_blend_reach_px == 1
    assert np.array_equal(otsu.mask, hole)
    assert np.array_equal(unbounded.mask, hole | shelf)
    assert np.array_equal(default.mask, hole | box(50, 15, 51, 45))


def test_blend_level_is_the_linear_midpoint_on_the_log_scale():
    step = np.log(4.0) / 200                      # 200 levels span a factor of 4 in ρ
    assert _blend_level(0, 200, step, 0.5) == pytest.approx(np.log(2.5) / step)
    assert _blend_level(0, 200, step, 0.0) == pytest.approx(0.0, abs=1e-9)
    assert _blend_level(0, 200, step, 1.0) == pytest.approx(200.0)


def test_every_step_looks_beyond_the_next_step_when_the_sharpest_hides_no_hole():
    # a floor across the bottom, four times the wall's inverse depth, and a gap at 0.6 of it: the floor's step is
    # the sharpest, and beyond it lie the wall and the gap, which span the frame and are no hole in anything
    floor, gap = box(0, H - 12, W, H), box(30, 15, 50, 35)
    rho = np.where(floor, 2.0, np.where(gap, 0.3, 0.5))
    flow = np.zeros((H, W, 2), np.float32)
    flow[..., 0] = -rho * F
    cfg = dict(RAW, area_min_frac=0.001, border_min_frac=0.0)
    assert not detect_gap_parallax(flow, ParallaxGapConfig(**cfg), motion=LATERAL).found
    res = detect_gap_parallax(flow, ParallaxGapConfig(every_step=True, **cfg), motion=LATERAL)
    assert res.found and iou(res.mask, gap) > 0.9


def test_what_lies_past_the_walls_end_is_set_aside_and_the_opening_found_in_the_rest():
    """ParallaxGapConfig.past_the_end (off by default): seen past the wall's end (here its left third, 25 times as
    deep as the wall), the empty space is the sharpest depth step, reaches the image's border and holds no hole;
    set aside, the rest (the wall and an opening at half its inverse depth) is split again and the opening found.
    Without an opening nothing is found, and a far region that touches what was set aside is no hole in the wall."""
    past, gap = box(0, 0, 28, H), box(45, 18, 65, 38)
    rho = np.where(past, 0.02, np.where(gap, 0.25, 0.5))
    flow = np.zeros((H, W, 2), np.float32)
    flow[..., 0] = -rho * F
    assert not ParallaxGapConfig().past_the_end
    on = ParallaxGapConfig(past_the_end=True)
    assert not detect_gap_parallax(flow, ParallaxGapConfig(), motion=LATERAL).found
    res = detect_gap_parallax(flow, on, motion=LATERAL)
    assert res.found and iou(res.mask, gap) > 0.9
    # no opening: the wall alone beside the empty space
    flow[..., 0] = -np.where(past, 0.02, 0.5) * F
    none = detect_gap_parallax(flow, on, motion=LATERAL)
    assert not none.found and "enclosed by a nearer surface" in none.reason
    # a far patch against the wall's end (a notch of its edge seen as deep as an opening) is no hole either
    notch = box(28, 18, 40, 38)
    flow[..., 0] = -np.where(past, 0.02, np.where(notch, 0.25, 0.5)) * F
    assert not detect_gap_parallax(flow, on, motion=LATERAL).found

"""The parallax detector's work at the edges of what it sees, on hand-made inputs with exact answers: which pixels
are textured, how far a mask grows, the band of an opening the wall hides in the second frame (filled back), and
what lies past the wall's end (set aside).  Expected values come from the geometry: a grey ramp of slope k has a
Sobel gradient of exactly 8k, a lateral step of the camera moves the background against the wall by
fraction·(ρ_far − ρ_near)·f pixels, and a rectangle's chessboard rings have known pixel counts."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from companion.gap import ParallaxGapConfig, textured_pixels
from companion.holes import _holes, _holes_past_the_end, fill_occluded, within
from tests.companion.synthetic import SMALL, box

H, W = SMALL
F = 100.0                       # the lateral step's focal length: g = (-F, 0) everywhere
G = (np.full((H, W), -F), np.zeros((H, W)))
EVERYWHERE = np.ones((H, W), bool)


def grey_rgb(values: np.ndarray) -> np.ndarray:
    """An RGB image of equal channels (its grey is exactly ``values``)."""
    return np.repeat(values.astype(np.uint8)[..., None], 3, axis=2)


def outline(mask: np.ndarray) -> np.ndarray:
    contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    assert len(contours) == 1
    return contours[0]


def filled(contour: np.ndarray) -> np.ndarray:
    m = np.zeros((H, W), np.uint8)
    cv2.drawContours(m, [contour], -1, 1, thickness=cv2.FILLED)
    return m.astype(bool)


def rings(mask: np.ndarray) -> np.ndarray:
    """Each pixel's chessboard distance from ``mask`` (0 inside), up to 20."""
    d = np.where(mask, 0, 99)
    for k in range(1, 21):
        d[(d == 99) & within(mask, k)] = k
    return d


# ------------------------------------------------------------------------------------------------- texture

@pytest.mark.parametrize("axis", [0, 1])
def test_a_ramp_exactly_at_the_gradient_threshold_is_texture_across_and_along(axis):
    """A ramp rising 5 grey levels a pixel has a Sobel gradient of exactly 40 inside the frame (and 0 on the two
    border lines, whose reflected neighbours are equal): at a threshold of 40 it is texture, and one pixel of
    reach covers the border lines.  Falling ramps give the same magnitude."""
    cfg = ParallaxGapConfig(texture_min_gradient=40.0, texture_reach_px=1)
    ramp = np.arange(40) * 5
    for values in (ramp, ramp[::-1]):
        image = np.tile(values, (12, 1)) if axis == 1 else np.tile(values[:, None], (1, 12))
        textured = textured_pixels(grey_rgb(image), cfg)
        assert textured.dtype == bool and textured.all()
    # a hair under the threshold's slope it is not
    assert not textured_pixels(grey_rgb(np.tile(np.arange(40) * 4, (12, 1))), cfg).any()


@pytest.mark.parametrize("falling", [False, True])
def test_an_edge_is_texture_exactly_its_reach_either_side(falling):
    """A step of 10 grey levels between columns 19 and 20 has a gradient of 40 on those two columns: with a
    reach of 3 px, columns 16-23 are textured and no other (rising or falling: the magnitude counts)."""
    image = np.zeros((12, 40))
    image[:, 20:] = 10
    if falling:
        image = 10 - image
    textured = textured_pixels(grey_rgb(image), ParallaxGapConfig(texture_min_gradient=40.0, texture_reach_px=3))
    expected = np.zeros(40, bool)
    expected[16:24] = True
    assert textured.dtype == bool
    assert (textured == expected[None, :]).all()


# ------------------------------------------------------------------------------------------------- growing

def test_growing_by_nothing_is_the_mask_itself():
    mask = box(10, 10, 20, 20)
    assert within(mask, 0) is mask


def test_growing_a_pixel_by_two_gives_a_five_pixel_square_centred_on_it():
    mask = np.zeros((21, 21), bool)
    mask[10, 10] = True
    grown = within(mask, 2)
    assert grown.dtype == bool
    assert np.array_equal(np.argwhere(grown).min(axis=0), [8, 8]) and np.array_equal(np.argwhere(grown).max(axis=0),
                                                                                       [12, 12])
    assert grown.sum() == 25


# ------------------------------------------------------------------------------------- the occluded band

OPENING = box(20, 20, 40, 40)          # 20 × 20 px


def depth_by_ring(values: dict[int, float], inside: float = 0.1, beyond: float = 0.5) -> np.ndarray:
    """Inverse depth: ``inside`` the opening, ``values[k]`` on its k-th chessboard ring, ``beyond`` further out."""
    d = rings(OPENING)
    rho = np.full((H, W), beyond)
    rho[d == 0] = inside
    for k, v in values.items():
        rho[d == k] = v
    return rho


def test_the_band_the_wall_hides_is_filled_back_by_the_step_between_the_two_depths():
    """ρ 0.1 beyond the opening, 0.3 on the wall around it (and 0.5 further out, a floor, say): a lateral step
    with f = 100 px moves the background 0.5·(0.1 − 0.3)·100 = 10 px against the wall, so the opening's mask is
    filled back 10 px on the side the background moved to.  The wall is read in the ring around the opening only:
    taken over the whole frame, the floor's 0.5 would make it 20 px."""
    rho = depth_by_ring({k: 0.3 for k in range(1, 7)})
    out = fill_occluded(outline(OPENING), rho, EVERYWHERE, G, 0.5)
    assert np.array_equal(filled(out), box(20, 20, 50, 40))


def test_the_wall_is_read_in_the_ring_from_three_to_six_pixels_out():
    """Measurable only on rings 3-5 (0.24, 0.26, 0.28: 100, 108 and 116 px): the median is ring 4's 0.26, and the
    band 0.5·(0.1 − 0.26)·100 = 8 px; rings 4-5 alone would give ring 5's 0.28 (9 px)."""
    d = rings(OPENING)
    rho = depth_by_ring({3: 0.24, 4: 0.26, 5: 0.28})
    measurable = (d == 0) | (d == 3) | (d == 4) | (d == 5)
    out = fill_occluded(outline(OPENING), rho, measurable, G, 0.5)
    assert np.array_equal(filled(out), box(20, 20, 48, 40))


def test_the_ring_reaches_six_pixels_out_and_no_further():
    """Measurable on rings 6 (0.3, 124 px) and 7 (0.9, 132 px): the ring is 6 only, the band 10 px.  With ring 7
    in it the median would be 0.9, and the band 40 px."""
    d = rings(OPENING)
    rho = depth_by_ring({6: 0.3, 7: 0.9})
    measurable = (d == 0) | (d == 6) | (d == 7)
    out = fill_occluded(outline(OPENING), rho, measurable, G, 0.5)
    assert np.array_equal(filled(out), box(20, 20, 50, 40))


@pytest.mark.parametrize("axis", [0, 1])
def test_the_opening_is_read_two_pixels_in_from_its_outline(axis):
    """Inside the opening: 0.3 one pixel in from the outline (its blurred edge), then 0.10 on one half and 0.14 on
    the other (split across rows, or across columns).  Read two pixels in (a 5 × 5 erosion, symmetric), the median
    is 0.12 and the band 0.5·(0.12 − 0.3)·100 = 9 px; with the edge's pixels in it would be 0.14 (8 px), and an
    erosion lopsided by one pixel would take 0.10 or 0.14."""
    ys, xs = np.mgrid[0:H, 0:W]
    half = (ys if axis == 0 else xs) < 30
    rho = depth_by_ring({k: 0.3 for k in range(1, 7)})
    rho[OPENING] = np.where(half, 0.10, 0.14)[OPENING]
    inner = box(21, 21, 39, 39)
    rho[OPENING & ~box(22, 22, 38, 38) & inner] = 0.3      # one pixel in from the outline
    out = fill_occluded(outline(OPENING), rho, EVERYWHERE, G, 0.5)
    assert np.array_equal(filled(out), box(20, 20, 49, 40))


def test_an_opening_and_a_ring_of_twenty_measurable_pixels_each_are_enough():
    """The fill needs 20 measurable pixels two in from the outline (a 9 × 8 opening has 5 × 4) and 20 on the ring
    (here one row of 20 on ring 3): with exactly that, the band is filled back (5 px, then 10)."""
    small = box(20, 20, 29, 28)
    rho = np.where(small, 0.1, 0.2)
    out = fill_occluded(outline(small), rho, EVERYWHERE, G, 0.5)
    assert np.array_equal(filled(out), box(20, 20, 34, 28))
    ring_row = box(20, 17, 40, 18)                          # 20 px, three rows above the opening: ring 3
    assert (rings(OPENING)[ring_row] == 3).all()
    rho = depth_by_ring({k: 0.3 for k in range(1, 7)})
    out = fill_occluded(outline(OPENING), rho, OPENING | ring_row, G, 0.5)
    assert np.array_equal(filled(out), box(20, 20, 50, 40))


def test_with_too_few_measurable_pixels_in_the_opening_the_outline_is_kept_as_it_is():
    """An 8 × 8 opening has 4 × 4 = 16 pixels two in from its outline, under 20: nothing is filled, however many
    the ring has."""
    small = box(20, 20, 28, 28)
    contour = outline(small)
    assert fill_occluded(contour, np.where(small, 0.1, 0.3), EVERYWHERE, G, 0.5) is contour


@pytest.mark.parametrize("inside", [0.3, 0.32])
def test_no_band_is_filled_when_the_opening_is_not_deeper_than_the_wall(inside):
    """The same inverse depth inside and around (no step), or the opening nearer than the wall around it (a step
    that would move the mask the other way): the outline as it was."""
    rho = depth_by_ring({k: 0.3 for k in range(1, 7)}, inside=inside)
    contour = outline(OPENING)
    assert fill_occluded(contour, rho, EVERYWHERE, G, 0.5) is contour


def test_a_band_wider_than_the_opening_keeps_the_larger_piece():
    """A 15 px wide opening whose background moves 30 px: the shifted copy lies apart from it, cut by the frame's
    edge to 10 px; the larger piece, the opening itself, is kept."""
    narrow = box(40, 20, 55, 40)
    rho = np.where(narrow, 0.1, 0.7)
    out = fill_occluded(outline(narrow), rho, EVERYWHERE, G, 0.5)
    assert np.array_equal(filled(out), narrow)


# ------------------------------------------------------------------------------------------ past the end

SIDES = {"top": box(30, 0, 50, 10), "bottom": box(30, H - 10, 50, H),
         "left": box(0, 20, 10, 40), "right": box(W - 10, 20, W, 40)}
# an opening one pixel in from that same side, away from what lies past the end there
NEAR_SIDE = {"top": box(5, 1, 20, 12), "bottom": box(5, H - 12, 20, H - 1),
             "left": box(1, 45, 12, 58), "right": box(W - 12, 45, W - 1, 58)}


@pytest.mark.parametrize("side", list(SIDES))
def test_what_reaches_one_side_of_the_frame_is_set_aside_and_an_opening_a_pixel_from_it_is_not(side):
    """The far class holds what lies past the wall's end, reaching one side of the frame only, and an opening one
    pixel in from that side (not reaching it).  What reaches the side is set aside; the opening is split off the
    wall again in the rest and found (area bounds off)."""
    past, opening = SIDES[side], NEAR_SIDE[side]
    log_img = np.where(past | opening, 10, 200).astype(np.uint8)
    cfg = ParallaxGapConfig(open_ksize=1, close_ksize=1, border_min_frac=0.0, past_the_end_reach_px=2)
    found = _holes_past_the_end(log_img, past | opening, 0.02, cfg, 1.0, H * W)
    assert len(found) == 1 and np.array_equal(filled(found[0]), opening)


def test_an_opening_two_pixels_from_what_is_set_aside_is_still_one():
    """What is set aside is grown by its reach (here 2 px); a region touching the pixels right beside that is no
    hole in the wall, one a pixel further away is."""
    past = box(0, 20, 10, 40)                               # set aside: columns 0-11 once grown by 2
    cfg = ParallaxGapConfig(open_ksize=1, close_ksize=1, border_min_frac=0.0, past_the_end_reach_px=2)
    for x0, kept in ((12, False), (13, True)):              # column 12 is beside it; 13 is two away
        opening = box(x0, 24, x0 + 12, 36)
        log_img = np.where(past | opening, 10, 200).astype(np.uint8)
        found = _holes_past_the_end(log_img, past | opening, 0.02, cfg, 1.0, H * W)
        assert bool(found) == kept


@pytest.mark.parametrize("order", ["outside first", "outside last"])
def test_a_region_reaching_outside_the_wall_is_passed_over_and_the_next_one_taken(order):
    """Of two far regions, the one that reaches pixels of no wall is no hole; the other is taken whichever of the
    two the contour search meets first."""
    top, bottom = box(30, 5, 50, 20), box(30, 35, 50, 50)
    first, second = (top, bottom) if order == "outside first" else (bottom, top)
    outside = np.zeros((H, W), bool)
    outside[first] = True
    found = _holes(top | bottom, ParallaxGapConfig(open_ksize=1, close_ksize=1), 1.0, H * W, outside=outside)
    assert len(found) == 1 and np.array_equal(filled(found[0]), second)


# ------------------------------------------------------------------------------------------- the far class

def test_a_pixel_exactly_at_the_blend_level_is_far():
    """With the blend at 0 the edge is put at the far class's own level (0 here, exactly): its pixels are far."""
    from companion.holes import far_regions

    log_img = np.where(OPENING, 0, 200).astype(np.uint8)
    cfg = ParallaxGapConfig(edge_blend=0.0, edge_blend_reach_px=None)
    fars, _ = far_regions(log_img, np.log(4.0) / 200, cfg)
    assert len(fars) == 1 and np.array_equal(fars[0], OPENING)

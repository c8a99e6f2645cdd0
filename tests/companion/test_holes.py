"""companion.holes piece by piece: the contour filter, the search against a turned wall's plane and the search with
plain regions set aside (what the detector's own tests reach only through whole frames)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from companion.gap import CameraMotion, ParallaxGapConfig
from companion.holes import _holes, _holes_against_wall, filled, hole_contours

H, W, F = 120, 160, 100.0
LATERAL = CameraMotion(translation=(1.0, 0.0, 0.0), focal_px=F)
IDEAL = ParallaxGapConfig(occlusion_fill=None)
EVERYWHERE = np.ones((H, W), bool)


def box(x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
    m = np.zeros((H, W), bool)
    m[y0:y1, x0:x1] = True
    return m


def outline_mask(contour: np.ndarray) -> np.ndarray:
    return filled((H, W), contour).astype(bool)


def turned_wall_log_rho(hole: np.ndarray, turn: float = 0.4, hole_ratio: float = 0.5) -> np.ndarray:
    """log ρ of a wall turned against the camera (ρ linear across the image, as a plane's is) with ``hole`` at
    ``hole_ratio`` of the wall's ρ."""
    x = (np.arange(W) - (W - 1) / 2) / F
    wall = np.broadcast_to(0.5 + turn * x, (H, W))
    return np.log(np.where(hole, hole_ratio * wall, wall))


@pytest.mark.parametrize("side", ["top", "bottom"])
def test_a_small_region_at_the_border_is_passed_over_and_the_search_goes_on(side):
    """A far region touching the frame's border below ``border_min_frac`` of the frame is no opening; the regions
    after it are still looked at, whichever the contour search meets first."""
    speck = box(10, 0, 20, 6) if side == "top" else box(10, H - 6, 20, H)
    hole = box(60, 50, 100, 80)
    found = _holes(speck | hole, ParallaxGapConfig(open_ksize=1, close_ksize=1), 1.0, H * W)
    assert len(found) == 1 and np.array_equal(outline_mask(found[0]), hole)


# ------------------------------------------------------------------------------- against the wall's plane

# a hole whose edge lies one pixel in from each side of the frame: it does not reach the border
ONE_PIXEL_IN = {"top": box(60, 1, 100, 40), "bottom": box(60, H - 41, 100, H - 1),
                "left": box(1, 40, 40, 80), "right": box(W - 41, 40, W - 1, 80)}


# without the far mask's closing, which carries a region within a few pixels of the border onto it
UNSMOOTHED = dataclasses.replace(IDEAL, open_ksize=1, close_ksize=1)


@pytest.mark.parametrize("side", list(ONE_PIXEL_IN))
def test_against_the_wall_a_hole_a_pixel_in_from_the_border_is_one(side):
    hole = ONE_PIXEL_IN[side]
    found = _holes_against_wall(turned_wall_log_rho(hole), EVERYWHERE, LATERAL, UNSMOOTHED, 1.0, H * W)
    assert len(found) == 1 and (outline_mask(found[0]) == hole).mean() > 0.99


@pytest.mark.parametrize("side", list(ONE_PIXEL_IN))
def test_against_the_wall_a_hole_reaching_the_border_is_none(side):
    """What reaches the frame's border below the wall's plane is what lies past the wall's end, however it is
    walled inside the frame (the contour filter alone would keep it, a fifth of its outline on the border)."""
    hole = ONE_PIXEL_IN[side] | dict(top=box(60, 0, 100, 1), bottom=box(60, H - 1, 100, H), left=box(0, 40, 1, 80),
                                     right=box(W - 1, 40, W, 80))[side]
    log_rho = turned_wall_log_rho(hole)
    assert _holes_against_wall(log_rho, EVERYWHERE, LATERAL, UNSMOOTHED, 1.0, H * W) == []
    assert _holes(hole, UNSMOOTHED, 1.0, H * W), "the contour filter alone keeps it: the border is what refuses it"


def test_against_the_wall_needs_a_plane_that_dominates_the_view():
    """With the wall's plane on under 70 % of what is measurable (``against_wall_walled``; over a quarter of the
    view lies past the wall's end), there is no wall to measure holes against; asked for 60 %, the hole is
    found."""
    hole = box(30, 40, 60, 80)
    log_rho = turned_wall_log_rho(hole, turn=0.1)
    beyond = box(115, 0, W, H)                                # 28 % of the view: a surface farther than the wall
    log_rho = np.where(beyond, np.log(0.2), log_rho)
    assert _holes_against_wall(log_rho, EVERYWHERE, LATERAL, IDEAL, 1.0, H * W) == []
    lenient = dataclasses.replace(IDEAL, against_wall_walled=0.6)
    found = _holes_against_wall(log_rho, EVERYWHERE, LATERAL, lenient, 1.0, H * W)
    assert len(found) == 1 and (outline_mask(found[0]) == hole).mean() > 0.99


# --------------------------------------------------------------------------- with plain regions set aside

def test_with_plain_regions_set_aside_a_hole_beside_them_is_none():
    """The search with the plain regions at the border set aside: a far region touching them is part of what lies
    past the wall's end; the same region a few pixels from them is a hole in the wall."""
    plain = box(0, 0, 30, H)                                  # the empty space past the wall's end, on the left
    measurable = ~plain
    cfg = dataclasses.replace(IDEAL, against_wall=False)
    for x0, kept in ((30, False), (40, True)):
        hole = box(x0, 40, x0 + 30, 80)
        rho = np.where(hole, 0.25, 0.5)
        found, _ = hole_contours(rho, measurable, LATERAL, cfg, 1.0, H * W, plain)
        assert bool(found) == kept, x0
        if kept:
            assert (outline_mask(found[0]) == hole).mean() > 0.99

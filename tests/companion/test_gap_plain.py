"""The parallax detector, finding no hole, sets aside the plain regions at the image's border and looks again
(ParallaxGapConfig.plain_aside); in every pair it drops a hole that is mostly such plain space
(ParallaxGapConfig.plain_candidate_frac).

Past a wall's end the camera sees empty space: no texture, and a flow network reads it as barely moving, the
deepest thing in view.  Each split of log ρ then peels that region off, and a hole in the wall, nearer than it,
stays in the near class.  The flows are a lateral step's (t = (1, 0, 0)), so the inverse depth read back is the
one drawn.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from companion import gap, holes
from companion.gap import CameraMotion, ParallaxGapConfig
from tests.companion.synthetic import iou

H, W, F = 120, 160, 100.0
LATERAL = CameraMotion(translation=(1.0, 0.0, 0.0), focal_px=F)
HOLE = np.zeros((H, W), bool)
HOLE[40:80, 70:110] = True
VOID = np.zeros((H, W), bool)
VOID[:, :40] = True                                  # past the wall's end, on the left
FLOWN = ParallaxGapConfig(occlusion_fill=None)       # every far pixel has its true flow here: nothing to fill
SPLITS_ONLY = dataclasses.replace(FLOWN, against_wall=False)


def lateral_flow(rho: np.ndarray) -> np.ndarray:
    flow = np.zeros((H, W, 2), np.float32)
    flow[..., 0] = -rho * F
    return flow


def wall_with(hole_rho: float, void_rho: float, seed: int = 0) -> np.ndarray:
    """ρ 0.5 on the wall, ``hole_rho`` through the hole, ``void_rho`` past the wall's end, 2 % noise."""
    rho = np.where(VOID, void_rho, np.where(HOLE, hole_rho, 0.5))
    return lateral_flow(rho * np.exp(np.random.default_rng(seed).normal(0.0, 0.02, (H, W))))


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("config", [SPLITS_ONLY, FLOWN], ids=["splits", "flown"])
def test_a_hole_nearer_than_the_empty_space_past_the_walls_end_is_found_with_it_set_aside(config, seed):
    flow = wall_with(hole_rho=0.3, void_rho=0.005, seed=seed)
    blind = gap.detect_gap_parallax(flow, SPLITS_ONLY, LATERAL)
    assert not blind.found                            # the split peels the empty space; the hole stays near
    found = gap.detect_gap_parallax(flow, config, LATERAL, textured=~VOID)
    assert found.found and iou(found.mask, HOLE) > 0.9
    off = gap.detect_gap_parallax(flow, dataclasses.replace(SPLITS_ONLY, plain_aside=False), LATERAL, ~VOID)
    assert not off.found


def test_a_plain_region_walled_all_round_is_not_set_aside():
    """Sky through a window, beside the empty space past the wall's end: plain inside, beyond a texture's reach of
    the window's edge, and walled all round: part of the opening."""
    textured = ~VOID
    textured[43:77, 73:107] = False
    found = gap.detect_gap_parallax(wall_with(hole_rho=0.3, void_rho=0.005), SPLITS_ONLY, LATERAL, textured)
    assert found.found and iou(found.mask, HOLE) > 0.9


def test_a_frame_almost_all_plain_is_not_searched_again():
    """Nearly the whole frame plain and reaching the border (looking past a wall's end into empty space): what is
    left after setting it aside is smaller than the smallest opening, so there is nothing to search again (the
    second search once raised on an empty set of measurable pixels)."""
    flow = wall_with(hole_rho=0.5, void_rho=0.5)     # no depth step anywhere: the first search finds nothing
    for textured in (np.zeros((H, W), bool), np.pad(np.ones((4, 4), bool), ((58, H - 62), (78, W - 82)))):
        found = gap.detect_gap_parallax(flow, FLOWN, LATERAL, textured=textured)
        assert not found.found and found.reason.startswith("no depth contrast")


BESIDE = np.zeros((H, W), bool)
BESIDE[30:90, 130:] = True                           # past the wall's end at the right border, wall above and below


@pytest.mark.parametrize("seed", range(3))
def test_a_hole_that_is_mostly_the_plain_space_past_the_walls_end_is_no_candidate(seed):
    """The empty space past the wall's end reads as deep as the background through the hole, and both are holes
    to the splits; the one that is mostly plain and reaches the border is dropped, in every pair."""
    rho = np.where(BESIDE | HOLE, 0.3, 0.5) * np.exp(np.random.default_rng(seed).normal(0.0, 0.02, (H, W)))
    flow = lateral_flow(rho)
    kept = gap.detect_gap_parallax(flow, dataclasses.replace(FLOWN, plain_candidate_frac=None), LATERAL, ~BESIDE)
    assert len(kept.candidates) == 2                 # without the rule the empty space is a second opening
    found = gap.detect_gap_parallax(flow, FLOWN, LATERAL, textured=~BESIDE)
    assert len(found.candidates) == 1 and iou(found.mask, HOLE) > 0.9
    no_second_search = dataclasses.replace(FLOWN, plain_aside=False)
    first = gap.detect_gap_parallax(flow, no_second_search, LATERAL, textured=~BESIDE)
    assert len(first.candidates) == 1 and iou(first.mask, HOLE) > 0.9     # kept in the first search, not found again
    at_the_bound = dataclasses.replace(no_second_search, plain_candidate_frac=0.0)
    assert len(gap.detect_gap_parallax(flow, at_the_bound, LATERAL, textured=~BESIDE).candidates) == 1  # 0 of 0: kept
    alone = gap.detect_gap_parallax(lateral_flow(np.where(BESIDE, 0.3, 0.5)), FLOWN, LATERAL, textured=~BESIDE)
    assert not alone.found and alone.reason.startswith("every hole found is mostly plain")  # nor alone
    textured = np.ones((H, W), bool)
    textured[43:77, 73:107] = False                  # sky through the window, walled all round: kept
    walled = gap.detect_gap_parallax(flow, FLOWN, LATERAL, textured=textured & ~BESIDE)
    assert len(walled.candidates) == 1 and iou(walled.mask, HOLE) > 0.9


def test_the_plain_fraction_counts_every_pixel_inside_the_outline():
    """Plain inside a square but not on its outline: 18 × 18 of its 20 × 20 filled pixels, though none of the
    outline's own."""
    square = np.array([[[10, 10]], [[29, 10]], [[29, 29]], [[10, 29]]], np.int32)
    plain = np.zeros((H, W), bool)
    plain[11:29, 11:29] = True
    assert holes.plain_fraction(square, plain) == pytest.approx(18 * 18 / (20 * 20))

"""The parallax detector's second look, against the wall's plane (ParallaxGapConfig.against_wall).

A wall turned against the camera spans a range of inverse depths; a hole on its near side shows a background
as deep as the wall's far side, and no one split of ρ separates them.  The flows are those of a lateral step
(t = (1, 0, 0)), so that the inverse depth read back is exactly the one drawn: the wall's ρ linear across the
image, as a plane's is, and the hole's a fraction of the wall's there.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from companion import gap
from companion.gap import CameraMotion, ParallaxGapConfig
from companion.inverse_depth import wall_plane_log
from tests.companion.synthetic import iou

H, W, F = 120, 160, 100.0
LATERAL = CameraMotion(translation=(1.0, 0.0, 0.0), focal_px=F)
HOLE = np.zeros((H, W), bool)
HOLE[40:80, 60:100] = True
IDEAL = ParallaxGapConfig(occlusion_fill=None)     # every far pixel has its true flow here: nothing to fill


def turned_wall(turn: float, far: np.ndarray | None = None, far_ratio: float = 0.55, noise: float = 0.0,
                seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Flow of the lateral step and the wall's ρ: ρ = 0.5 + ``turn``·x/f on the wall, ``far_ratio`` of it
    where ``far`` is, times a log-normal noise of ``noise``."""
    x = (np.arange(W) - (W - 1) / 2) / F
    wall = np.broadcast_to(0.5 + turn * x, (H, W)).copy()
    rho = wall if far is None else np.where(far, far_ratio * wall, wall)
    rho = rho * np.exp(np.random.default_rng(seed).normal(0.0, noise, (H, W)))
    flow = np.zeros((H, W, 2), np.float32)
    flow[..., 0] = -rho * F
    return flow, wall


@pytest.mark.parametrize("turn", [0.3, 0.4])
@pytest.mark.parametrize("far_ratio", [0.4, 0.55, 0.7])
def test_a_hole_in_a_turned_wall_that_one_split_misses_is_found_against_the_wall(turn, far_ratio):
    flow, _ = turned_wall(turn, HOLE, far_ratio)
    plain = gap.detect_gap_parallax(flow, dataclasses.replace(IDEAL, against_wall=False), LATERAL)
    assert not plain.found and "enclosed by a nearer surface" in plain.reason
    found = gap.detect_gap_parallax(flow, IDEAL, LATERAL)
    assert found.found and iou(found.mask, HOLE) > 0.9


def test_a_hole_one_split_finds_is_found_as_before():
    flow, _ = turned_wall(0.0, HOLE, 0.5)
    on = gap.detect_gap_parallax(flow, IDEAL, LATERAL)
    off = gap.detect_gap_parallax(flow, dataclasses.replace(IDEAL, against_wall=False), LATERAL)
    assert on.found and np.array_equal(on.mask, off.mask)


@pytest.mark.parametrize("seed", range(3))
def test_a_turned_wall_without_a_hole_shows_none(seed):
    flow, _ = turned_wall(0.4, noise=0.05, seed=seed)
    assert not gap.detect_gap_parallax(flow, IDEAL, LATERAL).found


def test_what_lies_past_the_wall_s_end_is_no_hole_in_it():
    # the wall ends 30 columns from the left border; beyond it, a far surface reaching the border on three sides
    beyond = np.zeros((H, W), bool)
    beyond[:, :30] = True
    flow, _ = turned_wall(0.4, beyond, 0.3)
    assert not gap.detect_gap_parallax(flow, IDEAL, LATERAL).found


def test_a_blob_beside_the_wall_s_end_is_no_hole_either():
    # far past the end on the left, and a far blob in it that does not reach the border: not walled all round
    beyond = np.zeros((H, W), bool)
    beyond[:, :50] = True
    flow, _ = turned_wall(0.4, beyond, 0.5)
    blob = np.zeros((H, W), bool)
    blob[50:70, 15:35] = True
    flow[blob, 0] *= 0.4
    assert not gap.detect_gap_parallax(flow, IDEAL, LATERAL).found


def test_the_wall_plane_is_recovered_through_a_hole():
    flow, wall = turned_wall(0.3, HOLE, 0.5, noise=0.01)
    rho = -flow[..., 0] / F
    plane = wall_plane_log(np.log(rho), np.ones((H, W), bool), F, band=0.15)
    assert plane is not None and np.allclose(np.exp(plane), wall, rtol=0.01)


def test_no_plane_without_enough_measurable_pixels():
    flow, _ = turned_wall(0.3)
    measurable = np.zeros((H, W), bool)
    measurable[:5, :5] = True
    assert wall_plane_log(np.log(-flow[..., 0] / F), measurable, F, band=0.15) is None

"""Near the focus of expansion the parallax detector reads the inverse depth from the flow's rate of expansion over
a window (ParallaxGapConfig.focus_window_px, off as flown) instead of inpainting it from around.

Flying at an opening puts the focus of expansion in it, and one pixel's flow there is too small to divide by:
the pixels within ``min_g_frac`` of the largest |g| (a 16 px disc at 320×240) used to be inpainted from the
wall around them, so an opening seen whole inside that disc (0.5 m at 3 m) was not there at all.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from companion import gap
from companion.gap import CameraMotion, ParallaxGapConfig
from companion.inverse_depth import focus_inverse_depth
from tests.companion.synthetic import FOCAL_320x240, iou, translation_flow

H, W = 240, 320
FORWARD = CameraMotion(translation=(0.0, 0.0, 1.0), focal_px=FOCAL_320x240)
INPAINTED = ParallaxGapConfig(focus_window_px=None)
WINDOW = ParallaxGapConfig(focus_window_px=9)


def noisy(flow: np.ndarray, seed: int) -> np.ndarray:
    """``flow`` with an estimator's kind of error: noise correlated over a few pixels, about 0.017 px per component."""
    noise = np.random.default_rng(seed).normal(0.0, 0.06, flow.shape).astype(np.float32)
    return flow + cv2.GaussianBlur(noise, (0, 0), 1.0)


def square_at_focus(half_px: int, dx: int = 0) -> np.ndarray:
    cx, cy = (W - 1) / 2.0 + dx, (H - 1) / 2.0
    return np.array([[cx - half_px, cy - half_px], [cx + half_px, cy - half_px], [cx + half_px, cy + half_px],
                     [cx - half_px, cy + half_px]])


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("dx", [0, 8])
def test_an_opening_inside_the_disc_around_the_focus_is_found(seed, dx):
    """A 24 px opening at (or 8 px beside) the focus, wholly inside the 16 px disc: found, and only with the
    window (inpainted from the wall around, the disc shows no opening).  Its mask is rough (IoU 0.55 centred on the
    focus, 0.72-0.75 beside it): a window that straddles an edge reads the step in flow as expansion."""
    flow, hole = translation_flow(H, W, (0.0, 0.0, 1.0), square_at_focus(12, dx), rho_near=1 / 3, rho_far=1 / 8,
                                  scale=0.1, occlusion=True)
    flow = noisy(flow, seed)
    assert not gap.detect_gap_parallax(flow, INPAINTED, FORWARD).found
    found = gap.detect_gap_parallax(flow, WINDOW, FORWARD)
    assert found.found and iou(found.mask, hole) > 0.5      # the window blurs the edges inside the disc


def test_the_window_reads_the_inverse_depth_at_the_focus():
    """On a wall facing the camera the ρ read near the focus is the wall's, to the flow's noise, and measurable
    there (it was not before)."""
    flow, _ = translation_flow(H, W, (0.0, 0.0, 1.0), [[-20, -20], [-10, -20], [-10, -10]], rho_near=0.5, scale=0.1)
    flow = noisy(flow, 0)
    rho, valid, g = gap._inverse_depth(flow, FORWARD, ParallaxGapConfig())
    near_focus = ~valid
    assert 600 < near_focus.sum() < 1000                       # the disc, 16 px across its radius
    filled, measurable = focus_inverse_depth(flow, rho, valid, g, 9)
    assert measurable.all()
    assert np.allclose(filled[valid], rho[valid])              # away from the focus ρ is left as it was
    assert np.median(np.abs(filled[near_focus] / 0.05 - 1.0)) < 0.02
    assert np.abs(filled[near_focus] / 0.05 - 1.0).max() < 0.1


def test_a_focus_placed_wrong_does_not_make_the_wall_near_it_look_far():
    """The translation's direction estimated 8 px off (here: told straight ahead, moving 0.04 and 0.03 aside): the
    expansion rate does not depend on where the focus is, so the wall near it reads as the wall.  ΣF·g/Σ|g|² over
    the same window read parts of it at a quarter of the wall's ρ, a far blob that a flight followed as an opening."""
    t = np.array([0.04, 0.03, 1.0]) / np.linalg.norm([0.04, 0.03, 1.0])
    flow, _ = translation_flow(H, W, tuple(t), [[-20, -20], [-10, -20], [-10, -10]], rho_near=1 / 3, scale=0.1)
    flow = noisy(flow, 0)
    rho, valid, g = gap._inverse_depth(flow, FORWARD, ParallaxGapConfig())
    filled, _ = focus_inverse_depth(flow, rho, valid, g, 9)
    ratio = filled[~valid] / (0.1 / 3)
    assert 0.85 < ratio.min() and ratio.max() < 1.15

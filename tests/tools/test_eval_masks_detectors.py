"""flowgap-eval-masks' detector names: 'parallax_end' is the parallax detector looking past the wall's end too."""

from __future__ import annotations

import numpy as np
import pytest

from scenes.camera import PinholeCamera, Pose
from tools.eval_masks import DETECTORS, run_detector


def wall_end_flow(camera: PinholeCamera) -> tuple[np.ndarray, np.ndarray]:
    """A sideways step's flow: the empty space past the wall's end (left quarter, 25 times as deep as the wall)
    and an opening at half the wall's inverse depth; and the opening's mask."""
    h, w = camera.height, camera.width
    past = np.zeros((h, w), bool)
    past[:, : w // 4] = True
    gap = np.zeros((h, w), bool)
    gap[90:150, 170:230] = True
    rho = np.where(past, 0.02, np.where(gap, 0.25, 0.5))
    flow = np.zeros((h, w, 2), np.float32)
    flow[..., 0] = -rho * camera.fy * 0.05
    return flow, gap


def test_parallax_end_finds_the_opening_the_flown_detector_misses_past_the_walls_end():
    camera = PinholeCamera()
    flow, gap = wall_end_flow(camera)
    pose = Pose((0.0, 0.0, -1.5))
    assert not run_detector("parallax", flow, camera, pose, pose).found
    det = run_detector("parallax_end", flow, camera, pose, pose)
    assert det.found
    assert (det.mask & gap).sum() / (det.mask | gap).sum() > 0.9


def test_an_unknown_detector_names_the_choices():
    camera = PinholeCamera()
    with pytest.raises(KeyError, match="parallax_end"):
        run_detector("nope", np.zeros((camera.height, camera.width, 2), np.float32), camera, Pose((0, 0, 0)),
                     Pose((0, 0, 0)))
    assert "parallax_end" in DETECTORS

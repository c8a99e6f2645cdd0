"""The ``groundtruth`` flow backend: the renderer's exact flow, for evaluation only.

It needs what no camera has — the scene and both poses — so besides ``estimate(img1, img2)`` it must be told
the poses of the two frames (``set_poses`` or the ``pose1``/``pose2`` keywords).  Flow comes from
``scenes.groundtruth.flow_between`` (depth of both renders, occlusion-checked); pixels it marks invalid
(occluded, no depth, leaving the image) are filled from the nearest valid pixel so that detectors see a
dense field.  ``fill_invalid=False`` leaves them NaN instead.
"""

from __future__ import annotations

import cv2
import numpy as np

from companion.flow.base import check_pair


def fill_from_nearest(flow: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Replace invalid pixels of ``flow`` by the value of the nearest valid pixel."""
    if valid.all() or not valid.any():
        return flow
    _, labels = cv2.distanceTransformWithLabels((~valid).astype(np.uint8), cv2.DIST_L2, 5,
                                                labelType=cv2.DIST_LABEL_PIXEL)
    # label ids number the zero (valid) pixels in raster order
    ys, xs = np.nonzero(valid)
    lut = np.zeros((labels.max() + 1, 2), np.float32)
    lut[labels[ys, xs]] = flow[ys, xs]
    out = flow.copy()
    out[~valid] = lut[labels[~valid]]
    return out


class GroundTruthBackend:
    """Exact flow of a scene between two poses (``scene``: suite name, spec path/object)."""

    name = "groundtruth"
    device = "cpu"

    def __init__(self, scene, camera=None, render_backend: str = "cpu", fill_invalid: bool = True) -> None:
        from scenes.build import load_scene
        from scenes.camera import PinholeCamera

        self.spec, self.cloud = load_scene(scene)
        self.camera = camera if camera is not None else PinholeCamera()
        self.render_backend = render_backend
        self.fill_invalid = fill_invalid
        self._poses = None
        self._renders = None
        self.valid: np.ndarray | None = None   # validity mask of the last estimate

    def set_poses(self, pose1, pose2, renders=None) -> None:
        """Poses (NED body poses) of the next pair; ``renders`` (RenderResult, RenderResult) saves rendering."""
        self._poses = (pose1, pose2)
        self._renders = renders

    def estimate(self, img1: np.ndarray, img2: np.ndarray, *, pose1=None, pose2=None) -> np.ndarray:
        from scenes.groundtruth import flow_between

        h, w = check_pair(img1, img2)
        if pose1 is not None and pose2 is not None:
            self.set_poses(pose1, pose2)
        if self._poses is None:
            raise RuntimeError("groundtruth backend: call set_poses(pose1, pose2) (or pass pose1=, pose2=) first")
        if (h, w) != (self.camera.height, self.camera.width):
            raise ValueError(f"images are {w}×{h}, the camera is {self.camera.width}×{self.camera.height}")
        flow, valid = flow_between(self.cloud, self.camera, *self._poses, backend=self.render_backend,
                                   renders=self._renders)
        self._renders = None
        self.valid = valid
        flow = np.asarray(flow, np.float32)
        if self.fill_invalid:
            return fill_from_nearest(flow, valid)
        flow = flow.copy()
        flow[~valid] = np.nan
        return flow

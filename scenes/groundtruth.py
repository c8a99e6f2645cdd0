"""Ground truth from the scene: gap masks, dense optical flow between two poses, collision geometry.

* ``gap_mask``: pixels whose first visible surface (the label where transmittance crosses 0.5) lies
  beyond the wall, i.e. the opening as seen from the pose (``LABEL_BACKGROUND``).
* ``flow_between``: forward flow from image 1 to image 2. Each pixel centre of image 1 is back-projected
  with depth 1, moved into camera 2 and projected; it is valid when it has depth, lands inside image 2
  in front of the camera, and agrees with image 2's depth at that pixel (within ``depth_tol``, relative),
  so occluded and disoccluded pixels are invalid.
* ``load_collision``: the vehicle's collision geometry (see :mod:`scenes.collision`).
* ``corridor_clearance`` / ``passable_openings``: whether a body fits through an opening, flying along a heading
  (by default, for ``passable_openings``, square to the wall's face: the widest straight path through it).
"""

from __future__ import annotations

import cv2
import numpy as np

from scenes.camera import PinholeCamera, Pose, euler_to_quat
from scenes.collision import SceneCollision, load_collision
from scenes.render import RenderResult, render_splats
from scenes.spec import SceneSpec
from scenes.splats import LABEL_BACKGROUND, GaussianCloud

__all__ = ["gap_mask", "gap_mask_from_labels", "flow_between", "flow_from_depth", "warp_backward",
           "sample_pose_pair", "DEFAULT_PAIR_DISTANCE", "load_collision", "SceneCollision", "corridor_clearance",
           "passable_openings"]


def gap_mask_from_labels(label: np.ndarray) -> np.ndarray:
    """(H, W) bool: the label image shows something beyond the wall."""
    return np.asarray(label) == LABEL_BACKGROUND


def gap_mask(cloud: GaussianCloud, camera: PinholeCamera, pose: Pose | tuple, backend: str = "cpu") -> np.ndarray:
    """(H, W) bool gap mask at ``pose`` (renders the label image)."""
    return gap_mask_from_labels(render_splats(cloud, camera, pose, backend=backend).label)


def _pixel_rays(camera: PinholeCamera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    jj, ii = np.meshgrid(np.arange(camera.width, dtype=np.float64) + 0.5,
                         np.arange(camera.height, dtype=np.float64) + 0.5)
    px, py = camera.principal_point
    return jj, ii, np.stack([(jj - px) / camera.fx, (ii - py) / camera.fy, np.ones_like(jj)], -1)


def flow_from_depth(depth1: np.ndarray, depth2: np.ndarray, camera: PinholeCamera, pose1: Pose | tuple,
                    pose2: Pose | tuple, depth_tol: float = 0.03) -> tuple[np.ndarray, np.ndarray]:
    """(flow (H, W, 2) float32 [du, dv] from image 1 to image 2, valid (H, W) bool) from depths (H, W)."""
    r1, t1 = camera.world_to_camera(pose1)
    r2, t2 = camera.world_to_camera(pose2)
    jj, ii, rays = _pixel_rays(camera)
    d1 = np.asarray(depth1, np.float64)
    pc1 = rays * d1[..., None]
    pw = (pc1 - t1) @ r1            # R1^T (X - t1), row-vector form
    pc2 = pw @ r2.T + t2
    z2 = pc2[..., 2]
    px, py = camera.principal_point
    with np.errstate(divide="ignore", invalid="ignore"):
        u2 = camera.fx * pc2[..., 0] / z2 + px
        v2 = camera.fy * pc2[..., 1] / z2 + py
    flow = np.stack([u2 - jj, v2 - ii], -1)
    h, w = d1.shape
    valid = (d1 > 0) & (z2 > camera.near) & np.isfinite(u2) & np.isfinite(v2)
    valid &= (u2 >= 0) & (u2 < w) & (v2 >= 0) & (v2 < h)
    col = np.clip(np.floor(np.where(valid, u2, 0)).astype(np.int64), 0, w - 1)
    row = np.clip(np.floor(np.where(valid, v2, 0)).astype(np.int64), 0, h - 1)
    d2 = np.asarray(depth2, np.float64)[row, col]
    valid &= (d2 > 0) & (np.abs(d2 - z2) <= depth_tol * np.maximum(z2, 1e-6))
    flow = np.where(valid[..., None], flow, 0.0)
    return flow.astype(np.float32), valid


def flow_between(cloud: GaussianCloud, camera: PinholeCamera, pose1: Pose | tuple, pose2: Pose | tuple,
                 backend: str = "cpu", depth_tol: float = 0.03,
                 renders: tuple[RenderResult, RenderResult] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Ground-truth forward flow image 1 -> image 2 and its validity mask (renders both depths unless
    ``renders`` are given)."""
    if renders is None:
        renders = (render_splats(cloud, camera, pose1, backend=backend),
                   render_splats(cloud, camera, pose2, backend=backend))
    valid_alpha = renders[0].alpha > 0.99
    flow, valid = flow_from_depth(renders[0].depth, renders[1].depth, camera, pose1, pose2, depth_tol)
    return flow, valid & valid_alpha


def warp_backward(image2: np.ndarray, flow: np.ndarray) -> np.ndarray:
    """Sample image 2 at x + flow(x): reproduces image 1 where the flow is valid (bilinear)."""
    h, w = flow.shape[:2]
    jj, ii = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    return cv2.remap(image2, jj + flow[..., 0], ii + flow[..., 1], cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE)


DEFAULT_PAIR_DISTANCE = (0.6, 2.6)  # m before the wall's front face: the first pose of a training pair


def sample_pose_pair(spec: SceneSpec, rng: np.random.Generator, max_step: float = 0.15,
                     max_turn_rad: float = 0.05,
                     distance: tuple[float, float] = DEFAULT_PAIR_DISTANCE) -> tuple[Pose, Pose]:
    """Two nearby NED body poses in front of the wall, roughly facing its opening (for flow training).

    The first pose is ``distance`` (low, high) metres before the wall's front face (never more than 0.5 m
    behind the start x = 0), within about a metre of the opening's centre; the second is displaced by up to
    ``max_step`` metres per axis and rotated by up to ``max_turn_rad`` per axis. All draws come from
    ``rng``."""
    near, far = (float(v) for v in distance)
    if not (0.0 < near <= far and np.isfinite(far)):
        raise ValueError(f"distance must be a range 0 < low <= high in metres (got {distance})")
    poly = np.array(spec.openings[0].polygon()) if spec.openings else np.array([[0.0, -1.5]])
    cy, cz = poly.mean(0)
    x = spec.wall_x - rng.uniform(near, max(near, min(far, spec.wall_x + 0.5)))
    y = cy + rng.uniform(-1.0, 1.0)
    z = float(np.clip(cz + rng.uniform(-0.5, 0.5), -3.0, -0.5))
    yaw = np.arctan2(cy - y, spec.wall_x - x) * rng.uniform(0.3, 1.0)
    att = (rng.uniform(-0.08, 0.08), rng.uniform(-0.08, 0.08), yaw)
    p1 = Pose((float(x), float(y), z), euler_to_quat(*att))
    step = rng.uniform(-max_step, max_step, 3) * np.array([1.0, 0.6, 0.4])
    step[0] = abs(step[0])  # mostly forward, as in flight
    att2 = np.asarray(att) + rng.uniform(-max_turn_rad, max_turn_rad, 3)
    p2 = Pose((float(x + step[0]), float(y + step[1]), float(z + step[2])), euler_to_quat(*att2))
    return p1, p2


PASSABILITY_RESOLUTION_M = 0.001   # the grid (m) the clearance is measured on: 1 mm, a tenth of the margin


def corridor_clearance(spec: SceneSpec, index: int, heading_rad: float | None = None) -> float:
    """Clear radius (m) of opening ``index`` for a body flying straight along ``heading_rad`` (NED yaw; default
    the scene's start heading): the largest circle inside both the opening and its far edge as seen along the
    heading, i.e. the opening intersected with itself shifted across by ``thickness·tan(heading)`` (exact to
    :data:`PASSABILITY_RESOLUTION_M`)."""
    heading = np.radians(spec.start_yaw_deg) if heading_rad is None else heading_rad
    shift = spec.wall.thickness * float(np.tan(heading))
    poly = np.asarray(spec.openings[index].polygon(), dtype=np.float64)
    res = PASSABILITY_RESOLUTION_M
    lo = poly.min(0) - 2 * res
    size = np.ceil((poly.max(0) - lo + 2 * res) / res).astype(int) + 1 + int(np.ceil(abs(shift) / res))
    grid = np.zeros((size[1], size[0]), np.uint8)
    front = cv2.fillPoly(grid.copy(), [np.round((poly - lo) / res).astype(np.int32)], 1)
    back = cv2.fillPoly(grid.copy(), [np.round((poly - lo - (shift, 0.0)) / res).astype(np.int32)], 1)
    both = (front & back).astype(np.uint8)
    if not both.any():
        return 0.0
    # fillPoly fills the outline's own pixels, so the middle is one pixel further from the nearest pixel outside
    # than from the outline: that pixel is taken off (exact for edges along the grid, at most a pixel short for
    # others; counted in, a rectangle 0.47 m wide had 0.48 m of clearance, and passed for one a 0.38 m body with
    # 0.05 m each side fits through)
    return max(0.0, float(cv2.distanceTransform(both, cv2.DIST_L2, cv2.DIST_MASK_PRECISE).max()) - 1.0) * res


def passable_openings(spec: SceneSpec, body_radius_m: float, margin_m: float,
                      heading_rad: float | None = 0.0) -> list[bool]:
    """Per opening: whether a sphere of ``body_radius_m`` with ``margin_m`` to spare on every side fits through
    it flying along ``heading_rad`` (:func:`corridor_clearance`; None: the scene's start heading).  The default, 0,
    is square to the wall's face: the widest straight path through an opening (any other is the opening
    intersected with itself shifted by thickness·tan(heading)), and the one a companion that crosses a turned wall
    square to its face takes."""
    return [corridor_clearance(spec, i, heading_rad) >= body_radius_m + margin_m for i in range(len(spec.openings))]

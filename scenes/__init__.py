"""flowgap scenes: the world both processes see (scene specs, textures, splats, camera, renderer,
ground truth, collision). Imports neither ``companion`` nor ``sitl_vehicle``.

Conventions: world NED (x forward, y right, z down), metres, radians; quaternions (w, x, y, z) rotating
body -> world; camera OpenCV (x right, y down, z forward), pixel (row i, col j) centred at (j+0.5, i+0.5).
The vehicle starts at (0, 0, -1.5) looking along +x; the wall is the plane x = wall_x facing it; the
floor is z = 0.

Stable interfaces (other packages rely on these):

* ``scenes.library.SUITE`` -- the 16 suite names ``window{1..4}_{brick,granite,newspaper,stone}``;
  ``scenes.library.DEFAULT_SCENE`` = ``"window1_brick"``.
* ``scenes.load_scene(name_or_path) -> (SceneSpec, GaussianCloud)`` -- builds and caches on demand
  under ``cache/scenes/`` (override with ``$FLOWGAP_SCENE_CACHE``; kept within ``$FLOWGAP_SCENE_CACHE_MB``,
  least recently used scenes first, by ``scenes.cache``); for a capture scene ``.json``
  (``scenes.capture``: a third-party 3DGS ``.ply`` placed in NED) ``(CaptureSpec, GaussianCloud in NED)``.
  Both specs have ``start_ned`` and ``start_yaw_deg``.
* ``scenes.random_scene(rng: numpy.random.Generator) -> SceneSpec`` -- random training/Monte-Carlo
  scene; ``scenes.build.build_scene(spec) -> GaussianCloud`` builds it in memory (~0.2 s, no disk),
  ``load_scene(spec)`` also caches it on disk (~18 MB).
* ``scenes.camera.PinholeCamera(width=320, height=240, vfov_rad=radians(75), mount=CameraMount())``,
  ``scenes.camera.Pose(position, quat_wxyz)``, ``camera.world_to_camera(pose) -> (R, t)``,
  ``camera.project(points, pose)``.
* ``scenes.render.render_splats(cloud, camera, pose, backend="cpu"|"torch"|"reference")
  -> RenderResult(rgb HxWx3 uint8, depth HxW float32, alpha HxW float32, label HxW uint8)``.
  Labels: 0 none, 1 wall, 2 frame, 3 background (anything beyond the wall), 4 floor in front of it.
* ``scenes.groundtruth.gap_mask(cloud, camera, pose) -> HxW bool``,
  ``scenes.groundtruth.flow_between(cloud, camera, pose1, pose2) -> (flow HxWx2 float32, valid HxW bool)``
  (forward flow 1 -> 2, occlusion-checked; pass ``renders=(r1, r2)`` to reuse renders),
  ``scenes.groundtruth.sample_pose_pair(spec, rng) -> (Pose, Pose)`` for random training pairs.
* ``scenes.collision.load_collision(name_or_path) -> SceneCollision`` with ``.clearance((x, y, z))``
  (metres to the nearest solid, negative inside; wall slab minus openings, frames; not the floor) and
  ``.wall_x`` (front face); for a capture scene a ``scenes.occupancy.CaptureCollision`` (the distance field of
  its opaque splats, cached beside it) with ``.clearance`` and ``.gate`` (the rectangle to fly through).
* ``scenes.splats.read_ply / write_ply`` (standard 3DGS layout) raising ``PlyError`` on bad files.
"""

from __future__ import annotations

from typing import Any

__all__ = ["load_scene", "random_scene", "SUITE", "DEFAULT_SCENE", "render_splats", "PinholeCamera", "Pose"]


def __getattr__(name: str) -> Any:  # lazy, so that importing scenes.collision stays light
    if name == "load_scene":
        from scenes.build import load_scene

        return load_scene
    if name in ("random_scene", "SUITE", "DEFAULT_SCENE"):
        from scenes import library

        return getattr(library, name)
    if name == "render_splats":
        from scenes.render import render_splats

        return render_splats
    if name in ("PinholeCamera", "Pose"):
        from scenes import camera

        return getattr(camera, name)
    raise AttributeError(f"module 'scenes' has no attribute {name!r}")

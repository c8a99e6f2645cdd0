"""Gaussian splat rendering: one API, three backends.

``render_splats(cloud, camera, pose, backend="cpu")`` -> :class:`RenderResult` with rgb (H, W, 3) uint8,
depth (H, W) float32 (expected depth along the optical axis, 0 where empty), alpha (H, W) float32 and
label (H, W) uint8. ``pose`` is the NED body pose (``scenes.camera.Pose`` or (position, quat_wxyz));
the camera's mount turns it into the OpenCV world-to-camera transform.

Backends: ``"cpu"`` (numba, parallel, default), ``"torch"`` (CUDA when available, also CPU),
``"reference"`` (slow numpy oracle). Stages (project -> sort/bin -> rasterise) and the exact maths are
described in :mod:`scenes.render.common`.
"""

from __future__ import annotations

from scenes.render.common import RenderResult, render_reference

BACKENDS = ("cpu", "torch", "reference")


def render_splats(cloud, camera, pose, backend: str = "cpu", background=(0.0, 0.0, 0.0),
                  device: str | None = None) -> RenderResult:
    """Render ``cloud`` from the camera on a body at ``pose``. ``device`` is for the torch backend."""
    if backend == "cpu":
        from scenes.render.cpu import render_cpu

        return render_cpu(cloud, camera, pose, background)
    if backend == "torch":
        from scenes.render.torch_backend import render_torch

        return render_torch(cloud, camera, pose, background, device=device)
    if backend == "reference":
        return render_reference(cloud, camera, pose, background)
    raise ValueError(f"unknown render backend {backend!r}; use one of {BACKENDS}")


__all__ = ["BACKENDS", "RenderResult", "render_splats"]

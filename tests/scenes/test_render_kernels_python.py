"""The CPU renderer's numba kernels run as plain Python (their ``py_func``) give the image the compiled kernels
give: numba compiles what the source says (fastmath may move the last bit), and coverage, which cannot trace
compiled code, sees the kernels' lines run here."""

from __future__ import annotations

import numpy as np
import pytest

import scenes.render.cpu as cpu
from scenes.camera import PinholeCamera, Pose, euler_to_quat
from scenes.splats import GaussianCloud

KERNELS = ("prepare_kernel", "project_kernel", "sort_and_bin", "rasterise_kernel")


def _cloud(n: int, seed: int) -> GaussianCloud:
    rng = np.random.default_rng(seed)
    means = np.stack([rng.uniform(1.5, 4, n), rng.uniform(-1, 1, n), rng.uniform(-2.2, -0.8, n)], 1)
    means[:5] = [[-1.0, 0.0, -1.5], [2.0, 30.0, -1.5], [0.05, 0.0, -1.5], [2.0, 0.0, -1.5], [2.0, 0.0, -1.5]]
    return GaussianCloud(means, np.log(rng.uniform(0.01, 0.2, (n, 3))), rng.normal(size=(n, 4)),
                         rng.normal(1, 1.5, n), rng.normal(0, 0.3, (n, 16, 3)), rng.integers(1, 5, n))


@pytest.mark.parametrize("seed", [0, 1])
def test_the_kernels_as_python_render_what_the_compiled_kernels_render(monkeypatch, seed):
    # behind the camera, far off to the side, nearer than the near plane, and two at one place: the
    # kernels' culling and depth-ordering branches
    cloud = _cloud(120, seed)
    cam = PinholeCamera(40, 30)
    pose = Pose((0.1, 0.05, -1.5), euler_to_quat(0.04, -0.03, 0.06))
    compiled = cpu.render_cpu(cloud, cam, pose, background=(0.2, 0.3, 0.4))
    for name in KERNELS:
        monkeypatch.setattr(cpu, name, getattr(cpu, name).py_func)
    cloud = _cloud(120, seed)                      # a new cloud: nothing cached from the compiled run
    python = cpu.render_cpu(cloud, cam, pose, background=(0.2, 0.3, 0.4))
    assert python.alpha.max() > 0.5                # the view is not empty
    assert np.abs(python.rgb.astype(int) - compiled.rgb).max() <= 1
    assert np.abs(python.alpha - compiled.alpha).max() < 1e-4
    assert np.abs(python.depth - compiled.depth).max() < 1e-3
    assert (python.label != compiled.label).sum() <= 1

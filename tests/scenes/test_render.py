import dataclasses

import numpy as np
import pytest

from scenes.build import build_scene
from scenes.camera import START_POSE, PinholeCamera, Pose, euler_to_quat
from scenes.render import render_splats
from scenes.render.common import DILATION, project_reference
from scenes.render.cpu import project
from scenes.splats import LABEL_BACKGROUND, LABEL_WALL, GaussianCloud


def _single(mean, scales, quat=(1, 0, 0, 0), opacity_logit=0.0, sh=None):
    return GaussianCloud(np.array([mean]), np.log([scales]), np.array([quat]), np.array([opacity_logit]),
                         np.full((1, 1, 3), 1.0) if sh is None else sh, np.array([LABEL_WALL]))


def test_single_gaussian_pixel_and_covariance():
    cam = PinholeCamera(160, 120)
    pose = START_POSE
    mean = np.array([2.0, 0.3, -1.7])  # camera frame: X = 0.3, Y = -0.2, Z = 2.0
    sx, sy, sz = 0.08, 0.06, 0.05  # several pixels wide, so pixel sampling barely biases the moments
    cloud = _single(mean, (sx, sy, sz), opacity_logit=0.0)
    X, Y, Z = 0.3, -0.2, 2.0
    u_exp = cam.fx * X / Z + 80
    v_exp = cam.fy * Y / Z + 60
    # world axes x, y, z are camera z, x, y: the camera-frame covariance is diag(sy^2, sz^2, sx^2)
    sig_c = np.diag([sy**2, sz**2, sx**2])
    J = np.array([[cam.fx / Z, 0, -cam.fx * X / Z**2], [0, cam.fy / Z, -cam.fy * Y / Z**2]])
    cov_exp = J @ sig_c @ J.T + DILATION * np.eye(2)

    uv, conic, depth, rgb, opacity, box, visible = project(cloud, cam, pose)
    assert visible[0] and depth[0] == pytest.approx(2.0)
    assert uv[0] == pytest.approx([u_exp, v_exp], rel=1e-5)
    a, b, c = conic[0]
    assert np.linalg.inv([[a, b], [b, c]]) == pytest.approx(cov_exp, rel=1e-4)
    ref = project_reference(cloud, cam, pose)
    assert ref.cov2d[0] == pytest.approx([cov_exp[0, 0], cov_exp[0, 1], cov_exp[1, 1]], rel=1e-6)

    # the rendered footprint of one Gaussian is alpha itself (opacity 0.5 never saturates); its moments are
    # the mean and the covariance, less ~3 % from the 3-sigma box
    for backend in ("cpu", "reference", "torch"):
        res = render_splats(cloud, cam, pose, backend=backend)
        w = res.alpha.astype(np.float64)
        jj, ii = np.meshgrid(np.arange(160) + 0.5, np.arange(120) + 0.5)
        mu = np.array([(w * jj).sum(), (w * ii).sum()]) / w.sum()
        assert mu == pytest.approx([u_exp, v_exp], abs=0.02)
        d = np.stack([jj - mu[0], ii - mu[1]], -1)
        cov = np.einsum("hwi,hwj,hw->ij", d, d, w) / w.sum()
        assert cov == pytest.approx(cov_exp * 0.975, rel=0.03, abs=0.05)
        peak = np.unravel_index(np.argmax(w), w.shape)
        assert (peak[1], peak[0]) == (int(u_exp), int(v_exp))


def _closed(spec):
    return dataclasses.replace(spec, openings=(), name="closed")


def test_wall_depth_and_closed_wall_hides_background(light_spec):
    cloud = build_scene(_closed(light_spec))
    cam = PinholeCamera(96, 72)
    for pose in (START_POSE, Pose((1.0, 0.4, -1.2), euler_to_quat(0.05, -0.1, 0.3)),
                 Pose((2.4, -0.3, -1.8), euler_to_quat(0.0, 0.0, -0.6))):
        res = render_splats(cloud, cam, pose)
        assert not (res.label == LABEL_BACKGROUND).any()
        # the background's colour does not leak through the wall: removing it changes no wall pixel
        no_bg = render_splats(cloud.subset(np.nonzero(cloud.labels != LABEL_BACKGROUND)[0]), cam, pose)
        wall = res.label == LABEL_WALL
        diff = np.abs(res.rgb.astype(int) - no_bg.rgb)[wall]
        assert diff.max() <= 3 and diff.mean() < 0.5  # < 1 % of the background colour
        assert wall.mean() > 0.3
        if pose is START_POSE:
            assert np.abs(res.depth[wall] - light_spec.wall_x).max() <= 0.01 * light_spec.wall_x
            assert res.alpha[wall].min() > 0.99


def test_wall_depth_with_opening(brick_cloud, brick_spec):
    res = render_splats(brick_cloud, PinholeCamera(80, 60), START_POSE)
    wall = res.label == LABEL_WALL
    assert np.median(np.abs(res.depth[wall] - 3.0)) < 0.01 * 3.0
    bg = res.label == LABEL_BACKGROUND
    assert bg.any() and np.median(res.depth[bg]) == pytest.approx(brick_spec.background_x, rel=0.01)


def test_cpu_matches_torch(brick_cloud):
    """cpu and torch (on CPU) give the same image: mean absolute difference <= 1/255."""
    cam = PinholeCamera(160, 120)
    for pose in (START_POSE, Pose((1.2, 0.2, -1.4), euler_to_quat(0.03, 0.05, 0.1))):
        a = render_splats(brick_cloud, cam, pose, backend="cpu")
        b = render_splats(brick_cloud, cam, pose, backend="torch", device="cpu")
        assert np.abs(a.rgb.astype(float) - b.rgb).mean() <= 1.0
        assert (a.label != b.label).mean() < 1e-3
        assert np.abs(a.depth - b.depth).mean() < 1e-3


def test_cpu_matches_reference_with_sh3():
    rng = np.random.default_rng(1)
    n = 300
    means = np.stack([rng.uniform(2, 4, n), rng.uniform(-1, 1, n), rng.uniform(-2.2, -0.8, n)], 1)
    cloud = GaussianCloud(means, np.log(rng.uniform(0.01, 0.08, (n, 3))), rng.normal(size=(n, 4)),
                          rng.normal(1, 1, n), rng.normal(0, 0.3, (n, 16, 3)), rng.integers(1, 5, n))
    cam = PinholeCamera(64, 48)
    pose = Pose((0.2, 0.1, -1.5), euler_to_quat(0.05, 0.02, -0.05))
    a = render_splats(cloud, cam, pose, backend="cpu")
    r = render_splats(cloud, cam, pose, backend="reference")
    t = render_splats(cloud, cam, pose, backend="torch")
    for other in (r, t):
        assert np.abs(a.rgb.astype(int) - other.rgb).max() <= 1
        assert np.abs(a.depth - other.depth).max() < 1e-3
        assert (a.label != other.label).sum() <= 2


def test_unknown_backend(brick_cloud):
    with pytest.raises(ValueError, match="unknown render backend"):
        render_splats(brick_cloud, PinholeCamera(8, 6), START_POSE, backend="vulkan")


def test_frame_label_and_random_scenes(light_spec):
    from scenes.library import random_scene
    from scenes.spec import OpeningSpec

    framed = dataclasses.replace(light_spec, openings=(OpeningSpec("rect", (0.0, -1.5), (0.9, 0.9),
                                                                   frame_width=0.08),))
    res = render_splats(build_scene(framed), PinholeCamera(96, 72), START_POSE)
    assert (res.label == 2).any() and (res.label == LABEL_BACKGROUND).any()
    rng = np.random.default_rng(3)
    for _ in range(2):
        spec = dataclasses.replace(random_scene(rng), density=light_spec.density)
        cloud = build_scene(spec)
        res = render_splats(cloud, PinholeCamera(96, 72), START_POSE)
        assert (res.label == LABEL_BACKGROUND).mean() > 0.005   # the opening is in view from the start
        assert (res.label == LABEL_WALL).mean() > 0.3

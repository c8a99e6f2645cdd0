import math

import numpy as np
import pytest

from scenes.camera import START_POSE, CameraMount, PinholeCamera, Pose, euler_to_quat, matrix_to_quat, quat_to_matrix


def test_default_intrinsics():
    cam = PinholeCamera()
    assert (cam.width, cam.height) == (320, 240)
    assert cam.principal_point == (160.0, 120.0)
    assert 2 * math.atan(120 / cam.fy) == pytest.approx(math.radians(75))


def test_start_pose_looks_along_north():
    cam = PinholeCamera()
    uv, z = cam.project(np.array([[3.0, 0.0, -1.5], [3.0, 1.0, -1.5], [3.0, 0.0, -0.5]]), START_POSE)
    assert z[0] == pytest.approx(3.0)
    assert uv[0] == pytest.approx([160.0, 120.0])
    assert uv[1, 0] > 160 and uv[1, 1] == pytest.approx(120)   # east is image right
    assert uv[2, 1] > 120 and uv[2, 0] == pytest.approx(160)   # down is image down


def test_yaw_and_mount():
    cam = PinholeCamera()
    yawed = Pose((0.0, 0.0, -1.5), euler_to_quat(0.0, 0.0, math.pi / 2))  # facing east
    uv, z = cam.project(np.array([[0.0, 2.0, -1.5]]), yawed)
    assert z[0] == pytest.approx(2.0) and uv[0] == pytest.approx([160, 120])
    tilted = PinholeCamera(mount=CameraMount(offset=(0.1, 0.0, 0.0), rpy=(0.0, 0.2, 0.0)))  # pitched up
    uv, z = tilted.project(np.array([[3.0, 0.0, -1.5]]), START_POSE)
    assert uv[0, 1] > 120  # the camera looks up, so a level point appears low
    assert tilted.camera_centre(START_POSE) == pytest.approx([0.1, 0.0, -1.5])


def test_quaternion_round_trip():
    rng = np.random.default_rng(0)
    for _ in range(20):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        q = q if q[0] >= 0 else -q
        assert matrix_to_quat(quat_to_matrix(q)) == pytest.approx(q, abs=1e-9)

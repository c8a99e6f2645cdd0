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


def test_scaled_keeps_the_field_of_view_mount_and_clip_planes_at_the_new_size():
    mount = CameraMount(offset=(0.05, 0.0, 0.01), rpy=(0.0, 0.1, 0.0))
    cam = PinholeCamera(320, 240, math.radians(60), cx=150.0, cy=100.0, mount=mount, near=0.1, far=50.0)
    small = cam.scaled(160, 90)
    assert (small.width, small.height) == (160, 90)
    assert small.principal_point == (80.0, 45.0)              # a custom principal point does not carry over
    assert 2 * math.atan(45 / small.fy) == pytest.approx(math.radians(60))
    assert (small.vfov_rad, small.mount, small.near, small.far) == (cam.vfov_rad, mount, 0.1, 50.0)


def _qmul(a, b):
    """Hamilton product of (w, x, y, z) quaternions."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


def _axis_quat(axis, angle):
    s = math.sin(angle / 2)
    return (math.cos(angle / 2), axis[0] * s, axis[1] * s, axis[2] * s)


@pytest.mark.parametrize("roll, pitch, yaw", [(0.3, -0.2, 1.1), (-1.0, 0.7, -2.5), (2.9, 1.2, 0.4)])
def test_euler_to_quat_is_yaw_then_pitch_then_roll(roll, pitch, yaw):
    want = _qmul(_qmul(_axis_quat((0, 0, 1), yaw), _axis_quat((0, 1, 0), pitch)), _axis_quat((1, 0, 0), roll))
    assert euler_to_quat(roll, pitch, yaw) == pytest.approx(want, abs=1e-12)


def test_quat_to_matrix_normalises_and_refuses_zero():
    c, s = math.cos(0.4), math.sin(0.4)
    rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])                 # 0.4 rad about z
    assert quat_to_matrix(tuple(3.0 * v for v in _axis_quat((0, 0, 1), 0.4))) == pytest.approx(rz, abs=1e-12)
    for axis in [(1, 0, 0), (0, 1, 0)]:
        q = tuple(0.5 * v for v in _axis_quat(axis, 0.4))
        assert quat_to_matrix(q) == pytest.approx(quat_to_matrix(_axis_quat(axis, 0.4)), abs=1e-12)
        assert np.linalg.det(quat_to_matrix(q)) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="^zero quaternion$"):
        quat_to_matrix((0.0, 0.0, 0.0, 0.0))


@pytest.mark.parametrize("axis", [(1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (0.6, 0.0, -0.8),
                                  (0.0, -0.8, 0.6), (0.48, 0.6, 0.64)])
@pytest.mark.parametrize("angle_deg", [170.0, 100.0, 30.0])
def test_matrix_to_quat_of_a_rotation_about_an_axis(axis, angle_deg):
    """Rodrigues: R = I + sin θ K + (1 − cos θ) K², its quaternion (cos θ/2, sin θ/2 · axis)."""
    t = math.radians(angle_deg)
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    r = np.eye(3) + math.sin(t) * k + (1 - math.cos(t)) * k @ k
    assert matrix_to_quat(r) == pytest.approx(_axis_quat(axis, t), abs=1e-12)


def test_pose_of_accepts_a_pose_a_pair_or_a_position():
    p = Pose((1.0, 2.0, 3.0), (0.0, 1.0, 0.0, 0.0))
    assert Pose.of(p) is p
    assert Pose.of([(1, 2, 3), (0, 1, 0, 0)]) == p
    assert Pose.of((4, 5, 6)) == Pose((4.0, 5.0, 6.0), (1.0, 0.0, 0.0, 0.0))
    for bad in [((1, 2), (1, 0, 0, 0)), (1, 2, 3, 4)]:
        with pytest.raises(ValueError, match="cannot interpret"):
            Pose.of(bad)


def test_projecting_a_point_in_the_cameras_plane_does_not_warn():
    import warnings

    cam = PinholeCamera()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        uv, z = cam.project(np.array([[0.0, 1.0, -1.5], [0.0, 0.0, -1.5]]), START_POSE)   # depth 0
    assert z == pytest.approx([0.0, 0.0]) and not np.isfinite(uv).all()

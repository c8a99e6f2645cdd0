"""Our centroid filter's safeguards, and flow derotation with the attitude change."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.motion import body_to_world_from_euler, derotate, rotational_flow
from companion.tracking import ConfirmingCentroidFilter


def test_first_centroid_needs_confirmation():
    f = ConfirmingCentroidFilter()
    assert f.update((100, 100)) is None and not f.last_accepted
    assert f.update((110, 105)) == (110, 105) and f.last_accepted


def test_a_single_false_first_detection_does_not_lock_the_filter():
    f = ConfirmingCentroidFilter()
    f.update((300, 20))  # false
    f.update((150, 120))  # true, twice
    assert f.update((152, 121)) == (152, 121)


def test_within_tau_follows_and_a_jump_is_rejected_once_then_reacquired():
    f = ConfirmingCentroidFilter(reacquire_after=2)
    f.update((150, 120))
    f.update((150, 120))
    assert f.update((180, 130)) == (180, 130)  # within 80 px
    assert f.update((20, 20)) == (180, 130) and not f.last_accepted  # a jump: reuse
    assert f.update(None) == (180, 130)
    f.update((300, 200))
    assert f.update((305, 205)) == (305, 205)  # two agreeing fresh detections: the old one was stale


def test_rotational_flow_is_zero_without_rotation_and_derotate_removes_it():
    K = np.array([[156.4, 0, 160.0], [0, 156.4, 120.0], [0, 0, 1.0]])
    a1, a2 = (0.01, -0.02, 0.3), (0.013, -0.015, 0.302)
    same = body_to_world_from_euler(*a1)
    assert np.abs(rotational_flow(K, same, same, 240, 320)).max() < 1e-9
    rot = rotational_flow(K, body_to_world_from_euler(*a1), body_to_world_from_euler(*a2), 240, 320)
    assert np.abs(rot).max() > 0.5  # 0.3° of pitch is more than a pixel


def _yaw_flow(K, psi, h, w):
    """Hand-worked flow of a pure yaw ψ (nose right) at pixel centres (j + ½, i + ½): a ray at bearing α from
    the axis ends at α − ψ, so u' = cx + f·tan(α − ψ) and v' = cy + (v − cy)·cos α / cos(α − ψ)."""
    f, cx, cy = K[0, 0], K[0, 2], K[1, 2]
    ys, xs = np.mgrid[0:h, 0:w] + 0.5
    alpha = np.arctan((xs - cx) / f)
    return np.stack([cx + f * np.tan(alpha - psi) - xs, (ys - cy) * np.cos(alpha) / np.cos(alpha - psi) - (ys - cy)],
                    -1)


def test_rotational_flow_of_a_yaw_is_the_hand_worked_flow_and_derotate_removes_it():
    K = np.array([[150.0, 0, 80.0], [0, 150.0, 50.0], [0, 0, 1.0]])
    h, w, psi = 90, 170, math.radians(3.0)
    want = _yaw_flow(K, psi, h, w)
    got = rotational_flow(K, body_to_world_from_euler(0, 0, 0.2), body_to_world_from_euler(0, 0, 0.2 + psi), h, w)
    assert got.dtype == np.float32 and got.shape == (h, w, 2)
    assert got == pytest.approx(want, abs=1e-4)
    assert np.abs(derotate(want.astype(np.float32), K, (0, 0, 0.2), (0, 0, 0.2 + psi))).max() < 1e-4
    assert derotate(np.zeros((h, w, 2), np.float32), K, (0, 0, -0.1), (0, 0, -0.1 + psi)) == pytest.approx(-want,
                                                                                                            abs=1e-4)


def test_derotation_cancels_the_exact_flow_of_a_rendered_pure_rotation():
    """The camera turns on the spot (roll, pitch and yaw all change): the flow, from the rendered depth
    reprojected between the two poses (scenes.groundtruth, no derotation formula in it), is all rotation, so
    derotating it with the two attitudes leaves nothing; the same flow derotated with the attitudes swapped
    is left with twice the rotation."""
    from scenes import PinholeCamera, Pose, load_scene
    from scenes.camera import euler_to_quat
    from scenes.groundtruth import flow_between

    _, cloud = load_scene("window1_brick")
    camera = PinholeCamera()
    a1, a2 = (0.01, -0.02, 0.05), (0.025, 0.004, 0.068)          # about 1.5° on each axis
    here = (0.0, 0.0, -1.5)
    flow, valid = flow_between(cloud, camera, Pose(here, euler_to_quat(*a1)), Pose(here, euler_to_quat(*a2)))
    assert valid.mean() > 0.9 and np.abs(flow[valid]).max() > 3.0
    residual = derotate(flow, camera.K, a1, a2)[valid]
    assert np.abs(residual).max() < 0.05
    doubled = derotate(flow, camera.K, a2, a1)[valid]
    assert np.median(np.hypot(*doubled.T)) == pytest.approx(2 * np.median(np.hypot(*flow[valid].T)), rel=0.05)


def test_pitch_up_moves_the_image_down():
    # Nose up (positive pitch in FRD/NED): the scene moves down in the image (v grows).
    K = np.array([[156.4, 0, 160.0], [0, 156.4, 120.0], [0, 0, 1.0]])
    flow = rotational_flow(K, body_to_world_from_euler(0, 0, 0), body_to_world_from_euler(0, math.radians(1), 0),
                           240, 320)
    assert flow[120, 160, 1] == pytest.approx(156.4 * math.tan(math.radians(1)), rel=1e-3)


def test_level_pixel_undoes_the_pitch():
    from companion.motion import level_pixel

    K = np.array([[156.4, 0, 160.0], [0, 156.4, 120.0], [0, 0, 1.0]])
    pitched = rotational_flow(K, body_to_world_from_euler(0, 0, 0), body_to_world_from_euler(0, math.radians(4), 0),
                              240, 320)
    # A point at the level image centre seen by the nose-up camera, mapped back to the level camera.
    u, v = 160.0 + pitched[120, 160, 0], 120.0 + pitched[120, 160, 1]
    assert v > 130  # nose up: the point appears lower
    assert level_pixel((u, v), K, 0.0, math.radians(4)) == pytest.approx((160.0, 120.0), abs=0.05)
    assert level_pixel((100.0, 50.0), K, 0.0, 0.0) == pytest.approx((100.0, 50.0))


# --- level and tilted pixels against hand-worked camera geometry (x right, y down, z forward) --------------

KF, CX, CY = 156.4, 160.0, 120.0
KM = np.array([[KF, 0, CX], [0, KF, CY], [0, 0, 1.0]])


@pytest.mark.parametrize("pitch_deg", [6.0, -10.0])
def test_the_pitched_cameras_centre_is_above_the_level_centre_by_f_tan_pitch(pitch_deg):
    from companion.motion import level_pixel, tilted_pixel

    t = math.radians(pitch_deg)
    # nose up by t: the camera's axis points t above the horizon, which the level camera sees f·tan t higher
    assert level_pixel((CX, CY), KM, 0.0, t) == pytest.approx((CX, CY - KF * math.tan(t)), abs=1e-9)
    # and the level camera's centre (the heading's axis) appears f·tan t lower to the pitched camera
    assert tilted_pixel((CX, CY), KM, 0.0, t) == pytest.approx((CX, CY + KF * math.tan(t)), abs=1e-9)


def test_rolled_right_the_level_horizon_rises_on_the_right():
    from companion.motion import level_pixel, tilted_pixel

    phi, d = math.radians(20.0), 50.0
    # right wing down by φ: the camera's x axis tips down, a level point d px right of centre appears at
    # (cx + d·cos φ, cy − d·sin φ)
    shown = (CX + d * math.cos(phi), CY - d * math.sin(phi))
    assert tilted_pixel((CX + d, CY), KM, phi, 0.0) == pytest.approx(shown, abs=1e-9)
    assert level_pixel(shown, KM, phi, 0.0) == pytest.approx((CX + d, CY), abs=1e-9)
    # rolled and pitched: the two are inverses
    for pixel in [(40.0, 30.0), (250.0, 200.0)]:
        assert level_pixel(tilted_pixel(pixel, KM, 0.2, -0.15), KM, 0.2, -0.15) == pytest.approx(pixel, abs=1e-9)


@pytest.mark.parametrize("off_deg", [2.0, -4.5])
def test_a_camera_yawed_off_the_heading_sees_its_axis_aside_by_f_tan_yaw(off_deg):
    from companion.motion import level_pixel, tilted_pixel

    t = math.radians(off_deg)
    # yawed right by t: the camera's axis points t right of the heading, which the heading's camera sees
    # f·tan t to the right; the heading's axis appears f·tan t to the left to the yawed camera
    assert level_pixel((CX, CY), KM, 0.0, 0.0, t) == pytest.approx((CX + KF * math.tan(t), CY), abs=1e-9)
    assert tilted_pixel((CX, CY), KM, 0.0, 0.0, t) == pytest.approx((CX - KF * math.tan(t), CY), abs=1e-9)
    for pixel in [(40.0, 30.0), (250.0, 200.0)]:
        assert level_pixel(tilted_pixel(pixel, KM, 0.1, -0.05, t), KM, 0.1, -0.05, t) == pytest.approx(pixel,
                                                                                                         abs=1e-9)


@pytest.mark.parametrize("yaw, heading, expected", [
    (0.3, 0.1, 0.2), (-0.1, 0.1, -0.2), (math.pi - 0.05, -math.pi + 0.05, -0.1), (-math.pi + 0.05, math.pi - 0.05, 0.1),
])
def test_off_heading_is_the_yaw_less_the_heading_wrapped(yaw, heading, expected):
    from companion.motion import off_heading

    assert off_heading(yaw, heading) == pytest.approx(expected, abs=1e-12)


def test_openings_are_placed_as_seen_along_the_heading_whatever_the_cameras_yaw():
    from types import SimpleNamespace

    from companion.opening import candidates_in

    t = math.radians(3.0)
    seen = SimpleNamespace(found=True, candidates=None, clear_centre=(CX, CY), centroid=(CX, CY))
    heading = 1.2
    # the vehicle yawed 3° right of its heading sees an opening straight ahead of its camera: that opening is
    # f·tan 3° right of the heading's axis; looking along the heading, it is where the camera sees it
    (yawed,) = candidates_in(seen, KM, (0.0, 0.0, heading + t), heading)
    assert yawed.target_px == pytest.approx((CX + KF * math.tan(t), CY), abs=1e-9)
    (along,) = candidates_in(seen, KM, (0.0, 0.0, heading), heading)
    assert along.target_px == pytest.approx((CX, CY), abs=1e-9)
    # without a heading (a replay's image phase): placed along the camera's own yaw, as before
    assert candidates_in(seen, KM, (0.0, 0.0, heading + t))[0].target_px == pytest.approx((CX, CY), abs=1e-9)


def test_a_ray_behind_the_other_camera_keeps_the_pixel():
    from companion.motion import level_pixel, tilted_pixel

    # pitched 120° nose up the camera's axis points backwards and up: behind the level camera, and the other way
    assert level_pixel((200.0, 50.0), KM, 0.0, math.radians(120)) == (200.0, 50.0)
    assert tilted_pixel((200.0, 50.0), KM, 0.0, math.radians(120)) == (200.0, 50.0)


@pytest.mark.parametrize("yaw_deg, move_ned, expected", [
    (0.0, (0.2, 0.0, 0.0), (0.0, 0.0, 0.2)),       # heading north, moving north: along the optical axis
    (90.0, (0.0, 0.2, 0.0), (0.0, 0.0, 0.2)),      # heading east, moving east: the same
    (0.0, (0.0, 0.1, 0.0), (0.1, 0.0, 0.0)),       # heading north, moving east: to the camera's right
    (90.0, (0.0, 0.0, 0.1), (0.0, 0.1, 0.0)),      # moving down: the camera's y (down) whatever the heading
])
def test_a_move_in_ned_is_expressed_in_the_first_cameras_axes(yaw_deg, move_ned, expected):
    from companion.motion import translation_in_camera

    start = (1.0, -2.0, -1.5)
    end = tuple(a + b for a, b in zip(start, move_ned, strict=True))
    assert translation_in_camera(start, end, (0.0, 0.0, math.radians(yaw_deg))) == pytest.approx(expected, abs=1e-12)
    # pitched nose-down by 10°, a level move north has a component up in the camera (y negative)
    pitched = translation_in_camera((0, 0, 0), (1.0, 0, 0), (0.0, math.radians(-10.0), 0.0))
    assert pitched[1] == pytest.approx(-math.sin(math.radians(10.0))) and pitched[2] > 0.98

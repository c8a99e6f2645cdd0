import dataclasses
import math

import cv2
import numpy as np
import pytest

from scenes.camera import START_POSE, PinholeCamera, Pose, euler_to_quat
from scenes.groundtruth import flow_between, gap_mask, warp_backward
from scenes.render import render_splats


def test_warping_frame2_by_flow_reproduces_frame1(brick_cloud):
    cam = PinholeCamera(160, 120)
    pairs = [(Pose((0.5, 0.0, -1.5)), Pose((0.5, 0.06, -1.5))),
             (Pose((0.5, 0.0, -1.5)), Pose((0.75, 0.05, -1.45), euler_to_quat(0.02, 0.03, 0.04))),
             (Pose((1.0, 0.2, -1.6)), Pose((1.0, 0.2, -1.6), euler_to_quat(0.0, 0.0, -0.03)))]
    for p1, p2 in pairs:
        r1, r2 = render_splats(brick_cloud, cam, p1), render_splats(brick_cloud, cam, p2)
        flow, valid = flow_between(brick_cloud, cam, p1, p2, renders=(r1, r2))
        assert flow.shape == (120, 160, 2) and flow.dtype == np.float32 and valid.mean() > 0.7
        warped = warp_backward(r2.rgb, flow)
        err = np.abs(warped.astype(float) - r1.rgb)[valid].mean()
        unwarped = np.abs(r2.rgb.astype(float) - r1.rgb)[valid].mean()
        assert err < 6.0 and err < 0.4 * unwarped, (err, unwarped)
    # the same pose gives zero flow everywhere valid
    flow, valid = flow_between(brick_cloud, cam, pairs[0][0], pairs[0][0])
    assert valid.mean() > 0.95 and np.abs(flow[valid]).max() < 1e-3


def test_occlusions_are_invalid(brick_cloud, brick_spec):
    """Moving sideways uncovers background beside the opening's edge: those pixels have no match."""
    cam = PinholeCamera(160, 120)
    p1, p2 = Pose((1.5, 0.0, -1.5)), Pose((1.5, 0.3, -1.5))
    r1 = render_splats(brick_cloud, cam, p1)
    flow, valid = flow_between(brick_cloud, cam, p1, p2)
    bg = r1.label == 3
    assert (~valid[bg]).mean() > 0.05  # part of the seen background is hidden by the wall in view 2


def test_gap_mask_matches_projected_opening(brick_cloud, brick_spec):
    """The mask is the opening's outline (the part seen through the slab), give or take the ~1 px that
    the edge splats' screen-space blur (0.3 px^2 dilation) covers."""
    cam = PinholeCamera(320, 240)
    for pose in (START_POSE, Pose((1.0, 0.2, -1.4), euler_to_quat(0.0, 0.05, -0.05))):
        mask = gap_mask(brick_cloud, cam, pose)
        poly = np.array(brick_spec.openings[0].polygon())
        # the opening's outline at the back face bounds what is seen through the slab from the front
        inter = None
        for x in (brick_spec.wall_x, brick_spec.wall_back_x):
            pts = np.stack([np.full(len(poly), x), poly[:, 0], poly[:, 1]], 1)
            uv, _ = cam.project(pts, pose)
            m = np.zeros((240, 320), np.uint8)
            cv2.fillPoly(m, [np.round((uv - 0.5) * 16).astype(np.int32)], 1, shift=4)  # pixel centres
            inter = m if inter is None else inter & m
        expected = inter.astype(bool)
        iou = (mask & expected).sum() / (mask | expected).sum()
        assert iou > 0.8, iou
        k = np.ones((3, 3), np.uint8)
        inner = cv2.erode(expected.astype(np.uint8), k, iterations=2).astype(bool)
        outer = cv2.dilate(expected.astype(np.uint8), k, iterations=1).astype(bool)
        assert mask[inner].all() and not mask[~outer].any()


def test_sample_pose_pair(brick_cloud, brick_spec):
    from scenes.groundtruth import sample_pose_pair

    rng = np.random.default_rng(0)
    cam = PinholeCamera(96, 72)
    a = sample_pose_pair(brick_spec, np.random.default_rng(4))
    assert a == sample_pose_pair(brick_spec, np.random.default_rng(4))
    for _ in range(3):
        p1, p2 = sample_pose_pair(brick_spec, rng)
        assert p1.position[0] < brick_spec.wall_x - 0.5 and p2.position[0] >= p1.position[0]
        flow, valid = flow_between(brick_cloud, cam, p1, p2)
        assert valid.mean() > 0.5


def test_sample_pose_pair_distance_range(brick_spec):
    from scenes.groundtruth import DEFAULT_PAIR_DISTANCE, sample_pose_pair

    # the default range is the one training pairs always had: the same draws as asking for it
    assert DEFAULT_PAIR_DISTANCE == (0.6, 2.6)
    for seed in range(5):
        assert sample_pose_pair(brick_spec, np.random.default_rng(seed)) == sample_pose_pair(
            brick_spec, np.random.default_rng(seed), distance=(0.6, 2.6))
    far = [brick_spec.wall_x - sample_pose_pair(brick_spec, np.random.default_rng(s), distance=(2.9, 3.4))[0]
           .position[0] for s in range(20)]
    assert min(far) >= 2.9 and max(far) <= min(3.4, brick_spec.wall_x + 0.5)
    # never further back than 0.5 m behind the start (x = 0), however far the range reaches
    deep = [sample_pose_pair(brick_spec, np.random.default_rng(s), distance=(0.6, 50.0))[0].position[0]
            for s in range(20)]
    assert min(deep) >= -0.5 - 1e-9
    for bad in ((0.0, 2.0), (3.0, 2.0), (1.0, float("nan"))):
        with pytest.raises(ValueError, match="distance"):
            sample_pose_pair(brick_spec, np.random.default_rng(0), distance=bad)


# --- flow_from_depth / flow_between on analytic scenes: a fronto-parallel plane seen from two poses ----------

from types import SimpleNamespace  # noqa: E402

from scenes.groundtruth import (  # noqa: E402
    corridor_clearance,
    flow_from_depth,
    gap_mask_from_labels,
    passable_openings,
    sample_pose_pair,
)
from scenes.spec import OpeningSpec, SceneSpec, WallSpec  # noqa: E402
from scenes.splats import LABEL_BACKGROUND, LABEL_FLOOR, LABEL_FRAME, LABEL_NONE, LABEL_WALL  # noqa: E402

# non-square, principal point off the centre (and cx != cy), so swapped axes or offsets show
PLANE_CAM = PinholeCamera(64, 48, cx=30.25, cy=21.75)


def pixel_centres(cam):
    u, v = np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5)
    return u, v


def test_flow_of_a_sideways_move_in_front_of_a_plane_is_the_stereo_disparity():
    """A camera moved right by b in front of a plane at depth D: every pixel moves by -fx b / D (stereo
    disparity), vertically by 0; valid exactly where the moved pixel still lands inside image 2."""
    cam, depth, b = PLANE_CAM, 2.0, 0.3
    p1, p2 = Pose((0.0, 0.0, -1.5)), Pose((0.0, b, -1.5))  # body +y is image right
    d = np.full((cam.height, cam.width), depth, np.float32)
    flow, valid = flow_from_depth(d, d, cam, p1, p2)
    assert flow.shape == (48, 64, 2) and flow.dtype == np.float32 and valid.dtype == bool
    du = -cam.fx * b / depth
    u, _ = pixel_centres(cam)
    expect_valid = (u + du >= 0) & (u + du < cam.width)
    assert 0 < expect_valid.sum() < expect_valid.size
    np.testing.assert_array_equal(valid, expect_valid)
    np.testing.assert_allclose(flow[..., 0][valid], du, atol=1e-4)
    np.testing.assert_allclose(flow[..., 1][valid], 0.0, atol=1e-4)
    assert np.all(flow[~valid] == 0.0)  # invalid pixels carry no flow
    # moving down (body +z, image down) by b: the flow is vertical, -fy b / D
    flow, valid = flow_from_depth(d, d, cam, p1, Pose((0.0, 0.0, -1.5 + b)))
    _, v = pixel_centres(cam)
    dv = -cam.fy * b / depth
    np.testing.assert_array_equal(valid, (v + dv >= 0) & (v + dv < cam.height))
    np.testing.assert_allclose(flow[..., 1][valid], dv, atol=1e-4)
    np.testing.assert_allclose(flow[..., 0][valid], 0.0, atol=1e-4)


def test_flow_of_a_forward_move_expands_about_the_principal_point():
    """Moving forward by s towards a plane at D scales offsets from the principal point by D / (D - s)."""
    cam, depth, s = PLANE_CAM, 2.0, 0.5
    u, v = pixel_centres(cam)
    px, py = cam.principal_point
    d1 = np.full((cam.height, cam.width), depth)
    d2 = np.full((cam.height, cam.width), depth - s)
    flow, valid = flow_from_depth(d1, d2, cam, Pose((0.0, 0.0, -1.5)), Pose((s, 0.0, -1.5)))
    scale = depth / (depth - s)
    u2, v2 = px + (u - px) * scale, py + (v - py) * scale
    expect = (u2 >= 0) & (u2 < cam.width) & (v2 >= 0) & (v2 < cam.height)
    np.testing.assert_array_equal(valid, expect)
    np.testing.assert_allclose(flow[..., 0][valid], (u2 - u)[valid], atol=1e-4)
    np.testing.assert_allclose(flow[..., 1][valid], (v2 - v)[valid], atol=1e-4)
    # image 2's depth must agree with the moved point's depth (D - s), relative to depth_tol
    for rel, tol, ok in ((0.02, 0.03, True), (0.02, 0.01, False), (-0.02, 0.03, True), (-0.02, 0.01, False),
                         (0.05, 0.03, False)):
        _, valid = flow_from_depth(d1, d2 * (1 + rel), cam, Pose((0.0, 0.0, -1.5)), Pose((s, 0.0, -1.5)),
                                   depth_tol=tol)
        np.testing.assert_array_equal(valid, expect & ok)
    # the default tolerance is 3 %
    _, valid = flow_from_depth(d1, d2 * 1.025, cam, Pose((0.0, 0.0, -1.5)), Pose((s, 0.0, -1.5)))
    np.testing.assert_array_equal(valid, expect)
    _, valid = flow_from_depth(d1, d2 * 1.035, cam, Pose((0.0, 0.0, -1.5)), Pose((s, 0.0, -1.5)))
    assert not valid.any()


def test_flow_is_invalid_without_depth_behind_the_near_plane_or_at_a_mismatched_pixel():
    cam, depth = PLANE_CAM, 1.0
    shape = (cam.height, cam.width)
    p1 = Pose((0.0, 0.0, -1.5))
    d1 = np.full(shape, depth)
    # no depth in image 1 (empty pixel): invalid
    holes = d1.copy()
    holes[5, 7] = 0.0
    holes[40, 60] = -1.0
    _, valid = flow_from_depth(holes, d1, cam, p1, p1)
    assert valid.sum() == valid.size - 2 and not valid[5, 7] and not valid[40, 60]
    # no depth in image 2 where the pixel lands: invalid
    _, valid = flow_from_depth(d1, holes, cam, p1, p1)
    assert valid.sum() == valid.size - 2 and not valid[5, 7] and not valid[40, 60]
    # the plane closer than the near plane (0.05 m) after the move: invalid, just beyond it: valid at the centre
    for s, near_ok in ((0.97, False), (0.9, True)):
        d2 = np.full(shape, depth - s)
        _, valid = flow_from_depth(d1, d2, cam, p1, Pose((s, 0.0, -1.5)))
        r, c = int(cam.principal_point[1]), int(cam.principal_point[0])
        assert valid[r, c] == near_ok and (valid.any() == near_ok)
    # moved past the plane: it is behind the camera, nothing valid
    _, valid = flow_from_depth(d1, d1, cam, p1, Pose((2.0, 0.0, -1.5)))
    assert not valid.any()
    # image 2's depth is read at the pixel the point lands in (floor of its coordinates, row then column):
    # a sideways move of b lands column j on column j - 5 (du = -5.5 px: pixel centre j + 0.5 -> j - 5)
    b = 5.5 * depth / cam.fx
    d2 = d1.copy()
    d2[:, 20] = 3.0  # column 20 of image 2 sees something else: image-1 column 25 has no match
    d2[10, :] = 3.0  # and row 10: image-1 row 10 has none
    flow, valid = flow_from_depth(d1, d2, cam, p1, Pose((0.0, b, -1.5)))
    cols = np.arange(cam.width)
    expect_cols = (cols >= 5) & (cols != 25)
    expect = expect_cols[None, :] & (np.arange(cam.height) != 10)[:, None]
    np.testing.assert_array_equal(valid, expect)
    np.testing.assert_allclose(flow[..., 0][valid], -5.5, atol=1e-4)


def test_flow_from_depth_accepts_pose_tuples_and_rotations():
    """A pure yaw (poses given as (position, quaternion) tuples): the point seen at a pixel, rotated into the
    yawed camera by hand (camera x right, z forward; yawing right turns x towards -z), projects where the
    flow says."""
    cam, depth = PLANE_CAM, 2.0
    yaw = 0.05
    d1 = np.full((cam.height, cam.width), depth)
    # a point straight ahead at depth D has depth D cos(yaw) after the yaw (within 0.1 % near the centre)
    d2 = np.full((cam.height, cam.width), depth * math.cos(yaw))
    flow, valid = flow_from_depth(d1, d2, cam, ((0.0, 0.0, -1.5), (1.0, 0.0, 0.0, 0.0)),
                                  ((0.0, 0.0, -1.5), euler_to_quat(0.0, 0.0, yaw)))
    px, py = cam.principal_point
    # the pixel whose centre is nearest the principal point: (30.5, 21.5) -> ray (0.25/fx, -0.25/fy, 1)
    r, c = 21, 30
    x1, y1 = (c + 0.5 - px) / cam.fx * depth, (r + 0.5 - py) / cam.fy * depth
    x2 = x1 * math.cos(yaw) - depth * math.sin(yaw)  # camera x right, z forward: yaw right turns x towards -z
    z2 = x1 * math.sin(yaw) + depth * math.cos(yaw)
    assert valid[r, c]
    assert flow[r, c, 0] == pytest.approx(cam.fx * x2 / z2 + px - (c + 0.5), abs=1e-4)
    assert flow[r, c, 1] == pytest.approx(cam.fy * y1 / z2 + py - (r + 0.5), abs=1e-4)


def test_flow_between_uses_the_given_renders_and_needs_opaque_pixels():
    cam, depth, b = PLANE_CAM, 2.0, 0.3
    shape = (cam.height, cam.width)
    p1, p2 = Pose((0.0, 0.0, -1.5)), Pose((0.0, b, -1.5))
    alpha = np.full(shape, 1.0, np.float32)
    alpha[3, 40] = 0.99  # not above 0.99: not opaque enough
    alpha[4, 40] = 0.995
    d = np.full(shape, depth, np.float32)
    r1 = SimpleNamespace(depth=d, alpha=alpha)
    r2 = SimpleNamespace(depth=d, alpha=np.zeros(shape, np.float32))  # image 2's alpha is not used
    flow, valid = flow_between(None, cam, p1, p2, renders=(r1, r2))
    ref_flow, ref_valid = flow_from_depth(d, d, cam, p1, p2)
    np.testing.assert_array_equal(flow, ref_flow)  # flow_between passes the flow through unchanged
    expect = ref_valid.copy()
    expect[3, 40] = False
    np.testing.assert_array_equal(valid, expect)
    assert ref_valid[3, 40] and valid[4, 40]
    # depth_tol is passed on: image 2 2 % deeper is invalid at 1 %
    r2 = SimpleNamespace(depth=d * 1.02, alpha=alpha)
    assert flow_between(None, cam, p1, p2, renders=(r1, r2))[1].sum() == expect.sum()
    assert not flow_between(None, cam, p1, p2, depth_tol=0.01, renders=(r1, r2))[1].any()


def test_warp_backward_samples_image2_bilinearly_at_x_plus_flow():
    h, w = 6, 9
    jj, ii = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    image2 = (10.0 * jj + 100.0 * ii).astype(np.float32)  # linear: bilinear sampling is exact
    flow = np.zeros((h, w, 2), np.float32)
    flow[..., 0], flow[..., 1] = 1.5, 0.25
    out = warp_backward(image2, flow)
    assert out.shape == (h, w)
    inside = (jj + 1.5 <= w - 1) & (ii + 0.25 <= h - 1)
    np.testing.assert_allclose(out[inside], (10.0 * (jj + 1.5) + 100.0 * (ii + 0.25))[inside], atol=1e-2)
    # beyond the border the edge is replicated: sampling at x = w - 1 + 0.5 gives column w - 1
    np.testing.assert_allclose(out[0, w - 1], 10.0 * (w - 1) + 25.0, atol=1e-2)
    flow[..., 0], flow[..., 1] = -3.0, -2.0
    out = warp_backward(image2, flow)
    np.testing.assert_allclose(out[0, 0], 0.0, atol=1e-3)
    np.testing.assert_allclose(out[3, 5], 10.0 * 2 + 100.0 * 1, atol=1e-3)


def test_gap_mask_from_labels_is_the_background_label():
    labels = np.array([[LABEL_NONE, LABEL_WALL, LABEL_FRAME], [LABEL_BACKGROUND, LABEL_FLOOR, LABEL_BACKGROUND]],
                      np.uint8)
    mask = gap_mask_from_labels(labels)
    assert mask.dtype == bool
    np.testing.assert_array_equal(mask, [[False, False, False], [True, False, True]])
    assert gap_mask_from_labels([[LABEL_BACKGROUND]]).tolist() == [[True]]  # array-likes too


# --- sample_pose_pair: the documented ranges, checked with a recording stand-in for the generator -----------

class RecordingRng:
    """Stands in for np.random.Generator.uniform: records every (low, high, size) and returns the point at
    ``frac`` of the way from low to high."""

    def __init__(self, frac):
        self.frac = frac
        self.calls = []

    def uniform(self, low, high, size=None):
        self.calls.append((low, high, size))
        value = low + self.frac * (high - low)
        return value if size is None else np.full(size, value)


def quat_close(q1, q2):
    return np.allclose(q1, q2, atol=1e-12) or np.allclose(q1, -np.asarray(q2), atol=1e-12)


@pytest.mark.parametrize("frac", [0.0, 1.0, 0.25])
def test_sample_pose_pair_draws_the_documented_ranges(frac):
    spec = SceneSpec(openings=(OpeningSpec("rect", center=(0.4, -1.2), size=(0.8, 0.6)),
                               OpeningSpec("rect", center=(-2.0, -2.5), size=(0.5, 0.5))))
    rng = RecordingRng(frac)
    p1, p2 = sample_pose_pair(spec, rng, max_step=0.2, max_turn_rad=0.04, distance=(1.0, 2.0))
    (x_lo, x_hi, _), (y_lo, y_hi, _), (z_lo, z_hi, _), (r_lo, r_hi, _), (pi_lo, pi_hi, _), \
        (f_lo, f_hi, _), (s_lo, s_hi, s_n), (t_lo, t_hi, t_n) = rng.calls[:3] + rng.calls[4:6] + [rng.calls[3]] \
        + rng.calls[6:]
    assert len(rng.calls) == 8
    # distance before the wall, the offsets around the first opening's centre, the yaw factor
    assert (x_lo, x_hi) == (1.0, 2.0) and (y_lo, y_hi) == (-1.0, 1.0) and (z_lo, z_hi) == (-0.5, 0.5)
    assert (f_lo, f_hi) == (0.3, 1.0) and (r_lo, r_hi) == (-0.08, 0.08) and (pi_lo, pi_hi) == (-0.08, 0.08)
    assert (s_lo, s_hi, s_n) == (-0.2, 0.2, 3) and (t_lo, t_hi, t_n) == (-0.04, 0.04, 3)
    x = spec.wall_x - (1.0 + frac)
    y = 0.4 + (-1.0 + 2 * frac)
    z = -1.2 + (-0.5 + frac)
    assert p1.position == pytest.approx((x, y, z), abs=1e-12)
    yaw = math.atan2(0.4 - y, spec.wall_x - x) * (0.3 + 0.7 * frac)
    att = np.array([-0.08 + 0.16 * frac, -0.08 + 0.16 * frac, yaw])
    assert quat_close(p1.quat_wxyz, euler_to_quat(*att))
    step = (-0.2 + 0.4 * frac) * np.array([1.0, 0.6, 0.4])
    step[0] = abs(step[0])  # always forward
    assert p2.position == pytest.approx((x + step[0], y + step[1], z + step[2]), abs=1e-12)
    assert quat_close(p2.quat_wxyz, euler_to_quat(*(att + (-0.04 + 0.08 * frac))))
    assert all(isinstance(c, float) for c in (*p1.position, *p2.position))


def test_sample_pose_pair_clips_height_and_range_and_defaults_without_an_opening():
    # an opening high up and one near the floor: the first pose stays between 3 m and 0.5 m up
    for cz, expect in ((-4.0, -3.0), (-0.2, -0.5)):
        spec = SceneSpec(openings=(OpeningSpec("rect", center=(0.0, cz), size=(0.5, 0.5)),))
        p1, _ = sample_pose_pair(spec, RecordingRng(0.5))
        assert p1.position[2] == expect
    # no opening: aims at (y, z) = (0, -1.5)
    spec = SceneSpec(openings=())
    rng = RecordingRng(0.5)
    p1, _ = sample_pose_pair(spec, rng)
    assert p1.position[1:] == (0.0, -1.5)
    # the default range (0.6, 2.6), its far end limited to 0.5 m behind x = 0 (wall 1.5 m away: 2.0 m)
    near_wall = SceneSpec(wall=WallSpec(distance=1.5))
    rng = RecordingRng(1.0)
    p1, _ = sample_pose_pair(near_wall, rng)
    assert rng.calls[0][:2] == (0.6, 2.0) and p1.position[0] == pytest.approx(-0.5)
    # a range entirely beyond that limit: the near end wins (never an empty or inverted range)
    rng = RecordingRng(1.0)
    p1, _ = sample_pose_pair(near_wall, rng, distance=(2.5, 3.0))
    assert rng.calls[0][:2] == (2.5, 2.5) and p1.position[0] == pytest.approx(1.5 - 2.5)
    # default step and turn
    rng = RecordingRng(0.0)
    sample_pose_pair(SceneSpec(), rng)
    assert rng.calls[-2] == (-0.15, 0.15, 3) and rng.calls[-1] == (-0.05, 0.05, 3)
    for bad in ((-1.0, 2.0), (2.0, float("inf"))):
        with pytest.raises(ValueError, match="distance"):
            sample_pose_pair(SceneSpec(), RecordingRng(0.5), distance=bad)
    sample_pose_pair(SceneSpec(), RecordingRng(0.5), distance=(1.0, 1.0))  # low == high is a range


# --- corridor_clearance / passable_openings ----------------------------------------------------------------

RES = 0.0015  # clearances are exact to PASSABILITY_RESOLUTION_M (0.001 m), a vertex rounded to the grid aside


def test_a_slot_a_centimetre_narrower_than_the_body_and_its_margins_is_not_passable():
    """The hard world's threshold: a 0.38 m body with 0.05 m each side needs 0.48 m.  Slots 0.47 and 0.479 m wide
    do not pass (the outline's own pixels, counted in, once made the first 0.48 m); 0.48 m does, and 0.481 m."""
    def slot(width):
        return SceneSpec(openings=(OpeningSpec("rect", center=(0.013, -1.517), size=(width, 1.2)),))
    for width in (0.47, 0.479):
        assert corridor_clearance(slot(width), 0, 0.0) == pytest.approx(width / 2, abs=RES)
        assert passable_openings(slot(width), 0.19, 0.05) == [False]
    for width in (0.48, 0.481):
        assert passable_openings(slot(width), 0.19, 0.05) == [True]
    # an opening a millimetre across (a pixel of the grid, its outline) leaves no clearance at all
    assert corridor_clearance(SceneSpec(openings=(OpeningSpec("rect", center=(0.0, -1.5), size=(0.001, 0.001)),)),
                              0, 0.0) == 0.0


def test_corridor_clearance_of_rectangles_circles_and_a_slant():
    wall = WallSpec(thickness=0.2)
    wide = SceneSpec(wall=wall, openings=(OpeningSpec("rect", center=(0.3, -1.4), size=(1.2, 0.5)),
                                          OpeningSpec("rect", center=(-1.5, -1.5), size=(0.5, 1.2)),
                                          OpeningSpec("ellipse", center=(1.8, -2.0), size=(0.7, 0.7))))
    # head-on: the inscribed circle, half the smaller side (rect), the radius (circle, 64-gon: cos(pi/64) r)
    assert corridor_clearance(wide, 0, 0.0) == pytest.approx(0.25, abs=RES)
    assert corridor_clearance(wide, 1, 0.0) == pytest.approx(0.25, abs=RES)
    assert corridor_clearance(wide, 2, 0.0) == pytest.approx(0.35, abs=0.012)
    # flying at 25 deg the far edge is seen shifted sideways (along y) by t tan(25 deg): it narrows the opening
    # that is narrow along y, and not the one that is narrow along z
    shift = 0.2 * math.tan(math.radians(25.0))
    for heading in (math.radians(25.0), math.radians(-25.0)):
        assert corridor_clearance(wide, 0, heading) == pytest.approx(0.25, abs=RES)
        assert corridor_clearance(wide, 1, heading) == pytest.approx((0.5 - shift) / 2, abs=RES)
    # the default heading is the scene's start heading
    turned = SceneSpec(wall=wall, openings=wide.openings, start_yaw_deg=25.0)
    assert corridor_clearance(turned, 1) == pytest.approx((0.5 - shift) / 2, abs=RES)
    assert corridor_clearance(turned, 1, 0.0) == pytest.approx(0.25, abs=RES)
    # a slant that shifts the far edge by more than the width: no straight line through at all
    assert corridor_clearance(wide, 1, math.radians(80.0)) == 0.0  # shift 1.13 m > 0.5 m
    # ... and across the wide one a sliver is left, at its far side for either sign of the heading
    sliver = (1.2 - 0.2 * math.tan(math.radians(80.0))) / 2
    assert corridor_clearance(wide, 0, math.radians(80.0)) == pytest.approx(sliver, abs=RES)
    assert corridor_clearance(wide, 0, math.radians(-80.0)) == pytest.approx(sliver, abs=RES)
    # a big opening far from the origin (the grid covers it wherever it is)
    far = SceneSpec(wall=wall, openings=(OpeningSpec("rect", center=(3.0, -3.0), size=(2.0, 1.6)),))
    assert corridor_clearance(far, 0, 0.0) == pytest.approx(0.8, abs=RES)
    assert corridor_clearance(far, 0, math.radians(60.0)) == pytest.approx(0.8, abs=RES)  # 2 - 0.35 > 1.6
    # a thick wall and a steep heading: the shift (0.9 m) is larger than the margin around the polygon
    thick = SceneSpec(wall=WallSpec(thickness=0.9), openings=(OpeningSpec("rect", center=(0.0, -1.5),
                                                                          size=(2.0, 2.0)),))
    assert corridor_clearance(thick, 0, math.radians(45.0)) == pytest.approx((2.0 - 0.9) / 2, abs=RES)
    assert corridor_clearance(thick, 0, math.radians(-45.0)) == pytest.approx((2.0 - 0.9) / 2, abs=RES)


def test_passable_openings_compares_the_clearance_with_radius_plus_margin():
    spec = SceneSpec(wall=WallSpec(thickness=0.2),
                     openings=(OpeningSpec("rect", center=(0.3, -1.4), size=(1.2, 0.5)),
                               OpeningSpec("rect", center=(-1.5, -1.5), size=(0.3, 1.2))))
    c0, c1 = corridor_clearance(spec, 0, 0.0), corridor_clearance(spec, 1, 0.0)
    assert c1 < c0
    assert passable_openings(spec, c1 / 2, c1 / 2, 0.0) == [True, True]  # exactly the clearance fits
    assert passable_openings(spec, c1, 1e-3, 0.0) == [True, False]
    assert passable_openings(spec, 1e-3, c1, 0.0) == [True, False]
    assert passable_openings(spec, c0 / 2, c0 / 2 + 1e-3, 0.0) == [False, False]
    # along a heading: the narrow-in-y opening closes first
    heading = math.radians(20.0)
    c1h = corridor_clearance(spec, 1, heading)
    assert c1h < c1 - 0.02
    assert passable_openings(spec, c1h, 0.0, heading) == [True, True]
    assert passable_openings(spec, c1h + 0.01, 0.0, heading) == [True, False]
    assert passable_openings(spec, c1h + 0.01, 0.0) == [True, True]  # the default heading is 0 here
    # ... and square to the wall's face whatever the start heading: the widest straight path through it
    turned = dataclasses.replace(spec, start_yaw_deg=20.0)
    assert passable_openings(turned, c1h + 0.01, 0.0) == [True, True]
    assert passable_openings(turned, c1h + 0.01, 0.0, None) == [True, False]     # along the start heading
    assert passable_openings(SceneSpec(openings=()), 0.1, 0.0) == []


def test_the_render_backend_is_passed_on():
    cloud, pose = None, Pose((0.0, 0.0, -1.5))
    with pytest.raises(ValueError, match="unknown render backend 'no-such'"):
        gap_mask(cloud, PLANE_CAM, pose, backend="no-such")
    with pytest.raises(ValueError, match="unknown render backend 'no-such'"):
        flow_between(cloud, PLANE_CAM, pose, pose, backend="no-such")


# fx = 24 / tan(atan(0.75)) = 32 exactly: with dyadic depths and moves every coordinate below is exact, so the
# bounds (inclusive at 0, exclusive at the width / height) and the tolerance (inclusive) are tested at the edge
EXACT_CAM = PinholeCamera(64, 48, vfov_rad=2 * math.atan(0.75), cx=16.0, cy=8.0)


def test_flow_validity_bounds_are_exact():
    cam = EXACT_CAM
    assert cam.fx == 32.0 and cam.fy == 32.0
    shape = (cam.height, cam.width)
    d = np.full(shape, 2.0)
    p1 = Pose((0.0, 0.0, -1.5))
    # moving right by 1.03125 m: column 16 (centre 16.5) lands on u = 0 exactly (valid), column 15 just left
    _, valid = flow_from_depth(d, d, cam, p1, Pose((0.0, 1.03125, -1.5)))
    assert valid[:, 16].all() and not valid[:, 15].any()
    # moving left so that column 47 (centre 47.5) lands on u = 64 = the width exactly: outside
    b = (64.0 - 47.5) * 2.0 / 32.0
    _, valid = flow_from_depth(d, d, cam, p1, Pose((0.0, -b, -1.5)))
    assert valid[:, 46].all() and not valid[:, 47:].any()
    # the same vertically: row 8 (centre 8.5) lands on v = 0 moving down by 0.53125 m ...
    _, valid = flow_from_depth(d, d, cam, p1, Pose((0.0, 0.0, -1.5 + 0.53125)))
    assert valid[8, :].all() and not valid[7, :].any()
    # ... and row 39 (centre 39.5) on v = 48 = the height moving up by (48 - 39.5 - 8) / 16
    b = (48.0 - 39.5) * 2.0 / 32.0
    _, valid = flow_from_depth(d, d, cam, p1, Pose((0.0, 0.0, -1.5 - b)))
    assert valid[38, :].all() and not valid[39:, :].any()
    # the depth tolerance is inclusive: |1.5 - 1| = 0.5 * 1
    ones = np.ones(shape)
    assert flow_from_depth(ones, 1.5 * ones, cam, p1, p1, depth_tol=0.5)[1].all()
    assert not flow_from_depth(ones, 1.5 * ones, cam, p1, p1, depth_tol=0.4375)[1].any()
    # the near plane is exclusive: a plane at 1 m after moving 0.75 m towards it is at 0.25 m
    near = PinholeCamera(64, 48, vfov_rad=2 * math.atan(0.75), cx=16.0, cy=8.0, near=0.25)
    assert not flow_from_depth(ones, 0.25 * ones, near, p1, Pose((0.75, 0.0, -1.5)))[1].any()
    assert flow_from_depth(ones, 0.25 * ones, cam, p1, Pose((0.75, 0.0, -1.5)))[1].any()


def test_flow_reads_image2_depth_in_the_first_and_last_rows_and_columns():
    cam = EXACT_CAM
    shape = (cam.height, cam.width)
    d = np.full(shape, 2.0)
    p1 = Pose((0.0, 0.0, -1.5))
    for move, (rows, cols) in (((0.0, 1.0, -1.5), (slice(None), 0)), ((0.0, -1.0, -1.5), (slice(None), -1)),
                               ((0.0, 0.0, -1.0), (0, slice(None))), ((0.0, 0.0, -2.0), (-1, slice(None)))):
        # a 1 m move is 16 px: the pixels landing in the first / last column (row) of image 2 see 3 m there
        d2 = d.copy()
        d2[rows, cols] = 3.0
        _, ref = flow_from_depth(d, d, cam, p1, Pose(move))
        _, valid = flow_from_depth(d, d2, cam, p1, Pose(move))
        lost = ref & ~valid
        assert lost.sum() == (cam.height if cols != slice(None) else cam.width)


def test_flow_needs_depth_in_both_images_whatever_the_tolerance():
    cam = EXACT_CAM
    shape = (cam.height, cam.width)
    p1 = Pose((0.0, 0.0, -1.5))
    d1 = np.full(shape, 1.0)
    d1[4, 20] = 0.0  # no surface: stays invalid even where its (degenerate) point would match image 2
    d2 = np.full(shape, 0.5)
    _, valid = flow_from_depth(d1, d2, cam, p1, Pose((-0.5, 0.0, -1.5)))  # back 0.5 m: its centre lands on 0.5
    assert not valid.any()
    d2 = np.ones(shape)
    d2[8, 16] = 0.0  # the pixel at the principal point sees nothing in image 2
    _, valid = flow_from_depth(np.ones(shape), d2, cam, p1, p1, depth_tol=1.0)
    assert valid.sum() == valid.size - 1 and not valid[8, 16]
    # the tolerance is relative to the depth, also below 1 m
    small = np.full(shape, 0.5)
    assert not flow_from_depth(small, small * 1.04, cam, p1, p1)[1].any()
    assert flow_from_depth(small, small * 1.02, cam, p1, p1)[1].all()


def test_a_plane_through_the_camera_centre_is_invalid_without_warnings():
    import warnings

    cam = PinholeCamera(64, 48, vfov_rad=2 * math.atan(0.75), cx=16.5, cy=8.5)  # a pixel centre on the axis
    d = np.ones((cam.height, cam.width))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        flow, valid = flow_from_depth(d, d, cam, Pose((0.0, 0.0, -1.5)), Pose((1.0, 0.0, -1.5)))  # z2 = 0: x/0, 0/0
    assert not valid.any() and np.all(flow == 0.0)


def test_both_renders_use_the_backend_asked_for(monkeypatch):
    import scenes.groundtruth as gt

    calls = []
    shape = (PLANE_CAM.height, PLANE_CAM.width)

    def fake_render(cloud, camera, pose, backend="cpu"):
        calls.append((pose, backend))
        return SimpleNamespace(depth=np.full(shape, 2.0, np.float32), alpha=np.ones(shape, np.float32),
                               label=np.full(shape, LABEL_BACKGROUND, np.uint8))

    monkeypatch.setattr(gt, "render_splats", fake_render)
    p1, p2 = Pose((0.0, 0.0, -1.5)), Pose((0.0, 0.1, -1.5))
    gt.flow_between(None, PLANE_CAM, p1, p2, backend="torch")
    assert calls == [(p1, "torch"), (p2, "torch")]
    calls.clear()
    assert gt.gap_mask(None, PLANE_CAM, p1, backend="torch").all()
    assert calls == [(p1, "torch")]

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

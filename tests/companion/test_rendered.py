"""Flow and gap detection on rendered suite frames against the renderer's ground truth (needs ``scenes``)."""

import json

import numpy as np
import pytest

groundtruth = pytest.importorskip("scenes.groundtruth")

from companion.flow import make_flow_backend  # noqa: E402
from companion.flow.groundtruth import GroundTruthBackend, fill_from_nearest  # noqa: E402
from companion.gap import CameraMotion, detect_gap_parallax  # noqa: E402
from tests.companion.synthetic import iou  # noqa: E402

POSE1, POSE2 = (1.0, 0.0, -1.5), (1.08, 0.06, -1.5)     # 2 m from the wall, diagonal step


@pytest.fixture(scope="module")
def rendered():
    from scenes.build import load_scene
    from scenes.camera import PinholeCamera, Pose
    from scenes.render import render_splats

    spec, cloud = load_scene("window1_brick")
    camera = PinholeCamera()
    p1, p2 = Pose(POSE1), Pose(POSE2)
    r1, r2 = render_splats(cloud, camera, p1), render_splats(cloud, camera, p2)
    flow, valid = groundtruth.flow_between(cloud, camera, p1, p2, renders=(r1, r2))
    return {"spec": spec, "cloud": cloud, "camera": camera, "p1": p1, "p2": p2, "r1": r1, "r2": r2,
            "flow": flow, "valid": valid, "truth": groundtruth.gap_mask_from_labels(r1.label)}


@pytest.mark.parametrize("preset, bound", [("ultrafast", 0.8), ("medium", 0.25), ("fine", 0.12)])
def test_dis_epe_on_rendered_pair(rendered, preset, bound):
    flow = make_flow_backend("dis", preset=preset).estimate(rendered["r1"].rgb, rendered["r2"].rgb)
    valid = rendered["valid"]
    assert valid.mean() > 0.8
    epe = np.hypot(*(flow - rendered["flow"])[valid].T)
    assert epe.mean() < bound, f"DIS {preset}: mean EPE {epe.mean():.3f} px over {valid.sum()} valid pixels"


def test_parallax_detector_on_rendered_dis_flow(rendered):
    flow = make_flow_backend("dis", preset="fine").estimate(rendered["r1"].rgb, rendered["r2"].rgb)
    cam = rendered["camera"]
    motion = CameraMotion(focal_px=cam.fy, principal_point=(cam.principal_point[0] - 0.5,
                                                            cam.principal_point[1] - 0.5))
    res = detect_gap_parallax(flow, motion=motion)
    assert res.found, res.reason
    assert iou(res.mask, rendered["truth"]) >= 0.85


def test_groundtruth_backend_matches_scenes_flow(rendered):
    backend = make_flow_backend("groundtruth", scene=rendered["spec"], camera=rendered["camera"])
    with pytest.raises(RuntimeError, match="set_poses"):
        backend.estimate(rendered["r1"].rgb, rendered["r2"].rgb)
    flow = backend.estimate(rendered["r1"].rgb, rendered["r2"].rgb, pose1=rendered["p1"], pose2=rendered["p2"])
    valid = rendered["valid"]
    np.testing.assert_allclose(flow[valid], rendered["flow"][valid], atol=1e-4)
    assert np.isfinite(flow).all()
    assert isinstance(backend, GroundTruthBackend)


def test_fill_from_nearest():
    flow = np.zeros((3, 4, 2), np.float32)
    flow[0, 0] = (5, 6)
    flow[2, 3] = (-1, -2)
    valid = np.zeros((3, 4), bool)
    valid[0, 0] = valid[2, 3] = True
    out = fill_from_nearest(flow, valid)
    np.testing.assert_array_equal(out[0, 1], (5, 6))
    np.testing.assert_array_equal(out[2, 2], (-1, -2))


def test_eval_masks_cli_smoke(tmp_path):
    from tools.eval_masks import main

    rc = main(["--quick", "--scenes", "window1_brick", "--backends", "dis:medium", "raft", "--detectors",
               "parallax", "paper", "--out", str(tmp_path), "--no-progress", "--raft-weights",
               str(tmp_path / "missing.pth")])
    assert rc == 0
    data = json.loads((tmp_path / "eval_masks.json").read_text())
    assert len(data["rows"]) == 2 * 2                        # 2 viewpoint pairs × 1 backend × 2 detectors
    row = data["rows"][0]
    assert {"scene", "backend", "detector", "iou", "centroid_err_px", "detected", "ms"} <= set(row)
    assert "raft" in data["meta"]["skipped_backends"]
    parallax = [r for r in data["rows"] if r["detector"] == "parallax"]
    assert all(r["detected"] and r["iou"] > 0.8 for r in parallax)
    # the areas bound the IoU: it is at most the smaller over the larger
    assert all(r["iou"] <= min(r["mask_area_px"], r["truth_area_px"]) / max(r["mask_area_px"], r["truth_area_px"])
               + 1e-9 for r in parallax)
    assert (tmp_path / "eval_masks.md").read_text().startswith("# Gap masks")
    assert (tmp_path / "montage.png").stat().st_size > 1000


def test_eval_masks_on_random_scenes_places_the_viewpoints_before_each_opening(tmp_path):
    from scenes.library import random_scene
    from tools.eval_masks import main, make_viewpoints

    spec = random_scene(np.random.default_rng([4, 0xF1, 0]))
    poly = np.asarray(spec.openings[0].polygon())
    views = make_viewpoints(spec=spec)
    assert sorted({round(v.position[1], 9) for v in views}) == pytest.approx(
        sorted([poly[:, 0].mean(), poly[:, 0].mean() - 0.3]))
    assert {round(spec.wall_x - v.position[0], 6) for v in views} == {3.0, 2.0, 1.2}
    assert make_viewpoints()[0].position == (0.0, 0.0, -1.5)              # the suite's stay where they were
    rc = main(["--quick", "--random", "2", "--seed", "4", "--backends", "dis:medium", "--detectors", "parallax",
               "--out", str(tmp_path), "--no-progress"])
    assert rc == 0
    data = json.loads((tmp_path / "eval_masks.json").read_text())
    assert {r["scene"] for r in data["rows"]} == {spec.name, random_scene(np.random.default_rng([4, 0xF1, 1])).name}
    assert len(list((tmp_path / "scenes").glob("*.json"))) == 2 and data["meta"]["seed"] == 4
    assert np.median([r["iou"] for r in data["rows"]]) > 0.6


def test_variational_refinement_sharpens_a_coarse_flow_towards_the_truth(rendered):
    """Started from the exact flow blurred to RAFT's 1/8 grid (block means, upsampled bilinearly), the
    refinement lowers the error, most of all on the planar wall where the images' gradients pin the match."""
    import cv2

    from companion.flow.raft.variational import variational_refine

    truth, valid = rendered["flow"], rendered["valid"]
    h, w = truth.shape[:2]
    coarse = cv2.resize(cv2.resize(np.where(valid[..., None], truth, 0).astype(np.float32), (w // 8, h // 8),
                                   interpolation=cv2.INTER_AREA), (w, h), interpolation=cv2.INTER_LINEAR)
    coarse = coarse + np.float32([0.4, -0.3])          # and a sub-pixel bias, as a coarse matcher leaves
    before = np.hypot(*(coarse - truth)[valid].T).mean()
    refined = variational_refine(rendered["r1"].rgb, rendered["r2"].rgb, coarse, levels=2, iterations=10)
    after = np.hypot(*(refined - truth)[valid].T).mean()
    assert after < 0.5 * before, (before, after)
    assert after < 0.2
    np.testing.assert_array_equal(variational_refine(rendered["r1"].rgb, rendered["r2"].rgb, coarse, levels=0),
                                  coarse)
    assert refined is not coarse and np.isfinite(refined).all()


def _flown(cloud, camera, heading: float, off: float, places: list) -> object:
    """The last :func:`companion.look.see_frame` view of window1_brick from frame pairs taken at ``places``
    (north, east, down; each pair from one to the next) along ``heading`` (0: the suite faces north) by a vehicle
    whose yaw is ``off`` that heading."""
    import math

    from companion.gap import get_detector
    from companion.look import see_frame
    from companion.opening import OpeningTracker
    from companion.perception import perceive
    from companion.wall import WallTrack
    from scenes.camera import Pose, euler_to_quat
    from scenes.render import render_splats

    flow, detect = make_flow_backend("dis", preset="fine"), get_detector("parallax")
    openings, wall = OpeningTracker(), WallTrack()
    attitude = (0.0, 0.0, heading + off)
    for a, b in zip(places[:-1], places[1:], strict=True):
        first, second = (render_splats(cloud, camera, Pose(p, euler_to_quat(*attitude))).rgb for p in (a, b))
        seen = perceive(first, second, attitude, attitude, camera.K, flow, detect, True, math.dist(a, b), 0.02)
        view = see_frame(seen, first, a, b, attitude, math.dist(a, b), False, camera.K, heading, openings, wall)
    return view


def _placed(cloud, camera, heading: float, off: float) -> tuple:
    """(wall distance, wall turn, offset right) of window1_brick's opening after five pairs stepping 0.08 m on
    and 0.12 m across (1.9-1.5 m from the wall, 0.04-0.16 m right of the opening's centre)."""
    places = [(1.1 + 0.08 * k, 0.1 + (0.06 if k % 2 else -0.06), -1.5) for k in range(6)]
    view = _flown(cloud, camera, heading, off, places)
    return view.wall_distance, view.wall_yaw, view.sight.offset_m[0]


def test_an_opening_is_placed_where_it_is_whatever_the_vehicles_yaw_off_its_heading(rendered):
    """A vehicle yawed 3° off its heading sees the opening 1.6 m ahead 0.08 m aside of where it is; placed as a
    level camera along the heading sees it, it is where the unyawed vehicle places it (measured with RAFT on a
    hard-world scene: 0.003-0.009 m apart, against 0.08-0.09 m before)."""
    import math

    along = _placed(rendered["cloud"], rendered["camera"], 0.0, 0.0)
    assert along[2] == pytest.approx(-0.16, abs=0.03)                # the last frame's 0.16 m right of it
    for off_deg in (-3.0, 3.0):
        distance, turn, offset = _placed(rendered["cloud"], rendered["camera"], 0.0, math.radians(off_deg))
        assert offset == pytest.approx(along[2], abs=0.02), off_deg
        assert distance == pytest.approx(along[0], rel=0.02) and turn == pytest.approx(along[1], abs=0.01)


def test_a_turned_walls_distance_is_read_where_the_first_frame_looked(rendered):
    """Flown along a heading 15° off the wall's normal, stepping 0.3 m across and 0.05 m on per pair: forward flow
    gives the wall's depth from the second frame where the first frame looked, and put ahead of the second frame
    it was 0.3·tan 15° = 0.08 m off (measured here: 0.066 m short, and 0.005 m long read where it was)."""
    import math

    heading = math.radians(15.0)
    places = [(1.4 + 0.05 * k, -0.75 + 0.3 * k, -1.5) for k in range(6)]   # across the wall, left to right
    view = _flown(rendered["cloud"], rendered["camera"], heading, 0.0, places)
    north = places[-1][0]
    truth = (rendered["spec"].wall.distance - north) / math.cos(heading)   # along the heading to the wall
    assert view.wall_yaw == pytest.approx(heading, abs=0.03)
    assert view.wall_distance == pytest.approx(truth, abs=0.025)

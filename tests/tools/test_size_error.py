"""tools.size_error: near-threshold openings rendered on the approach, sized as the companion sizes them."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from companion.opening import OpeningConfig
from companion.servo import ServoConfig
from scenes.groundtruth import corridor_clearance
from scenes.spec import OpeningSpec, SceneSpec
from tools import size_error


@pytest.mark.parametrize("opening", [
    OpeningSpec("rect", center=(0.2, -1.4), size=(0.9, 0.7)),
    OpeningSpec("ellipse", center=(-0.3, -1.6), size=(0.6, 0.8)),
    OpeningSpec("polygon", vertices=((-0.4, -1.9), (0.35, -1.95), (0.5, -1.2), (-0.3, -1.1), (-0.5, -1.5))),
])
def test_an_opening_is_scaled_alone_to_the_clear_radius_asked_for(opening):
    other = OpeningSpec("rect", center=(1.5, -1.5), size=(0.4, 0.4))
    spec = SceneSpec(openings=(other, opening))
    scaled = size_error.scaled_opening(spec, 1, 0.23)
    assert len(scaled.openings) == 1 and scaled.openings[0].shape == opening.shape
    assert corridor_clearance(scaled, 0, 0.0) == pytest.approx(0.23, abs=0.002)
    # about its own middle: a rectangle keeps its centre
    if opening.shape == "rect":
        assert scaled.openings[0].center == opening.center
        assert scaled.openings[0].size[0] / scaled.openings[0].size[1] == pytest.approx(0.9 / 0.7)


def test_the_clear_centre_is_the_middle_of_the_largest_circle_inside():
    # a square's plateau is a single point: its middle
    y, z = size_error.clear_centre_yz(OpeningSpec("rect", center=(0.3, -1.2), size=(0.4, 0.4)))
    assert (y, z) == pytest.approx((0.3, -1.2), abs=0.003)
    # a triangle's incentre: legs 0.6 along y and z from (0, -1): incircle radius (a + b - c) / 2
    tri = OpeningSpec("polygon", vertices=((0.0, -1.0), (0.6, -1.0), (0.0, -1.6)))
    r = (0.6 + 0.6 - math.hypot(0.6, 0.6)) / 2
    assert size_error.clear_centre_yz(tri) == pytest.approx((r, -1.0 - r), abs=0.004)
    # an elongated one's plateau is a segment: its middle, where the servo aims, not an end
    slot = OpeningSpec("rect", center=(0.3, -1.2), size=(1.2, 0.4))
    assert size_error.clear_centre_yz(slot) == pytest.approx((0.3, -1.2), abs=0.003)


@pytest.mark.parametrize("yaw_deg", [0.0, 15.0, -20.0])
def test_the_camera_looks_along_the_start_heading_at_the_clear_centre_from_the_distance_asked(yaw_deg):
    spec = SceneSpec(start_yaw_deg=yaw_deg)
    centre = (0.25, -1.4)
    pose, euler = size_error.approach_pose(spec, centre, 1.3, (0.0, 0.0), (0.0, 0.0))
    yaw = math.radians(yaw_deg)
    ahead = np.asarray(pose.position) + 1.3 * np.array([math.cos(yaw), math.sin(yaw), 0.0])
    assert ahead == pytest.approx((spec.wall_x, *centre))
    assert euler == (0.0, 0.0, pytest.approx(yaw))
    # across: right of the heading and down
    moved, _ = size_error.approach_pose(spec, centre, 1.3, (0.1, 0.05), (0.0, 0.0))
    shift = np.asarray(moved.position) - np.asarray(pose.position)
    assert shift == pytest.approx((-0.1 * math.sin(yaw), 0.1 * math.cos(yaw), 0.05))


def _pair(distance, estimate, truth=0.24, turn=0.0):
    return {"distance_m": distance, "estimate_m": estimate, "truth_m": truth, "turn_deg": turn}


def test_a_scene_is_judged_by_the_upper_quartile_of_its_first_near_estimates_in_approach_order():
    config, servo = OpeningConfig(), ServoConfig()
    need = servo.body_radius_m + servo.clearance_margin_m
    pairs = [_pair(1.0, 0.30), _pair(1.5, 0.20), _pair(config.decide_within_m + 0.1, 0.40), _pair(1.3, 0.22),
             _pair(1.2, None), _pair(1.1, 0.26)]
    judged = size_error.judge_scene(pairs, config, servo)
    # within decide_within_m, furthest first: 1.5, 1.3, 1.1 (1.2 found nothing; 1.0 comes after the first three)
    assert judged["judged_m"] == pytest.approx(np.percentile([0.20, 0.22, 0.26], 75))
    assert judged["ratio"] == pytest.approx(judged["judged_m"] / 0.24)
    assert judged["passable"] == (0.24 >= need) and judged["judged_fit"] == (judged["judged_m"] >= need)
    assert size_error.judge_scene(pairs[:3], config, servo) is None


def test_the_summary_counts_misjudged_openings_and_splits_turned_walls():
    rows = [{"mask_radius_px": 20.0, "truth_radius_px": 21.0}, {"mask_radius_px": None, "truth_radius_px": 22.0},
            {"mask_radius_px": 25.0, "truth_radius_px": 24.0}]
    scenes = [{"ratio": 1.05, "turn_deg": 1.0, "passable": False, "judged_fit": True},
              {"ratio": 0.9, "turn_deg": -12.0, "passable": True, "judged_fit": False},
              {"ratio": 1.0, "turn_deg": 5.0, "passable": True, "judged_fit": True}]
    summary = size_error.summarise(rows, scenes, turned_deg=3.0)
    assert summary["pairs"] == 3 and summary["detected"] == 2
    assert summary["mask_minus_truth_px"]["median"] == pytest.approx(0.0)
    assert summary["judged_over_truth"]["facing"]["n"] == 1 and summary["judged_over_truth"]["turned"]["n"] == 2
    assert (summary["impassable"], summary["impassable_judged_fit"]) == (1, 1)
    assert (summary["passable"], summary["passable_judged_too_small"]) == (2, 1)
    text = size_error.markdown(summary, "dis:fine", 3)
    assert "Impassable judged to fit: 1/1; passable judged too small: 1/2." in text


def test_a_run_renders_the_truth_where_the_geometry_puts_it(tmp_path):
    """Two scenes end to end with DIS: the rendered truth's clear radius is the opening's, seen past the wall's
    back face from the distance flown (a pixel or so under it: the splats' edges spill into the opening)."""
    assert size_error.main(["--scenes", "2", "--pairs", "2", "--seed", "7", "--flow", "dis:fine",
                            "-o", str(tmp_path)]) == 0
    out = json.loads((tmp_path / "size_error.json").read_text())
    assert (tmp_path / "size_error.md").is_file()
    assert all("reveal_ratio" in row for row in out["rows"])
    near = [r for r in out["rows"] if abs(r["turn_deg"]) < 10.0]   # (a turned wall's far edge is nearer on one side)
    assert len(near) >= 2
    focal = 156.4
    for row in near:
        geometry = focal * row["truth_m"] / (row["distance_m"] + row["thickness_m"])
        assert -2.0 < row["truth_radius_px"] - geometry < 0.0


def test_bad_arguments_are_refused_in_one_line(capsys):
    assert size_error.main(["--band", "0.5"]) == 2
    assert "--band" in capsys.readouterr().err
    assert size_error.main(["--flow", "nosuchflow"]) == 2
    assert capsys.readouterr().err.startswith("size_error: ")


@pytest.mark.parametrize("motion", ["forward", "sideways"])
def test_a_pair_steps_toward_the_wall_or_across_the_heading(motion):
    spec = SceneSpec(start_yaw_deg=12.0)
    heading = np.array([math.cos(math.radians(12.0)), math.sin(math.radians(12.0)), 0.0])
    for seed in range(5):
        (pose0, _), (pose1, _), distance = size_error.pair_poses(spec, (0.2, -1.4), np.random.default_rng(seed),
                                                                 (0.75, 1.45), motion)
        step = np.subtract(pose1.position, pose0.position)
        along = float(step @ heading)
        assert 0.87 <= distance <= 1.67
        if motion == "forward":
            assert 0.12 <= along <= 0.22 and np.linalg.norm(step - along * heading) < 0.08
        else:
            assert abs(along) < 0.04 and 0.12 - 0.05 < abs(step[0] * heading[1] - step[1] * heading[0]) < 0.22 + 0.05


# ------------------------------------------------------------------------------------ the reveal's thickness

def _reveal_row(scene: int, distance: float, thickness: float, blur: float = 1.0) -> dict:
    """A pair whose reveal reads ρ at d/(d + blur·t) of the wall plane's: a sharp reveal with blur 1."""
    return {"scene": scene, "distance_m": distance, "thickness_m": thickness,
            "reveal_ratio": distance / (distance + blur * thickness)}


def test_a_sharp_reveal_gives_the_thickness_exactly_and_a_blurred_one_by_its_fit():
    rows = [_reveal_row(k, d, t) for k, (d, t) in enumerate([(1.0, 0.10), (1.2, 0.15), (0.9, 0.22), (1.4, 0.25)])]
    sharp = size_error.thickness_from_reveal(rows, 0.15)
    assert sharp["fit"] == pytest.approx([0.0, 1.0], abs=1e-9) and sharp["error_sd_m"] == pytest.approx(0.0, abs=1e-9)
    assert sharp["world_sd_m"] == pytest.approx(np.std([0.10, 0.15, 0.22, 0.25]))
    assert sharp["assumed_rms_m"] == pytest.approx(np.sqrt(np.mean(np.square([-0.05, 0.0, 0.07, 0.10]))))
    blurred = [_reveal_row(k, d, t, blur=0.5) for k, (d, t) in enumerate([(1.0, 0.10), (1.1, 0.15), (1.2, 0.22)])]
    assert size_error.thickness_from_reveal(blurred, 0.15)["fit"] == pytest.approx([0.0, 2.0], abs=1e-9)
    given = size_error.thickness_from_reveal(blurred, 0.15, fit=(0.0, 1.0))
    assert not given["fitted_here"] and given["bias_m"] == pytest.approx(np.mean([0.05, 0.075, 0.11]))


def test_the_reveal_fit_is_judged_on_scenes_it_never_saw():
    """Left out a scene at a time: a scene alone off the line costs its own error and moves the fit for the
    others; pairs without a reading, and runs of under three scenes, give nothing."""
    rows = [_reveal_row(k, 1.0 + 0.1 * k, 0.1 + 0.03 * k) for k in range(5)] + [_reveal_row(5, 1.1, 0.3, blur=0.6)]
    result = size_error.thickness_from_reveal(rows + [{"scene": 6, "distance_m": 1.0, "thickness_m": 0.2,
                                                       "reveal_ratio": None}], 0.15)
    assert result["pairs"] == 6 and result["scenes"] == 6 and result["error_sd_m"] > 0.01
    assert size_error.thickness_from_reveal(rows[:2], 0.15) is None


def test_the_reveal_ratio_reads_the_ring_just_outside_the_mask_against_the_wall_further_out():
    """A lateral step past a wall (ρ 0.5) with a hole (ρ 0.2) whose reveal, the 3 px round it, reads 0.8 of the
    wall: the ratio is 0.8; with no reveal, 1."""
    h, w, focal = 120, 160, 100.0
    hole = np.zeros((h, w), bool)
    hole[40:80, 60:100] = True
    reveal = np.zeros((h, w), bool)
    reveal[37:83, 57:103] = True
    reveal &= ~hole
    for reveal_rho, expected in ((0.4, 0.8), (0.5, 1.0)):
        rho = np.where(hole, 0.2, np.where(reveal, reveal_rho, 0.5))
        flow = np.zeros((h, w, 2), np.float32)
        flow[..., 0] = -rho * focal
        assert size_error.reveal_ratio(flow, hole, focal) == pytest.approx(expected, rel=0.01)
    assert size_error.reveal_ratio(np.zeros((h, w, 2), np.float32), hole, focal) is None   # no flow, no plane


def test_the_report_gives_the_reveal_s_thickness_error():
    rows = [_reveal_row(k, 1.0 + 0.1 * k, 0.1 + 0.03 * k) for k in range(4)]
    summary = size_error.summarise([{**r, "mask_radius_px": None, "truth_radius_px": 20.0} for r in rows], [],
                                   turned_deg=3.0)
    assert summary["thickness_from_reveal"]["scenes"] == 4
    assert "Wall thickness from the reveal" in size_error.markdown(summary, "raft", 1)

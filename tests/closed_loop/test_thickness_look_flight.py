"""The thickness look in a closed-loop flight (lockstep, the shipped RAFT: DIS fine misreads the look's 40 px sidestep
and the look then keeps the depth assumed): an opening scaled to within a centimetre of the need in a wall 0.21 m deep,
not the 0.15 m the companion assumes; the companion reads the depth square to the wall and judges by it (without the
look it refuses this opening as 0.47 m clear), and the flight's logs still replay.  When the look is due:
tests/companion/test_thickness.py."""

from __future__ import annotations

import json

import numpy as np
import pytest

from companion.camera import SplatCamera
from companion.flow import make_flow_backend
from companion.gap import get_detector
from companion.link import make_link
from companion.lockstep import open_clock
from companion.mission import Mission
from companion.mission_config import MissionConfig, State
from companion.runlog import RunLog
from companion.servo import ServoConfig
from companion.thickness import ThicknessLookConfig
from scenes.collision import load_collision
from scenes.library import random_scene
from sitl_vehicle.sim import VehicleConfig
from tools.size_error import scaled_opening
from tools.tlog.replay import replay


@pytest.fixture(scope="module")
def near_scene(tmp_path_factory):
    """A hard-world draw (seed [500, 17]) with its one opening scaled near the need: 0.206 m deep, turned 1.3°."""
    servo = ServoConfig()
    need = servo.body_radius_m + servo.clearance_margin_m
    rng = np.random.default_rng([500, 17])
    spec = random_scene(rng, world="hard")
    spec = scaled_opening(spec, int(rng.integers(len(spec.openings))), float(rng.uniform(need - 0.04, need + 0.04)))
    path = tmp_path_factory.mktemp("near") / "near.json"
    spec.save(path)
    return spec, path


def fly(vehicle_for_link, scene, run_dir, thickness: ThicknessLookConfig):
    """One lockstep flight of ``scene``: (the mission's result, the vehicle's verdict)."""
    server, api, truth = vehicle_for_link(vehicle=VehicleConfig(), world=load_collision(scene), scene=str(scene),
                                          seed=0, lockstep=True)
    clock, poses = open_clock(f"udpin://127.0.0.1:{truth}", True)
    link = make_link(f"udpin://127.0.0.1:{api}", tlog_path=run_dir / "link.tlog", clock=clock)
    camera = SplatCamera(str(scene), poses, clock=clock)
    mission = Mission(link, camera, make_flow_backend("raft"), get_detector("parallax"),
                      RunLog(run_dir), config=MissionConfig(step_timeout_s=6.0), thickness=thickness)
    try:
        result = mission.run()
    finally:
        link.close()
        clock.close()
        camera.close()
        mission.record.runlog.close()
    server.stop()
    return result, server.verdict()


def test_the_companion_reads_the_walls_depth_near_the_need_and_judges_by_it(vehicle_for_link, near_scene, tmp_path):
    spec, path = near_scene
    assert spec.wall.thickness == pytest.approx(0.2055, abs=1e-3)
    run_dir = tmp_path / "flight"
    result, verdict = fly(vehicle_for_link, path, run_dir, ThicknessLookConfig())
    look = result.thickness_look
    assert look is not None, result.reason
    assert abs(look["judged_before_m"] - 0.247) <= ThicknessLookConfig().band_m
    assert result.wall_thickness_m == pytest.approx(spec.wall.thickness, abs=0.03), look["why"]
    assert look["judged_after_m"] > look["judged_before_m"]          # deeper than assumed: larger than judged
    assert not verdict["collision"], verdict
    assert result.state is State.DONE and verdict["success"], result.reason
    # the servo's frame after the look opens a pair of its own: every decision's pair replays, and no other
    decided = len((run_dir / "decisions.jsonl").read_text().splitlines())
    frames = len((run_dir / "frames.jsonl").read_text().splitlines())
    assert decided == result.servo_steps and frames == decided + 2
    (run_dir / "summary.json").write_text(json.dumps({"scene": str(path), "flow": "raft",
                                                      "detector": "parallax"}))
    assert replay(run_dir)["steps"] == decided


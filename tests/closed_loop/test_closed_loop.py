"""Both sides in one process over 127.0.0.1: the vehicle server (with the scene's collision geometry) and
the companion's mission (DIS flow, our parallax detector), judged by the vehicle's own ground truth."""

from __future__ import annotations

import json
import threading
import time

from companion.camera import SplatCamera
from companion.flow import make_flow_backend
from companion.gap import get_detector
from companion.link import make_link
from companion.mission import Mission
from companion.mission_config import MissionConfig, State
from companion.runlog import RunLog
from scenes.collision import load_collision
from sitl_vehicle.modes import FlightMode
from sitl_vehicle.sim import VehicleConfig
from tools.tlog.replay import replay

SCENE = "window1_brick"


def make_mission(api_port, truth_port, run_dir):
    link = make_link(f"udpin://127.0.0.1:{api_port}", tlog_path=run_dir / "link.tlog")
    camera = SplatCamera(SCENE, f"udpin://127.0.0.1:{truth_port}")
    mission = Mission(link, camera, make_flow_backend("dis", preset="fine"), get_detector("parallax"),
                      RunLog(run_dir), config=MissionConfig(step_timeout_s=6.0))
    return mission, link, camera


def _fly_once(vehicle_for_link, run_dir):
    """One flight in lockstep (the vehicle's clock serves both sides), so that it is the same flight on any
    machine at any load: no retry hides a loop that succeeds only sometimes."""
    from companion.lockstep import open_clock

    server, api, truth = vehicle_for_link(vehicle=VehicleConfig(), world=load_collision(SCENE), scene=SCENE, seed=0,
                                          lockstep=True)
    clock, poses = open_clock(f"udpin://127.0.0.1:{truth}", True)
    link = make_link(f"udpin://127.0.0.1:{api}", tlog_path=run_dir / "link.tlog", clock=clock)
    camera = SplatCamera(SCENE, poses, clock=clock)
    mission = Mission(link, camera, make_flow_backend("dis", preset="fine"), get_detector("parallax"),
                      RunLog(run_dir), config=MissionConfig(step_timeout_s=6.0))
    try:
        result = mission.run()
    finally:
        link.close()
        clock.close()          # the vehicle's last simulated second, to settle before its verdict
        camera.close()
        mission.record.runlog.close()
    server.stop()
    return result, server.verdict()


def test_closed_loop_flight_through_a_suite_window(vehicle_for_link, tmp_path):
    run_dir = tmp_path / "flight"
    result, verdict = _fly_once(vehicle_for_link, run_dir)
    assert not (verdict["success"] and verdict["collision"])  # a touch is never a success
    assert result.state is State.DONE, result.reason
    assert verdict["crossed_wall"] and not verdict["collision"], verdict
    assert verdict["success"] and result.servo_steps >= 3
    lines = (run_dir / "decisions.jsonl").read_text().splitlines()
    assert len(lines) == result.servo_steps
    assert len(list((run_dir / "masks").glob("*.png"))) == result.servo_steps
    assert len((run_dir / "frames.jsonl").read_text().splitlines()) == result.servo_steps + 1
    # Replaying the run with the flight's own settings reproduces every decision it took.
    (run_dir / "summary.json").write_text(json.dumps({"scene": SCENE, "flow": "dis:fine", "detector": "parallax"}))
    replayed = replay(run_dir)
    assert replayed["steps"] == result.servo_steps and replayed["differing_steps"] == []


def _run_in_thread(mission):
    out = {}
    thread = threading.Thread(target=lambda: out.setdefault("result", mission.run()), daemon=True)
    thread.start()
    return thread, out


def test_vehicle_disappearing_mid_flight_is_a_clear_companion_failure(vehicle_for_link, tmp_path):
    server, api, truth = vehicle_for_link(world=load_collision(SCENE), scene=SCENE)
    mission, link, camera = make_mission(api, truth, tmp_path)
    thread, out = _run_in_thread(mission)
    try:
        assert _wait(lambda: mission.result.state is State.SERVO, 30), mission.result
        server.stop()  # the vehicle process is gone
        thread.join(timeout=30)
    finally:
        link.close()
        camera.close()
    result = out["result"]
    assert result.state is State.FAILED and "link lost" in result.reason


def test_companion_disappearing_mid_flight_makes_the_vehicle_fail_safe(vehicle_for_link, tmp_path):
    server, api, truth = vehicle_for_link(world=load_collision(SCENE), scene=SCENE)
    mission, link, camera = make_mission(api, truth, tmp_path)
    thread, _ = _run_in_thread(mission)
    assert _wait(lambda: mission.result.state is State.SERVO, 30), mission.result
    link.close()  # the companion is gone: its setpoint stream stops
    camera.close()
    assert _wait(lambda: server.commander.failsafe, 10)
    assert server.commander.mode is FlightMode.AUTO_LOITER and server.sim.armed and not server.sim.crashed
    thread.join(timeout=30)


def _wait(predicate, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.05)
    return False


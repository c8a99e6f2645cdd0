"""``flowgap-sitl --rerun``: a two-process lockstep flight recorded for Rerun, read back with the SDK; then the
same run directory replayed into a recording, and its tlog's report with the run's storyboard."""

from __future__ import annotations

import json

import pytest

from companion.recording import recorded_entities
from tools.eval_flights import InstancePool
from tools.launch import main as sitl
from tools.tlog import main as tlog

SCENE = "window1_brick"


@pytest.fixture(scope="module")
def recorded_flight(tmp_path_factory):
    run_dir = tmp_path_factory.mktemp("rerun") / "flight"
    pool = InstancePool()
    instance = pool.acquire()
    try:
        rc = sitl(["--scene", SCENE, "--lockstep", "--rerun", "--quiet", "--run-dir", str(run_dir),
                   "--instance", str(instance), "--timeout", "120"])
    finally:
        pool.release(instance)
    return rc, run_dir, json.loads((run_dir / "verdict.json").read_text())


@pytest.mark.slow
def test_flowgap_sitl_rerun_records_every_servo_step_the_trajectories_and_the_setpoints(recorded_flight):
    rc, run_dir, verdict = recorded_flight
    assert rc == 0 and verdict["success"], verdict
    assert verdict["rerun"] == str(run_dir / "flight.rrd")
    rows = recorded_entities(run_dir / "flight.rrd")
    steps = verdict["servo_steps"]
    assert rows["/camera/frame"] == rows["/camera/mask/targets"] == steps + 1       # the first frame, then one a step
    assert rows["/camera/flow"] == rows["/camera/mask"] == steps
    # the start, a waypoint a step, then the push's increments
    summary = json.loads((run_dir / "companion" / "summary.json").read_text())
    pushed = round(summary["push_length_m"] / 0.05 + 0.4999)
    assert rows["/world/setpoints"] == 1 + steps + pushed
    simulated = verdict["sim_time_s"]
    assert 0.6 * 10 * simulated <= rows["/world/trajectory/estimated"] <= 10 * simulated + 2   # at 10 Hz
    assert rows["/world/trajectory/true"] >= rows["/world/trajectory/estimated"]
    assert rows["/plots/attitude/pitch"] >= 0.6 * 10 * simulated
    assert rows["/world/scene/splats"] == rows["/world/scene/wall/front"] == 1


@pytest.mark.slow
def test_a_recorded_run_replays_into_a_recording_and_its_tlog_report_carries_the_storyboard(recorded_flight,
                                                                                            tmp_path):
    rc, run_dir, verdict = recorded_flight
    companion = run_dir / "companion"
    assert tlog(["replay", str(companion), "--rerun", str(tmp_path / "replay.rrd")]) == 0
    rows = recorded_entities(tmp_path / "replay.rrd")
    assert rows["/camera/frame"] == verdict["servo_steps"]
    assert rows["/world/trajectory/estimated"] > 20 and rows["/world/setpoints"] > 20   # from link.tlog
    assert tlog([str(companion / "link.tlog"), "--out", str(tmp_path / "report"), "--no-plots"]) == 0
    assert (tmp_path / "report" / "storyboard.png").read_bytes() == (companion / "storyboard.png").read_bytes()


@pytest.mark.slow
def test_a_run_without_its_storyboard_gets_one_rebuilt_from_its_step_images(recorded_flight, tmp_path):
    import shutil

    import cv2

    from companion.storyboard import TEXT_H

    _, run_dir, _ = recorded_flight
    copy = tmp_path / "companion"
    shutil.copytree(run_dir / "companion", copy)
    (copy / "storyboard.png").unlink()
    assert tlog([str(copy / "link.tlog"), "--out", str(tmp_path / "report"), "--no-plots"]) == 0
    rebuilt = cv2.imread(str(tmp_path / "report" / "storyboard.png"))
    flown = cv2.imread(str(run_dir / "companion" / "storyboard.png"))
    assert rebuilt.shape[1] == flown.shape[1]           # the same rows of panels ...
    assert 0 <= flown.shape[0] - rebuilt.shape[0] <= 2 * TEXT_H   # ... less the vehicle's verdict line
    shutil.rmtree(copy / "frames")                      # --no-images and no storyboard: nothing to add
    assert tlog([str(copy / "link.tlog"), "--out", str(tmp_path / "bare"), "--no-plots"]) == 0
    assert not (tmp_path / "bare" / "storyboard.png").exists()

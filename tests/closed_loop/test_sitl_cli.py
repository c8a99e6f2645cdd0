"""``flowgap-sitl`` as a user runs it (the `make demo` path): a process that writes its verdict, exits with the
flight's status, and stops both of its processes on Ctrl-C."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

import pytest

from tools.eval_flights import InstancePool, _ports_free


@pytest.mark.slow
def test_ctrl_c_mid_flight_stops_both_processes_and_leaves_a_verdict(tmp_path):
    pool = InstancePool()
    instance = pool.acquire()
    run_dir, result = tmp_path / "flight", tmp_path / "verdict-copy.json"
    try:
        sitl = subprocess.Popen([sys.executable, "-m", "tools.launch", "--scene", "window1_brick", "--lockstep",
                                 "--quiet", "--run-dir", str(run_dir), "--instance", str(instance),
                                 "--result", str(result)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True)
        frames = run_dir / "companion" / "frames.jsonl"
        deadline = time.monotonic() + 60
        while not (frames.exists() and len(frames.read_text().splitlines()) >= 3):   # servoing
            assert sitl.poll() is None and time.monotonic() < deadline, "the flight never got to its third frame"
            time.sleep(0.1)
        sitl.send_signal(signal.SIGINT)
        out, _ = sitl.communicate(timeout=60)
        assert sitl.returncode == 1
        verdict = json.loads((run_dir / "verdict.json").read_text())
        assert verdict["success"] is False and verdict["error"].startswith("interrupted")
        assert json.loads(result.read_text()) == verdict and '"success": false' in out
        deadline = time.monotonic() + 10                  # both processes gone: their ports are free again
        while not _ports_free(instance):
            assert time.monotonic() < deadline, "a process of the flight still holds its ports"
            time.sleep(0.2)
    finally:
        if sitl.poll() is None:
            sitl.kill()
        pool.release(instance)


@pytest.mark.slow
def test_a_lockstep_flight_is_limited_in_simulated_time_and_says_so(tmp_path):
    """In lockstep ``--timeout`` counts simulated seconds (a wall limit once cut hard-world flights short on a
    busy machine, each row then reading "interrupted"): the flight ends where its simulated time runs out,
    whatever the load, and the verdict says why."""
    from tools.launch import launch

    pool = InstancePool()
    instance = pool.acquire()
    try:
        verdict = launch("window1_brick", tmp_path / "flight", instance=instance, images=False, log_sink=None,
                         lockstep=True, timeout_s=3.0, flow="dis:fine")
    finally:
        pool.release(instance)
    assert verdict["success"] is False and verdict["sim_time_s"] == pytest.approx(3.0, abs=0.01)
    assert verdict["error"] == "the flight's 3 simulated seconds (--timeout) ran out before the mission ended"


def test_a_companion_that_dies_at_once_is_a_failure_whatever_an_earlier_flight_left_in_its_run_dir(tmp_path):
    """A run directory flown before holds that flight's verdicts; a companion that exits before it flies (here, on
    a flow it cannot build) must not inherit them: the flight fails and the error quotes the companion's reason."""
    from tools.launch import launch

    run_dir = tmp_path / "flight"
    (run_dir / "companion").mkdir(parents=True)
    (run_dir / "vehicle_result.json").write_text(json.dumps({"success": True, "collision": False}))
    (run_dir / "companion" / "summary.json").write_text(json.dumps({"state": "done", "servo_steps": 9}))
    pool = InstancePool()
    instance = pool.acquire()
    try:
        verdict = launch("window1_brick", run_dir, instance=instance, images=False, log_sink=None, lockstep=True,
                         timeout_s=5.0, flow="nosuchflow")
    finally:
        pool.release(instance)
    assert verdict["success"] is False and verdict["companion_state"] is None and verdict["servo_steps"] is None
    assert verdict["error"].startswith("the companion exited (code 2) without a summary: ")
    assert "nosuchflow" in verdict["error"] and "\n" not in verdict["error"]
    assert json.loads((run_dir / "verdict.json").read_text()) == verdict

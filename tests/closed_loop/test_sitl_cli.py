"""``flowgap-sitl`` as a user runs it (the `make demo` path): a process that writes its verdict, exits with the
flight's status, and stops both of its processes on Ctrl-C or SIGTERM (so does a sweep)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from support.processes import alive, children
from tools.eval_flights import InstancePool, _ports_free


@pytest.mark.slow
def test_ctrl_c_mid_flight_stops_both_processes_and_leaves_a_verdict_whatever_signal_follows(tmp_path):
    """Ctrl-C, or SIGTERM (pkill, a CI time limit; it reaches the launcher alone, not its two processes as a
    terminal's Ctrl-C does; a sweep stopped by it is tested below): both processes are stopped, and a second
    signal while they are being stopped does not cut that short (it used to: the vehicle was left running)."""
    pool = InstancePool()
    instance = pool.acquire()
    run_dir, result = tmp_path / "flight", tmp_path / "verdict-copy.json"
    flight: set[int] = set()
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
        flight = children(sitl.pid)
        assert len(flight) == 2, "the vehicle and the companion are the launcher's children"
        for sig in (signal.SIGINT, signal.SIGTERM):       # sent to the launcher alone
            sitl.send_signal(sig)
            time.sleep(0.1)
        out, _ = sitl.communicate(timeout=60)
        assert not alive(flight), "a process of the flight outlived the launcher"
        assert sitl.returncode == 1
        verdict = json.loads((run_dir / "verdict.json").read_text())
        assert verdict["success"] is False and verdict["error"].startswith("interrupted")
        assert json.loads(result.read_text()) == verdict and '"success": false' in out
        deadline = time.monotonic() + 10                  # both processes gone: their ports are free again
        while not _ports_free(instance):
            assert time.monotonic() < deadline, "a process of the flight still holds its ports"
            time.sleep(0.2)
    finally:
        for pid in alive(flight | {sitl.pid}):
            os.kill(pid, signal.SIGKILL)
        pool.release(instance)


@pytest.mark.slow
def test_a_sweep_stopped_by_sigterm_stops_its_flights_and_starts_no_more(tmp_path):
    """``pkill -f flowgap-eval-flights`` once left every flight's vehicle running idle; now the sweep stops the
    flights in progress, starts none of those queued, saves none of the stopped ones, and exits 130."""
    out = tmp_path / "sweep"
    sweep = subprocess.Popen([sys.executable, "-m", "tools.eval_flights", "window1_brick", "--starts", "3",
                              "--jobs", "1", "--flow", "dis:fine", "-o", str(out)],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    flight: set[int] = set()
    try:
        frames = out / "window1_brick-0" / "companion" / "frames.jsonl"
        deadline = time.monotonic() + 60
        while not (frames.exists() and len(frames.read_text().splitlines()) >= 3):
            assert sweep.poll() is None and time.monotonic() < deadline, "the first flight never got to its third frame"
            time.sleep(0.1)
        flight = children(sweep.pid)
        assert len(flight) == 2
        sweep.send_signal(signal.SIGTERM)
        _, err = sweep.communicate(timeout=60)
        assert sweep.returncode == 130, err
        assert not alive(flight), "a process of the stopped flight outlived the sweep"
        assert not (out / "window1_brick-1").exists(), "a queued flight started after the SIGTERM"
        assert not list((out / "results").glob("*.json")), "a stopped flight was saved as flown"
        assert "Traceback" not in err and "interrupted" in err
    finally:
        for pid in alive(flight | {sweep.pid}):
            os.kill(pid, signal.SIGKILL)


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


def test_launch_hands_no_thickness_look_to_the_companion_and_records_it(tmp_path, monkeypatch):
    """``flowgap-sitl --no-thickness-look`` / ``flowgap-eval-flights --no-thickness-look`` reach the companion's
    command line, and the verdict says how the flight was flown."""
    import tools.launch
    from tools.launch import launch

    commands = []

    def start(cmd, *args):
        commands.append(cmd)
        raise KeyboardInterrupt         # stop before anything runs: only the command is looked at

    monkeypatch.setattr(tools.launch, "_start", start)
    for look in (True, False):
        verdict = launch("window1_brick", tmp_path / str(look), images=False, log_sink=None, lockstep=True,
                         thickness_look=look)
        assert verdict["thickness_look"] is look and verdict["success"] is False
        assert ("--no-thickness-look" in commands[-1]) is not look and "companion" in commands[-1]

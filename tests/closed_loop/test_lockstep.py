"""Lockstep flights, two processes as ``flowgap-sitl --lockstep`` flies them: the same flight at any machine
load, and the camera-to-setpoint latency as simulated time."""

from __future__ import annotations

import json
import multiprocessing
import statistics
from pathlib import Path

import pytest
from pymavlink import mavutil

from companion.flow.registry import DEFAULT_FLOW
from tests.support.tlog import tlog_messages
from tools.launch import launch

SCENE = "window1_brick"


def _setpoints(tlog: Path) -> list[tuple]:
    conn = mavutil.mavlink_connection(str(tlog))
    out = []
    while (msg := conn.recv_match(type="SET_POSITION_TARGET_LOCAL_NED")) is not None:
        out.append((msg.time_boot_ms, round(msg.x, 5), round(msg.y, 5), round(msg.z, 5), round(msg.yaw, 5)))
    conn.close()
    return out


def _fly(run_dir: Path, latency_s: float = 0.0, flow: str = DEFAULT_FLOW, threads: int | None = None) -> dict:
    return launch(SCENE, run_dir, start=(0.0, 0.1, 0.0), instance=7, flow=flow, images=False, log_sink=None,
                  lockstep=True, latency_s=latency_s, seed=3, timeout_s=120, threads=threads)


def _spin(stop) -> None:
    while not stop.is_set():
        pass


@pytest.mark.slow
def test_the_same_lockstep_flight_twice_the_second_on_a_loaded_machine_and_a_thread_each_is_identical(tmp_path):
    # a thread per library is how a sweep flies two flights at once on 2 CPUs (tools.threads): the flow's
    # arithmetic must not depend on it
    quiet = _fly(tmp_path / "quiet")
    stop = multiprocessing.Event()
    hogs = [multiprocessing.Process(target=_spin, args=(stop,), daemon=True) for _ in range(2)]
    for hog in hogs:
        hog.start()
    try:
        loaded = _fly(tmp_path / "loaded", threads=1)
    finally:
        stop.set()
        for hog in hogs:
            hog.join(timeout=5)
    assert quiet["success"], quiet
    for verdict in (quiet, loaded):
        verdict.pop("wall_time_s"), verdict.pop("run_dir"), verdict.pop("storyboard")   # (paths in the run dirs)
    assert loaded == quiet
    vehicle = [json.loads((tmp_path / d / "vehicle_result.json").read_text()) for d in ("quiet", "loaded")]
    for v in vehicle:
        v.pop("wall_time_s")
    assert vehicle[0] == vehicle[1] and vehicle[0]["clock"] == "lockstep"
    # everything the companion sent and received, field by field (the vehicle's estimate included: reading it
    # for a heartbeat the wall clock sends while time is held once moved the flight by an ulp)
    first, second = (tlog_messages(tmp_path / d / "companion" / "link.tlog") for d in ("quiet", "loaded"))
    assert len(first) > 1000 and first == second


def _waypoint_delays(run_dir: Path) -> list[float]:
    """For each servo step after the first: simulated seconds from its frame to the first setpoint of the
    waypoint decided from it."""
    decisions = [json.loads(line) for line in (run_dir / "companion" / "decisions.jsonl").read_text().splitlines()]
    setpoints = _setpoints(run_dir / "companion" / "link.tlog")
    delays = []
    for this, after in zip(decisions[:-1], decisions[1:], strict=True):
        # the log rounds to 1e-5 m and MAVLink carries float32: the same waypoint within 2e-5 m (an exact match of
        # rounded values misses one that rounds the other way)
        sent = next(sp[0] * 1e-3 for sp in setpoints
                    if all(abs(a - b) <= 2e-5 for a, b in zip(sp[1:4], after["waypoint"], strict=True)))
        delays.append(sent - this["frame_time_s"])
    return delays


@pytest.mark.slow
def test_a_modelled_latency_sends_each_waypoint_that_much_later_in_simulated_time(tmp_path):
    prompt = _waypoint_delays(_fly_dir(tmp_path / "prompt", 0.0))
    late = _waypoint_delays(_fly_dir(tmp_path / "late", 0.2))
    assert len(prompt) >= 3 and len(late) >= 3
    # the setpoint stream runs at 20 Hz and the truth stream (the frame's time stamp) at 100 Hz
    assert all(0.0 <= d <= 0.07 for d in prompt), prompt
    assert all(0.2 - 1e-3 <= d <= 0.27 for d in late), late
    assert statistics.median(late) - statistics.median(prompt) == pytest.approx(0.2, abs=0.05)


def _fly_dir(run_dir: Path, latency_s: float) -> Path:
    # dis:fine: the latency is the clock's and the link's, whatever the flow (the default's flights are above)
    verdict = _fly(run_dir, latency_s, flow="dis:fine")
    assert verdict["latency_s"] == latency_s and verdict["clock"] == "lockstep"
    return run_dir

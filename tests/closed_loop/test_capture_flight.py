"""A suite scene re-expressed as a third-party capture (random frame and scale, SH degree 3, floaters out to
200 m, the NED world turned by a yaw) flown as a user flies one: ``flowgap-sitl --scene capture.json --lockstep``,
starting where the capture says, judged by the vehicle's splat-derived collision field and the capture's gate."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from scenes.library import suite_spec
from scenes.synthetic_capture import write_reexpressed_capture
from tools.eval_flights import InstancePool


@pytest.mark.slow
def test_flowgap_sitl_flies_through_a_reexpressed_capture(tmp_path):
    made = write_reexpressed_capture(suite_spec("window1", "brick"), tmp_path / "capture", np.random.default_rng(2019))
    doc = json.loads(made.json.read_text())
    assert 0.2 <= doc["to_ned"]["scale"] <= 5.0 and abs(doc["start_yaw_deg"]) > 1.0
    pool = InstancePool()
    instance = pool.acquire()
    run_dir = tmp_path / "flight"
    try:
        out = subprocess.run([sys.executable, "-m", "tools.launch", "--scene", str(made.json), "--lockstep",
                              "--quiet", "--run-dir", str(run_dir), "--instance", str(instance)],
                             capture_output=True, text=True, timeout=240)
    finally:
        pool.release(instance)
    verdict = json.loads((run_dir / "verdict.json").read_text())
    assert out.returncode == 0 and verdict["success"], (out.stdout[-2000:], out.stderr[-2000:])
    assert verdict["gate"]["crossed"] and verdict["crossed_wall"] and not verdict["collision"]
    assert verdict["start_ned"] == pytest.approx(doc["start_ned"]) and verdict["start_yaw_deg"] == doc["start_yaw_deg"]
    assert 0.0 < verdict["min_clearance_m"] < 0.5          # the splat field was checked all the way through
    assert (made.json.parent / f"{made.json.stem}.collision.npz").exists()    # built once, beside the scene

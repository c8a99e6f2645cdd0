"""The demo flight end to end: wall time of one two-process SITL flight through the default window
(``flight.demo_wall_s``, the demo's settings: speed ×2) and the companion's perception latency per servo step
(``flight.step_latency_ms``: render + flow + derotation + detection, median over every step of every run), with
the companion's default flow (``companion.flow.registry.DEFAULT_FLOW``), as the demo flies."""

from __future__ import annotations

import json
import statistics
import tempfile
from pathlib import Path

from companion.flow.registry import DEFAULT_FLOW
from tools.eval_flights import InstancePool
from tools.launch import launch

RUNS = 3


def run() -> dict:
    walls, latencies, successes = [], [], 0
    pool = InstancePool()
    instance = pool.acquire()
    try:
        with tempfile.TemporaryDirectory() as tmp:
            for i in range(RUNS):
                run_dir = Path(tmp) / f"demo-{i}"
                verdict = launch("window1_brick", run_dir, speed=2.0, instance=instance, flow=DEFAULT_FLOW,
                                 images=False, log_sink=None)
                if str(verdict.get("error", "")).startswith("interrupted"):
                    raise KeyboardInterrupt      # stopped by Ctrl-C or SIGTERM: no timing to take from it
                walls.append(verdict["wall_time_s"])
                successes += bool(verdict["success"])
                for line in (run_dir / "companion" / "decisions.jsonl").read_text().splitlines():
                    t = json.loads(line)["timing"]
                    latencies.append(t["capture_ms"] + t["flow_ms"] + t["detect_ms"])
    finally:
        pool.release(instance)
    return {
        "flight.demo_wall_s": {"value": round(statistics.median(walls), 2),
                               "unit": f"s wall per demo flight (window1_brick, speed x2, median of {RUNS}; "
                                       f"{successes}/{RUNS} succeeded)"},
        "flight.step_latency_ms": {"value": round(statistics.median(latencies), 1),
                                   "unit": f"ms per servo step: render + {DEFAULT_FLOW} flow + derotation + detection"},
    }

"""Sweep throughput: ``eval.flights_per_hour`` of ``flowgap-eval-flights`` as it runs by default (lockstep,
two flights at once on this machine's local pool), ``eval.flights_per_hour_ray`` of the same sweep as Ray tasks on
a local Ray sized for two flights at once (``--ray local --jobs 2``), ``eval.ray_overhead_pct`` (how much slower
Ray flies them), and ``eval.flights_per_hour_realtime`` of the same sweep paced by the wall clock at
``--speed 2`` (the default before lockstep); all from the same run, with ``dis:fine``; and
``eval.flights_per_hour_default_flow``, the lockstep sweep with the companion's default flow (RAFT), whose flights
hold their libraries to a thread each on 2 CPUs (:mod:`tools.threads`).

The local pool and Ray sweeps run in turns, twice each, and each keeps its better run, so that a change in the
machine's load (other work on a 2-core machine moves a 4-flight sweep by 10-20 %) hits both alike. Flights per
hour count the sweep's own wall time; Ray's start (a few seconds, once per sweep) is reported in the unit, not in
the rate. The Ray sweep runs in a loopback-only network namespace (:mod:`tools.loopback`), so that its traffic
stays on 127.0.0.1; where none can be made, or Ray is not installed, its keys are left out.
"""

from __future__ import annotations

import importlib.util
import json
import logging
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from companion.flow.registry import DEFAULT_FLOW
from tools.eval_flights import main as eval_flights

log = logging.getLogger(__name__)

SCENES = ["window1_brick", "window2_stone", "window3_granite", "window4_newspaper"]
SWEEP = [*SCENES, "--starts", "1", "--jobs", "2", "--seed", "0", "--flow", "dis:fine"]
ROUNDS = 2          # local pool and Ray in turns; each keeps its better run


def _sweep(extra: list[str]) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        eval_flights([*SWEEP, "--out", tmp, *extra])
        return json.loads((Path(tmp) / "flights.json").read_text())["summary"]


def _ray_sweep() -> dict | None:
    """The sweep on a local Ray in a loopback-only namespace; None where that cannot run here."""
    from tools.loopback import loopback_command, unavailable

    why = "Ray is not installed (pip install -e '.[ray]')" if importlib.util.find_spec("ray") is None else unavailable()
    if why:
        log.warning("eval.flights_per_hour_ray left out: %s", why)
        return None
    ray_tmp = tempfile.mkdtemp(prefix="fgray-", dir="/tmp")       # short: Ray's socket paths have a length limit
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
    env.update(RAY_TMPDIR=ray_tmp, RAY_USAGE_STATS_ENABLED="0")
    try:
        with tempfile.TemporaryDirectory() as tmp:
            command = [sys.executable, "-m", "tools.eval_flights", *SWEEP, "--ray", "local", "--out", tmp]
            done = subprocess.run(loopback_command(command), env=env, capture_output=True, text=True, timeout=1800)
            if done.returncode != 0:
                log.warning("eval.flights_per_hour_ray left out: the Ray sweep failed: %s",
                            (done.stderr.strip().splitlines() or ["?"])[-1])
                return None
            return json.loads((Path(tmp) / "flights.json").read_text())["summary"]
    finally:
        shutil.rmtree(ray_tmp, ignore_errors=True)


def _per_hour(summary: dict) -> float:
    return 3600 * summary["flights"] / summary["total_wall_s"]


def run() -> dict:
    locks, rays = [], []
    for _ in range(ROUNDS):
        locks.append(_sweep([]))
        ray = _ray_sweep() if len(rays) == len(locks) - 1 else None      # (not again once it could not run)
        if ray is not None:
            rays.append(ray)
    lock = max(locks, key=_per_hour)
    ray = max(rays, key=_per_hour) if rays else None
    real = _sweep(["--realtime", "--speed", "2"])
    default = _sweep(["--flow", DEFAULT_FLOW])
    n = lock["flights"]
    what = f"flights per wall hour, {n} suite flights 2 at a time, dis:fine"
    out = {
        "eval.flights_per_hour": {"value": round(_per_hour(lock)),
                                  "unit": f"{what}, lockstep (the default; local pool, better of {len(locks)} "
                                          f"runs; {lock['success']}/{n} through)"},
        "eval.flights_per_hour_realtime": {"value": round(_per_hour(real)),
                                           "unit": f"{what}, --realtime --speed 2 ({real['success']}/{n} through)"},
        "eval.flights_per_hour_default_flow": {
            "value": round(_per_hour(default)),
            "unit": f"flights per wall hour, {n} suite flights 2 at a time, {DEFAULT_FLOW} (the companion's default "
                    f"flow), lockstep, {default['threads_per_flight']} thread(s) per library a flight "
                    f"({default['success']}/{n} through)"},
    }
    if ray is not None:
        overhead = 100 * (1 - _per_hour(ray) / _per_hour(lock))
        out["eval.flights_per_hour_ray"] = {
            "value": round(_per_hour(ray)),
            "unit": f"{what}, lockstep, as Ray tasks on a local Ray (--ray local --jobs 2: 2 CPUs a flight; better "
                    f"of {len(rays)} runs; {ray['success']}/{n} through; Ray's start, {ray['ray']['start_s']:.0f} s "
                    f"once per sweep, not counted)"}
        out["eval.ray_overhead_pct"] = {
            "value": round(overhead, 1),
            "unit": "% fewer flights per hour on the local Ray than on the local pool, same run (negative: faster; "
                    "the goal: at most 10)"}
    return out

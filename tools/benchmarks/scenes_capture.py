"""Capture benchmark: a 1M-Gaussian capture like real ones, loaded, rendered and given its collision field.

The capture is ``window3_stone`` at about 1M Gaussians (splat spacing scaled), written as a third-party export
would be (:mod:`scenes.synthetic_capture`: Inria layout, SH degree 3, 10,000 floaters out to 470 m, another frame
and scale). A fresh child process then does what ``flowgap-sitl --scene capture.json`` needs before a flight, and
reports its times and peak memory (VmHWM, Python and its libraries included): read and place the ``.ply``
(``scenes.capture_load_s``), render the first 320x240 frame from the start (``scenes.capture_render_ms``, including
the per-cloud preparation; the kernels come from numba's cache), build the collision field without a cache
(``scenes.capture_field_s``), all three (``scenes.capture_total_s``, goal < 30 s) and ``scenes.capture_peak_mb``
(goal < 2048).

    python -m tools.benchmarks.scenes_capture [--gaussians N] [--keep DIR]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

GAUSSIANS = 1_000_000


def make_capture(out_dir: Path, gaussians: int = GAUSSIANS) -> Path:
    import numpy as np

    from scenes.library import suite_spec
    from scenes.synthetic_capture import write_reexpressed_capture

    made = write_reexpressed_capture(suite_spec("window3", "stone"), out_dir, np.random.default_rng(1),
                                     gaussians=gaussians, floater_count=10_000, floater_far_m=470.0,
                                     name="capture_1m")
    return made.json


def measure(capture_json: Path) -> dict:
    """In this process: load, first render, field (no cache); seconds and peak resident memory."""
    import math

    from scenes.build import load_scene
    from scenes.camera import PinholeCamera, Pose, euler_to_quat
    from scenes.occupancy import build_capture_collision
    from scenes.render import render_splats

    t0 = time.perf_counter()
    spec, cloud = load_scene(capture_json)
    t1 = time.perf_counter()
    start = (spec.start_ned[0], spec.start_ned[1], -spec.altitude_m)
    frame = render_splats(cloud, PinholeCamera(), Pose(start, euler_to_quat(0.0, 0.0,
                                                                             math.radians(spec.start_yaw_deg))))
    t2 = time.perf_counter()
    world = build_capture_collision(spec, cloud)
    t3 = time.perf_counter()
    return {"gaussians": len(cloud), "load_s": t1 - t0, "render_ms": 1e3 * (t2 - t1), "field_s": t3 - t2,
            "total_s": t3 - t0, "peak_mb": _peak_mb(),
            "covered": float((frame.alpha > 0.9).mean()), "solid_voxels": world.solid_voxels,
            "ply_mb": spec.ply.stat().st_size / 1e6}


def _peak_mb() -> float:
    """This process's peak resident memory: VmHWM (ru_maxrss would count the parent's memory at the fork)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _child(capture_json: Path) -> dict:
    out = subprocess.run([sys.executable, "-m", "tools.benchmarks.scenes_capture", "--measure", str(capture_json)],
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def run(gaussians: int = GAUSSIANS, keep: Path | None = None) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        folder = keep or Path(tmp)
        capture = make_capture(folder, gaussians)
        m = _child(capture)
    return {"scenes.capture_gaussians": {"value": m["gaussians"], "unit": "Gaussians"},
            "scenes.capture_load_s": {"value": m["load_s"], "unit": "s"},
            "scenes.capture_render_ms": {"value": m["render_ms"], "unit": "ms"},
            "scenes.capture_field_s": {"value": m["field_s"], "unit": "s"},
            "scenes.capture_total_s": {"value": m["total_s"], "unit": "s"},
            "scenes.capture_peak_mb": {"value": m["peak_mb"], "unit": "MB"}}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m tools.benchmarks.scenes_capture", description=__doc__.split("\n\n")[0])
    p.add_argument("--gaussians", type=int, default=GAUSSIANS, help="about how many (default %(default)s)")
    p.add_argument("--keep", type=Path, default=None, metavar="DIR", help="write the capture here and keep it")
    p.add_argument("--measure", type=Path, default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.measure is not None:
        print(json.dumps(measure(args.measure)))
        return 0
    for key, entry in run(args.gaussians, args.keep).items():
        print(f"{key}: {entry['value']:.4g} {entry['unit']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

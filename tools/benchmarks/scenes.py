"""Scenes benchmarks: splat render time (numba CPU backend) and suite scene build time.

Keys: scenes.render_ms_320x240, scenes.render_ms_640x480 (window1_brick from 15 poses along the
approach, after a warm-up render for the JIT; each pose is rendered 3 times and its fastest time kept, to
damp other processes on a shared machine; the value is the median over the poses), scenes.gaussians,
scenes.build_s (median of 3 builds of window1_brick: textures + splats, no disk I/O).
"""

from __future__ import annotations

import statistics
import time

from scenes.build import build_scene
from scenes.camera import PinholeCamera, Pose, euler_to_quat
from scenes.library import DEFAULT_SCENE, NAMED
from scenes.render import render_splats


def _poses() -> list[Pose]:
    out = []
    for i in range(15):
        x = 0.15 * i                       # 0 .. 2.1 m along the approach to the wall at 3 m
        out.append(Pose((x, 0.05 * (i % 3 - 1), -1.5 + 0.03 * (i % 2)), euler_to_quat(0.0, 0.02, 0.03 * (i % 3 - 1))))
    return out


def run() -> dict:
    spec = NAMED[DEFAULT_SCENE]()
    builds = []
    cloud = None
    for _ in range(3):
        t0 = time.perf_counter()
        cloud = build_scene(spec)
        builds.append(time.perf_counter() - t0)
    out = {"scenes.gaussians": {"value": len(cloud), "unit": "Gaussians"},
           "scenes.build_s": {"value": statistics.median(builds), "unit": "s"}}
    for w, h in ((320, 240), (640, 480)):
        cam = PinholeCamera(w, h)
        render_splats(cloud, cam, _poses()[0])  # warm-up (JIT compile or cache load)
        times = []
        for pose in _poses():
            best = float("inf")
            for _ in range(3):
                t0 = time.perf_counter()
                render_splats(cloud, cam, pose)
                best = min(best, 1e3 * (time.perf_counter() - t0))
            times.append(best)
        out[f"scenes.render_ms_{w}x{h}"] = {"value": statistics.median(times), "unit": "ms"}
    return out


if __name__ == "__main__":
    for k, v in run().items():
        print(f"{k}: {v['value']:.4g} {v['unit']}")

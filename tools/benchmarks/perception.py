"""Perception timings on a 320×240 frame pair: flow backends and gap detectors (medians).

The pair is a smooth random texture shifted by (2.5, −1.5) px, so no scene build or rendering is needed.
RAFT-small runs the shipped weights (``companion/flow/weights``); RAFT-large, which has none, runs seeded random
weights (its time is the architecture's).  Accuracy lives in ``flowgap-train-raft --eval-only`` and
``flowgap-eval-masks``, not here.  torch and OpenCV are held to 2 threads.
"""

from __future__ import annotations

import statistics
import time

import cv2
import numpy as np

H, W = 240, 320
RUNS = 7


def _pair() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    pad = 20
    tex = cv2.GaussianBlur(rng.random((H + 2 * pad, W + 2 * pad, 3)).astype(np.float32), (0, 0), 2.0)
    tex = (tex - tex.min()) / (tex.max() - tex.min()) * 255.0
    moved = cv2.warpAffine(tex, np.float32([[1, 0, 2.5], [0, 1, -1.5]]), tex.shape[1::-1])
    crop = (slice(pad, pad + H), slice(pad, pad + W))
    return tex[crop].astype(np.uint8), moved[crop].astype(np.uint8)


def _median_ms(fn, runs: int = RUNS) -> float:
    fn()                                                    # warm-up (allocation, lazy init)
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)


def _refine_scales(raft) -> str:
    """'2-2.5 (lowered for motion over 64 px)' for an adaptive refinement pass, '2' for a fixed one."""
    from companion.flow.raft.backend import refinement_is_adaptive

    if refinement_is_adaptive(raft.refine_scale, raft.refine_min_scale, raft.refine_max_flow):
        return (f"{raft.refine_min_scale:g}-{raft.refine_scale:g} (lowered for motion over "
                f"{raft.refine_max_flow:g} px)")
    return f"{raft.refine_scale:g}"


def run() -> dict[str, dict]:
    import torch

    from companion.flow import make_flow_backend
    from companion.gap import detect_gap, detect_gap_parallax

    torch.set_num_threads(2)
    cv2.setNumThreads(2)
    img1, img2 = _pair()
    out: dict[str, dict] = {}
    for preset in ("ultrafast", "fast", "medium", "fine"):
        dis = make_flow_backend("dis", preset=preset)
        out[f"perception.dis_{preset}_ms_320x240"] = {
            "value": _median_ms(lambda d=dis: d.estimate(img1, img2)),
            "unit": f"ms per 320x240 pair, OpenCV DIS preset {preset}, median of {RUNS}"}
    far = make_flow_backend("farneback")
    out["perception.farneback_ms_320x240"] = {"value": _median_ms(lambda: far.estimate(img1, img2)),
                                              "unit": f"ms per 320x240 pair, median of {RUNS}"}
    # RAFT-small runs the shipped weights with the backend's default settings (a pass at input scale 1, then a
    # refinement pass at scale 2-2.5, lowered for large motions) and, for comparison, in one pass on the frames
    # as they are; no RAFT-large weights are shipped, so it is timed with random ones (a forward pass costs the
    # same whatever the weights)
    for key, variant, options in (("raft_small_12it", "small", {"iters": 12}),
                                  ("raft_small_6it", "small", {"iters": 6}),
                                  ("raft_small_12it_onepass", "small", {"iters": 12, "refine_scale": 0}),
                                  ("raft_large_12it", "large", {"iters": 12, "refine_scale": 0})):
        shipped = variant == "small"
        raft = make_flow_backend("raft", **options) if shipped else \
            make_flow_backend("raft", variant=variant, random_init_seed=0, **options)
        runs = 3 if variant == "large" else 5
        passes = f"RAFT-{variant} {raft.iters} iterations at input scale {raft.input_scale:g}" + (
            f" then {raft.refine_iters} at scale {_refine_scales(raft)}" if raft.refine_scale else " (one pass)")
        out[f"perception.{key}_ms_320x240"] = {
            "value": _median_ms(lambda r=raft: r.estimate(img1, img2), runs),
            "unit": f"ms per 320x240 pair, {passes}, CPU 2 threads, "
                    + ("shipped weights" if shipped else "random weights (timing only)") + f", median of {runs}"}
    flow = make_flow_backend("dis", preset="medium").estimate(img1, img2)
    ys, xs = np.mgrid[0:H, 0:W].astype(np.float32)
    expansion = np.stack([xs - W / 2, ys - H / 2], -1) * 0.03        # forward-motion field for the detectors
    expansion[90:150, 130:200] *= 0.3
    for name, fn in (("paper", detect_gap), ("parallax", detect_gap_parallax)):
        out[f"perception.detect_{name}_ms_320x240"] = {
            "value": _median_ms(lambda f=fn: (f(flow), f(expansion))) / 2,
            "unit": f"ms per 320x240 flow field, {name} gap detector, median of {RUNS}"}
    return out

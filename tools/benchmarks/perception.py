"""Perception timings on a 320×240 frame pair: flow backends and gap detectors (medians).

The pair is a smooth random texture shifted by (2.5, −1.5) px, so no scene build or rendering is needed.
``perception.raft_default_*`` is the companion's default RAFT exactly as it flies (``make_flow_backend("raft")``:
the default weights with their own inference settings and precision, which the label states): over a sequence
of frames, as the companion sees them, where each frame's features are computed once (``_first_pair`` gives
the sequence's first pair, both frames encoded), with its peak memory per pair; the RAFT-small stage-6
weights run their own two-pass settings and one pass; RAFT-large, which has no weights, runs seeded random ones
(its time is the architecture's).  Accuracy lives in ``flowgap-train-raft
--eval-only`` and ``flowgap-eval-masks``, not here.  torch and OpenCV are held to 2 threads.
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


def _sequence(n: int) -> list[np.ndarray]:
    """``n`` frames of the benchmark texture, each moved on from the last as a flight's frames are."""
    first, second = _pair()
    return [first, second] + [np.roll(second, (k, 2 * k), axis=(0, 1)) for k in range(1, n - 1)]


def _sequence_median_ms(backend, frames: list[np.ndarray]) -> float:
    """Median ms of the pairs (f0, f1), (f1, f2), ... after the first two, as the companion flies them: each
    frame's features (RAFT's encoder) are computed once, for the pair it ends, and reused for the next."""
    backend.reset()
    times = []
    for a, b in zip(frames, frames[1:], strict=False):
        t0 = time.perf_counter()
        backend.estimate(a, b)
        times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times[2:])


def _median_ms(fn, runs: int = RUNS) -> float:
    fn()                                                    # warm-up (allocation, lazy init)
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)


_PEAK_SCRIPT = """
import sys, numpy as np, torch
from pathlib import Path
torch.set_num_threads(2)
from companion.flow import make_flow_backend
from tools.benchmarks.perception import _pair
def status(key):
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(key):
            return int(line.split()[1]) / 1024.0
img1, img2 = _pair()
raft = make_flow_backend("raft")
raft.estimate(img1, img2)
Path("/proc/self/clear_refs").write_text("5")     # resets the peak (VmHWM) to the current size
base = status("VmRSS:")
raft.estimate(img1, img2)
print(status("VmHWM:") - base, base)
"""


def _peak_mb() -> tuple[float, float] | None:
    """(peak MB one pair of the default RAFT adds to the loaded process, the process's MB before it), in a
    fresh process (Linux: /proc/self/status); None where that cannot be read."""
    import subprocess
    import sys
    from pathlib import Path

    if not Path("/proc/self/clear_refs").exists():
        return None
    root = Path(__file__).resolve().parents[2]
    proc = subprocess.run([sys.executable, "-c", _PEAK_SCRIPT], cwd=root, capture_output=True, text=True, timeout=600)
    if proc.returncode != 0:
        return None
    peak, base = (float(v) for v in proc.stdout.split())
    return peak, base


def run() -> dict[str, dict]:
    import torch

    from companion.flow import make_flow_backend
    from companion.gap import detect_gap_parallax, textured_pixels
    from companion.gap_paper import detect_gap

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
    from companion.flow.raft.backend import WEIGHTS_DIR

    stage6 = WEIGHTS_DIR / "raft-small-flowgap.pth"
    for key, options, runs in (("raft_default", {}, 7),
                               ("raft_default_fp32", {"precision": "fp32"}, 7),
                               ("raft_small_12it", {"weights": stage6}, 5),
                               ("raft_small_12it_onepass", {"weights": stage6, "refine_scale": 0}, 5),
                               ("raft_large_12it", {"variant": "large", "random_init_seed": 0, "iters": 12,
                                                    "refine_scale": 0}, 3)):
        raft = make_flow_backend("raft", **options)
        weights = ("random weights (timing only)" if raft.weights_path is None else
                   "the default weights" if "weights" not in options else f"weights {raft.weights_path.name}")
        if key.startswith("raft_default") and getattr(raft, "reuses_features", False):
            out[f"perception.{key}_ms_320x240"] = {
                "value": _sequence_median_ms(raft, _sequence(runs + 3)),
                "unit": f"ms per 320x240 pair as flown (a sequence: each frame's features computed once), "
                        f"{raft.describe()}, CPU 2 threads, {weights}, median of {runs}"}
            out[f"perception.{key}_first_pair_ms_320x240"] = {
                "value": _median_ms(lambda r=raft: (r.reset(), r.estimate(img1, img2)), runs),
                "unit": f"ms for a sequence's first pair (both frames encoded), {raft.describe()}, median of {runs}"}
            continue
        out[f"perception.{key}_ms_320x240"] = {
            "value": _median_ms(lambda r=raft: (r.reset(), r.estimate(img1, img2)), runs),
            "unit": f"ms per 320x240 pair, {raft.describe()}, CPU 2 threads, {weights}, median of {runs}"}
    peak = _peak_mb()
    if peak is not None:
        out["perception.raft_default_peak_mb"] = {
            "value": round(peak[0], 1),
            "unit": f"MB a 320x240 pair of the default RAFT adds at its peak to the process (which holds "
                    f"{peak[1]:.0f} MB with the model loaded; VmHWM, fresh process)"}
    flow = make_flow_backend("dis", preset="medium").estimate(img1, img2)
    ys, xs = np.mgrid[0:H, 0:W].astype(np.float32)
    expansion = np.stack([xs - W / 2, ys - H / 2], -1) * 0.03        # forward-motion field for the detectors
    expansion[90:150, 130:200] *= 0.3
    def parallax_as_flown(field):        # perceive gives it the first frame's textured pixels, found each pair
        return detect_gap_parallax(field, textured=textured_pixels(img1))

    for name, fn, how in (("paper", detect_gap, ""),
                          ("parallax", parallax_as_flown, " (as flown: the first frame's textured pixels found and "
                                                          "passed)")):
        out[f"perception.detect_{name}_ms_320x240"] = {
            "value": _median_ms(lambda f=fn: (f(flow), f(expansion))) / 2,
            "unit": f"ms per 320x240 flow field, {name} gap detector{how}, median of {RUNS}"}
    from companion.edges import refine_detection

    found = detect_gap_parallax(expansion)
    focal = (H / 2) / np.tan(np.radians(37.5))           # the flowgap camera: vertical field of view 75°
    K = np.array([[focal, 0.0, W / 2], [0.0, focal, H / 2], [0.0, 0.0, 1.0]])
    still = np.zeros((H, W, 2), np.float32)
    out["perception.edges_ms_320x240"] = {
        "value": _median_ms(lambda: refine_detection(found, img1, img2, expansion, still, K)),
        "unit": f"ms per 320x240 pair, an opening's edge read again from the frames (companion.edges, as flown, "
                f"{len(found.candidates)} opening), median of {RUNS}"}
    return out

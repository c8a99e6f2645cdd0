"""Evaluate flow backends × gap detectors on the scene suite: ``flowgap-eval-masks`` (``python -m tools.eval_masks``).

For every suite scene and several approach viewpoints (each a pair of frames: a pose and a small forward,
lateral or diagonal move), every flow backend computes the flow from frame 1 to frame 2 and every detector
turns it into a gap mask.  Compared with the ground-truth gap mask of frame 1 (the pixels whose line of sight
passes through the opening) it records IoU, centroid error, detection and time.

Outputs (in ``-o/--out``): ``eval_masks.json`` (``rows`` with scene, viewpoint, backend, detector, iou,
centroid_err_px, detected, ms, flow_ms, detect_ms, truth_area_px, mask_area_px; ``summary`` per backend ×
detector; ``goals``), ``eval_masks.md`` (Markdown tables) and ``montage.png`` (per scene: frame, flow colour,
each detector's mask over the ground truth: green = truth only, red = detection only, yellow = both, cross =
centroid).

Ground truth comes from ``scenes.groundtruth``: the gap mask is frame 1's label image (pixels showing what
lies beyond the wall); the ``groundtruth`` backend is its occlusion-checked exact flow.

With ``--ray [ADDRESS]`` each scene's pairs are one Ray task on any node of a cluster (``tools.eval_masks_ray``).
"""

from __future__ import annotations

import argparse
import json
import logging
import statistics
import sys
import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import cv2
import numpy as np

from companion.flow.registry import parse_backend

log = logging.getLogger("flowgap.eval_masks")

DEFAULT_BACKENDS = ("dis:fast", "dis:medium", "dis:fine", "farneback", "groundtruth", "raft")
DEFAULT_DETECTORS = ("paper", "parallax", "parallax_known")
# ... and on request "parallax_end": the parallax detector with ParallaxGapConfig.past_the_end on (off as flown),
# and "parallax_edges": its openings' edges read again from the two frames, as the companion flies (companion.edges)
DETECTORS = (*DEFAULT_DETECTORS, "parallax_end", "parallax_edges")
GOALS = {"dis_median_iou": 0.85, "dis_detection_rate": 0.95, "best_median_iou": 0.90, "best_min_scene_iou": 0.75}


@dataclass(frozen=True)
class Viewpoint:
    """Frame 1 at ``position`` (NED, level, facing +x); frame 2 after moving by ``motion`` (NED metres)."""

    name: str
    position: tuple[float, float, float]
    motion: tuple[float, float, float]


def make_viewpoints(quick: bool = False, spec=None) -> list[Viewpoint]:
    """Approach viewpoints: distances 3.0/2.0/1.2 m from the wall, centred or 0.3 m left.

    For the suite (``spec`` None) in absolute coordinates, as ever: x = 0/1/1.8 before the wall at x = 3, y 0 or
    -0.3, at 1.5 m.  For another scene, relative to its wall and its (first) opening's centre, which in a random
    scene may be a metre to the side and at another height."""
    motions = {"fwd": (0.10, 0.0, 0.0), "lat": (0.0, 0.10, 0.0), "diag": (0.08, 0.06, 0.0)}
    distances = (3.0, 2.0, 1.2)
    ys = (0.0, -0.3)
    if quick:
        distances, ys, motions = (2.0,), (0.0,), {"diag": motions["diag"], "fwd": motions["fwd"]}
    if spec is None:
        wall_x, cy, cz = 3.0, 0.0, -1.5
    else:
        poly = np.asarray(spec.openings[0].polygon())
        wall_x, cy, cz = spec.wall_x, float(poly[:, 0].mean()), float(poly[:, 1].mean())
    return [Viewpoint(f"x{3.0 - d:.1f}_y{y:+.1f}_{m}", (wall_x - d, cy + y, cz), motion) for d in distances
            for y in ys for m, motion in motions.items()]


# ------------------------------------------------------------------------------------------------------------
# ground truth (scenes.groundtruth)
# ------------------------------------------------------------------------------------------------------------

def gt_mask(cloud, camera, pose, render=None) -> np.ndarray:
    """Ground-truth gap mask of the frame at ``pose`` (from its label image when already rendered)."""
    from scenes import groundtruth

    if render is not None:
        return groundtruth.gap_mask_from_labels(render.label)
    return np.asarray(groundtruth.gap_mask(cloud, camera, pose), bool)


# ------------------------------------------------------------------------------------------------------------
# backends and detectors
# ------------------------------------------------------------------------------------------------------------

def build_backends(specs, raft_weights, raft_iters: int, threads: int):
    from companion.flow import FlowError, make_flow_backend

    backends, skipped = {}, {}
    for spec in specs:
        name, options = parse_backend(spec)
        try:
            if name == "groundtruth":
                continue            # built per scene
            if name == "raft":
                if raft_iters is not None:
                    options.setdefault("iters", raft_iters)
                options["num_threads"] = threads
                if raft_weights:
                    options["weights"] = raft_weights
            backends[spec] = make_flow_backend(name, **options)
        except (FlowError, ValueError, KeyError) as exc:
            skipped[spec] = str(exc)
            log.warning("skipping backend %s: %s", spec, exc)
    return backends, skipped


def camera_translation(camera, pose1, pose2) -> tuple[float, float, float]:
    """Camera-frame translation direction of frame 2's centre seen from frame 1."""
    r1, t1 = camera.world_to_camera(pose1)
    c2 = camera.camera_centre(pose2)
    return tuple(float(v) for v in (r1 @ c2 + t1))


def run_detector(name: str, flow: np.ndarray, camera, pose1, pose2, frames=None):
    """``frames``: the pair's two RGB images: the parallax detectors read the first's texture (as flown), and
    "parallax_edges" the edges from both."""
    from companion.gap import CameraMotion, ParallaxGapConfig, detect_gap_parallax, textured_pixels
    from companion.gap_paper import detect_gap

    if name == "parallax_edges":
        from companion.edges import refine_detection

        found = run_detector("parallax", flow, camera, pose1, pose2, frames)
        level = np.zeros((*flow.shape[:2], 2), np.float32)      # the viewpoints are level: no rotation's flow
        return refine_detection(found, frames[0], frames[1], flow, level, camera.K)
    if name == "paper":
        return detect_gap(flow)
    textured = textured_pixels(frames[0]) if frames is not None else None
    if name in ("parallax", "parallax_end"):
        # "parallax" is the detector as flown, whatever its defaults; "parallax_end" that with past_the_end on
        config = ParallaxGapConfig(past_the_end=True) if name == "parallax_end" else ParallaxGapConfig()
        return detect_gap_parallax(flow, config,
                                   motion=CameraMotion(focal_px=camera.fy, principal_point=_cv_pp(camera)),
                                   textured=textured)
    if name == "parallax_known":
        motion = CameraMotion(camera_translation(camera, pose1, pose2), camera.fy, _cv_pp(camera))
        return detect_gap_parallax(flow, motion=motion, textured=textured)
    raise KeyError(f"unknown detector {name!r}; choose from {DETECTORS}")


def _cv_pp(camera) -> tuple[float, float]:
    px, py = camera.principal_point          # scenes: pixel centres at +0.5; ours: at integers
    return px - 0.5, py - 0.5


# ------------------------------------------------------------------------------------------------------------
# metrics, summary, montage
# ------------------------------------------------------------------------------------------------------------

def iou(a: np.ndarray, b: np.ndarray) -> float:
    union = np.logical_or(a, b).sum()
    return float(np.logical_and(a, b).sum() / union) if union else 1.0


def centroid(mask: np.ndarray) -> tuple[float, float] | None:
    ys, xs = np.nonzero(mask)
    return (float(xs.mean()), float(ys.mean())) if len(xs) else None


def summarise(rows: list[dict]) -> list[dict]:
    groups: dict[tuple[str, str], list[dict]] = {}
    for r in rows:
        groups.setdefault((r["backend"], r["detector"]), []).append(r)
    out = []
    for (backend, detector), rs in groups.items():
        per_scene: dict[str, list[float]] = {}
        for r in rs:
            per_scene.setdefault(r["scene"], []).append(r["iou"])
        scene_iou = {s: statistics.median(v) for s, v in per_scene.items()}
        errs = [r["centroid_err_px"] for r in rs if r["centroid_err_px"] is not None]
        out.append({
            "backend": backend, "detector": detector, "pairs": len(rs),
            "median_iou": statistics.median(r["iou"] for r in rs),
            "mean_iou": statistics.fmean(r["iou"] for r in rs),
            "min_scene_iou": min(scene_iou.values()),
            "worst_scene": min(scene_iou, key=scene_iou.get),
            "detection_rate": sum(r["detected"] for r in rs) / len(rs),
            "median_centroid_err_px": statistics.median(errs) if errs else None,
            "median_ms": statistics.median(r["ms"] for r in rs),
            "median_flow_ms": statistics.median(r["flow_ms"] for r in rs),
            "scene_iou": scene_iou,
        })
    out.sort(key=lambda s: (-s["median_iou"], -s["min_scene_iou"]))
    return out


def check_goals(summary: list[dict]) -> dict:
    dis = [s for s in summary if s["backend"].startswith("dis")]
    real = [s for s in summary if s["backend"] != "groundtruth"]
    best_dis = max(dis, key=lambda s: (s["median_iou"], s["detection_rate"]), default=None)
    best = max(real, key=lambda s: (s["median_iou"], s["min_scene_iou"]), default=None)
    goals = {}
    if best_dis:
        goals["dis"] = {"combo": f"{best_dis['backend']} + {best_dis['detector']}",
                        "median_iou": best_dis["median_iou"], "detection_rate": best_dis["detection_rate"],
                        "met": best_dis["median_iou"] >= GOALS["dis_median_iou"]
                        and best_dis["detection_rate"] >= GOALS["dis_detection_rate"]}
    if best:
        goals["best"] = {"combo": f"{best['backend']} + {best['detector']}", "median_iou": best["median_iou"],
                         "min_scene_iou": best["min_scene_iou"],
                         "met": best["median_iou"] >= GOALS["best_median_iou"]
                         and best["min_scene_iou"] >= GOALS["best_min_scene_iou"]}
    return goals


def markdown(summary: list[dict], goals: dict, skipped: dict, n_scenes: int, n_views: int) -> str:
    lines = [f"# Gap masks: {n_scenes} scenes × {n_views} viewpoint pairs", "",
             "| backend | detector | median IoU | mean IoU | worst scene (median IoU) | detected | "
             "median centroid err px | median ms (flow+detect) |",
             "| --- | --- | ---: | ---: | --- | ---: | ---: | ---: |"]
    for s in summary:
        err = "–" if s["median_centroid_err_px"] is None else f"{s['median_centroid_err_px']:.1f}"
        lines.append(f"| {s['backend']} | {s['detector']} | {s['median_iou']:.3f} | {s['mean_iou']:.3f} | "
                     f"{s['worst_scene']} ({s['min_scene_iou']:.3f}) | {100 * s['detection_rate']:.0f} % | "
                     f"{err} | {s['median_ms']:.1f} |")
    lines += ["", "Goals (DIS: median IoU ≥ 0.85 and detection ≥ 95 %; best backend+detector, ground truth "
              "excluded: median IoU ≥ 0.90, no scene < 0.75):", ""]
    for key, g in goals.items():
        lines.append(f"- {key}: {g['combo']} — " + ", ".join(
            f"{k} {v:.3f}" for k, v in g.items() if isinstance(v, float)) + f" — {'met' if g['met'] else 'NOT met'}")
    if skipped:
        lines += ["", "Skipped backends:", ""] + [f"- {k}: {v}" for k, v in skipped.items()]
    if summary:
        lines += ["", "Per-scene median IoU:", "",
                  "| scene | " + " | ".join(f"{s['backend']} + {s['detector']}" for s in summary) + " |",
                  "| --- |" + " ---: |" * len(summary)]
        for scene in summary[0]["scene_iou"]:
            lines.append(f"| {scene} | " + " | ".join(f"{s['scene_iou'].get(scene, float('nan')):.3f}"
                                                     for s in summary) + " |")
    return "\n".join(lines) + "\n"


def overlay(frame: np.ndarray, truth: np.ndarray, det) -> np.ndarray:
    """RGB tile: dimmed grey frame, truth only green, detection only red, both yellow, centroid cross."""
    grey = cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY)
    out = np.repeat((grey * 0.5)[..., None], 3, axis=2).astype(np.uint8)
    both, t_only, d_only = truth & det.mask, truth & ~det.mask, det.mask & ~truth
    out[t_only] = (0, 200, 0)
    out[d_only] = (220, 0, 0)
    out[both] = (230, 230, 0)
    if det.centroid is not None:
        c = (int(round(det.centroid[0])), int(round(det.centroid[1])))
        cv2.drawMarker(out, c, (255, 255, 255), cv2.MARKER_CROSS, 12, 2)
    return out


def label(tile: np.ndarray, text: str) -> np.ndarray:
    tile = tile.copy()
    cv2.putText(tile, text, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 3, cv2.LINE_AA)
    cv2.putText(tile, text, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1, cv2.LINE_AA)
    return tile


# ------------------------------------------------------------------------------------------------------------
# main
# ------------------------------------------------------------------------------------------------------------

def scene_viewpoints(spec, quick: bool = False) -> list[Viewpoint]:
    """A scene's viewpoints: the suite's absolute ones for a suite scene, else placed before its opening."""
    from scenes.library import SUITE

    return make_viewpoints(quick, None if spec is None or spec.name in SUITE else spec)


def evaluate_scene(scene, views_of, backends: dict, backend_specs, detectors, *, montage_backend="dis:medium",
                   montage_view=None, on_pair=None):
    """One scene's viewpoint pairs through every backend and detector: (rows, montage tile or None).
    ``views_of(spec)`` gives its viewpoints; ``on_pair(n)`` is called after each of its ``n`` pairs (progress)."""
    from companion.flow.colour import flow_to_colour
    from scenes.build import load_scene
    from scenes.camera import PinholeCamera, Pose
    from scenes.render import render_splats

    camera = PinholeCamera()
    spec, cloud = load_scene(scene)
    name = spec.name if spec is not None else str(scene)     # spec paths are reported by their scene's name
    views = views_of(spec)
    montage_view = montage_view or views[len(views) // 2].name
    backends = dict(backends)
    if any(parse_backend(b)[0] == "groundtruth" for b in backend_specs):
        from companion.flow.groundtruth import GroundTruthBackend

        backends["groundtruth"] = GroundTruthBackend(spec, camera)
    rows, tile_row = [], None
    for vp in views:
        pose1 = Pose(vp.position)
        pose2 = Pose(tuple(p + d for p, d in zip(vp.position, vp.motion, strict=True)))
        r1 = render_splats(cloud, camera, pose1)
        r2 = render_splats(cloud, camera, pose2)
        truth = gt_mask(cloud, camera, pose1, r1)
        truth_c = centroid(truth)
        tiles = None
        for bname, backend in backends.items():
            if bname == "groundtruth":
                backend.set_poses(pose1, pose2, renders=(r1, r2))
            if hasattr(backend, "reset"):
                backend.reset()
            t0 = time.perf_counter()
            flow = backend.estimate(r1.rgb, r2.rgb)
            flow_ms = 1e3 * (time.perf_counter() - t0)
            flow = np.nan_to_num(flow, nan=0.0)
            if bname == montage_backend and vp.name == montage_view:
                tiles = [label(r1.rgb, f"{name} {vp.name}"), label(flow_to_colour(flow), bname)]
            for dname in detectors:
                t0 = time.perf_counter()
                det = run_detector(dname, flow, camera, pose1, pose2, (r1.rgb, r2.rgb))
                det_ms = 1e3 * (time.perf_counter() - t0)
                err = (None if det.centroid is None or truth_c is None
                       else float(np.hypot(det.centroid[0] - truth_c[0], det.centroid[1] - truth_c[1])))
                rows.append({"scene": name, "viewpoint": vp.name, "backend": bname, "detector": dname,
                             "iou": iou(det.mask, truth), "centroid_err_px": err, "detected": det.found,
                             "ms": flow_ms + det_ms, "flow_ms": flow_ms, "detect_ms": det_ms,
                             "truth_area_px": int(truth.sum()), "mask_area_px": int(det.mask.sum()),
                             "reason": det.reason})
                if tiles is not None and len(tiles) < 2 + len(detectors):
                    tiles.append(label(overlay(r1.rgb, truth, det), f"{dname} IoU {rows[-1]['iou']:.2f}"))
        if tiles is not None:
            tile_row = np.concatenate(tiles, axis=1)
        if on_pair is not None:
            on_pair(len(views))
    return rows, tile_row


def evaluate(scenes_list, viewpoints, backend_specs, detectors, *, raft_weights=None, raft_iters=None,
             threads=2, montage_backend="dis:medium", montage_view=None, progress=True):
    """Run the evaluation on this machine; returns (rows, skipped backends, montage rows).  ``viewpoints``: a
    list, or a function of a scene's spec that gives its list."""
    from tqdm import tqdm

    backends, skipped = build_backends(backend_specs, raft_weights, raft_iters, threads)
    views_of = viewpoints if callable(viewpoints) else (lambda spec: viewpoints)
    rows, montage = [], []
    with tqdm(total=None, desc="pairs", disable=not progress, unit="pair") as bar:
        def on_pair(n_views: int) -> None:
            if bar.total is None:
                bar.total = len(scenes_list) * n_views
            bar.update(1)

        for scene in scenes_list:
            scene_rows, tile = evaluate_scene(scene, views_of, backends, backend_specs, detectors,
                                              montage_backend=montage_backend, montage_view=montage_view,
                                              on_pair=on_pair)
            rows += scene_rows
            if tile is not None:
                montage.append(tile)
    return rows, skipped, montage


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="flowgap-eval-masks",
        description="Gap-mask accuracy of every flow backend × gap detector over the scene suite "
                    "(IoU with ground truth, centroid error, detection rate, time). Writes JSON, Markdown "
                    "and a montage PNG; prints the summary table.")
    parser.add_argument("--scenes", nargs="*", default=None,
                        help="scene names or spec paths (default: the 16-scene suite scenes.library.SUITE, unless "
                             "--random is given)")
    parser.add_argument("--random", type=int, default=0, metavar="N",
                        help="also evaluate N random scenes (scenes.random_scene, the suite's texture families; "
                             "the scenes flowgap-eval-flights --random N --seed S flies), viewpoints placed "
                             "relative to each one's opening; specs saved under OUT/scenes")
    parser.add_argument("--seed", type=int, default=0, help="seed of the --random scenes (default 0)")
    parser.add_argument("--backends", nargs="*", default=list(DEFAULT_BACKENDS),
                        help="flow backends, 'dis:<preset>' / 'raft:<variant>' allowed (default: %(default)s); "
                             "a backend that cannot be built (e.g. RAFT without weights) is skipped and reported")
    parser.add_argument("--detectors", nargs="*", default=list(DEFAULT_DETECTORS),
                        help="gap detectors (default: %(default)s; 'parallax_end': the parallax detector looking "
                             "past the wall's end too, ParallaxGapConfig.past_the_end; 'parallax_edges': its "
                             "openings' edges read again from the two frames, as the companion flies)")
    parser.add_argument("--raft-weights", type=Path, default=None, help="RAFT weights file (default: backend's)")
    parser.add_argument("--raft-iters", type=int, default=None,
                        help="RAFT iterations (default: the weights file's own setting)")
    parser.add_argument("--threads", type=int, default=2, help="torch/OpenCV threads (default: %(default)s)")
    parser.add_argument("--quick", action="store_true", help="2 viewpoint pairs per scene instead of 18")
    parser.add_argument("--montage-backend", default="dis:medium",
                        help="backend whose flow the montage shows (default: %(default)s)")
    parser.add_argument("-o", "--out", "--out-dir", dest="out_dir", metavar="DIR", type=Path,
                        default=Path("runs/eval_masks"),
                        help="output folder (default: %(default)s)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    from tools.ray_sweep import add_ray_argument

    add_ray_argument(parser, "scene's mask pairs (with --threads CPUs)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    cv2.setNumThreads(args.threads)

    try:
        from scenes.library import SUITE
    except ImportError as exc:
        print(f"flowgap-eval-masks: the scenes package is not available ({exc})", file=sys.stderr)
        return 2
    if args.random < 0 or args.threads <= 0:
        print("flowgap-eval-masks: error: --random must be >= 0 and --threads positive", file=sys.stderr)
        return 2
    from tools.eval_flights import random_scene_files
    from tools.ray_sweep import RaySetupError, TaskFailed, ray_session, require_ray

    scenes_list = list(args.scenes or ([] if args.random else SUITE))
    scenes_list += random_scene_files(args.random, args.seed, args.out_dir / "scenes")
    t0 = time.perf_counter()
    nodes = None
    if args.ray is None:
        rows, skipped, montage = evaluate(scenes_list, partial(scene_viewpoints, quick=args.quick), args.backends,
                                          args.detectors, raft_weights=args.raft_weights,
                                          raft_iters=args.raft_iters, threads=args.threads,
                                          montage_backend=args.montage_backend, progress=not args.no_progress)
    else:
        from tools.eval_masks_ray import evaluate_on_ray

        try:
            require_ray()
            with ray_session(args.ray):
                rows, skipped, montage, nodes = evaluate_on_ray(
                    scenes_list, args.quick, args.backends, args.detectors, raft_weights=args.raft_weights,
                    raft_iters=args.raft_iters, threads=args.threads, montage_backend=args.montage_backend,
                    progress=not args.no_progress)
        except (RaySetupError, TaskFailed) as exc:
            print(f"flowgap-eval-masks: error: {exc}", file=sys.stderr)
            return 2 if isinstance(exc, RaySetupError) else 1
    if not rows:
        print("flowgap-eval-masks: no backend could run: " + "; ".join(f"{k}: {v}" for k, v in skipped.items()),
              file=sys.stderr)
        return 1
    summary = summarise(rows)
    goals = check_goals(summary)
    args.out_dir.mkdir(parents=True, exist_ok=True)
    meta = {"scenes": scenes_list, "random": args.random, "seed": args.seed,
            "viewpoints": [vp.__dict__ for vp in make_viewpoints(args.quick)], "backends": args.backends,
            "detectors": args.detectors, "skipped_backends": skipped, "seconds": time.perf_counter() - t0,
            "executor": "local" if args.ray is None else "ray", "nodes": nodes,
            "ground_truth": "scenes.groundtruth (label image of frame 1; occlusion-checked depth flow)"}
    (args.out_dir / "eval_masks.json").write_text(json.dumps(
        {"meta": meta, "summary": summary, "goals": goals, "rows": rows}, indent=1) + "\n")
    md = markdown(summary, goals, skipped, len(scenes_list), len(make_viewpoints(args.quick)))
    (args.out_dir / "eval_masks.md").write_text(md)
    if montage:
        width = max(m.shape[1] for m in montage)
        grid = np.concatenate([np.pad(m, ((0, 0), (0, width - m.shape[1]), (0, 0))) for m in montage], axis=0)
        cv2.imwrite(str(args.out_dir / "montage.png"), grid[..., ::-1])
    print(md)
    print(f"wrote {args.out_dir}/eval_masks.json, eval_masks.md" + (", montage.png" if montage else "")
          + f" ({len(rows)} rows, {meta['seconds']:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Gap masks on the views a flight actually took, against the rendered truth.

``flowgap-eval-masks`` scores masks on fixed viewpoint pairs; this re-perceives the frame pairs of flown runs
(``flowgap-eval-flights`` output: each flight's ``companion/frames.jsonl`` has the true and estimated poses of
every frame), re-rendering both frames from the scene's spec, and compares what the servo reads from each mask
with the truth: the clear radius, and the clearance straight ahead (the mask's edge from where the vehicle is
at the second frame, as :class:`companion.opening.OpeningTracker` measures it), in pixels.  Pairs are split
into sideways and forward ones by the camera's motion; each ``--fill`` value of the parallax detector's
``occlusion_fill`` is scored on the same flow.

    python -m tools.flown_masks runs/r32 runs/hard46 --flow raft --pairs 70 --fill none 0.5 0.75 1 -o runs/fm
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import math
import random
import sys
from pathlib import Path

import numpy as np

from tools.tlog.replay import ReplayError, read_jsonl

log = logging.getLogger(__name__)

SIDEWAYS_RATIO = 0.6   # a pair is sideways when its across-heading motion exceeds this fraction of its forward one


def is_sideways(motion: tuple[float, float, float]) -> bool:
    """(forward, right, down) motion of the camera between the frames (metres, NED from a north-facing start)."""
    return abs(motion[1]) + abs(motion[2]) > SIDEWAYS_RATIO * abs(motion[0])


def summarise(rows: list[dict], fills: list[str]) -> dict:
    """Per group (all, sideways, forward) and fill: the pairs scored and the percentiles (10, 50, 90) and maximum of
    the clear radius's and the clearance's error (detected − truth, px; negative: the mask is short)."""
    groups = {"all": rows, "sideways": [r for r in rows if r["sideways"]],
              "forward": [r for r in rows if not r["sideways"]]}
    out: dict = {}
    for group, members in groups.items():
        out[group] = {}
        for fill in fills:
            scored = [r["fills"][fill] for r in members if r["fills"].get(fill) is not None]
            entry: dict = {"pairs": len(scored)}
            for key, det, truth in (("radius_err_px", "radius_px", "truth_radius_px"),
                                    ("clearance_err_px", "clearance_px", "truth_clearance_px")):
                errs = np.array([s[det] - s[truth] for s in scored if key == "radius_err_px" or s[truth] > 0])
                entry[key] = ({"p10": float(np.percentile(errs, 10)), "median": float(np.median(errs)),
                               "p90": float(np.percentile(errs, 90)), "max": float(errs.max())}
                              if errs.size else None)
            out[group][fill] = entry
    return out


def markdown(summary: dict) -> str:
    lines = ["| pairs | occlusion_fill | n | clear radius err px (p10 / median / p90 / max) | "
             "clearance ahead err px (p10 / median / p90 / max) |", "| --- | --- | ---: | --- | --- |"]
    for group, fills in summary.items():
        for fill, e in fills.items():
            cells = [" / ".join(f"{e[k][q]:+.1f}" for q in ("p10", "median", "p90", "max")) if e[k] else "–"
                     for k in ("radius_err_px", "clearance_err_px")]
            lines.append(f"| {group} | {fill} | {e['pairs']} | {cells[0]} | {cells[1]} |")
    return "\n".join(lines) + "\n"


def _pairs_of(run: Path) -> list[tuple[Path, Path, int, dict]]:
    pairs = []
    for flight in sorted(p for p in run.iterdir() if (p / "companion" / "frames.jsonl").is_file()):
        scene = run / "scenes" / f"{flight.name.rsplit('-', 1)[0]}.json"
        if not scene.is_file():
            continue
        try:
            frames = {f["step"]: f for f in read_jsonl(flight / "companion" / "frames.jsonl")}
        except ReplayError as exc:     # a flight stopped mid-write: the others still count
            log.warning("skipping %s: %s", flight.name, exc)
            continue
        pairs += [(flight, scene, step, frames) for step in sorted(frames) if step - 1 in frames]
    return pairs


def score_pair(cloud, spec, camera, first: dict, second: dict, backend, configs: dict) -> dict | None:
    """One frame pair through the flow backend and the detector under each config; None when the wall is not
    0.9-2 m ahead (where the servo decides) or the camera moved under 2 cm."""
    import cv2

    from companion.gap import CameraMotion, clear_circle, detect_gap_parallax, textured_pixels
    from companion.motion import derotate, off_heading, tilted_pixel
    from companion.opening_geometry import edge_distance_px
    from scenes import Pose, render_splats
    from tools.eval_masks import gt_mask

    # along north: the suite's and the standard world's walls face a north-facing start; a hard world's wall turned
    # by up to 20° makes this the distance at the wall's middle, a few centimetres off at the opening
    forward = spec.wall.distance - first["position_true"][0]
    p0, p1 = first["position_est"], second["position_est"]
    if not 0.9 <= forward <= 2.0 or math.dist(p0, p1) < 0.02:
        return None
    pose0 = Pose(tuple(first["position_true"]), tuple(first["attitude_true"]))
    pose1 = Pose(tuple(second["position_true"]), tuple(second["attitude_true"]))
    a, b = render_splats(cloud, camera, pose0), render_splats(cloud, camera, pose1)
    flow = derotate(backend.estimate(a.rgb, b.rgb), camera.K, first["attitude_est"], second["attitude_est"])
    truth = gt_mask(cloud, camera, pose0, a)
    n_labels, labels = cv2.connectedComponents(truth.astype(np.uint8))
    focal = float(camera.K[0, 0])
    w, h = camera.width, camera.height
    looks_off = off_heading(first["attitude_est"][2], math.radians(spec.start_yaw_deg))   # the heading flown
    axis = tilted_pixel(((w - 1) / 2, (h - 1) / 2), camera.K, first["attitude_est"][0], first["attitude_est"][1],
                        looks_off)
    shift = focal / forward
    ahead = (axis[0] + (p1[1] - p0[1]) * shift, axis[1] + (p1[2] - p0[2]) * shift)
    motion = (p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2])
    row = {"motion_m": motion, "wall_m": forward, "sideways": is_sideways(motion), "fills": {}}
    textured = textured_pixels(a.rgb)
    for name, config in configs.items():
        det = detect_gap_parallax(flow, config, CameraMotion(focal_px=focal), textured)
        overlaps = [(int(np.logical_and(det.mask, labels == k).sum()), k) for k in range(1, n_labels)]
        best = max(overlaps) if overlaps else (0, 0)
        if not det.found or best[0] == 0:
            row["fills"][name] = None
            continue
        opening = labels == best[1]
        row["fills"][name] = {"radius_px": clear_circle(det.mask)[1], "truth_radius_px": clear_circle(opening)[1],
                              "clearance_px": edge_distance_px(det.mask, ahead),
                              "truth_clearance_px": edge_distance_px(opening, ahead)}
    return row


def fill_value(text: str) -> str:
    """An --fill value: 'none', or a fraction from 0 to 2."""
    if text != "none":
        try:
            ok = 0.0 <= float(text) <= 2.0
        except ValueError:
            ok = False
        if not ok:
            raise argparse.ArgumentTypeError(f"{text!r} is neither 'none' nor a fraction from 0 to 2 (e.g. 0.75)")
    return text


def main(argv: list[str] | None = None) -> int:
    from tqdm import tqdm

    from companion.flow.base import FlowError
    from companion.flow.registry import DEFAULT_FLOW, make_flow_backend, parse_backend
    from companion.gap import ParallaxGapConfig
    from scenes import PinholeCamera, load_scene

    parser = argparse.ArgumentParser(prog="python -m tools.flown_masks", description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("runs", nargs="+", type=Path, help="flowgap-eval-flights output folders (-o of that run)")
    parser.add_argument("--flow", default=DEFAULT_FLOW, help="flow backend to re-perceive with")
    parser.add_argument("--pairs", type=int, default=70, help="frame pairs drawn from each run")
    parser.add_argument("--fill", nargs="+", type=fill_value, default=["none", "0.75"],
                        help="occlusion_fill values to score ('none': off)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the pairs' draw")
    parser.add_argument("-o", "--out", type=Path, default=Path("runs/flown_masks"), help="output folder")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    try:
        configs = {f: dataclasses.replace(ParallaxGapConfig(),
                                          occlusion_fill=None if f == "none" else float(f)) for f in args.fill}
        name, options = parse_backend(args.flow)
        backend = make_flow_backend(name, **options)
    except (ValueError, KeyError, FlowError) as exc:
        print(f"flown_masks: {exc}", file=sys.stderr)
        return 2
    missing = [str(r) for r in args.runs if not (r / "scenes").is_dir()]
    if missing:
        print(f"flown_masks: not a flowgap-eval-flights output (no scenes/ folder): {', '.join(missing)}; "
              "give the -o folder of a flowgap-eval-flights run", file=sys.stderr)
        return 2
    camera, rng, rows = PinholeCamera(), random.Random(args.seed), []
    for run in args.runs:
        pairs = _pairs_of(run)
        rng.shuffle(pairs)
        taken, loaded = 0, {}
        with tqdm(total=args.pairs, desc=run.name, unit="pair") as bar:
            for flight, scene, step, frames in pairs:
                if taken >= args.pairs:
                    break
                if scene not in loaded:
                    loaded = {scene: load_scene(scene)}
                spec, cloud = loaded[scene]
                row = score_pair(cloud, spec, camera, frames[step - 1], frames[step], backend, configs)
                if row is None:
                    continue
                rows.append({"run": str(run), "flight": flight.name, "step": step, **row})
                taken += 1
                bar.update()
    summary = summarise(rows, list(configs))
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "flown_masks.json").write_text(json.dumps({"flow": args.flow, "seed": args.seed,
                                                            "summary": summary, "rows": rows}, indent=1))
    text = markdown(summary)
    (args.out / "flown_masks.md").write_text(text)
    print(text + f"{len(rows)} pairs, flow {args.flow} -> {args.out / 'flown_masks.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""How well a step sideways, square to the wall, reads the wall's thickness: ``python -m tools.thickness_look``.

The size the companion judges an opening by is scaled by the depth of its far edges, the wall's face plus its
thickness, which the companion assumes (0.15 m; the hard world draws 0.10-0.25 m): near the need, that assumption
decides most refusals of passable openings (docs/evaluation.md).  This measures, on renders, the look the companion
flies to read it (:mod:`companion.thickness`; in flight the views' places and tilt add their own errors):

- each scene is a hard-world draw with one opening kept and scaled near the fit threshold, as
  ``python -m tools.size_error`` draws them;
- the camera faces the wall squarely on the normal through the opening's clear centre, ``--distance`` from the face,
  and takes two views ``--step`` apart across it (A and B); at each, a forward pair of 0.15 m gives the opening's
  mask (the flow backend, the parallax detector and, as flown, the edges read again from the frames);
- the flow from A to B gives the face's shift beside the opening, the masks' centroids the opening's, and
  :func:`companion.thickness.thickness_reading` the thickness, as the flown look reads it (the opening nearest the
  image's centre; a view whose opening reaches the frame's edge, or whose width changes by more than 5 % between A
  and B, is left out).  The same with the rendered truth's masks shows what the geometry alone allows.

Outputs (in ``-o/--out``): ``thickness_look.json`` (one row per scene
and a summary) and ``thickness_look.md``.

    python -m tools.thickness_look --scenes 40 --seed 7000 -o runs/thickness_look
"""

from __future__ import annotations

import argparse
import functools
import json
import logging
import math
import sys
from pathlib import Path

import numpy as np

log = logging.getLogger("flowgap.thickness_look")



def square_pose(spec, centre_yz: tuple[float, float], distance_m: float, right_m: float):
    """A camera facing the wall squarely (north), ``distance_m`` from its face, ``right_m`` east of the clear centre."""
    from scenes import Pose
    from scenes.camera import euler_to_quat

    return Pose((spec.wall_x - distance_m, centre_yz[0] + right_m, centre_yz[1]), euler_to_quat(0.0, 0.0, 0.0))


def measure_scene(index: int, seed: int, args, backend, camera) -> dict | None:
    """One scene's row; None where the draw cannot be scaled near the threshold."""
    from companion.edges import edges_for
    from companion.gap import CameraMotion, ParallaxGapConfig, detect_gap_parallax
    from companion.perception import perceive
    from companion.servo import ServoConfig
    from companion.thickness import ThicknessLookConfig, opening_at_centre, thickness_reading
    from scenes import load_scene, render_splats
    from scenes.library import random_scene
    from scenes.spec import SpecError
    from tools.eval_masks import gt_mask
    from tools.size_error import clear_centre_yz, scaled_opening

    rng = np.random.default_rng([seed, index])
    servo = ServoConfig()
    need = servo.body_radius_m + servo.clearance_margin_m
    spec = random_scene(rng, world="hard")
    spec = scaled_opening(spec, int(rng.integers(len(spec.openings))), float(rng.uniform(need - 0.05, need + 0.05)))
    if spec is None:
        return None
    try:
        spec.validate()
    except SpecError:       # scaled past the wall's edge
        return None
    centre = clear_centre_yz(spec.openings[0])
    spec, cloud = load_scene(spec)
    focal = float(camera.K[0, 0])
    detector = functools.partial(detect_gap_parallax, config=ParallaxGapConfig(), motion=CameraMotion(focal_px=focal))
    distance = float(rng.uniform(*args.distance))
    # what the flown look judges by, less its bound on a plausible depth: the spread of the readings is measured
    look = ThicknessLookConfig(plausible_m=(-math.inf, math.inf))
    level = (0.0, 0.0, 0.0)
    views, truths, firsts = [], [], []
    for right in (-args.step / 2.0, args.step / 2.0):
        pose0 = square_pose(spec, centre, distance, right)
        pose1 = square_pose(spec, centre, distance - look.forward_m, right)
        first, second = render_splats(cloud, camera, pose0), render_splats(cloud, camera, pose1)
        seen = perceive(first.rgb, second.rgb, level, level, camera.K, backend, detector, edges=edges_for(args.edges))
        views.append(opening_at_centre(seen.detection))
        truths.append(gt_mask(cloud, camera, pose0, first))
        firsts.append(first.rgb)
    flow = backend.estimate(firsts[0], firsts[1])
    row = {"scene": index, "distance_m": distance, "thickness_m": spec.wall.thickness, "turn_deg": spec.start_yaw_deg,
           "shape": spec.openings[0].shape}
    for label, (mask_a, mask_b) in (("detected", views), ("truth", truths)):
        reading = thickness_reading(mask_a, mask_b, flow, distance, look)
        row[f"{label}_wall_shift_px"] = reading.wall_shift_px
        row[f"{label}_thickness_m"] = reading.thickness_m
    return row


def summarise(rows: list[dict]) -> dict:
    """Per mask source: how many scenes gave a thickness, its error's median, robust spread (1.4826 × the median
    absolute deviation) and plain spread, and the share within 0.02 and 0.04 m, against the world's own spread."""
    out = {"scenes": len(rows), "world_sd_m": float(np.std([r["thickness_m"] for r in rows])) if rows else None}
    for label in ("detected", "truth"):
        errors = np.array([r[f"{label}_thickness_m"] - r["thickness_m"] for r in rows
                           if r[f"{label}_thickness_m"] is not None])
        if not len(errors):
            out[label] = None
            continue
        median = float(np.median(errors))
        out[label] = {"n": int(len(errors)), "median_error_m": median,
                      "robust_sd_m": float(1.4826 * np.median(np.abs(errors - median))),
                      "sd_m": float(np.std(errors)), "within_0_02": float(np.mean(np.abs(errors) < 0.02)),
                      "within_0_04": float(np.mean(np.abs(errors) < 0.04))}
    return out


def markdown(summary: dict, flow: str, seed: int, step: float) -> str:
    lines = [f"# The wall's thickness from a {step:.2f} m sidestep square to it (flow {flow}, seed {seed})", "",
             f"{summary['scenes']} scenes; the world's thickness spread {summary['world_sd_m'] or 0:.3f} m (sd).", "",
             "| masks | scenes | median error | robust sd | sd | within 0.02 m | within 0.04 m |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    for label in ("detected", "truth"):
        s = summary.get(label)
        if s:
            lines.append(f"| {label} | {s['n']} | {s['median_error_m']:+.3f} m | {s['robust_sd_m']:.3f} m | "
                         f"{s['sd_m']:.3f} m | {100 * s['within_0_02']:.0f} % | {100 * s['within_0_04']:.0f} % |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    from tqdm import tqdm

    from companion.edges import EDGE_MODES
    from companion.flow.registry import DEFAULT_FLOW
    from scenes import PinholeCamera
    from tools.size_error import flow_backend_or_say

    parser = argparse.ArgumentParser(prog="python -m tools.thickness_look", description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--scenes", type=int, default=40, help="hard-world scenes drawn")
    parser.add_argument("--seed", type=int, default=0, help="seed of the scenes' and the distances' draws")
    parser.add_argument("--step", type=float, default=0.3, metavar="M", help="the step across, between the views")
    parser.add_argument("--distance", type=float, nargs=2, default=(1.0, 1.6), metavar=("NEAR", "FAR"),
                        help="the views' distance from the wall's face (metres), drawn between these")
    parser.add_argument("--flow", default=DEFAULT_FLOW, help="flow backend, as flowgap-companion --flow")
    parser.add_argument("--edges", choices=EDGE_MODES, default="photo",
                        help="openings' edges read again from the frames, as flown (photo), or the detector's masks")
    parser.add_argument("-o", "--out", type=Path, default=Path("runs/thickness_look"), help="output folder")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    near, far = args.distance
    if args.scenes < 1 or not 0.05 <= args.step <= 0.4 or not 0.5 <= near <= far:
        print("thickness_look: --scenes must be at least 1, --step between 0.05 and 0.4 m (the views stay within "
              "the opening's width), and --distance NEAR FAR with 0.5 <= NEAR <= FAR", file=sys.stderr)
        return 2
    backend = flow_backend_or_say(args.flow, "thickness_look")
    if backend is None:
        return 2
    camera, rows = PinholeCamera(), []
    for index in tqdm(range(args.scenes), desc="scenes", unit="scene"):
        row = measure_scene(index, args.seed, args, backend, camera)
        if row is not None:
            rows.append(row)
    summary = summarise(rows)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "thickness_look.json").write_text(json.dumps({"flow": args.flow, "edges": args.edges,
                                                              "seed": args.seed, "step_m": args.step,
                                                              "summary": summary, "rows": rows}, indent=1))
    text = markdown(summary, args.flow, args.seed, args.step)
    (args.out / "thickness_look.md").write_text(text)
    print(text + f"-> {args.out / 'thickness_look.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

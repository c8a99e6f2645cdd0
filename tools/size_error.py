"""How well the companion sizes an opening near the fit threshold: ``python -m tools.size_error``.

The hard world's refusals turn on openings within a few centimetres of the body's diameter plus its margin, and a
sweep of 100 flights judges only a dozen of them.  This renders many such openings on the approach instead:

- each scene is a hard-world draw (``scenes.random_scene(rng, world="hard")``) with one of its openings kept and
  scaled so that its clear radius, square to the wall (``scenes.groundtruth.corridor_clearance``), is drawn
  uniformly within ``--band`` of the threshold (the servo's body radius plus margin);
- ``--pairs`` frame pairs per scene, flown toward the opening's clear centre along the start heading: the first
  frame 0.87-1.67 m from the wall (by default), a forward step of 0.12-0.22 m (``--motion sideways``: the step
  across the heading instead, both frames at the first's distance), a few centimetres and a few hundredths of a
  radian of jitter;
- each pair goes through the flow backend, the derotation, the parallax detector and the edges read again from the
  frames (:mod:`companion.edges`; ``--edges flow`` leaves the detector's masks) as flown; the widest opening
  it finds is stretched to the wall's plane (:func:`companion.opening.turned_wall_stretch`, with the true turn)
  and sized by :meth:`companion.opening.OpeningTracker.clear_radius_m`, with the true distance: what is measured
  is the mask and the size estimate, not the wall's distance or turn.

Per scene, the pairs taken within ``decide_within_m`` in approach order, the judgement is the upper quartile of
the first ``min_estimates`` estimates, as :class:`companion.opening.OpeningTracker` judges.  The summary gives the
mask's clear radius against the rendered truth's (pixels), the judgement over the truth, and how many impassable
openings were judged to fit and passable ones too small.

Each pair also reads the wall's thickness from the reveal, the opening's inner faces between the wall's front face
and the back edge that bounds what is seen through it (measured here, not flown): just outside the mask the inverse
depth falls below the wall's plane toward d/(d+t).  ``reveal_ratio`` is the median of ρ over the plane's ρ in the
ring ``REVEAL_RING_PX`` outside the mask, over its median in the rings ``REVEAL_PLATEAU_PX`` out, and the summary
fits t = a + b·d·(1/ratio - 1) to the run's pairs (d the first frame's distance) and gives its error left out a
scene at a time, against the world's own spread and the 0.15 m the companion assumes; ``--reveal-fit A B`` tries
a fit from another run (another seed) instead.

Outputs (in ``-o/--out``): ``size_error.json`` (``rows``: one per pair; ``scenes``: one per scene; ``summary``)
and ``size_error.md``.

    python -m tools.size_error --scenes 150 --seed 8000 -o runs/size_error
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import logging
import math
import sys
from pathlib import Path

import numpy as np

log = logging.getLogger("flowgap.size_error")


def scaled_opening(spec, index: int, clearance_m: float):
    """``spec`` with opening ``index`` alone, scaled about its centre so that its clear radius square to the wall
    is ``clearance_m`` (to the clearance's 1 mm grid); None where the opening has no clearance to scale."""
    from scenes.groundtruth import corridor_clearance

    opening = spec.openings[index]
    alone = dataclasses.replace(spec, openings=(opening,))
    now = corridor_clearance(alone, 0, 0.0)
    if now <= 0.0:
        return None
    factor = clearance_m / now
    if opening.shape == "polygon":
        vertices = np.asarray(opening.vertices, float)
        middle = vertices.mean(0)
        opening = dataclasses.replace(opening, vertices=tuple(map(tuple, (middle + (vertices - middle) * factor)
                                                                  .tolist())))
    else:
        opening = dataclasses.replace(opening, size=(opening.size[0] * factor, opening.size[1] * factor))
    return dataclasses.replace(spec, openings=(opening,))


def clear_centre_yz(opening, resolution_m: float = 0.002) -> tuple[float, float]:
    """(y, z) of the centre of the largest circle inside the opening's outline, the middle of its plateau for an
    elongated opening, where the servo aims (:func:`companion.gap.clear_circle`; before 2026-12-05, an end of the
    plateau: the clear radius seen from there is the same, the view is not the servo's)."""
    import cv2

    from companion.gap import clear_circle

    poly = np.asarray(opening.polygon(), float)
    lo = poly.min(0) - 2 * resolution_m
    size = np.ceil((poly.max(0) - lo + 2 * resolution_m) / resolution_m).astype(int) + 1
    grid = cv2.fillPoly(np.zeros((size[1], size[0]), np.uint8), [np.round((poly - lo) / resolution_m)
                                                                  .astype(np.int32)], 1)
    (col, row), _ = clear_circle(grid.astype(bool))
    return float(lo[0] + col * resolution_m), float(lo[1] + row * resolution_m)


def approach_pose(spec, centre_yz: tuple[float, float], distance_m: float, across_m: tuple[float, float],
                  tilt: tuple[float, float]):
    """A camera ``distance_m`` from the opening's clear centre along the start heading (NED), moved
    ``across_m`` (right, down) across it, rolled and pitched by ``tilt``: (Pose, (roll, pitch, yaw))."""
    from scenes import Pose
    from scenes.camera import euler_to_quat

    yaw = math.radians(spec.start_yaw_deg)
    x = spec.wall_x - distance_m * math.cos(yaw) - across_m[0] * math.sin(yaw)
    y = centre_yz[0] - distance_m * math.sin(yaw) + across_m[0] * math.cos(yaw)
    euler = (tilt[0], tilt[1], yaw)
    return Pose((x, y, centre_yz[1] + across_m[1]), euler_to_quat(*euler)), euler


def pair_poses(spec, centre_yz: tuple[float, float], rng, distance_m: tuple[float, float], motion: str = "forward"):
    """One pair's ((pose, euler), (pose, euler)) and the first frame's distance along the heading to the clear
    centre (as the servo's wall reading is).  ``forward``: a step of 0.12-0.22 m toward the wall, the second frame
    ``distance_m`` (NEAR, FAR) from it, as on the approach; ``sideways``: the same step across the heading, to the
    right or left, at the first frame's distance.  A few centimetres and hundredths of a radian of jitter."""
    near = float(rng.uniform(*distance_m))
    step = float(rng.uniform(0.12, 0.22))
    across = rng.normal(0.0, 0.02, 2)
    if motion == "sideways":
        side = np.array([step * float(rng.choice((-1.0, 1.0))) / 2.0, 0.0])
        first = approach_pose(spec, centre_yz, near + step, tuple(across - side), tuple(rng.normal(0.0, 0.01, 2)))
        second = approach_pose(spec, centre_yz, near + step + float(rng.normal(0.0, 0.01)),
                               tuple(across + side + rng.normal(0.0, 0.01, 2)), tuple(rng.normal(0.0, 0.01, 2)))
    else:
        first = approach_pose(spec, centre_yz, near + step, tuple(across), tuple(rng.normal(0.0, 0.01, 2)))
        second = approach_pose(spec, centre_yz, near, tuple(across + rng.normal(0.0, 0.01, 2)),
                               tuple(rng.normal(0.0, 0.01, 2)))
    return first, second, near + step


def judge_scene(pairs: list[dict], tracker_config, servo_config) -> dict | None:
    """One scene's judgement from its pairs (see the module docstring); None with fewer than ``min_estimates``
    estimates within ``decide_within_m``."""
    near = sorted((p for p in pairs if p["estimate_m"] is not None
                   and p["distance_m"] <= tracker_config.decide_within_m), key=lambda p: -p["distance_m"])
    if len(near) < tracker_config.min_estimates:
        return None
    judged = float(np.percentile([p["estimate_m"] for p in near[:tracker_config.min_estimates]], 75))
    need = servo_config.body_radius_m + servo_config.clearance_margin_m
    truth = near[0]["truth_m"]
    return {"truth_m": truth, "judged_m": judged, "ratio": judged / truth, "turn_deg": near[0]["turn_deg"],
            "passable": truth >= need, "judged_fit": judged >= need}


REVEAL_RING_PX = 2                 # the ring just outside the mask where the reveal is read ...
REVEAL_PLATEAU_PX = (11, 15)       # ... against these rings, on the wall's plane beyond the reveal


def reveal_ratio(flow: np.ndarray, mask: np.ndarray, focal_px: float) -> float | None:
    """The inverse depth just outside an opening's ``mask`` over the wall plane's there, relative to the same ratio
    on the wall further out (see the module docstring); None without a plane or enough measurable pixels."""
    import cv2

    from companion.gap import CameraMotion, inverse_depth_from_flow
    from companion.inverse_depth import wall_plane_log

    rho, valid = inverse_depth_from_flow(flow, CameraMotion(focal_px=focal_px))
    measurable = valid & (rho > 0)
    log_rho = np.log(np.where(measurable, rho, np.nan))
    plane = wall_plane_log(log_rho, measurable, focal_px, band=0.15)
    if plane is None:
        return None
    ratio = np.exp(log_rho - plane)
    m = mask.astype(np.uint8)

    def grown(px: int) -> np.ndarray:
        return cv2.dilate(m, np.ones((2 * px + 1, 2 * px + 1), np.uint8)).astype(bool)

    ring = grown(REVEAL_RING_PX) & ~grown(REVEAL_RING_PX - 1) & measurable
    plateau = grown(REVEAL_PLATEAU_PX[1]) & ~grown(REVEAL_PLATEAU_PX[0] - 1) & measurable
    if ring.sum() < 10 or plateau.sum() < 10:
        return None
    return float(np.median(ratio[ring]) / np.median(ratio[plateau]))


def reveal_feature(row: dict) -> float:
    """d·(1/ratio - 1): the wall's thickness a sharp reveal would give at the first frame's distance d."""
    return row["distance_m"] * (1.0 / row["reveal_ratio"] - 1.0)


def thickness_from_reveal(rows: list[dict], assumed_m: float, fit: tuple[float, float] | None = None) -> dict | None:
    """How well the reveal gives the wall's thickness over ``rows`` (pairs with a ``reveal_ratio``): t = a + b·x
    (x = :func:`reveal_feature`) fitted to them and its error left out a scene at a time, or, with ``fit`` (a, b)
    from another run, that fit's error; against the spread of the walls' thickness and the error of
    ``assumed_m``.  None with pairs from fewer than three scenes."""
    rows = [r for r in rows if r.get("reveal_ratio")]
    scenes = np.array([r["scene"] for r in rows])
    if len(set(scenes.tolist())) < 3:
        return None
    x = np.array([reveal_feature(r) for r in rows])
    t = np.array([r["thickness_m"] for r in rows])
    design = np.column_stack([np.ones_like(x), x])
    if fit is None:
        coef = np.linalg.lstsq(design, t, rcond=None)[0]
        errors = np.empty_like(t)
        for scene in set(scenes.tolist()):
            out = scenes == scene
            left = np.linalg.lstsq(design[~out], t[~out], rcond=None)[0]
            errors[out] = t[out] - design[out] @ left
    else:
        coef = np.asarray(fit, float)
        errors = t - design @ coef
    return {"pairs": len(rows), "scenes": len(set(scenes.tolist())), "fit": [float(c) for c in coef],
            "fitted_here": fit is None, "error_sd_m": float(np.std(errors)), "bias_m": float(np.mean(errors)),
            "world_sd_m": float(np.std(t)), "assumed_m": assumed_m,
            "assumed_rms_m": float(np.sqrt(np.mean((t - assumed_m) ** 2)))}


def _percentiles(values) -> dict | None:
    values = np.asarray(values, float)
    if values.size == 0:
        return None
    return {"p10": float(np.percentile(values, 10)), "median": float(np.median(values)),
            "p90": float(np.percentile(values, 90)), "n": int(values.size)}


def summarise(rows: list[dict], scenes: list[dict], turned_deg: float, assumed_thickness_m: float = 0.15,
              reveal_fit: tuple[float, float] | None = None) -> dict:
    """Mask error (px) over the pairs, the judgement over the truth over the scenes (all, facing, turned more
    than ``turned_deg``), the misjudged counts and the wall's thickness from the reveal
    (:func:`thickness_from_reveal`)."""
    found = [r for r in rows if r["mask_radius_px"] is not None]
    facing = [s for s in scenes if abs(s["turn_deg"]) <= turned_deg]
    turned = [s for s in scenes if abs(s["turn_deg"]) > turned_deg]
    return {
        "pairs": len(rows), "detected": len(found),
        "mask_minus_truth_px": _percentiles([r["mask_radius_px"] - r["truth_radius_px"] for r in found]),
        "judged_over_truth": {"all": _percentiles([s["ratio"] for s in scenes]),
                              "facing": _percentiles([s["ratio"] for s in facing]),
                              "turned": _percentiles([s["ratio"] for s in turned])},
        "impassable": sum(not s["passable"] for s in scenes),
        "impassable_judged_fit": sum(not s["passable"] and s["judged_fit"] for s in scenes),
        "passable": sum(s["passable"] for s in scenes),
        "passable_judged_too_small": sum(s["passable"] and not s["judged_fit"] for s in scenes),
        "thickness_from_reveal": thickness_from_reveal(rows, assumed_thickness_m, reveal_fit),
    }


def markdown(summary: dict, flow: str, seed: int) -> str:
    def cell(p):
        return f"{p['p10']:.3f} / {p['median']:.3f} / {p['p90']:.3f} (n {p['n']})" if p else "–"

    m = summary["mask_minus_truth_px"]
    lines = [f"Flow {flow}, seed {seed}: {summary['pairs']} pairs, {summary['detected']} detected.", "",
             "| measure | p10 / median / p90 |", "| --- | --- |",
             f"| mask's clear radius − the truth's (px) | "
             f"{m['p10']:+.2f} / {m['median']:+.2f} / {m['p90']:+.2f} (n {m['n']}) |" if m else "| mask | – |"]
    for group, p in summary["judged_over_truth"].items():
        lines.append(f"| judged clear radius / truth, {group} | {cell(p)} |")
    lines += ["", f"Impassable judged to fit: {summary['impassable_judged_fit']}/{summary['impassable']}; "
                  f"passable judged too small: {summary['passable_judged_too_small']}/{summary['passable']}."]
    reveal = summary.get("thickness_from_reveal")
    if reveal:
        a, b = reveal["fit"]
        how = "left out a scene at a time" if reveal["fitted_here"] else "with the fit given"
        lines += ["", f"Wall thickness from the reveal (t = {a:.3f} + {b:.3f}·d(1/ratio - 1), {reveal['pairs']} pairs "
                      f"of {reveal['scenes']} scenes): off by {reveal['error_sd_m']:.3f} m (sd) {how}, bias "
                      f"{reveal['bias_m']:+.3f} m; the walls' own spread {reveal['world_sd_m']:.3f} m, the assumed "
                      f"{reveal['assumed_m']:.2f} m off by {reveal['assumed_rms_m']:.3f} m (rms)."]
    return "\n".join(lines) + "\n"


def measure_scene(index: int, seed: int, args, backend, camera) -> tuple[list[dict], dict | None]:
    """One scene's pairs (rows) and judgement; ([], None) where the draw cannot be scaled into the band."""
    import cv2

    from companion.edges import edges_for
    from companion.gap import CameraMotion, ParallaxGapConfig, clear_circle, detect_gap_parallax
    from companion.opening import OpeningTracker
    from companion.opening_geometry import in_wall, turned_wall_stretch
    from companion.perception import perceive
    from companion.servo import TURN_NEGLIGIBLE_RAD, ServoConfig
    from scenes import load_scene, render_splats
    from scenes.groundtruth import corridor_clearance
    from scenes.library import random_scene
    from scenes.spec import SpecError
    from tools.eval_masks import gt_mask

    rng = np.random.default_rng([seed, index])
    servo, tracker = ServoConfig(), OpeningTracker()
    need = servo.body_radius_m + servo.clearance_margin_m
    spec = random_scene(rng, world="hard")
    spec = scaled_opening(spec, int(rng.integers(len(spec.openings))), float(rng.uniform(need - args.band,
                                                                                           need + args.band)))
    if spec is None:
        return [], None
    try:
        spec.validate()
    except SpecError:       # scaled past the wall's edge: another draw
        return [], None
    truth_m = corridor_clearance(spec, 0, 0.0)
    centre = clear_centre_yz(spec.openings[0])
    spec, cloud = load_scene(spec)
    focal = float(camera.K[0, 0])
    detector = functools.partial(detect_gap_parallax, config=ParallaxGapConfig(), motion=CameraMotion(focal_px=focal))
    turn = math.radians(spec.start_yaw_deg)
    rows = []
    for _ in range(args.pairs):
        (pose0, att0), (pose1, att1), distance = pair_poses(spec, centre, rng, args.distance, args.motion)
        first, second = render_splats(cloud, camera, pose0), render_splats(cloud, camera, pose1)
        seen = perceive(first.rgb, second.rgb, att0, att1, camera.K, backend, detector, edges=edges_for(args.edges))
        detection = seen.detection
        truth = gt_mask(cloud, camera, pose0, first)
        n_labels, labels = cv2.connectedComponents(truth.astype(np.uint8))
        truth_px = max((clear_circle(labels == k)[1] for k in range(1, n_labels)), default=0.0)
        found = [c for c in (detection.candidates or (detection,)) if c.found]
        estimate = radius_px = reveal = None
        if found:
            widest = max(found, key=lambda c: c.clear_radius_px)
            stretch = (turned_wall_stretch(need, distance, turn, servo.wall_thickness_m)
                       if abs(turn) > TURN_NEGLIGIBLE_RAD else 1.0)
            radius_px = widest.clear_radius_px
            estimate = tracker.clear_radius_m(in_wall(widest.mask, stretch)[1], distance, focal)
            reveal = reveal_ratio(seen.flow, widest.mask, focal)
        rows.append({"scene": index, "distance_m": distance, "step_m": float(np.linalg.norm(
                         np.subtract(pose1.position, pose0.position))), "turn_deg": spec.start_yaw_deg,
                     "thickness_m": spec.wall.thickness, "shape": spec.openings[0].shape, "truth_m": truth_m,
                     "truth_radius_px": truth_px, "mask_radius_px": radius_px, "estimate_m": estimate,
                     "reveal_ratio": reveal})
    return rows, judge_scene(rows, tracker.config, servo)


def flow_backend_or_say(spec: str, prog: str):
    """The flow backend ``spec`` names (as flowgap-companion --flow), or None after a one-line error naming it."""
    from companion.flow.base import FlowError
    from companion.flow.registry import make_flow_backend, parse_backend

    try:
        name, options = parse_backend(spec)
        return make_flow_backend(name, **options)
    except (ValueError, KeyError, FlowError) as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return None


def main(argv: list[str] | None = None) -> int:
    from tqdm import tqdm

    from companion.edges import EDGE_MODES
    from companion.flow.registry import DEFAULT_FLOW
    from companion.servo import ServoConfig
    from scenes import PinholeCamera

    parser = argparse.ArgumentParser(prog="python -m tools.size_error", description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--scenes", type=int, default=150, help="hard-world scenes drawn")
    parser.add_argument("--pairs", type=int, default=5, help="frame pairs per scene")
    parser.add_argument("--seed", type=int, default=0, help="seed of the scenes' and the poses' draws")
    parser.add_argument("--band", type=float, default=0.05, metavar="M",
                        help="clear radii drawn within this of the fit threshold (metres)")
    parser.add_argument("--distance", type=float, nargs=2, default=(0.75, 1.45), metavar=("NEAR", "FAR"),
                        help="the second frame's distance from the wall (metres); the first is a step further (with "
                             "--motion sideways, both frames)")
    parser.add_argument("--motion", choices=("forward", "sideways"), default="forward",
                        help="each pair's step: along the heading toward the wall, as on the approach, or across it")
    parser.add_argument("--flow", default=DEFAULT_FLOW, help="flow backend, as flowgap-companion --flow")
    parser.add_argument("--edges", choices=EDGE_MODES, default="photo",
                        help="openings' edges read again from the frames, as flown (photo), or the detector's masks")
    parser.add_argument("--turned", type=float, default=3.0, metavar="DEG",
                        help="walls turned more than this count as turned in the summary")
    parser.add_argument("--reveal-fit", type=float, nargs=2, metavar=("A", "B"),
                        help="try the thickness fit t = A + B·d(1/ratio - 1) from another run on this one's pairs "
                             "(default: fit it here, left out a scene at a time)")
    parser.add_argument("-o", "--out", type=Path, default=Path("runs/size_error"), help="output folder")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    near, far = args.distance
    if args.scenes < 1 or args.pairs < 1 or not 0.0 < args.band < 0.2 or not 0.3 <= near < far:
        print("size_error: --scenes and --pairs must be at least 1, --band between 0 and 0.2 m, and --distance "
              "NEAR FAR with 0.3 <= NEAR < FAR", file=sys.stderr)
        return 2
    backend = flow_backend_or_say(args.flow, "size_error")
    if backend is None:
        return 2
    camera, rows, scenes = PinholeCamera(), [], []
    for index in tqdm(range(args.scenes), desc="scenes", unit="scene"):
        pairs, judged = measure_scene(index, args.seed, args, backend, camera)
        rows += pairs
        if judged is not None:
            scenes.append({"scene": index, **judged})
    summary = summarise(rows, scenes, args.turned, ServoConfig().wall_thickness_m,
                        tuple(args.reveal_fit) if args.reveal_fit else None)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "size_error.json").write_text(json.dumps({"flow": args.flow, "edges": args.edges, "seed": args.seed,
                                                          "summary": summary, "scenes": scenes, "rows": rows},
                                                         indent=1))
    text = markdown(summary, args.flow, args.seed)
    (args.out / "size_error.md").write_text(text)
    print(text + f"-> {args.out / 'size_error.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""``flowgap-scenes place`` and ``flowgap-scenes info CAPTURE.json``: the file-reading edge of capture scenes."""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
from pathlib import Path

import numpy as np

log = logging.getLogger("scenes")

PLACE_EPILOG = """\
steps:
  1. flowgap-scenes place room.ply -o room.capture.json    # draft: floor at z = 0, views in room.capture.png
  2. look at the views; if the floor is wrong, pass --up (e.g. --up -y); give the scale with --scale-from
     (two points of the .ply's own frame, as a splat viewer shows them, and their distance in metres)
  3. edit the JSON: gate (centre, facing normal, [width, height] m) and start_ned / start_yaw_deg, in NED metres
     (x north, y east, z down: the top view's grid and axes give them)
  4. flowgap-scenes render room.capture.json --pose X Y Z --rpy 0 0 YAW   # check any view, gate drawn
  5. flowgap-sitl --scene room.capture.json --lockstep                    # fly it, judged by its splats
"""


def add_place_parser(sub) -> None:
    p = sub.add_parser("place", help="draft a capture scene JSON for a third-party 3DGS .ply (floor, scale, views)",
                       description="Propose how a third-party 3DGS .ply sits in the NED world: the up direction from "
                                   "the dominant floor plane (RANSAC over opaque splat centres), the floor at z = 0, "
                                   "the scale from two points; write a draft capture scene JSON and a sheet of views "
                                   "(top view with a metre grid, four level views) to finish it by.",
                       epilog=PLACE_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("ply", type=Path, help="the capture's 3DGS .ply (Inria, nerfstudio, gsplat export)")
    p.add_argument("-o", "--out", type=Path, default=None, metavar="JSON",
                   help="the draft capture JSON (default: <ply stem>.capture.json in the current folder)")
    p.add_argument("--views", type=Path, default=None, metavar="PNG",
                   help="the sheet of views (default: the JSON's path with .png)")
    p.add_argument("--up", default=None, metavar="AXIS",
                   help="the capture's up direction instead of the proposal: +x, -y, ... or X,Y,Z in the .ply's frame")
    p.add_argument("--scale-from", default=None, metavar="A,B,METRES",
                   help="metres per unit from two points of the .ply's frame, X1:Y1:Z1,X2:Y2:Z2,METRES (default: the "
                        "capture's units are metres)")
    p.add_argument("--seed", type=int, default=0, help="RANSAC seed (default %(default)s)")
    p.add_argument("--force", action="store_true", help="overwrite an existing JSON")
    p.add_argument("--width", type=int, default=320, help="view width in pixels (default %(default)s)")
    p.add_argument("--height", type=int, default=240, help="view height in pixels (default %(default)s)")
    p.set_defaults(func=cmd_place)


def _floor_offset_along(points: np.ndarray, up: np.ndarray) -> float:
    """With a given up: the floor is the densest level in the lowest quarter of the heights."""
    h = points @ up
    lo, hi = np.percentile(h, (1, 99))
    edges = np.linspace(lo, lo + 0.25 * (hi - lo), 26)
    counts, _ = np.histogram(h, edges)
    i = int(np.argmax(counts))
    return float((edges[i] + edges[i + 1]) / 2)


def cmd_place(args) -> int:
    import cv2

    from scenes.camera import PinholeCamera
    from scenes.capture import parse_capture, place_cloud
    from scenes.capture_views import placement_sheet
    from scenes.placement import (
        bulk_points,
        choose_floor,
        draft_capture,
        parse_scale_from,
        parse_up,
        plane_candidates,
        propose_placement,
        scale_from_points,
    )
    from scenes.splats import read_ply

    out = args.out or Path(args.ply.name).with_suffix(".capture.json")
    views = args.views or out.with_suffix(".png")
    if out.exists() and not args.force:
        raise OSError(f"{out} exists (a placement being finished?); pass --force to overwrite it or -o another path")
    try:
        up_given = parse_up(args.up) if args.up else None
        scale_points = parse_scale_from(args.scale_from) if args.scale_from else None
    except ValueError as exc:
        raise OSError(str(exc)) from None
    cloud = read_ply(args.ply)
    rng = np.random.default_rng(args.seed)
    pts = bulk_points(cloud, rng)
    print(f"{args.ply}: {len(cloud):,} Gaussians, SH degree {cloud.sh_degree}; {len(pts):,} opaque centres in its "
          f"bulk used for the floor")
    if up_given is None:
        candidates = plane_candidates(pts, rng)
        floor = choose_floor(candidates)
        print("planes (capture frame; 'boundary': nearly everything on one side):")
        for i, c in enumerate(candidates):
            mark = "  <- floor" if c is floor else ""
            print(f"  {i}: normal ({c.normal[0]:+.3f}, {c.normal[1]:+.3f}, {c.normal[2]:+.3f}), {c.inliers:,} points, "
                  f"{100 * c.one_sided:.0f}% on one side{' (boundary)' if c.boundary else ''}, spanning "
                  f"{c.area:.3g} units^2{mark}")
        up, offset = np.asarray(floor.normal), floor.offset
    else:
        up, offset = up_given, _floor_offset_along(pts, up_given)
    scale = 1.0
    if scale_points is not None:
        scale = scale_from_points(*scale_points)
    print(f"up (capture frame): ({up[0]:+.3f}, {up[1]:+.3f}, {up[2]:+.3f}); floor at up . p = {offset:.4g}; scale "
          f"{scale:.6g} m per unit" + ("" if scale_points is not None else
                                        " (units taken as metres: give --scale-from to set it)"))
    placement = propose_placement(pts, up, offset, scale)
    cloud = place_cloud(cloud, placement, inplace=True)
    ply_ref = os.path.relpath(args.ply.resolve(), out.resolve().parent)
    draft = draft_capture(ply_ref, placement, cloud)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(draft, indent=2) + "\n")
    spec = parse_capture(draft, out)
    sheet = placement_sheet(cloud, PinholeCamera(args.width, args.height), spec.start_ned, spec.start_yaw_deg,
                            spec.altitude_m, spec.gate)
    views.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(views), sheet[..., ::-1]):
        raise OSError(f"could not write {views}")
    print(f"draft capture scene: {out} (set its gate and start; see --help for the steps)")
    print(f"views: {views} (top view north up with a metre grid, four level views from the draft start)")
    return 0


def info_capture(path: Path) -> int:
    from scenes.capture import capture_cloud, load_capture
    from scenes.occupancy import load_capture_collision

    spec = load_capture(path)
    cloud = capture_cloud(spec)
    lo, hi = cloud.bounds()
    t = spec.to_ned
    print(f"{path}: capture scene {spec.name!r}: {spec.ply} ({len(cloud):,} Gaussians, SH degree {cloud.sh_degree})")
    print(f"to_ned  scale {t.scale:g}, rotation_wxyz {[round(v, 4) for v in t.rotation_wxyz]}, translation_m "
          f"{[round(v, 3) for v in t.translation_m]}")
    print(f"bounds  x [{lo[0]:.1f}, {hi[0]:.1f}]  y [{lo[1]:.1f}, {hi[1]:.1f}]  z [{lo[2]:.1f}, {hi[2]:.1f}] m (NED, "
          f"floaters included)")
    g = spec.gate
    print(f"gate    centre {list(g.center_ned)}, facing {[round(v, 3) for v in g.flight_normal]} (the way through), "
          f"{g.size_m[0]:g} x {g.size_m[1]:g} m")
    print(f"start   {list(spec.start_ned)}, heading {spec.start_yaw_deg:g} deg, flight altitude {spec.altitude_m:g} m")
    world = load_capture_collision(spec, cloud)
    d = world.describe()
    print(f"field   {d['voxel_m']:g} m voxels {d['voxels']} over NED {d['region_lo_ned']}..{d['region_hi_ned']}, "
          f"{d['solid_voxels']:,} solid from {d['gaussians_counted']:,} Gaussians (solid_alpha {d['solid_alpha']:g}, "
          f"floor band {d['floor_band_m']:g} m)")
    s = spec.start_ned
    above = (s[0], s[1], s[2] - spec.altitude_m)
    at_gate = world.clearance(g.center_ned)
    print(f"clear   {world.clearance(above):.2f} m above the start at flight altitude, {at_gate:.2f} m at the gate "
          f"centre (the vehicle's body sphere needs its radius, 0.19 m for quad250)")
    if at_gate < 0.25:
        print("warning: the gate centre is nearly blocked: check the gate against a render", file=sys.stderr)
    return 0


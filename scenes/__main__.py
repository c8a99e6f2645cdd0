"""``flowgap-scenes``: build, render, inspect and preview scenes.

    flowgap-scenes build --suite                 # all 16 suite scenes into cache/scenes/ (skips up-to-date)
    flowgap-scenes build window3_stone my.json   # named scenes or spec files
    flowgap-scenes render window1_brick --pose 1.0 0.2 -1.5 --rpy 0 0 5 -o frame.png
    flowgap-scenes info cache/scenes/window1_brick.ply
    flowgap-scenes montage -o docs/images/suite_montage.png
    flowgap-scenes cache                         # how much the cache holds; --prune to its limit, --clear all
    flowgap-scenes place room.ply --scale-from 0:0:0,1.2:0:0,3.5 -o room.capture.json   # draft a capture scene
    flowgap-scenes render room.capture.json --pose 1 0 -1.5 --rpy 0 0 30                # a view of it in NED
    flowgap-scenes info room.capture.json                                                # its gate, start, field
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from scenes.spec import SpecError
from scenes.splats import LABEL_NAMES, PlyError

log = logging.getLogger("scenes")

LABEL_COLOURS = np.array([[0, 0, 0], [180, 80, 60], [230, 200, 40], [60, 160, 230], [110, 110, 110]], np.uint8)


def _camera(args):
    from scenes.camera import PinholeCamera

    return PinholeCamera(args.width, args.height, math.radians(args.vfov_deg))


def _pose(args, spec=None):
    """--pose and --rpy; left out, the scene's start at its flight altitude, facing its start heading."""
    from scenes.camera import Pose, euler_to_quat

    start = tuple(getattr(spec, "start_ned", (0.0, 0.0, 0.0)))
    altitude = getattr(spec, "altitude_m", 1.5)
    position = args.pose if args.pose is not None else (start[0], start[1], start[2] - altitude)
    rpy = args.rpy if args.rpy is not None else (0.0, 0.0, getattr(spec, "start_yaw_deg", 0.0))
    roll, pitch, yaw = (math.radians(v) for v in rpy)
    return Pose(tuple(float(v) for v in position), euler_to_quat(roll, pitch, yaw))


def _depth_vis(depth: np.ndarray) -> np.ndarray:
    valid = depth > 0
    out = np.zeros(depth.shape + (3,), np.uint8)
    if valid.any():
        lo, hi = np.percentile(depth[valid], [1, 99])
        norm = np.clip((depth - lo) / max(hi - lo, 1e-6), 0, 1)
        col = cv2.applyColorMap((255 * (1 - norm)).astype(np.uint8), cv2.COLORMAP_TURBO)[..., ::-1]
        out[valid] = col[valid]
    return out


def cmd_build(args) -> int:
    from tqdm import tqdm

    from scenes.build import build_cached, resolve_spec
    from scenes.capture import CaptureSpec
    from scenes.library import SUITE
    from scenes.splats import read_ply_header

    names = list(args.scenes) + (SUITE if args.suite else [])
    if not names:
        print("flowgap-scenes build: name at least one scene or pass --suite", file=sys.stderr)
        return 2
    specs = [resolve_spec(n) for n in names]
    bar = tqdm(specs, desc="scenes", unit="scene", disable=len(specs) < 2 or args.quiet, leave=False)
    for spec in bar:
        t0 = time.perf_counter()
        if isinstance(spec, CaptureSpec):     # a capture's splats exist; what is built is its collision field
            from scenes.occupancy import load_capture_collision

            world = load_capture_collision(spec)
            tqdm.write(f"{spec.name}: capture scene, collision field {world.field.shape} of {world.field.voxel_m:g} m "
                       f"voxels, ready in {time.perf_counter() - t0:.1f} s (cached beside it)")
            continue
        path, built = build_cached(spec, args.cache_dir, force=args.force)
        n = read_ply_header(path)[0]
        state = f"built in {time.perf_counter() - t0:.1f} s" if built else "up to date"
        tqdm.write(f"{spec.name}: {n:,} Gaussians, {state} -> {path}")
    return 0


def _scenes(n: int) -> str:
    return f"{n} scene" + ("" if n == 1 else "s")


def cmd_cache(args) -> int:
    from scenes import cache as scene_cache
    from scenes.build import default_cache_dir

    root = args.cache_dir or default_cache_dir()
    limit = scene_cache.limit_bytes()
    if args.clear:
        removed = scene_cache.prune(root, 0, recent_s=0.0)
    elif args.prune:
        removed = scene_cache.prune(root, limit)
    else:
        removed = []
    listed = scene_cache.entries(root)
    limit_text = "no limit" if limit is None else f"limit {limit / 1e6:,.0f} MB"
    if removed:
        print(f"removed {_scenes(len(removed))} ({sum(e.bytes for e in removed) / 1e6:,.0f} MB)")
    print(f"{root}: {_scenes(len(listed))}, {sum(e.bytes for e in listed) / 1e6:,.0f} MB "
          f"({limit_text}, ${scene_cache.LIMIT_ENV})")
    return 0


def cmd_render(args) -> int:
    from scenes.build import load_scene
    from scenes.capture import CaptureSpec
    from scenes.render import render_splats

    spec, cloud = load_scene(args.scene, args.cache_dir)
    cam, pose = _camera(args), _pose(args, spec)
    t0 = time.perf_counter()
    res = render_splats(cloud, cam, pose, backend=args.backend)
    ms = 1e3 * (time.perf_counter() - t0)
    third = LABEL_COLOURS[np.minimum(res.label, 4)]
    if isinstance(spec, CaptureSpec):      # captures have no labels: show the gate instead
        from scenes.capture_views import draw_gate

        third = draw_gate(res.rgb.copy(), cam, pose, spec.gate)
    panel = np.concatenate([res.rgb, _depth_vis(res.depth), third], 1)
    out = Path(args.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(out), panel[..., ::-1]):
        raise OSError(f"could not write {out}")
    valid = res.depth > 0
    drange = f"{res.depth[valid].min():.2f}-{res.depth[valid].max():.2f} m" if valid.any() else "none"
    counts = ", ".join(f"{LABEL_NAMES[k].split(' ')[0]} {100 * (res.label == k).mean():.1f}%"
                       for k in range(5) if (res.label == k).any())
    capture = isinstance(spec, CaptureSpec)
    print(f"{out}: RGB | depth | {'gate' if capture else 'label'}, {cam.width}x{cam.height}, {args.backend} {ms:.0f} "
          f"ms (first call includes JIT), depth {drange}; "
          + (f"pose NED {[round(v, 3) for v in pose.position]}" if capture else counts))
    return 0


def cmd_info(args) -> int:
    from scenes.capture import is_capture_file
    from scenes.splats import read_ply

    if is_capture_file(args.ply):
        from scenes.capture_cli import info_capture

        return info_capture(args.ply)
    cloud = read_ply(args.ply)
    lo, hi = cloud.bounds()
    print(f"{args.ply}: {len(cloud):,} Gaussians, SH degree {cloud.sh_degree}")
    print(f"bounds  x [{lo[0]:.3f}, {hi[0]:.3f}]  y [{lo[1]:.3f}, {hi[1]:.3f}]  z [{lo[2]:.3f}, {hi[2]:.3f}] m")
    if cloud.labels.any():
        counts = np.bincount(cloud.labels, minlength=5)
        print("labels  " + ", ".join(f"{LABEL_NAMES.get(k, k)}: {c:,}" for k, c in enumerate(counts) if c))
    return 0


def cmd_montage(args) -> int:
    from tqdm import tqdm

    from scenes.build import load_scene
    from scenes.camera import START_POSE
    from scenes.library import SUITE
    from scenes.render import render_splats

    cam = _camera(args)
    tiles = []
    for name in tqdm(SUITE, desc="montage", unit="scene", disable=args.quiet, leave=False):
        _, cloud = load_scene(name, args.cache_dir)
        img = render_splats(cloud, cam, START_POSE).rgb.copy()
        cv2.putText(img, name, (5, 15), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (0, 0, 0), 1, cv2.LINE_AA)
        cv2.putText(img, name, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (255, 255, 255), 1, cv2.LINE_AA)
        tiles.append(img)
    rows = [np.concatenate(tiles[i:i + 4], 1) for i in range(0, 16, 4)]
    grid = np.concatenate(rows, 0)
    out = Path(args.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(out), grid[..., ::-1], [cv2.IMWRITE_PNG_COMPRESSION, 9]):
        raise OSError(f"could not write {out}")
    print(f"{out}: {len(SUITE)} suite scenes from the start pose, {grid.shape[1]}x{grid.shape[0]}, "
          f"{out.stat().st_size / 1e3:.0f} kB")
    return 0


def _add_camera_args(p: argparse.ArgumentParser, width: int = 320, height: int = 240) -> None:
    p.add_argument("--width", type=int, default=width, help="image width in pixels (default %(default)s)")
    p.add_argument("--height", type=int, default=height, help="image height in pixels (default %(default)s)")
    p.add_argument("--vfov-deg", type=float, default=75.0, help="vertical field of view (default %(default)s)")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="flowgap-scenes",
        description="Build, render and inspect flowgap's Gaussian-splat scenes (NED world; the vehicle starts "
                    "at (0, 0, -1.5) looking along +x at a wall with an opening).",
        epilog="Scenes are suite names (window1..4 x brick/granite/newspaper/stone, e.g. window1_brick), spec "
               ".json files, capture scene .json files (a third-party 3DGS .ply placed in NED: see 'place'), or "
               "(render) 3DGS .ply files.")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    from scenes.build import default_cache_dir

    def cache_arg(p):
        p.add_argument("--cache-dir", type=Path, default=None,
                       help=f"scene cache directory (default {default_cache_dir()}, or $FLOWGAP_SCENE_CACHE)")

    p = sub.add_parser("build", help="build scenes into the cache (skips those up to date)",
                       description="Generate scenes' splats (.ply + labels + spec .json) into the cache. The cache "
                                   "key is the spec JSON plus the generator code, so changed scenes rebuild.")
    p.add_argument("scenes", nargs="*", help="suite names, spec .json paths or capture scene .json paths (for "
                                             "these, the collision field is built)")
    p.add_argument("--suite", action="store_true", help="build all 16 suite scenes")
    p.add_argument("--force", action="store_true", help="rebuild even if up to date")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    cache_arg(p)
    p.set_defaults(func=cmd_build)

    p = sub.add_parser("render", help="render a scene at a pose to a PNG (RGB | depth | label)",
                       description="Render one view and write RGB, depth (turbo colour map, near = red) and the "
                                   "label image (wall red, frame yellow, beyond-the-wall blue, floor grey) side by "
                                   "side.")
    p.add_argument("scene", help="suite name, spec .json, capture scene .json (rendered in NED, its gate drawn in "
                                 "the third panel) or 3DGS .ply")
    p.add_argument("--pose", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"),
                   help="NED body position in metres (default: the scene's start at its flight altitude; 0 0 -1.5 "
                        "for the suite)")
    p.add_argument("--rpy", type=float, nargs=3, default=None, metavar=("ROLL", "PITCH", "YAW"),
                   help="body attitude in degrees (default level, facing the scene's start heading)")
    p.add_argument("--backend", choices=("cpu", "torch", "reference"), default="cpu", help="renderer")
    p.add_argument("-o", "--out", "--output", dest="output", metavar="PNG",
                   default="render.png", help="output PNG (default %(default)s)")
    _add_camera_args(p)
    cache_arg(p)
    p.set_defaults(func=cmd_render)

    p = sub.add_parser("info", help="Gaussian count, SH degree and bounds of a .ply or capture scene",
                       description="Read a 3DGS .ply (ours, the reference trainer's, nerfstudio's) and summarise it; "
                                   "for a capture scene .json, also its placement, gate, start and collision field "
                                   "(built and cached beside it if need be).")
    p.add_argument("ply", type=Path, help="path to a .ply or a capture scene .json")
    p.set_defaults(func=cmd_info)

    from scenes.capture_cli import add_place_parser

    add_place_parser(sub)

    p = sub.add_parser("montage", help="all 16 suite scenes from the start pose in one PNG",
                       description="Render every suite scene from the start pose into a 4x4 grid.")
    p.add_argument("-o", "--out", "--output", dest="output", metavar="PNG",
                   default="suite_montage.png", help="output PNG (default %(default)s)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    _add_camera_args(p, 200, 150)
    cache_arg(p)
    p.set_defaults(func=cmd_montage)

    p = sub.add_parser("cache", help="how much the scene cache holds; prune it to its limit or clear it",
                       description="Built scenes stay in the cache until it passes $FLOWGAP_SCENE_CACHE_MB (default "
                                   "5000 MB; 0 for no limit); each build then removes the least recently used "
                                   "scenes, sparing any used in the last 15 minutes. Without options, this says "
                                   "how many scenes and MB the cache holds.")
    what = p.add_mutually_exclusive_group()
    what.add_argument("--prune", action="store_true", help="remove least recently used scenes beyond the limit now")
    what.add_argument("--clear", action="store_true", help="remove every built scene (they rebuild on demand)")
    cache_arg(p)
    p.set_defaults(func=cmd_cache)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        return args.func(args)
    except (SpecError, PlyError) as exc:
        print(f"flowgap-scenes: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"flowgap-scenes: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())

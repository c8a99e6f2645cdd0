"""``flowgap-eval-flights``: closed-loop success rate over the scene suite from randomised starts.

Each flight is a full two-process SITL run (``tools.launch.launch``): the vehicle judges it from its own
ground truth. Starts are drawn from a seeded generator: lateral offset and altitude offset up to ±0.5 m,
distance to the wall 2–4 m. ``--random N`` evaluates N random scenes (``scenes.random_scene``: texture,
opening shape, size and place, wall and background distances; drawn from ``--seed``) instead of, or besides,
named ones; their specs are saved under ``OUT/scenes`` so any flight can be re-flown with ``flowgap-sitl
--scene OUT/scenes/NAME.json``. Several flights run at once on their own ports (PX4 instance numbers).
Flights run in lockstep (the vehicle advances only when its companion waits), so the same seed gives the same
rows at any machine load, as fast as the CPU allows; ``--realtime`` paces them by ``--speed`` instead.
Writes ``flights.json`` (rows + summary) and ``flights.md``, and prints the table.
"""

from __future__ import annotations

import argparse
import json
import logging
import queue
import sys
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path

import numpy as np
from tqdm import tqdm

from tools.launch import launch

log = logging.getLogger("flowgap-eval-flights")


def draw_starts(rng: np.random.Generator, k: int, wall_x: float, altitude: float) -> list[tuple]:
    """k starts (x, y, 0) on the ground with a takeoff altitude each: 2–4 m from the wall, ±0.5 m offsets."""
    out = []
    for _ in range(k):
        distance = float(rng.uniform(2.0, 4.0))
        lateral = float(rng.uniform(-0.5, 0.5))
        vertical = float(rng.uniform(-0.5, 0.5))
        out.append(((round(wall_x - distance, 3), round(lateral, 3), 0.0), round(altitude + vertical, 3)))
    return out


def random_scene_files(count: int, seed: int, folder: Path) -> list[str]:
    """Save ``count`` random scene specs (reproducible from ``seed``) under ``folder``; their paths."""
    from scenes.library import random_scene

    if count:
        folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for k in range(count):
        spec = random_scene(np.random.default_rng([seed, 0xF1, k]))
        path = folder / f"{spec.name}.json"
        spec.save(path)
        paths.append(str(path))
    return paths


def summarise(rows: list[dict]) -> dict:
    n = len(rows)
    ok = sum(r["success"] for r in rows)
    return {
        "flights": n,
        "success": ok,
        "success_rate": round(ok / n, 4) if n else None,
        "collisions": sum(bool(r["collision"]) for r in rows),
        "touching_counted_as_success": sum(bool(r["success"] and r["collision"]) for r in rows),
        "median_servo_steps": float(np.median([r["servo_steps"] or 0 for r in rows])) if n else None,
        "median_sim_time_s": float(np.median([r["sim_time_s"] or 0 for r in rows])) if n else None,
        "median_wall_time_s": float(np.median([r["wall_time_s"] for r in rows])) if n else None,
    }


def markdown(rows: list[dict], summary: dict) -> str:
    lines = ["| scene | flights | success | collisions | median steps |", "| --- | ---: | ---: | ---: | ---: |"]
    for scene in sorted({r["scene"] for r in rows}):
        sub = [r for r in rows if r["scene"] == scene]
        lines.append(f"| {scene} | {len(sub)} | {sum(r['success'] for r in sub)} | "
                     f"{sum(bool(r['collision']) for r in sub)} | "
                     f"{np.median([r['servo_steps'] or 0 for r in sub]):.0f} |")
    lines.append(f"| **all** | {summary['flights']} | **{summary['success']} "
                 f"({100 * (summary['success_rate'] or 0):.0f} %)** | {summary['collisions']} | "
                 f"{summary['median_servo_steps']:.0f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="flowgap-eval-flights", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scenes", nargs="*", help="scene names or spec paths (default: the 16-scene suite, "
                                             "unless --random is given)")
    p.add_argument("--random", type=int, default=0, metavar="N",
                   help="also fly N random scenes drawn from --seed (specs saved under OUT/scenes)")
    p.add_argument("--starts", type=int, default=3, help="randomised starts per scene (default 3)")
    p.add_argument("--seed", type=int, default=0, help="seed of the start draws and the vehicles' noise")
    p.add_argument("--jobs", type=int, default=2, help="flights at once (default 2)")
    p.add_argument("--realtime", action="store_true",
                   help="pace each flight by the wall clock at --speed instead of lockstep (a flight's outcome then "
                        "depends on this machine's load)")
    p.add_argument("--speed", type=float, default=2.0,
                   help="with --realtime: simulation speed-up of each flight (default 2)")
    p.add_argument("--latency", type=float, default=0.0, metavar="S",
                   help="the companion's camera-to-setpoint latency (default 0; in lockstep, what perception "
                        "costs in simulated time)")
    p.add_argument("--flow", default="dis:fine", help="companion flow backend (default %(default)s)")
    p.add_argument("--detector", default="parallax", choices=["parallax", "paper"])
    p.add_argument("--out", type=Path, default=Path("runs/eval_flights"), help="output directory")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(asctime)s %(levelname)s %(message)s")
    from scenes.build import resolve_spec
    from scenes.library import SUITE

    if args.random < 0 or args.starts <= 0 or args.jobs <= 0:
        print("flowgap-eval-flights: error: --random must be >= 0, --starts and --jobs positive", file=sys.stderr)
        return 2
    if not (args.speed > 0 and args.latency >= 0):
        print("flowgap-eval-flights: error: --speed must be positive and --latency >= 0", file=sys.stderr)
        return 2
    scenes = list(args.scenes) or ([] if args.random else list(SUITE))
    try:
        scenes += random_scene_files(args.random, args.seed, args.out / "scenes")
        specs = {s: resolve_spec(s) for s in scenes}
    except Exception as exc:  # noqa: BLE001 — unknown names, bad spec files: one line
        print(f"flowgap-eval-flights: error: {exc}", file=sys.stderr)
        return 2
    labels = {s: specs[s].name for s in scenes}      # spec paths are reported by their scene's name
    rng = np.random.default_rng(args.seed)
    jobs = []
    for scene in scenes:
        for i, (start, altitude) in enumerate(draw_starts(rng, args.starts, specs[scene].wall.distance, 1.5)):
            jobs.append((scene, i, start, altitude))
    instances: queue.Queue[int] = queue.Queue()
    for n in range(args.jobs):
        instances.put(20 + n)  # away from instance 0, which a user's own SITL may be using

    def fly(job):
        scene, i, start, altitude = job
        instance = instances.get()
        try:
            v = launch(scene, args.out / f"{labels[scene]}-{i}", start, args.speed, instance, args.flow,
                       args.detector, seed=args.seed + i, images=False, log_sink=None, altitude=altitude,
                       lockstep=not args.realtime, latency_s=args.latency)
        finally:
            instances.put(instance)
        v["scene"] = labels[scene]
        return v

    t0 = time.monotonic()
    rows = []
    with ThreadPoolExecutor(max_workers=args.jobs) as pool:
        futures = [pool.submit(fly, job) for job in jobs]
        for future in tqdm(as_completed(futures), total=len(futures), desc="flights", unit="flight"):
            rows.append(future.result())
    rows.sort(key=lambda r: (r["scene"], r["run_dir"]))
    summary = summarise(rows)
    summary.update(flow=args.flow, detector=args.detector, clock="realtime" if args.realtime else "lockstep",
                   speed=args.speed if args.realtime else None, latency_s=args.latency, seed=args.seed,
                   starts_per_scene=args.starts, total_wall_s=round(time.monotonic() - t0, 1))
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "flights.json").write_text(json.dumps({"summary": summary, "rows": rows}, indent=2) + "\n")
    table = markdown(rows, summary)
    (args.out / "flights.md").write_text(table)
    print(table)
    print(f"success {summary['success']}/{summary['flights']}, collisions {summary['collisions']}, "
          f"touching counted as success {summary['touching_counted_as_success']} -> {args.out}/flights.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())

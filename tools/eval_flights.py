"""``flowgap-eval-flights``: closed-loop success rate over the scene suite from randomised starts.

Each flight is a full two-process SITL run (``tools.launch.launch``): the vehicle judges it from its own
ground truth. A flight's draws (start, the vehicle's noise seed, and in the hard world wind and camera delay)
come from ``default_rng([seed, crc32(scene), start index])``, so they depend only on those three. Standard
world: lateral and altitude offsets up to ±0.5 m, 2–4 m from the wall. ``--random N`` evaluates N random scenes
(``scenes.random_scene``: texture, opening shape, size and place, wall and background distances; drawn from
``--seed``) instead of, or besides, named ones; ``--world hard`` draws hard-world scenes (1–3 openings of
0.3–1.3 m, some impassable, the wall turned up to ±20°, the background 0.6–4 m behind) and flies them from
lateral offsets up to ±1 m, in wind of up to 3 m/s with gusts up to 1 m/s, with camera frames arriving 30–80 ms
after exposure. Their specs are saved under ``OUT/scenes`` so any flight can be re-flown with ``flowgap-sitl
--scene OUT/scenes/NAME.json``. Several flights run at once on their own ports (PX4 instance numbers).

Each row says whether the scene had an opening the vehicle fits through (``passable``: its body sphere plus
the margin, crossing square to the wall's face, the widest straight path through it,
``scenes.groundtruth.passable_openings``) and whether the companion
declined (``refused``: it held, and the vehicle touched nothing). A flight succeeds when it crossed the wall
through an opening without touching anything, or, where no opening was passable, when it refused.
Flights run in lockstep (the vehicle advances only when its companion waits), so the same seed gives the same
rows at any machine load, as fast as the CPU allows; ``--realtime`` paces them by ``--speed`` instead.
With ``--link-loss``/``--link-delay``/``--link-duplicate``/``--link-reorder`` every flight's API link runs
through a seeded fault relay (``tools.link_relay``), seeded from the flight's own seed, or with ``--link-seed``
from ``default_rng([link seed, crc32(scene), start index])``; each row records what its link did
(``link_faults``) and the summary the settings.
With ``--ray [ADDRESS]`` each flight is a Ray task on any node of a cluster (``tools.ray_sweep``,
``tools.sweep_executors``), and rows and draws are the same as the local pool's. Each flight's row is saved as it
ends (``OUT/results``); ``--resume`` flies only the flights missing there (``tools.sweep_results``).
Writes ``flights.json`` (rows + summary: executor, reused, success with its 95 % Wilson interval, ...) and
``flights.md``, and prints the table.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import threading
import time
import zlib
from pathlib import Path

import numpy as np

from companion.edges import EDGE_MODES
from companion.flow.registry import DEFAULT_FLOW
from scenes.capture import CaptureSpec
from tools.link_faults import LinkFaultError, LinkFaults, add_link_fault_arguments, link_faults_from_args

log = logging.getLogger("flowgap-eval-flights")


BODY_RADIUS_M = 0.19       # quad250's collision sphere (sitl_vehicle.airframes)
PASS_MARGIN_M = 0.05       # to spare on every side for an opening to count as passable (0.10 m across)
HARD_LATERAL_M = 1.0
HARD_WIND_MPS = (3.0, 1.0)          # mean up to, gusts up to
HARD_CAMERA_DELAY_S = (0.03, 0.08)
IN_VIEW_DEG = 35.0                  # a hard start sees at least one opening within this of its heading


class InstancePool:
    """PX4 instance numbers (port offsets) for flights at once, never shared with another sweep on this machine:
    each held instance is an exclusive lock on a file in the temporary folder, and its ports must be free.
    Instances 1-9 and 11-19: not 0, which a user's own SITL may be using; not 10, whose API port 14550 is where
    every vehicle sends its ground-station streams; and none from 20, whose API ports 14560+ are the truth
    ports of instances 0 and up."""

    INSTANCES = (*range(1, 10), *range(11, 20))

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._held: dict[int, object] = {}

    def acquire(self) -> int:
        while True:
            with self._lock:
                for n in self.INSTANCES:
                    if n not in self._held and _ports_free(n):
                        handle = _try_lock(n)
                        if handle is not None:
                            self._held[n] = handle
                            return n
            time.sleep(0.5)

    def release(self, n: int) -> None:
        with self._lock:
            handle = self._held.pop(n, None)
        if handle is not None:
            handle.close()


def _try_lock(n: int):
    import fcntl
    import tempfile

    handle = open(Path(tempfile.gettempdir()) / f"flowgap-instance-{n}.lock", "w")  # noqa: SIM115
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        handle.close()
        return None
    return handle


def _ports_free(n: int) -> bool:
    """Whether instance n's UDP ports (vehicle 18570+n, 14580+n; companion 14540+n, 14560+n) are free."""
    import socket

    for port in (18570 + n, 14580 + n, 14540 + n, 14560 + n):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            try:
                s.bind(("0.0.0.0", port))
            except OSError:
                return False
    return True


def draw_starts(rng: np.random.Generator, k: int, wall_x: float, altitude: float, lateral_m: float = 0.5
                ) -> list[tuple]:
    """k starts (x, y, 0) on the ground with a takeoff altitude each: 2–4 m from the wall, lateral offsets up to
    ±``lateral_m`` and altitude offsets up to ±0.5 m."""
    out = []
    for _ in range(k):
        distance = float(rng.uniform(2.0, 4.0))
        lateral = float(rng.uniform(-lateral_m, lateral_m))
        vertical = float(rng.uniform(-0.5, 0.5))
        out.append(((round(wall_x - distance, 3), round(lateral, 3), 0.0), round(altitude + vertical, 3)))
    return out


def flight_rng(seed: int, scene: str, start_index: int) -> np.random.Generator:
    """The generator of one flight's draws: a function of (seed, scene name, start index) only."""
    return np.random.default_rng([seed, zlib.crc32(scene.encode()), start_index])


def draw_flight(spec, seed: int, start_index: int, world: str, altitude: float = 1.5) -> dict:
    """One flight's conditions: start, altitude, vehicle seed, and in the hard world wind and camera delay (a
    start is redrawn, up to 20 times, until an opening lies within ``IN_VIEW_DEG`` of its heading)."""
    rng = flight_rng(seed, spec.name, start_index)
    if isinstance(spec, CaptureSpec):
        return _draw_capture_flight(spec, rng)
    hard = world == "hard"
    for _ in range(20 if hard else 1):
        (start, alt), = draw_starts(rng, 1, spec.wall.distance, altitude, HARD_LATERAL_M if hard else 0.5)
        if not hard or _opening_in_view(spec, start):
            break
    flight = {"start": start, "altitude": alt, "seed": int(rng.integers(0, 2**31 - 1)), "wind": None,
              "camera_delay_s": 0.0}
    if hard:
        flight["wind"] = (round(float(rng.uniform(0, HARD_WIND_MPS[0])), 2),
                          round(float(rng.uniform(0, HARD_WIND_MPS[1])), 2), round(float(rng.uniform(0, 360)), 1))
        flight["camera_delay_s"] = round(float(rng.uniform(*HARD_CAMERA_DELAY_S)), 3)
    return flight


def _draw_capture_flight(spec, rng: np.random.Generator) -> dict:
    """A capture's flight: its own start moved up to ±0.5 m across its heading, on the ground, and its altitude
    moved up to ±0.1 m (a capture's opening is where it is: no wider draw is safe to assume)."""
    yaw = math.radians(spec.start_yaw_deg)
    lateral = float(rng.uniform(-0.5, 0.5))
    x, y, _ = spec.start_ned
    start = (round(x - lateral * math.sin(yaw), 3), round(y + lateral * math.cos(yaw), 3), 0.0)
    altitude = round(spec.altitude_m + float(rng.uniform(-0.1, 0.1)), 3)
    return {"start": start, "altitude": altitude, "seed": int(rng.integers(0, 2**31 - 1)), "wind": None,
            "camera_delay_s": 0.0}


def flight_link_faults(faults: LinkFaults | None, scene: str, start_index: int) -> LinkFaults | None:
    """One flight's link faults: with a ``--link-seed``, its own seed drawn from (link seed, scene, start index);
    without, the seed stays open and the flight's vehicle seed fills it (``tools.launch.launch``)."""
    if faults is None or faults.seed is None:
        return faults
    rng = np.random.default_rng([faults.seed, zlib.crc32(scene.encode()), start_index])
    return LinkFaults(**{**faults.settings(), "seed": int(rng.integers(0, 2**31 - 1))})


def _opening_in_view(spec, start) -> bool:
    heading = math.radians(spec.start_yaw_deg)
    for op in spec.openings:
        cy = float(np.mean([p[0] for p in op.polygon()]))
        bearing = math.atan2(cy - start[1], spec.wall.distance - start[0]) - heading
        if abs(math.degrees(bearing)) <= IN_VIEW_DEG:
            return True
    return False


def judge(row: dict, passable: bool) -> dict:
    """``row`` with ``passable`` and its success by the rule of the module docstring."""
    gate = row.get("gate")                      # a capture: through its gate's rectangle, not just its plane
    crossed = bool(gate["crossed"] if gate else row.get("crossed_wall")) and not row.get("collision")
    refused = bool(row.get("refused"))
    return {**row, "passable": passable, "through": crossed,
            "success": crossed if passable else (refused and not row.get("collision"))}


def random_scene_files(count: int, seed: int, folder: Path, world: str = "standard") -> list[str]:
    """Save ``count`` random scene specs of ``world`` (reproducible from ``seed``) under ``folder``; their paths."""
    from scenes.library import random_scene

    if count:
        folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for k in range(count):
        spec = random_scene(np.random.default_rng([seed, 0xF1, k]), world=world)
        path = folder / f"{spec.name}.json"
        spec.save(path)
        paths.append(str(path))
    return paths


def summarise(rows: list[dict]) -> dict:
    n = len(rows)
    ok = sum(r["success"] for r in rows)
    passable = [r for r in rows if r.get("passable", True)]
    impassable = [r for r in rows if not r.get("passable", True)]
    return {
        "flights": n,
        "success": ok,
        "success_rate": round(ok / n, 4) if n else None,
        "success_interval": wilson_interval(ok, n),
        "passable": len(passable),
        "passable_through": sum(bool(r.get("through", r["success"])) for r in passable),
        "impassable": len(impassable),
        "impassable_refused": sum(bool(r.get("refused")) for r in impassable),
        "refused": sum(bool(r.get("refused")) for r in rows),
        "collisions": sum(bool(r["collision"]) for r in rows),
        "touching_counted_as_success": sum(bool(r["success"] and r["collision"]) for r in rows),
        "median_servo_steps": float(np.median([r["servo_steps"] or 0 for r in rows])) if n else None,
        "median_sim_time_s": float(np.median([r["sim_time_s"] or 0 for r in rows])) if n else None,
        "median_wall_time_s": float(np.median([r["wall_time_s"] for r in rows])) if n else None,
    }


def wilson_interval(successes: int, n: int, z: float = 1.96) -> tuple[float, float] | None:
    """The 95 % Wilson score interval of a success rate (None for no trials)."""
    if n <= 0:
        return None
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return round(max(0.0, centre - half), 4), round(min(1.0, centre + half), 4)


def markdown(rows: list[dict], summary: dict) -> str:
    lines = ["| scene | flights | passable | success | refused | collisions | median steps |",
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for scene in sorted({r["scene"] for r in rows}):
        sub = [r for r in rows if r["scene"] == scene]
        lines.append(f"| {scene} | {len(sub)} | {'yes' if sub[0].get('passable', True) else 'no'} | "
                     f"{sum(r['success'] for r in sub)} | {sum(bool(r.get('refused')) for r in sub)} | "
                     f"{sum(bool(r['collision']) for r in sub)} | "
                     f"{np.median([r['servo_steps'] or 0 for r in sub]):.0f} |")
    lo, hi = summary["success_interval"] or (0.0, 0.0)
    lines.append(f"| **all** | {summary['flights']} | {summary['passable']} | **{summary['success']} "
                 f"({100 * (summary['success_rate'] or 0):.0f} %, 95 % CI {100 * lo:.0f}–{100 * hi:.0f} %)** | "
                 f"{summary['refused']} | {summary['collisions']} | {summary['median_servo_steps']:.0f} |")
    if "executor" in summary:
        lines += ["", f"Executor {summary['executor']}, rows from {len(summary['nodes'])} node(s); {summary['flown']} "
                      f"flights flown in this run, {summary['reused']} reused from an earlier one."]
    return "\n".join(lines) + "\n"


def summary_line(summary: dict, out: Path) -> str:
    """The one-line human summary printed after the table."""
    lo, hi = summary["success_interval"] or (0.0, 0.0)
    return (f"success {summary['success']}/{summary['flights']} (95 % CI {100 * lo:.0f}–{100 * hi:.0f} %), "
            f"collisions {summary['collisions']}, touching counted as success "
            f"{summary['touching_counted_as_success']}; passable scenes flown through {summary['passable_through']}/"
            f"{summary['passable']}, impassable refused {summary['impassable_refused']}/{summary['impassable']}; "
            f"{summary['flown']} flown on {summary['executor']}, {summary['reused']} reused -> {out}/flights.json")


def _parser() -> argparse.ArgumentParser:
    from tools.ray_sweep import add_ray_argument

    p = argparse.ArgumentParser(prog="flowgap-eval-flights", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog="examples: flowgap-eval-flights --random 100 --starts 1 --seed 8 -o runs/r100; "
                                       "the same on a cluster: RAY_ADDRESS=HEAD:6379 flowgap-eval-flights --ray auto "
                                       "--random 1000 --starts 1 --seed 8 -o runs/r1000 (add --resume after a stop)")
    p.add_argument("scenes", nargs="*", help="scene names or spec paths (default: the 16-scene suite, "
                                             "unless --random is given)")
    p.add_argument("--scenes", nargs="+", dest="more_scenes", default=[], metavar="SCENE",
                   help="more scene names or spec paths, as flowgap-eval-masks takes them (added to the above)")
    p.add_argument("--random", type=int, default=0, metavar="N",
                   help="also fly N random scenes drawn from --seed (specs saved under OUT/scenes)")
    p.add_argument("--world", choices=("standard", "hard"), default="standard",
                   help="the random scenes' world, and the flights' conditions (see the description); standard "
                        "draws the same scenes for a seed as ever")
    p.add_argument("--starts", type=int, default=3, help="randomised starts per scene (default 3)")
    p.add_argument("--seed", type=int, default=0, help="seed of the start draws and the vehicles' noise")
    p.add_argument("--jobs", type=int, default=2,
                   help="flights at once on this machine (default 2), each flight's processes held to their share "
                        "of its CPUs (a thread each per library on 2 CPUs; an OMP_NUM_THREADS or NUMBA_NUM_THREADS "
                        "you set is kept); with --ray local, the local Ray gets JOBS x --cpus-per-flight CPUs; on a "
                        "cluster, the cluster's CPUs decide")
    p.add_argument("--realtime", action="store_true",
                   help="pace each flight by the wall clock at --speed instead of lockstep (a flight's outcome then "
                        "depends on this machine's load)")
    p.add_argument("--speed", type=float, default=2.0,
                   help="with --realtime: simulation speed-up of each flight (default 2)")
    p.add_argument("--latency", type=float, default=0.0, metavar="S",
                   help="the companion's camera-to-setpoint latency (default 0; in lockstep, what perception "
                        "costs in simulated time)")
    p.add_argument("--flow", default=DEFAULT_FLOW,
                   help="companion flow backend (default %(default)s: the shipped RAFT; dis:fine for OpenCV DIS)")
    p.add_argument("--detector", default="parallax", choices=["parallax", "paper"])
    p.add_argument("--edges", default="photo", choices=EDGE_MODES,
                   help="how the companion reads an opening's edge: photo (default), decided again from the two "
                        "frames; flow, the detector's mask as the flow shows it (before 2026-12-06)")
    p.add_argument("--no-thickness-look", action="store_true",
                   help="fly the companion without the thickness look (flowgap-companion --no-thickness-look): "
                        "openings judged by the wall's assumed 0.15 m depth throughout, for A/B sweeps")
    p.add_argument("-o", "--out", type=Path, default=Path("runs/eval_flights"),
                   help="output directory (default %(default)s)")
    p.add_argument("--resume", action="store_true",
                   help="fly only the flights whose results (OUT/results) are missing, and merge the rest; the "
                        "other settings must be those the saved flights were flown with")
    add_ray_argument(p, "flight")
    p.add_argument("--cpus-per-flight", type=float, default=2.0, metavar="N",
                   help="with --ray: the CPUs each flight's task declares (default 2: vehicle and companion), and on a "
                        "cluster the threads per library its processes may use")
    add_link_fault_arguments(p)
    return p


def _fail(message: str) -> int:
    print(f"flowgap-eval-flights: error: {message}", file=sys.stderr)
    return 2


def main(argv: list[str] | None = None) -> int:
    from tools.launch import flights_stopped_by_signals

    try:
        with flights_stopped_by_signals():     # a killed sweep stops its flights' processes, as Ctrl-C does
            return _main(argv)
    except KeyboardInterrupt:      # Ctrl-C or SIGTERM before or after the flights (during them: see launch)
        print("flowgap-eval-flights: interrupted", file=sys.stderr)
        return 130


def _main(argv: list[str] | None) -> int:
    args = _parser().parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(asctime)s %(levelname)s %(message)s")
    from scenes.build import resolve_spec
    from scenes.library import SUITE

    if args.random < 0 or args.starts <= 0 or args.jobs <= 0:
        return _fail("--random must be >= 0, --starts and --jobs positive")
    if not (args.speed > 0 and args.latency >= 0):
        return _fail("--speed must be positive and --latency >= 0")
    if not args.cpus_per_flight > 0:
        return _fail(f"--cpus-per-flight must be positive, got {args.cpus_per_flight}: e.g. --cpus-per-flight 2")
    try:
        link_faults = link_faults_from_args(args)
    except LinkFaultError as exc:
        return _fail(str(exc))
    if args.ray is not None:
        from tools.ray_sweep import RaySetupError, check_address, require_ray

        try:
            check_address(args.ray)
            require_ray()
        except RaySetupError as exc:
            return _fail(str(exc))
    scenes = list(args.scenes) + list(args.more_scenes) or ([] if args.random else list(SUITE))
    try:
        scenes += random_scene_files(args.random, args.seed, args.out / "scenes", args.world)
        specs = {s: resolve_spec(s) for s in scenes}
    except Exception as exc:  # noqa: BLE001 — unknown names, bad spec files: one line
        return _fail(str(exc))
    return _sweep(args, scenes, specs, link_faults)


def sweep_settings(args, link_faults: LinkFaults | None) -> dict:
    """What a saved flight must share with a sweep that resumes it."""
    return {"world": args.world, "seed": args.seed, "flow": args.flow, "detector": args.detector,
            "clock": "realtime" if args.realtime else "lockstep", "speed": args.speed if args.realtime else None,
            "latency_s": args.latency, "link_faults": None if link_faults is None else link_faults.settings(),
            # absent from sweeps flown before the photometric edges: theirs were the flow's, and resume so
            **({} if args.edges == "flow" else {"edges": args.edges}),
            # absent from sweeps flown with the look, before it could be turned off here
            **({"thickness_look": False} if args.no_thickness_look else {})}


def _sweep(args, scenes: list[str], specs: dict, link_faults: LinkFaults | None) -> int:
    from contextlib import nullcontext

    from scenes.groundtruth import passable_openings
    from tools.ray_sweep import RaySetupError, ray_session
    from tools.sweep_executors import FlightFailed, FlightJob, FlightSettings, LocalFlights, RayFlights
    from tools.sweep_results import ResumeError, SweepInterrupted, record_run, recorded_runs, run_sweep
    from tools.threads import flight_threads

    labels = {s: specs[s].name for s in scenes}      # spec paths are reported by their scene's name
    # a capture's gate is taken as passable: its author says the vehicle fits through it
    passable = {labels[s]: isinstance(specs[s], CaptureSpec)
                or any(passable_openings(specs[s], BODY_RADIUS_M, PASS_MARGIN_M)) for s in scenes}
    jobs = [FlightJob(scene, labels[scene], i, draw_flight(specs[scene], args.seed, i, args.world),
                      flight_link_faults(link_faults, labels[scene], i))
            for scene in scenes for i in range(args.starts)]
    if len({job.key for job in jobs}) < len(jobs):
        return _fail("two scenes share a name; give each scene once")
    # this machine's share for each of --jobs flights (--ray local runs on it too); a cluster task's, its CPUs
    threads = flight_threads(args.jobs) if args.ray in (None, "local") else max(1, int(args.cpus_per_flight))
    settings = FlightSettings(flow=args.flow, detector=args.detector, edges=args.edges, lockstep=not args.realtime,
                              speed=args.speed, latency_s=args.latency, threads=threads,
                              thickness_look=not args.no_thickness_look)

    def make_row(job: FlightJob, verdict: dict) -> dict:
        row = {**verdict, "scene": job.label, "start_index": job.start_index, "seed": job.flight["seed"]}
        return judge(row, passable[job.label])

    args.out.mkdir(parents=True, exist_ok=True)
    ray_info: dict = {}
    try:
        session = (nullcontext({}) if args.ray is None
                   else ray_session(args.ray, args.jobs * args.cpus_per_flight if args.ray == "local" else None))
        with session as ray_info:
            executor = (LocalFlights(settings, args.out, args.jobs) if args.ray is None
                        else RayFlights(settings, args.out, args.cpus_per_flight))
            t0 = time.monotonic()
            try:
                outcome = run_sweep(jobs, executor, make_row, args.out, sweep_settings(args, link_faults),
                                    args.resume)
            except SweepInterrupted as exc:
                record_run(args.out, time.monotonic() - t0, exc.saved, "interrupted")
                raise
            except FlightFailed:
                record_run(args.out, time.monotonic() - t0, None, "failed")
                raise
            wall_s = time.monotonic() - t0
            record_run(args.out, wall_s, outcome.flown, "complete" if not outcome.missing else "stopped")
    except (RaySetupError, ResumeError) as exc:
        return _fail(str(exc))
    except SweepInterrupted as exc:
        print(f"flowgap-eval-flights: {exc}", file=sys.stderr)
        return 130
    except FlightFailed as exc:
        print(f"flowgap-eval-flights: error: a flight raised ({exc}); fix it and rerun with --resume to fly the "
              f"rest", file=sys.stderr)
        return 1
    runs = recorded_runs(args.out)
    # judged again with today's labels: a row reused by --resume keeps how it was flown, not how it was judged
    rows = sorted((judge(r, passable[r["scene"]]) for r in outcome.rows), key=lambda r: (r["scene"], r["start_index"]))
    summary = summarise(rows)
    summary.update(world=args.world, flow=args.flow, detector=args.detector, edges=args.edges,
                   thickness_look=not args.no_thickness_look, clock="realtime" if args.realtime else "lockstep",
                   speed=args.speed if args.realtime else None, latency_s=args.latency, seed=args.seed,
                   starts_per_scene=args.starts, threads_per_flight=threads,
                   # every run of the sweep (a resumed one's earlier runs too), and this one
                   total_wall_s=round(sum(run["wall_s"] for run in runs), 1), runs=len(runs),
                   this_run_wall_s=round(wall_s, 1),
                   link_faults=None if link_faults is None else link_faults.settings(),
                   executor=executor.name, reused=outcome.reused, flown=outcome.flown,
                   flights_per_hour=round(3600 * outcome.flown / wall_s, 1) if outcome.flown and wall_s else None,
                   nodes=sorted({str(r.get("node")) for r in rows}),
                   ray=({**ray_info, "cpus_per_flight": args.cpus_per_flight} if args.ray is not None else None))
    (args.out / "flights.json").write_text(json.dumps({"summary": summary, "rows": rows}, indent=2) + "\n")
    table = markdown(rows, summary)
    (args.out / "flights.md").write_text(table)
    print(table)
    print(summary_line(summary, args.out))
    if outcome.missing:
        print(f"flowgap-eval-flights: {len(outcome.missing)} flights were stopped before they ended "
              f"({', '.join(outcome.missing[:3])}{', ...' if len(outcome.missing) > 3 else ''}): rerun with --resume "
              f"to fly them", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())

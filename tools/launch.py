"""``flowgap-sitl``: the two-process SITL — the simulated PX4 vehicle and the companion, talking only MAVLink.

Starts ``flowgap-vehicle`` and ``flowgap-companion`` as two OS processes with matching addresses (PX4's
instance numbering: API 14540+N, truth 14560+N), streams their logs with a prefix, stops both when the
companion's mission ends (or on Ctrl-C or SIGTERM), and reports the verdict the *vehicle* wrote from its own ground
truth: no companion code marks its own homework.  With ``--link-loss``/``--link-delay``/... a seeded
fault relay (:mod:`tools.link_relay`) sits on the API link between them, like a lossy telemetry radio.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import json
import logging
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

from companion.edges import EDGE_MODES
from companion.flow.registry import DEFAULT_FLOW
from sitl_vehicle.__main__ import triple_arg
from tools.link_faults import LinkFaultError, LinkFaults, add_link_fault_arguments, link_faults_from_args
from tools.threads import thread_env


def _wind(text: str) -> tuple[float, ...]:
    """argparse type for --wind, checked as the vehicle checks it."""
    from sitl_vehicle.__main__ import wind_arg

    config = wind_arg(text)
    return (config.mean_mps, config.gust_mps) + (() if config.from_deg is None else (config.from_deg,))

log = logging.getLogger("flowgap-sitl")


def _pump(stream, prefix: str, sink, tail: collections.deque) -> None:
    for line in iter(stream.readline, ""):
        tail.append(line.rstrip())
        if sink is not None:
            sink.write(f"{prefix} {line}")
            sink.flush()
    stream.close()


# every flight process this one has started and not yet stopped, for a signal to stop (flights_stopped_by_signals)
_running: set[subprocess.Popen] = set()
_running_lock = threading.Lock()
_terminating = threading.Event()


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGINT arrived: taken as Ctrl-C is, so that each flight's ``finally`` stops its two processes."""


@contextlib.contextmanager
def flights_stopped_by_signals() -> Iterator[None]:
    """While inside, SIGTERM (``kill``, ``pkill``, a CI or batch scheduler's time limit) and a SIGINT sent to this
    process alone stop its flights as Ctrl-C in a terminal does.  Python's default for SIGTERM ends the process at
    once: no ``finally`` runs, and every flight's vehicle and companion run on with no parent (measured: a stopped
    sweep's ``sitl_vehicle`` processes, idle minutes later).  Ctrl-C reaches the children itself (the terminal
    signals the whole process group); these reach only this process, so they are passed on here, and no flight
    starts after them.  For a CLI's main thread (elsewhere it does nothing); a SIGINT ignored by the shell that
    started the process stays ignored."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def on_signal(signum, frame) -> None:
        with _running_lock:
            again = _terminating.is_set()
            _terminating.set()
            procs = list(_running)
        for proc in procs:
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        if not again:     # a second signal (Ctrl-C pressed twice) must not cut short the stopping the first began
            raise Terminated()

    before = {sig: signal.getsignal(sig) for sig in (signal.SIGTERM, signal.SIGINT)}
    for sig, handler in before.items():
        if handler is not signal.SIG_IGN:
            signal.signal(sig, on_signal)
    try:
        yield
    finally:
        for sig, handler in before.items():
            signal.signal(sig, handler)
        _terminating.clear()


def _start(cmd: list[str], prefix: str, sink, env: dict[str, str] | None = None) -> subprocess.Popen:
    """The process, its output streamed to ``sink`` (None: not shown) and its last lines kept in ``proc.tail``
    (read after ``proc.pump`` has finished) for an error that has to say why it died; ``env``: its environment
    (None: this process's)."""
    with _running_lock:
        if _terminating.is_set():
            raise Terminated()
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, bufsize=1,
                                env=env)
        _running.add(proc)
    proc.tail = collections.deque(maxlen=5)
    proc.pump = threading.Thread(target=_pump, args=(proc.stdout, prefix, sink, proc.tail), daemon=True)
    proc.pump.start()
    return proc


def _last_words(proc: subprocess.Popen) -> str:
    """The last non-empty line a stopped process wrote ('' when none)."""
    proc.pump.join(timeout=2.0)
    return next((line.strip() for line in reversed(proc.tail) if line.strip()), "")


def _stop(proc: subprocess.Popen, timeout: float = 10.0) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    with _running_lock:
        _running.discard(proc)


DEFAULT_ALTITUDE_M = 1.5      # the suite's openings are centred near 1.5 m up; a capture says its own
LOCKSTEP_HANG_S = 3600.0      # in lockstep, wall seconds after which a flight is taken for hung and stopped


def launch(scene: str, run_dir: Path, start=None, speed: float = 1.0, instance: int = 0,
           flow: str = DEFAULT_FLOW, detector: str = "parallax", seed: int = 0, no_noise: bool = False,
           timeout_s: float = 300.0, images: bool = True, log_sink=sys.stdout, altitude: float | None = None,
           link: str = "pymavlink", lockstep: bool = False, latency_s: float = 0.0,
           wind: tuple[float, ...] | None = None, yaw_deg: float | None = None,
           camera_delay_s: float = 0.0, rerun: bool = False, rerun_connect: str | None = None,
           link_faults: LinkFaults | None = None, signing_key: Path | None = None, edges: str = "photo",
           threads: int | None = None, thickness_look: bool = True) -> dict:
    """Fly one two-process SITL flight; returns the verdict dict (also written to run_dir/verdict.json).

    ``scene``: a suite name, spec ``.json`` or capture scene ``.json``; ``start`` (NED, on the ground), ``yaw_deg``
    and ``altitude`` (the companion's flight height) default to the scene's: a capture's ``start_ned``,
    ``start_yaw_deg`` and ``altitude_m`` (its gate's height), a procedural scene's origin, ``start_yaw_deg`` and
    1.5 m. ``lockstep``: both processes on the vehicle's clock (``speed`` is then unused); ``latency_s``: the
    companion's camera-to-setpoint latency; ``wind``: (mean m/s, gust m/s[, from deg]) on the vehicle;
    ``camera_delay_s``: how long after
    exposure each camera frame reaches the companion; ``rerun``: the companion records the flight in
    ``run_dir/flight.rrd`` (``rerun_connect``: streams it to a running viewer instead); ``link_faults``: relay
    the API link through seeded faults (a seed of None: ``seed``'s), recorded in the verdict's ``link_faults``;
    ``signing_key``: a PX4 key file both processes sign with (the vehicle then drops unsigned messages);
    ``threads``: the threads each library of both processes may use (:func:`thread_env`; None: as many as cores);
    ``thickness_look``: False flies the companion with ``--no-thickness-look`` (the wall's assumed depth throughout).
    ``timeout_s``: in real time, the wall seconds after which the flight is stopped; in lockstep, the simulated
    seconds after which the vehicle stops itself, so that the outcome never depends on the machine's load (a
    wall limit once cut hard-world flights short on a busy machine), and ``LOCKSTEP_HANG_S`` wall seconds bound
    a hung flight.  Either limit reached is said in the verdict's ``error``."""
    if start is None or yaw_deg is None or altitude is None:
        from scenes.build import resolve_spec

        spec = resolve_spec(scene)
        start = tuple(spec.start_ned) if start is None else start
        yaw_deg = spec.start_yaw_deg if yaw_deg is None else yaw_deg
        altitude = getattr(spec, "altitude_m", DEFAULT_ALTITUDE_M) if altitude is None else altitude
    run_dir.mkdir(parents=True, exist_ok=True)
    api, truth = 14540 + instance, 14560 + instance
    vehicle_result = run_dir / "vehicle_result.json"
    summary_path = run_dir / "companion" / "summary.json"
    # a run directory flown before holds that flight's results: read after a process that died early, they
    # were taken for this flight's (measured: a companion that failed on import "flew" a stale success)
    for stale in (vehicle_result, summary_path, run_dir / "verdict.json"):
        stale.unlink(missing_ok=True)
    vehicle_cmd = [sys.executable, "-m", "sitl_vehicle", "--scene", scene, "--instance", str(instance),
                   "--start=" + ",".join(f"{v:g}" for v in start), f"--start-yaw={yaw_deg:g}", "--speed", f"{speed:g}",
                   "--seed", str(seed),
                   "--result", str(vehicle_result), "--log-level", "WARNING"]
    if no_noise:
        vehicle_cmd.append("--no-noise")
    if lockstep:
        vehicle_cmd += ["--lockstep", "--duration", f"{timeout_s:g}"]
    wall_limit_s = max(timeout_s, LOCKSTEP_HANG_S) if lockstep else timeout_s
    if wind is not None:
        vehicle_cmd.append("--wind=" + ",".join(f"{v:g}" for v in wind))
    companion_cmd = [sys.executable, "-m", "companion", "--connect", f"udpin://127.0.0.1:{api}",
                     "--truth", f"udpin://127.0.0.1:{truth}", "--scene", scene, "--flow", flow,
                     "--detector", detector, "--edges", edges, "--run-dir", str(run_dir / "companion"),
                     "--altitude", f"{altitude:g}",
                     "--link", link, "--latency", f"{latency_s:g}", "--camera-delay", f"{camera_delay_s:g}"]
    if not images:
        companion_cmd.append("--no-images")
    if not thickness_look:
        companion_cmd.append("--no-thickness-look")
    if lockstep:
        companion_cmd.append("--lockstep")
    if rerun_connect:
        companion_cmd += ["--rerun-connect", rerun_connect]
    elif rerun:
        companion_cmd += ["--rerun", str(run_dir / "flight.rrd")]
    if signing_key is not None:
        vehicle_cmd += ["--signing-key", str(signing_key)]
        companion_cmd += ["--signing-key", str(signing_key)]
    relay = None
    if link_faults is not None and link_faults.active:
        from tools.link_relay import relay_for_instance

        relay = relay_for_instance(link_faults.with_seed(seed), instance, lockstep, speed).start()
        vehicle_cmd.append(f"--api-remote=127.0.0.1:{relay.vehicle_api_address[1]}")
        if lockstep:
            vehicle_cmd.append(f"--truth-remote=127.0.0.1:{relay.vehicle_truth_address[1]}")
    t0 = time.monotonic()
    companion = vehicle = None
    interrupted = vehicle_ended = timed_out = False
    try:
        env = None if threads is None else {**os.environ, **thread_env(threads, os.environ)}
        companion = _start(companion_cmd, "[companion]", log_sink, env)
        vehicle = _start(vehicle_cmd, "[vehicle]  ", log_sink, env)
        while companion.poll() is None:
            if vehicle.poll() is not None:
                vehicle_ended = True
                log.error("the vehicle process exited (code %s) before the mission ended", vehicle.returncode)
                break
            if time.monotonic() - t0 > wall_limit_s:
                timed_out = True
                log.error("flight timed out after %.0f wall seconds", wall_limit_s)
                break
            time.sleep(0.1)
        if not lockstep:  # (a lockstep companion hands the vehicle its settling second itself)
            time.sleep(1.0 / max(speed, 0.1))  # let the vehicle settle in Hold before the verdict is taken
    except KeyboardInterrupt:
        interrupted = True
        log.warning("interrupted: stopping both processes")
    finally:
        interrupted = interrupted or _terminating.is_set()   # (a flight in a sweep's thread: the signal hit main)
        for proc in (companion, vehicle):
            if proc is not None:
                _stop(proc)
        if relay is not None:
            relay.stop()
    wall = time.monotonic() - t0
    vehicle_verdict = json.loads(vehicle_result.read_text()) if vehicle_result.exists() else {}
    companion_summary = json.loads(summary_path.read_text()) if summary_path.exists() else {}
    verdict = {
        "scene": scene,
        "success": bool(vehicle_verdict.get("success", False)) and bool(companion_summary) and not interrupted,
        "collision": vehicle_verdict.get("collision"),
        "crossed_wall": vehicle_verdict.get("crossed_wall"),
        "min_clearance_m": vehicle_verdict.get("min_clearance_m"),
        "crash_reason": vehicle_verdict.get("crash_reason"),
        "servo_steps": companion_summary.get("servo_steps"),
        "companion_state": companion_summary.get("state"),
        "companion_reason": companion_summary.get("reason"),
        # declined by the companion, and the vehicle never touched anything
        "refused": companion_summary.get("state") == "refused" and not vehicle_verdict.get("collision", False),
        "sim_time_s": vehicle_verdict.get("sim_time_s"),
        "wall_time_s": round(wall, 2),
        "start_ned": list(start),
        "gate": vehicle_verdict.get("gate"),
        "start_yaw_deg": yaw_deg,
        "altitude_m": altitude,
        "flow": flow,
        "detector": detector,
        "edges": edges,
        "thickness_look": thickness_look,
        "clock": "lockstep" if lockstep else "realtime",
        "latency_s": latency_s,
        "wind": vehicle_verdict.get("wind"),
        "camera_delay_s": camera_delay_s,
        "link_faults": None if relay is None else relay.report(),
        "signing": vehicle_verdict.get("signing"),
        "run_dir": str(run_dir),
    }
    board = run_dir / "companion" / "storyboard.png"
    if board.exists():
        from companion.storyboard import append_footer

        append_footer(board, [f"vehicle's verdict: {describe(verdict)}"])
        verdict["storyboard"] = str(board)
    if rerun and not rerun_connect and (run_dir / "flight.rrd").exists():
        verdict["rerun"] = str(run_dir / "flight.rrd")
    if interrupted:
        verdict["error"] = "interrupted (Ctrl-C or SIGTERM): both processes were stopped"
    elif timed_out:
        verdict["error"] = (f"timed out after {wall_limit_s:.0f} wall seconds: both processes were stopped"
                            + (" (a lockstep flight this slow is hung)" if lockstep else
                               "; a longer --timeout, or --lockstep, lets a slow machine finish it"))
    elif vehicle_ended and lockstep and (vehicle_verdict.get("sim_time_s") or 0.0) >= timeout_s - 0.01:
        verdict["error"] = f"the flight's {timeout_s:g} simulated seconds (--timeout) ran out before the mission ended"
    elif not vehicle_verdict and (vehicle_ended or companion_summary):
        verdict["error"] = "the vehicle wrote no verdict (it did not exit cleanly)"
    elif not companion_summary:    # (the vehicle, if it wrote nothing, was stopped: the companion's end is the cause)
        words = _last_words(companion)
        verdict["error"] = (f"the companion exited (code {companion.returncode}) without a summary"
                            + (f": {words}" if words else "") + "; flowgap-sitl without --quiet shows its whole log")
    (run_dir / "verdict.json").write_text(json.dumps(verdict, indent=2) + "\n")
    return verdict


def describe(v: dict) -> str:
    if v["success"]:
        return (f"SUCCESS: flew through {v['scene']} in {v['servo_steps']} servo steps, min clearance "
                f"{v['min_clearance_m']} m, {v['sim_time_s']} s simulated, {v['wall_time_s']} s wall")
    gate = v.get("gate")
    why = v.get("crash_reason") or v.get("companion_reason") or v.get("error") or (
        "did not cross the wall" if not v.get("crossed_wall") else
        "crossed the gate's plane outside its rectangle" if gate and not gate.get("crossed") else "unknown")
    return f"FAILED: {v['scene']}: {why}"


def main(argv: list[str] | None = None) -> int:
    try:
        with flights_stopped_by_signals():
            return _main(argv)
    except KeyboardInterrupt:      # Ctrl-C or SIGTERM before or after the flights (during them: see launch)
        print("flowgap-sitl: interrupted", file=sys.stderr)
        return 130


def _main(argv: list[str] | None) -> int:
    p = argparse.ArgumentParser(prog="flowgap-sitl", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog="example: flowgap-sitl --scene window2_stone --start 0,0.3,0 "
                                       "--result runs/verdict.json")
    p.add_argument("--scene", default="window1_brick",
                   help="suite scene name, spec .json or capture scene .json (a placed 3DGS .ply; see docs/scenes.md) "
                        "(default %(default)s)")
    p.add_argument("--start", type=triple_arg, default=None, metavar="X,Y,Z",
                   help="vehicle start position NED (default: the scene's start_ned; 0,0,0 for the suite: on the "
                        "ground, 3 m before the wall)")
    p.add_argument("--speed", type=float, default=2.0, help="simulation speed-up (default 2; unused in lockstep)")
    p.add_argument("--lockstep", action="store_true",
                   help="run both processes on the vehicle's clock: the same seed gives the same flight at any "
                        "machine load, as fast as the CPU allows")
    p.add_argument("--latency", type=float, default=0.0, metavar="S",
                   help="the companion's camera-to-setpoint latency (default 0; in lockstep, what perception "
                        "costs in simulated time)")
    p.add_argument("--instance", type=int, default=0, help="port offset, to run several flights at once")
    p.add_argument("--flow", default=DEFAULT_FLOW,
                   help="companion flow backend (default %(default)s: the shipped RAFT; dis:fine for OpenCV DIS)")
    p.add_argument("--detector", default="parallax", choices=["parallax", "paper"], help="gap detector")
    p.add_argument("--edges", default="photo", choices=EDGE_MODES,
                   help="how the companion reads an opening's edge: photo (default), decided again from the two "
                        "frames; flow, the detector's mask as the flow shows it (before 2026-12-06)")
    p.add_argument("--no-thickness-look", action="store_true",
                   help="the companion never looks at the wall's depth near the need; it judges openings by the "
                        "assumed 0.15 m throughout (flowgap-companion --no-thickness-look)")
    p.add_argument("--link", default="pymavlink", choices=["pymavlink", "mavsdk"], help="companion link backend")
    p.add_argument("--seed", type=int, default=0, help="vehicle sensor-noise (and wind) seed")
    p.add_argument("--wind", type=_wind, default=None, metavar="MEAN,GUST[,FROM_DEG]",
                   help="wind on the vehicle (flowgap-vehicle --wind), e.g. 3,1")
    p.add_argument("--start-yaw", "--yaw", dest="yaw", type=float, default=None, metavar="DEG",
                   help="start heading in degrees (default: the scene's start_yaw_deg, 0 for the suite)")
    p.add_argument("--altitude", type=float, default=None, metavar="M",
                   help="flight height above the floor (default: a capture's altitude_m or gate height, else "
                        f"{DEFAULT_ALTITUDE_M:g})")
    p.add_argument("--camera-delay", type=float, default=0.0, metavar="S",
                   help="camera frames reach the companion S seconds after exposure (default 0)")
    p.add_argument("--no-noise", action="store_true", help="exact-truth vehicle estimate")
    p.add_argument("-o", "--out", "--run-dir", dest="run_dir", type=Path,
                   help="the flight's run directory: logs, verdict, storyboard (default runs/<time>-<scene>)")
    p.add_argument("--result", type=Path, help="also write the verdict JSON here")
    p.add_argument("--timeout", type=float, default=300.0,
                   help="seconds before giving up: wall seconds, or with --lockstep simulated ones (then a hung flight "
                        f"is stopped after {LOCKSTEP_HANG_S:.0f} wall seconds) (default 300)")
    p.add_argument("--quiet", action="store_true", help="do not stream the two processes' logs")
    p.add_argument("--rerun", action="store_true",
                   help="record the flight for the Rerun viewer in RUN_DIR/flight.rrd (extra: flowgap[viz])")
    p.add_argument("--rerun-connect", metavar="ADDRESS",
                   help="stream the recording live to a running Rerun viewer instead")
    p.add_argument("--signing-key", type=Path, metavar="FILE",
                   help="MAVLink 2 signing with this PX4 key file (flowgap-vehicle --new-signing-key makes one): "
                        "the vehicle and the companion sign, and the vehicle drops unsigned messages")
    add_link_fault_arguments(p)
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s sitl %(levelname)s %(message)s")
    if not args.speed > 0:
        print(f"flowgap-sitl: error: --speed must be positive, got {args.speed}", file=sys.stderr)
        return 2
    try:
        link_faults = link_faults_from_args(args)
    except LinkFaultError as exc:
        print(f"flowgap-sitl: error: {exc}", file=sys.stderr)
        return 2
    if args.signing_key is not None:
        from sitl_vehicle.signing import SigningKeyError, read_key_file

        try:
            read_key_file(args.signing_key)
        except SigningKeyError as exc:
            print(f"flowgap-sitl: error: {exc}", file=sys.stderr)
            return 2
        if args.link != "pymavlink":
            print("flowgap-sitl: error: --signing-key needs --link pymavlink (mavsdk_server has no message signing)",
                  file=sys.stderr)
            return 2
    try:
        from scenes.build import resolve_spec
        from scenes.capture import CaptureError, CaptureSpec

        if isinstance(resolve_spec(args.scene), CaptureSpec):
            from scenes.collision import load_collision

            load_collision(args.scene)     # checks the splats against the gate; the vehicle then finds it cached
    except CaptureError as exc:
        print(f"flowgap-sitl: error: {exc}", file=sys.stderr)
        return 2
    except Exception as exc:  # noqa: BLE001 — unknown scene names and bad spec files: one line
        print(f"flowgap-sitl: error: scene {args.scene!r}: {exc}", file=sys.stderr)
        return 2
    if args.rerun or args.rerun_connect:
        from companion.recording import RecordingError, require_rerun

        try:
            require_rerun()
        except RecordingError as exc:
            print(f"flowgap-sitl: error: {exc}", file=sys.stderr)
            return 2
    label = Path(args.scene).stem if args.scene.endswith(".json") else args.scene   # a path names no folder
    run_dir = args.run_dir or Path("runs") / f"{time.strftime('%Y%m%d-%H%M%S')}-{label}"
    verdict = launch(args.scene, run_dir, args.start, args.speed, args.instance, args.flow, args.detector,
                     args.seed, args.no_noise, args.timeout, log_sink=None if args.quiet else sys.stdout,
                     altitude=args.altitude,
                     link=args.link, lockstep=args.lockstep, latency_s=args.latency, wind=args.wind,
                     yaw_deg=args.yaw, camera_delay_s=args.camera_delay, rerun=args.rerun,
                     rerun_connect=args.rerun_connect, link_faults=link_faults, signing_key=args.signing_key,
                     edges=args.edges, thickness_look=not args.no_thickness_look)
    if args.result:
        args.result.parent.mkdir(parents=True, exist_ok=True)
        args.result.write_text(json.dumps(verdict, indent=2) + "\n")
    print(json.dumps(verdict, indent=2))
    print(describe(verdict))
    if verdict.get("storyboard"):
        print(f"storyboard: {verdict['storyboard']}")
    if verdict.get("rerun"):
        print(f"rerun recording: {verdict['rerun']} (rerun {verdict['rerun']})")
    return 0 if verdict["success"] else 1


if __name__ == "__main__":
    sys.exit(main())

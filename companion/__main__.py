"""``flowgap-companion`` / ``python -m companion``: see, decide and fly through the window over MAVLink."""

from __future__ import annotations

import argparse
import json
import logging
import math
import signal
import sys
import time
from pathlib import Path

from companion.clock import LockstepError
from companion.edges import EDGE_MODES, edges_for
from companion.flow.registry import DEFAULT_FLOW
from companion.gap import blind_detector, get_detector
from companion.link import BACKENDS, LinkError, make_link, parse_endpoint
from companion.lockstep import open_clock
from companion.mission import Mission
from companion.mission_config import MissionConfig, State
from companion.runlog import RunLog
from companion.thickness import ThicknessLookConfig

log = logging.getLogger("flowgap-companion")

EPILOG = """\
examples:
  flowgap-companion --scene window1_brick                      # SITL defaults: udpin://:14540, truth :14560
  flowgap-companion --scene window2_stone --flow dis:medium --detector paper
  flowgap-companion --connect serial:///dev/ttyUSB0:921600 ... # a real PX4 (needs a real camera source)

exit status: 0 the mission completed (the vehicle's own verdict says whether it got through), 1 the mission
failed (lost link, refused command) or declined to fly through (an opening too small, none seen),
2 bad input.
"""


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="flowgap-companion",
        description="Companion computer: renders the camera view, computes optical flow between successive "
                    "frames, finds the gap by parallax, and flies through it with offboard position setpoints.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--connect", default="udpin://:14540", help="autopilot MAVLink URL (default %(default)s)")
    p.add_argument("--link", choices=BACKENDS, default="pymavlink", help="link backend (default %(default)s)")
    p.add_argument("--truth", default="udpin://:14560",
                   help="ground-truth pose stream for the simulated camera (default %(default)s)")
    p.add_argument("--scene", default="window1_brick", help="scene the simulated camera renders (default %(default)s)")
    p.add_argument("--flow", default=DEFAULT_FLOW,
                   help="flow backend[:preset|variant]: raft, dis:fine, dis:medium, farneback (default %(default)s: "
                        "the shipped RAFT-small-refined; dis:fine needs no torch and is 3x faster)")
    p.add_argument("--raft-weights", type=Path, help="RAFT weights file (default: the shipped ones)")
    p.add_argument("--detector", choices=["parallax", "paper"], default="parallax",
                   help="gap detector: ours (parallax) or the paper's colour/Canny pipeline (default %(default)s)")
    p.add_argument("--edges", choices=EDGE_MODES, default="photo",
                   help="how an opening's edge is read: photo (default) decides the pixels near the detector's edge "
                        "again by which of the two depths predicts the next frame's colour (companion.edges); flow "
                        "keeps the detector's mask as the flow shows it (blurred by a pixel or more, the behaviour "
                        "before 2026-12-06)")
    p.add_argument("--no-thickness-look", action="store_true",
                   help="judge an opening near the vehicle's need by the wall depth assumed (0.15 m) instead of "
                        "reading the wall's depth from a sidestep square to it first (companion.thickness)")
    p.add_argument("--render-backend", choices=["cpu", "torch"], default="cpu", help="splat renderer")
    p.add_argument("--altitude", type=float, default=1.5, help="takeoff altitude in metres (default 1.5)")
    p.add_argument("--finish", choices=["hold", "land"], default="hold", help="after the traversal (default hold)")
    p.add_argument("--lockstep", action="store_true",
                   help="run on the simulated vehicle's clock (flowgap-vehicle --lockstep): the vehicle advances "
                        "only when this companion waits, so a flight repeats exactly at any machine load; the "
                        "release travels on the --truth side channel, never on the MAVLink link")
    p.add_argument("--latency", type=float, default=0.0, metavar="S",
                   help="camera-to-setpoint latency in seconds: the next waypoint goes out this long after its "
                        "frame, or when perception is done if later (in lockstep, what perception costs in "
                        "simulated time; default 0)")
    p.add_argument("--camera-delay", type=float, default=0.0, metavar="S",
                   help="the simulated camera's frames arrive S seconds after exposure, stamped with the exposure "
                        "time (default 0)")
    p.add_argument("-o", "--out", "--run-dir", dest="run_dir", type=Path,
                   help="run log directory (default runs/<time>)")
    p.add_argument("--no-images", action="store_true", help="do not save per-step PNGs (faster evaluations)")
    p.add_argument("--rerun", nargs="?", const="", default=None, metavar="FILE",
                   help="record the flight for the Rerun viewer in FILE (default RUN_DIR/flight.rrd); needs the "
                        "extra: pip install 'flowgap[viz]'")
    p.add_argument("--rerun-connect", metavar="ADDRESS",
                   help="stream the recording live to a running Rerun viewer instead "
                        "(e.g. rerun+http://127.0.0.1:9876/proxy)")
    p.add_argument("--signing-key", type=Path, metavar="FILE",
                   help="sign every MAVLink message with this PX4 key file (32-byte secret, 8-byte timestamp, mode "
                        "0600) and drop unsigned replies, for a vehicle that demands signing (pymavlink link only)")
    p.add_argument("--log-level", default="INFO", choices=["DEBUG", "INFO", "WARNING", "ERROR"])
    return p


def make_flow(spec: str, raft_weights: Path | None):
    from companion.flow import make_flow_backend
    from companion.flow.registry import parse_backend

    name, options = parse_backend(spec)
    if name == "raft" and raft_weights is not None:
        options["weights"] = raft_weights
    return make_flow_backend(name, **options)


def _close(*things) -> None:
    for thing in things:
        if thing is not None:
            thing.close()


def _interrupt(_signum, _frame) -> None:
    raise KeyboardInterrupt


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=args.log_level, format="%(asctime)s companion %(levelname)s %(message)s")
    run_dir = args.run_dir or Path("runs") / time.strftime("%Y%m%d-%H%M%S")
    for flag, value in (("--latency", args.latency), ("--camera-delay", args.camera_delay)):
        if not (math.isfinite(value) and value >= 0):
            print(f"flowgap-companion: error: {flag} must be a number of seconds >= 0 (got {value})",
                  file=sys.stderr)
            return 2
    if args.lockstep and args.link != "pymavlink":
        print(f"flowgap-companion: error: --lockstep needs --link pymavlink: the {args.link} link cannot run "
              f"in lockstep (mavsdk_server keeps its own wall-clock timers)", file=sys.stderr)
        return 2
    if args.signing_key is not None:       # before anything waits on the vehicle: a bad key is one line now
        from companion.link.signing import SigningKeyError, load_key

        if args.link != "pymavlink":
            print(f"flowgap-companion: error: the {args.link} link cannot sign MAVLink (mavsdk_server has no "
                  f"message signing): use --link pymavlink with --signing-key", file=sys.stderr)
            return 2
        try:
            load_key(args.signing_key)
        except SigningKeyError as exc:
            print(f"flowgap-companion: error: {exc}", file=sys.stderr)
            return 2
    recording = None
    if args.rerun is not None or args.rerun_connect:
        from companion.recording import RecordingError, open_recording
        try:
            recording = open_recording(Path(args.rerun) if args.rerun else run_dir / "flight.rrd",
                                       args.rerun_connect)
        except RecordingError as exc:
            print(f"flowgap-companion: error: {exc}", file=sys.stderr)
            return 2
    clock = None
    try:
        parse_endpoint(args.connect)
        parse_endpoint(args.truth)
        flow = make_flow(args.flow, args.raft_weights)
        detector, blind = get_detector(args.detector), blind_detector(args.detector)
        from companion.camera import SplatCamera

        clock, poses = open_clock(args.truth, args.lockstep)
        camera = SplatCamera(args.scene, poses, backend=args.render_backend, clock=clock,
                             delay_s=args.camera_delay)
    except (ValueError, KeyError, FileNotFoundError, OSError, LockstepError) as exc:
        print(f"flowgap-companion: error: {exc}", file=sys.stderr)
        _close(clock, recording)
        return 2
    except Exception as exc:  # noqa: BLE001 — weights/scene errors from other packages: one line, not a traceback
        print(f"flowgap-companion: error: {type(exc).__name__}: {exc}", file=sys.stderr)
        _close(clock, recording)
        return 2
    runlog = RunLog(run_dir, images=not args.no_images)
    if recording is not None:
        recording.truth = lambda: camera.poses.latest(0.0)
        recording.scene(camera.spec, camera.cloud)
        recording.camera(camera.K, camera.width, camera.height)
    try:
        link = make_link(args.connect, args.link, tlog_path=runlog.tlog_path, clock=clock,
                         signing_key=args.signing_key)
    except (ValueError, LinkError, ImportError) as exc:
        print(f"flowgap-companion: error: {exc}", file=sys.stderr)
        camera.close()
        _close(clock, recording)
        return 2
    if recording is not None:
        link.telemetry.listeners.append(recording.telemetry)
    mission = Mission(link, camera, flow, detector, runlog,
                      config=MissionConfig(altitude_m=args.altitude, finish=args.finish,
                                           perception_latency_s=args.latency), recording=recording,
                      blind_detector=blind, edges=edges_for(args.edges),
                      thickness=ThicknessLookConfig(enabled=not args.no_thickness_look))
    signal.signal(signal.SIGTERM, _interrupt)  # the launcher stops us with SIGTERM: end like Ctrl-C
    try:
        result = mission.run()
    except KeyboardInterrupt:
        log.warning("interrupted: asking the vehicle to hold")
        try:
            link.hold()
        except LinkError:
            pass
        result = mission.result
        result.reason = result.reason or "interrupted"
    finally:
        link.close()
        clock.close()       # in lockstep: the vehicle's last second, to settle before its verdict
        camera.close()
    summary = {"scene": args.scene, "flow": args.flow, "detector": args.detector, "edges": args.edges,
               "thickness_look_on": not args.no_thickness_look, "link": args.link, "clock": clock.name,
               "latency_s": args.latency, **result.as_dict()}
    runlog.summary(summary)
    push = f", pushed {result.push_length_m:.2f} m" if result.push_length_m else ""
    board = runlog.storyboard(mission.record.storyboard.render(
        [f"companion: {result.state.value.upper()}{push} after {result.servo_steps} servo steps"
         + (f" ({result.reason})" if result.reason else "")]))
    log.info("storyboard: %s", board)
    if recording is not None:
        recording.event(f"companion: {result.state.value.upper()}" + (f" ({result.reason})" if result.reason else ""))
        recording.close()
        log.info("rerun recording: %s", args.rerun_connect or (args.rerun or run_dir / "flight.rrd"))
    runlog.close()
    print(json.dumps({k: summary[k] for k in ("state", "reason", "servo_steps", "push_length_m")}))
    log.info("run log in %s", run_dir)
    return 0 if result.state is State.DONE else 1


if __name__ == "__main__":
    sys.exit(main())

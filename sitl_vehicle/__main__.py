"""``flowgap-vehicle`` / ``python -m sitl_vehicle``: the simulated PX4 flight controller process."""

from __future__ import annotations

import argparse
import logging
import math
import signal
import sys
import threading
from pathlib import Path

from sitl_vehicle.airframes import AIRFRAMES
from sitl_vehicle.params import COMMANDER_PARAMS, ParameterError
from sitl_vehicle.server import ServerConfig, VehicleServer
from sitl_vehicle.signing import SigningKeyError
from sitl_vehicle.sim import VehicleConfig
from sitl_vehicle.telemetry import Home
from sitl_vehicle.udp_link import PortInUseError, parse_hostport

log = logging.getLogger("flowgap-vehicle")

EPILOG = """\
ports (as PX4 SITL; --instance N adds N to every port but the GCS remote):
  GCS link     local 18570 -> 127.0.0.1:14550 (QGroundControl, MAVProxy)
  API link     local 14580 -> 127.0.0.1:14540 (MAVSDK, pymavlink, the flowgap companion)
  truth stream          ->   127.0.0.1:14560 (simulation only: ODOMETRY with the true pose)
The vehicle sends first and locks onto the first peer that answers on each link.

examples:
  flowgap-vehicle                                 # real time, default ports
  flowgap-vehicle --speed 4 --no-noise            # 4x real time with exact-truth telemetry
  flowgap-vehicle --scene window1_brick --result runs/verdict.json
  flowgap-vehicle --scene room.capture.json       # a placed 3DGS capture: starts at its start_ned
  flowgap-vehicle --param MIS_TAKEOFF_ALT=1.5 --param COM_OBL_RC_ACT=4
"""


class CliError(Exception):
    """Bad command-line input; printed as one line."""


def triple_arg(text: str) -> tuple[float, float, float]:
    """argparse type for X,Y,Z (also used by flowgap-sitl): three finite comma-separated numbers."""
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"{text!r} must be three comma-separated numbers, e.g. 0,0,0")
    return values  # type: ignore[return-value]


def _param(text: str) -> tuple[str, float]:
    name, sep, value = text.partition("=")
    try:
        return name.strip(), float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} must look like NAME=VALUE, e.g. MIS_TAKEOFF_ALT=1.5") from None


def wind_arg(text: str):
    from sitl_vehicle.wind import parse_wind

    try:
        return parse_wind(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix(f"--wind {text!r} ")) from None


def _address(text: str) -> tuple[str, int]:
    try:
        return parse_hostport(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="flowgap-vehicle",
        description="A simulated PX4 quadrotor: rigid-body dynamics, PX4's control cascade, a noisy-sensor "
                    "Kalman estimator, PX4 flight modes and failsafes, speaking MAVLink 2 over UDP.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    sim = p.add_argument_group("simulation")
    sim.add_argument("--airframe", choices=sorted(AIRFRAMES), default="quad250", help="airframe (default %(default)s)")
    sim.add_argument("--speed", type=float, default=1.0, help="simulation seconds per wall second (default 1)")
    sim.add_argument("--lockstep", action="store_true",
                     help="advance simulation time only as far as a companion releases it (flowgap-companion "
                          "--lockstep, over the truth side channel): flights repeat exactly and run as fast as "
                          "both processes allow; --speed is ignored; held, the vehicle beacons on the side "
                          "channel and heartbeats the GCS link once a second")
    sim.add_argument("--no-noise", action="store_true", help="exact-truth sensors and estimate (for tests)")
    sim.add_argument("--seed", type=int, default=0, help="seed of every random draw (default 0)")
    sim.add_argument("--start", type=triple_arg, default=None, metavar="X,Y,Z",
                     help="start position NED in metres (default: the scene's start_ned, else 0,0,0: on the ground "
                          "at the origin)")
    sim.add_argument("--start-yaw", "--yaw", dest="start_yaw", type=float, default=None, metavar="DEG",
                     help="start heading in degrees clockwise from north (default: the scene's start_yaw_deg, else "
                          "0: north)")
    sim.add_argument("--scene", help="scene name, spec .json or capture scene .json: load its collision geometry "
                                     "(a capture's: the distance field of its splats, cached beside it) and judge "
                                     "the flight through its opening or gate (default: ground only)")
    sim.add_argument("--wind", type=wind_arg, default=None, metavar="MEAN,GUST[,FROM_DEG]",
                     help="steady wind of MEAN m/s from FROM_DEG (clockwise from north; drawn from --seed when "
                          "left out) with gusts of GUST m/s standard deviation (first-order Gauss-Markov, 2 s), "
                          "acting through the airframe's drag; e.g. 3,1")
    sim.add_argument("--duration", type=float, help="stop after this many simulation seconds")
    sim.add_argument("--result", type=Path, help="write the ground-truth verdict JSON here at exit")
    sim.add_argument("--home", type=triple_arg, default=None, metavar="LAT,LON,ALT",
                     help="home position (default PX4 SITL's 47.397742,8.545594,488)")
    sim.add_argument("--param", type=_param, action="append", default=[], metavar="NAME=VALUE",
                     help="set a PX4 parameter at boot (repeatable); known: "
                          + ", ".join(s.name for s in COMMANDER_PARAMS))
    net = p.add_argument_group("MAVLink addresses")
    net.add_argument("--instance", type=int, default=0, help="PX4-style instance number: offsets the ports")
    net.add_argument("--gcs-local", type=_address, help="GCS link local address (default 0.0.0.0:18570+N)")
    net.add_argument("--gcs-remote", type=_address, help="GCS link first remote (default 127.0.0.1:14550)")
    net.add_argument("--api-local", type=_address, help="API link local address (default 0.0.0.0:14580+N)")
    net.add_argument("--api-remote", type=_address, help="API link first remote (default 127.0.0.1:14540+N)")
    net.add_argument("--truth-remote", type=_address, help="ground-truth stream target (default 127.0.0.1:14560+N)")
    net.add_argument("--truth-hz", type=float, default=100.0, help="ground-truth stream rate (default 100)")
    sec = p.add_argument_group("MAVLink 2 signing (as PX4 v1.18)")
    sec.add_argument("--signing-key", type=Path, metavar="FILE",
                     help="PX4 key file (32-byte secret, then an 8-byte little-endian timestamp; mode 0600): every "
                          "link signs what it sends and drops unsigned or badly signed messages but HEARTBEAT, "
                          "RADIO_STATUS, ADSB_VEHICLE and COLLISION; SETUP_SIGNING changes it (signed, disarmed) "
                          "and the timestamp is written back at exit. An all-zero file: signing off until a "
                          "SETUP_SIGNING sets a key, which is then kept in FILE")
    sec.add_argument("--new-signing-key", type=Path, metavar="FILE",
                     help="write a new random key file (mode 0600) for --signing-key and exit")
    p.add_argument("--log-level", default="INFO", choices=["DEBUG", "INFO", "WARNING", "ERROR"])
    return p


def config_from_args(args: argparse.Namespace, scene_start=((0.0, 0.0, 0.0), 0.0)) -> ServerConfig:
    """The server's configuration; ``scene_start`` (position, yaw in degrees) fills --start and --start-yaw."""
    if not args.speed > 0 or not math.isfinite(args.speed):
        raise CliError(f"--speed must be a positive number, got {args.speed}")
    if not 0 <= args.instance < 100:
        raise CliError(f"--instance must be between 0 and 99, got {args.instance}")
    n = args.instance
    vehicle = VehicleConfig(airframe=AIRFRAMES[args.airframe])
    if args.no_noise:
        vehicle = _replace(vehicle, noise=None)
    if args.wind is not None:
        vehicle = _replace(vehicle, wind=args.wind)
    home = Home(*args.home) if args.home else Home()
    return ServerConfig(
        vehicle=vehicle,
        gcs_local=args.gcs_local or ("0.0.0.0", 18570 + n),
        gcs_remote=args.gcs_remote or ("127.0.0.1", 14550),
        api_local=args.api_local or ("0.0.0.0", 14580 + n),
        api_remote=args.api_remote or ("127.0.0.1", 14540 + n),
        truth_remote=args.truth_remote or ("127.0.0.1", 14560 + n),
        truth_hz=args.truth_hz, speed=args.speed, seed=args.seed,
        start_position=args.start if args.start is not None else tuple(scene_start[0]),
        start_yaw=math.radians(args.start_yaw if args.start_yaw is not None else scene_start[1]), home=home,
        params=tuple(args.param), scene=args.scene, lockstep=args.lockstep, signing_key=args.signing_key,
    )


def _replace(obj, **changes):
    import dataclasses

    return dataclasses.replace(obj, **changes)


def scene_start(scene: str | None) -> tuple[tuple[float, float, float], float]:
    """(start position NED, start heading in degrees) of a scene: a capture's start_ned and start_yaw_deg, a
    procedural scene's origin and start_yaw_deg; the origin facing north without a scene."""
    if scene is None:
        return (0.0, 0.0, 0.0), 0.0
    try:
        from scenes.build import resolve_spec

        spec = resolve_spec(scene)
    except ImportError as exc:
        raise CliError(f"--scene needs the scenes package, not available here ({exc})") from None
    except (FileNotFoundError, KeyError, ValueError) as exc:
        raise CliError(_scene_error(scene, exc)) from None
    return tuple(spec.start_ned), float(spec.start_yaw_deg)


def _scene_error(scene: str, exc: Exception) -> str:
    """One line; a capture file's own messages already begin with its path."""
    text = str(exc)
    return text if text.startswith(str(Path(scene))) else f"cannot load scene {scene!r}: {text}"


def load_world(scene: str | None):
    if scene is None:
        return None
    try:
        from scenes.collision import load_collision
    except ImportError as exc:
        raise CliError(f"--scene needs the scenes package's collision geometry, not available here ({exc})") from None
    try:
        return load_collision(scene)
    except (FileNotFoundError, KeyError, ValueError) as exc:
        raise CliError(_scene_error(scene, exc)) from None


def _write_new_key(path: Path) -> int:
    import time

    from sitl_vehicle.signing import new_key, write_key_file

    if path.exists():
        print(f"flowgap-vehicle: error: {path} exists: it may hold a key in use; remove it first", file=sys.stderr)
        return 2
    try:
        write_key_file(path, new_key(time.time()))
    except OSError as exc:
        print(f"flowgap-vehicle: error: cannot write {path}: {exc.strerror}", file=sys.stderr)
        return 2
    print(f"new signing key written to {path} (mode 0600): pass it with --signing-key to the vehicle and the "
          f"companion (flowgap-sitl --signing-key {path})")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=args.log_level, format="%(asctime)s vehicle %(levelname)s %(message)s")
    if args.new_signing_key is not None:
        return _write_new_key(args.new_signing_key)
    stop = threading.Event()
    try:
        config = config_from_args(args, scene_start(args.scene))
        server = VehicleServer(config, world=load_world(config.scene))
    except (CliError, ParameterError, PortInUseError, SigningKeyError) as exc:
        print(f"flowgap-vehicle: error: {exc}", file=sys.stderr)
        return 2

    def _on_signal(signum, _frame):
        log.info("%s received: stopping", signal.Signals(signum).name)
        stop.set()

    signal.signal(signal.SIGINT, _on_signal)
    signal.signal(signal.SIGTERM, _on_signal)
    log.info("vehicle up: GCS %s:%d, API %s:%d, truth -> %s, %s", *server.address("gcs"),
             *server.address("api"), config.truth_remote,
             "lockstep" if config.lockstep else f"speed x{config.speed:g}")
    try:
        verdict = server.run(duration_s=args.duration, stop=stop)
    finally:
        server.close()
    if args.result:
        server.write_result(args.result)
        log.info("verdict written to %s", args.result)
    log.info("stopped at t=%.2f s: collision=%s crossed_wall=%s", verdict["sim_time_s"], verdict["collision"],
             verdict["crossed_wall"])
    return 0


if __name__ == "__main__":
    sys.exit(main())

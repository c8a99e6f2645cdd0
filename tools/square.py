"""``flowgap-square``: fly the vehicle process through a scripted offboard square (no camera, no companion).

Starts ``flowgap-vehicle`` as its own OS process, connects over MAVLink/UDP with pymavlink as an
offboard client would, arms, takes off, enters Offboard, flies a square at constant altitude streaming
SET_POSITION_TARGET_LOCAL_NED at 20 Hz, lands, and prints the tracking error at each corner (JSON with
--json, a table otherwise).
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import subprocess
import sys
import threading
import time

from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

log = logging.getLogger("flowgap-square")
POSITION_ONLY = 0b1001_1111_1000  # type_mask: position + yaw


def recv_unlocked(conn, lock: threading.Lock, accept, timeout: float):
    """The first message ``accept(msg)`` takes within ``timeout`` s, else None.

    Polls without blocking and holds ``lock`` only around each read, so a setpoint thread sharing the
    connection can send at any time.
    """
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        with lock:
            msg = conn.recv_match(blocking=False)
        if msg is None:
            time.sleep(0.002)
        elif accept(msg):
            return msg
    return None


class ScriptedClient:
    """The smallest honest offboard client: commands with acks, and a 20 Hz setpoint stream thread."""

    def __init__(self, url: str):
        self.conn = mavutil.mavlink_connection(url, source_system=255, source_component=190, dialect="common")
        self.lock = threading.Lock()
        self.target: tuple[float, float, float] | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._stream, daemon=True)

    def connect(self, timeout: float) -> None:
        if self.conn.wait_heartbeat(timeout=timeout) is None:
            raise RuntimeError(f"no heartbeat from the vehicle within {timeout:.0f} s")
        self.conn.target_system, self.conn.target_component = 1, 1
        self._thread.start()

    def _stream(self) -> None:
        while not self._stop.wait(0.05):
            if self.target is not None:
                with self.lock:
                    self.conn.mav.set_position_target_local_ned_send(
                        0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, POSITION_ONLY, *self.target, 0, 0, 0, 0, 0, 0, 0, 0)

    def recv(self, kind: str, timeout: float, condition=lambda m: True):
        def accept(msg) -> bool:
            if msg.get_type() == "STATUSTEXT" and msg.severity <= mavlink.MAV_SEVERITY_WARNING:
                log.warning("vehicle says: %s", msg.text)
            return msg.get_type() == kind and condition(msg)

        return recv_unlocked(self.conn, self.lock, accept, timeout)

    def command(self, command: int, *params: float) -> None:
        p = list(params) + [0.0] * (7 - len(params))
        with self.lock:
            self.conn.mav.command_long_send(1, 1, command, 0, *p)
        ack = self.recv("COMMAND_ACK", 5, lambda m: m.command == command)
        if ack is None or ack.result != mavlink.MAV_RESULT_ACCEPTED:
            text = self.recv("STATUSTEXT", 0.5)
            raise RuntimeError(f"command {command} refused: {ack and ack.result} {text.text if text else ''}")

    def close(self) -> None:
        self._stop.set()
        self.conn.close()


def fly_square(client: ScriptedClient, side: float, altitude: float, settle_s: float) -> list[dict]:
    client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    client.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, 488.0 + altitude)
    if client.recv("LOCAL_POSITION_NED", 30, lambda m: abs(m.z + altitude) < 0.1) is None:
        raise RuntimeError("takeoff did not reach its altitude")
    client.target = (0.0, 0.0, -altitude)
    time.sleep(0.5)
    base, main, sub = mavutil.px4_map["OFFBOARD"]
    client.command(mavlink.MAV_CMD_DO_SET_MODE, base, main, sub)
    corners = [(side, 0.0), (side, side), (0.0, side), (0.0, 0.0)]
    rows = []
    for x, y in corners:
        corner = (x, y, -altitude)
        client.target = corner
        peak, t0 = 0.0, None
        while True:
            msg = client.recv("LOCAL_POSITION_NED", 5)
            if msg is None:
                raise RuntimeError("telemetry stopped")
            t = msg.time_boot_ms / 1000
            t0 = t if t0 is None else t0
            peak = max(peak, math.hypot(msg.vx, msg.vy, msg.vz))
            if t - t0 >= settle_s:
                break
        error = math.dist((msg.x, msg.y, msg.z), corner)
        rows.append({"corner_ned": list(corner), "error_m": round(error, 4), "peak_speed_mps": round(peak, 3),
                     "leg_time_s": round(t - t0, 2)})
        log.info("corner %s: error %.3f m, peak speed %.2f m/s", corner, error, peak)
    client.target = None
    client.command(mavlink.MAV_CMD_NAV_LAND)
    if client.recv("HEARTBEAT", 60, lambda m: not m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED) is None:
        raise RuntimeError("vehicle did not land and disarm")
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="flowgap-square", description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--side", type=float, default=2.0, help="square side in metres (default 2)")
    parser.add_argument("--altitude", type=float, default=1.5, help="flight altitude in metres (default 1.5)")
    parser.add_argument("--speed", type=float, default=2.0, help="simulation speed-up (default 2)")
    parser.add_argument("--settle", type=float, default=4.0, help="seconds of simulation per leg (default 4)")
    parser.add_argument("--instance", type=int, default=0, help="vehicle instance (ports offset, default 0)")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.add_argument("--vehicle-log-level", default="WARNING", help="log level of the vehicle process")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s demo %(levelname)s %(message)s")
    api_port = 14540 + args.instance
    client = ScriptedClient(f"udpin:127.0.0.1:{api_port}")
    vehicle = subprocess.Popen([sys.executable, "-m", "sitl_vehicle", "--instance", str(args.instance),
                                "--speed", str(args.speed), "--log-level", args.vehicle_log_level])
    try:
        client.connect(timeout=30)
        rows = fly_square(client, args.side, args.altitude, args.settle)
    except RuntimeError as exc:
        print(f"flowgap-square: error: {exc}", file=sys.stderr)
        return 1
    finally:
        client.close()
        vehicle.terminate()
        vehicle.wait(timeout=10)
    result = {"side_m": args.side, "altitude_m": args.altitude, "corners": rows,
              "max_error_m": max(r["error_m"] for r in rows)}
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(f"\nOffboard square {args.side:g} m at {args.altitude:g} m (noisy estimator, PX4-style cascade):")
        print(f"{'corner (N, E, D)':>24}  {'error [m]':>9}  {'peak [m/s]':>10}")
        for r in rows:
            print(f"{str(tuple(r['corner_ned'])):>24}  {r['error_m']:9.3f}  {r['peak_speed_mps']:10.2f}")
        print(f"max tracking error after settling: {result['max_error_m']:.3f} m")
    return 0


if __name__ == "__main__":
    sys.exit(main())

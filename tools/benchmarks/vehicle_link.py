"""Real-time factor of the whole vehicle process loop: physics, control, commander, MAVLink streams.

The vehicle runs as fast as it can (speed far above what it reaches) with every default stream going to a
listening UDP socket, so encoding and sending cost what they cost in a flight. Key: vehicle.realtime_factor.
"""

from __future__ import annotations

import dataclasses
import socket
import statistics
import threading

from sitl_vehicle.server import ServerConfig, VehicleServer
from sitl_vehicle.sim import VehicleConfig

SIM_SECONDS = 5.0
RUNS = 5


def _drain(sock: socket.socket, stop: threading.Event) -> None:
    sock.settimeout(0.05)
    while not stop.is_set():
        try:
            sock.recv(65535)
        except (TimeoutError, OSError):
            pass


def measure_once(noise: bool = True) -> float:
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    stop = threading.Event()
    drainer = threading.Thread(target=_drain, args=(sink, stop), daemon=True)
    drainer.start()
    vehicle = VehicleConfig() if noise else dataclasses.replace(VehicleConfig(), noise=None)
    config = ServerConfig(vehicle=vehicle, gcs_local=("127.0.0.1", 0), gcs_remote=sink.getsockname(),
                          api_local=("127.0.0.1", 0), api_remote=sink.getsockname(), truth_remote=sink.getsockname(),
                          speed=1e6)
    server = VehicleServer(config)
    try:
        verdict = server.run(duration_s=SIM_SECONDS)
    finally:
        server.close()
        stop.set()
        drainer.join()
        sink.close()
    return verdict["sim_time_s"] / server.wall_time_s


def run() -> dict:
    factors = [measure_once() for _ in range(RUNS)]
    return {"vehicle.realtime_factor": {"value": round(statistics.median(factors), 2),
                                        "unit": "x real time (noisy estimator, all streams, 500 Hz physics)"}}

"""A vehicle server in a thread, with its API link pointed at a free UDP port for a companion link."""

from __future__ import annotations

import dataclasses
import socket

import pytest

from sitl_vehicle.server import ServerConfig, VehicleServer
from sitl_vehicle.sim import VehicleConfig


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def vehicle_for_link():
    """``vehicle_for_link(**changes) -> (server, api_port, truth_port)``; servers stop after the test."""
    servers = []

    def factory(vehicle: VehicleConfig | None = None, world=None, **changes):
        api_port, truth_port = free_udp_port(), free_udp_port()
        config = ServerConfig(vehicle=vehicle or dataclasses.replace(VehicleConfig(), noise=None),
                              gcs_local=("127.0.0.1", 0), gcs_remote=None, api_local=("127.0.0.1", 0),
                              api_remote=("127.0.0.1", api_port), truth_remote=("127.0.0.1", truth_port),
                              speed=3.0)
        server = VehicleServer(dataclasses.replace(config, **changes), world=world).start()
        servers.append(server)
        return server, api_port, truth_port

    yield factory
    for server in servers:
        server.stop()

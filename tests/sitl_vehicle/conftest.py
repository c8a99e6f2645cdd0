"""Loopback fixture: the vehicle server in a thread on ephemeral ports, with a pymavlink client."""

from __future__ import annotations

import dataclasses

import pytest

from sitl_vehicle.server import ServerConfig, VehicleServer
from sitl_vehicle.sim import VehicleConfig
from support.mavclient import MavClient

SPEED = 4.0  # simulation runs 4x faster than wall time in tests


@pytest.fixture
def make_vehicle():
    """Factory: ``make_vehicle(**server_config_changes) -> (server, client)``; both are closed after the test."""
    made = []

    def factory(vehicle: VehicleConfig | None = None, **changes):
        client = MavClient()
        config = ServerConfig(
            vehicle=vehicle or dataclasses.replace(VehicleConfig(), noise=None),
            gcs_local=("127.0.0.1", 0), gcs_remote=None,
            api_local=("127.0.0.1", 0), api_remote=("127.0.0.1", client.port),
            truth_local=("127.0.0.1", 0), truth_remote=None, speed=SPEED)
        config = dataclasses.replace(config, **changes)
        server = VehicleServer(config).start()
        made.append((server, client))
        client.wait_heartbeat()
        return server, client

    yield factory
    for server, client in made:
        client.close()
        server.stop()



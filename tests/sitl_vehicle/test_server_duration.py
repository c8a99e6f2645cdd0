"""``flowgap-vehicle --duration``: the run ends where its simulated time does, whatever the float sum says."""

from __future__ import annotations

import dataclasses
import threading

import pytest

from sitl_vehicle.server import ServerConfig, VehicleServer
from sitl_vehicle.sim import VehicleConfig


@pytest.mark.parametrize("duration_s", [0.1 + 0.2, 0.3, 0.7])
def test_a_run_ends_at_its_duration_even_an_ulp_past_a_physics_step(duration_s):
    # 0.1 + 0.2 is 0.30000000000000004, an ulp past the 150th 2 ms step (0.3): waiting for time_s to reach it
    # waited for a step that never came
    config = ServerConfig(vehicle=dataclasses.replace(VehicleConfig(), noise=None),
                          gcs_local=("127.0.0.1", 0), gcs_remote=None, api_local=("127.0.0.1", 0), api_remote=None,
                          truth_local=("127.0.0.1", 0), truth_remote=None, speed=20.0)
    server = VehicleServer(config)
    try:
        run = threading.Thread(target=server.run, kwargs={"duration_s": duration_s}, daemon=True)
        run.start()
        run.join(timeout=10)
        assert not run.is_alive(), "the run never ended"
        assert server.sim.time_s == pytest.approx(duration_s, abs=server.sim.dt / 2)
    finally:
        server.stop()

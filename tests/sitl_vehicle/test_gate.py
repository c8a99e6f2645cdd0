"""A capture scene's verdict: success when the vehicle's centre crosses the gate's rectangle (checked between
successive physics steps) and it never touched anything; the verdict gains a ``gate`` field; the vehicle starts
where and facing how the scene says (``--start``, ``--start-yaw`` override it); bad capture files are one line."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from scenes.capture import Gate
from sitl_vehicle.__main__ import build_parser, config_from_args, scene_start
from sitl_vehicle.__main__ import main as vehicle_main
from sitl_vehicle.collision import CollisionMonitor
from sitl_vehicle.server import ServerConfig, VehicleServer
from sitl_vehicle.sim import Setpoint, VehicleConfig, VehicleSim

GATE = Gate((3.0, 0.0, -1.5), (1.0, 0.0, 0.0), (1.0, 0.8), approach_side=(0.0, 0.0, 0.0))


class OpenRoomWithGate:
    """Nothing to hit but a wall far away; a gate in the middle of the room."""

    wall_x = None
    gate = GATE

    def clearance(self, p) -> float:
        return 20.0 - p[0]


def _fly(y: float, world=None) -> VehicleSim:
    sim = VehicleSim(dataclasses.replace(VehicleConfig(), noise=None), world=world or OpenRoomWithGate())
    sim.set_armed(True)
    sim.set_setpoint(Setpoint(position=(0.0, y, -1.5)))
    sim.run(3.0)
    sim.set_setpoint(Setpoint(position=(5.0, y, -1.5)))
    sim.run(4.0)
    return sim


def test_through_the_rectangle_is_a_pass_and_beside_it_only_a_plane_crossing():
    through = _fly(0.3)
    assert through.crossed_wall and through.passed and not through.crashed
    report = through.collision.gate_report()
    assert report["crossed"] and report["crossed_at_ned"][0] == pytest.approx(3.0, abs=1e-6)
    assert report["crossed_at_ned"][1] == pytest.approx(0.3, abs=0.05) and report["crossed_time_s"] > 3.0
    beside = _fly(0.7)                          # half the width is 0.5 m: the plane, not the gate
    assert beside.crossed_wall and not beside.passed and not beside.collision.gate_report()["crossed"]


def test_a_wall_scene_has_no_gate_and_passes_by_the_wall_plane():
    class Wall:
        wall_x = 3.0

        def clearance(self, p) -> float:
            return 50.0

    sim = _fly(0.0, Wall())
    assert sim.passed and sim.collision.gate_report() is None


def test_a_crossing_is_caught_between_two_steps():
    monitor = CollisionMonitor(OpenRoomWithGate(), body_radius_m=0.1)
    monitor.check((2.99, 0.0, -1.5), 0.0)
    monitor.check((3.01, 0.0, -1.5), 0.002)
    assert monitor.gate_crossed and monitor.gate_crossed_at == pytest.approx((3.0, 0.0, -1.5))
    monitor.reset()
    monitor.check((3.5, 0.0, -1.5), 0.0)       # started beyond the gate: coming back is no crossing
    monitor.check((2.5, 0.0, -1.5), 0.1)
    assert not monitor.crossed_wall and not monitor.gate_crossed


def test_the_verdict_carries_the_gate():
    config = ServerConfig(vehicle=dataclasses.replace(VehicleConfig(), noise=None), gcs_local=("127.0.0.1", 0),
                          gcs_remote=None, api_local=("127.0.0.1", 0), api_remote=None, truth_remote=None)
    server = VehicleServer(config, world=OpenRoomWithGate())
    try:
        verdict = server.verdict()
    finally:
        server.close()
    assert verdict["gate"]["size_m"] == [1.0, 0.8] and verdict["gate"]["crossed"] is False
    assert verdict["success"] is False and {"collision", "crossed_wall", "min_clearance_m"} <= set(verdict)


@pytest.fixture(scope="module")
def capture_json(tmp_path_factory):
    from scenes.library import suite_spec
    from scenes.spec import SplatDensity
    from scenes.synthetic_capture import write_reexpressed_capture

    spec = dataclasses.replace(suite_spec("window1", "brick"),
                               density=SplatDensity(wall_spacing=0.04, background_spacing=0.05, floor_spacing=0.06))
    return write_reexpressed_capture(spec, tmp_path_factory.mktemp("cap"), np.random.default_rng(7), yaw_deg=35.0,
                                     floater_count=50, view_dependence=0.0).json


def test_the_vehicle_starts_where_the_capture_says_unless_told(capture_json):
    doc = json.loads(capture_json.read_text())
    parser = build_parser()
    args = parser.parse_args(["--scene", str(capture_json)])
    config = config_from_args(args, scene_start(args.scene))
    assert config.start_position == pytest.approx(doc["start_ned"]) and math.degrees(config.start_yaw) == \
        pytest.approx(35.0)
    args = parser.parse_args(["--scene", str(capture_json), "--start", "1,2,0", "--start-yaw", "-10"])
    config = config_from_args(args, scene_start(args.scene))
    assert config.start_position == (1.0, 2.0, 0.0) and math.degrees(config.start_yaw) == pytest.approx(-10.0)
    assert config_from_args(parser.parse_args(["--yaw", "5"])).start_yaw == pytest.approx(math.radians(5.0))
    assert scene_start("window1_brick") == ((0.0, 0.0, 0.0), 0.0)


def test_a_bad_capture_file_is_one_line(tmp_path, capsys, capture_json):
    doc = json.loads(capture_json.read_text())
    doc["ply"] = str(capture_json.with_suffix(".ply"))
    doc["to_ned"]["rotation_wxyz"] = [1.0, 1.0, 0.0, 0.0]
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    assert vehicle_main(["--scene", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("flowgap-vehicle: error: ") and "not 1" in err and err.count("\n") == 1

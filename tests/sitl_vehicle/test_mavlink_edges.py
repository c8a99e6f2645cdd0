"""The vehicle's MAVLink edges, each checked against the vehicle's state and values computed here: COMMAND_INT,
target-system filtering, PARAM_REQUEST_READ, force-arm and force-disarm, --instance ports, and the contents
of GLOBAL_POSITION_INT, GPS_RAW_INT, BATTERY_STATUS, VFR_HUD and SYSTEM_TIME.

The vehicle runs in-process with its links bound to ephemeral ports and no remotes; what it would send is
captured at the link, so no packet timing is involved.
"""

from __future__ import annotations

import dataclasses
import math
import struct

import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.__main__ import build_parser, config_from_args
from sitl_vehicle.mavlink_io import Home, int_as_param_float, param_float_as_int
from sitl_vehicle.params import ParameterError
from sitl_vehicle.server import ServerConfig, VehicleServer
from sitl_vehicle.sim import VehicleConfig

R_EARTH = 6_378_137.0
FORCE = 21196


class Captured:
    """Stands in for a UdpLink's send: keeps what the vehicle sends on the API link."""

    def __init__(self, link):
        self.sent = []
        link.send = self.sent.append

    def of(self, kind: str) -> list:
        return [m for m in self.sent if m.get_type() == kind]


@pytest.fixture
def vehicle():
    config = ServerConfig(vehicle=dataclasses.replace(VehicleConfig(), noise=None), gcs_local=("127.0.0.1", 0),
                          gcs_remote=None, api_local=("127.0.0.1", 0), api_remote=None,
                          truth_local=("127.0.0.1", 0), truth_remote=None, start_position=(2.0, -1.0, 0.0),
                          home=Home(47.0, 8.0, 400.0))
    server = VehicleServer(config)
    server._next_control = server._next_truth = 0.0
    server.advance(0.2, 1 << 20)
    yield server, Captured(server.link("api"))
    server.close()


def handle(server, msg, system=255, component=190):
    frame = msg.pack(mavlink.MAVLink(None, system, component))
    link = server.link("api")
    for parsed in link._parse_datagram(frame):
        server.interface.receive(parsed, link)


def command_long(command, *params, target=(1, 1)):
    p = list(params) + [0.0] * (7 - len(params))
    return mavlink.MAVLink_command_long_message(*target, command, 0, *p)


def acks(cap, command):
    return [m.result for m in cap.of("COMMAND_ACK") if m.command == command]


def fly(server, seconds):
    server.advance(server.sim.time_s + seconds, 1 << 24)


# ------------------------------------------------------------------------------------------------ commands
def test_command_int_arms_and_takes_off_to_an_amsl_altitude(vehicle):
    server, cap = vehicle
    handle(server, mavlink.MAVLink_command_int_message(1, 1, mavlink.MAV_FRAME_GLOBAL, 400, 0, 0, 1, 0, 0, 0,
                                                       0, 0, 0))
    fly(server, 0.1)
    assert acks(cap, 400) == [mavlink.MAV_RESULT_ACCEPTED] and server.sim.armed
    handle(server, mavlink.MAVLink_command_int_message(1, 1, mavlink.MAV_FRAME_GLOBAL, 22, 0, 0, 0, 0, 0,
                                                       math.nan, 0, 0, 403.0))     # 3 m above home (400 m)
    fly(server, 8.0)
    assert acks(cap, 22) == [mavlink.MAV_RESULT_ACCEPTED]
    assert server.sim.truth.position[2] == pytest.approx(-3.0, abs=0.1)
    assert server.sim.truth.position[:2] == pytest.approx((2.0, -1.0), abs=0.05)   # climbed where it stood


@pytest.mark.parametrize("target", [(2, 1), (1, 5)])
def test_commands_for_another_system_or_component_are_ignored(vehicle, target):
    server, cap = vehicle
    handle(server, command_long(400, 1, target=target))
    fly(server, 0.1)
    assert not server.sim.armed and acks(cap, 400) == []
    handle(server, command_long(400, 1, target=(0, 0)))       # broadcast: taken
    fly(server, 0.1)
    assert server.sim.armed and acks(cap, 400) == [mavlink.MAV_RESULT_ACCEPTED]


def test_setpoints_and_parameter_sets_for_another_system_are_ignored(vehicle):
    server, cap = vehicle
    before = server.params["MIS_TAKEOFF_ALT"]
    handle(server, mavlink.MAVLink_param_set_message(2, 1, b"MIS_TAKEOFF_ALT", 7.0, 9))
    handle(server, mavlink.MAVLink_set_position_target_local_ned_message(0, 2, 1, 1, 0b1001_1111_1000, 1, 1, -1,
                                                                        0, 0, 0, 0, 0, 0, 0, 0))
    assert server.params["MIS_TAKEOFF_ALT"] == before and server.interface.setpoints_received == 0
    handle(server, mavlink.MAVLink_param_set_message(1, 1, b"MIS_TAKEOFF_ALT", 7.0, 9))
    assert server.params["MIS_TAKEOFF_ALT"] == 7.0


def test_force_arm_and_force_disarm_override_the_checks(vehicle):
    server, cap = vehicle
    handle(server, command_long(400, 1))
    fly(server, 0.1)
    handle(server, command_long(22, 0, 0, 0, math.nan, math.nan, math.nan, 402.0))
    fly(server, 3.0)
    assert not server.sim.landed
    handle(server, command_long(400, 0))                            # in the air: refused
    fly(server, 0.1)
    assert server.sim.armed and acks(cap, 400)[-1] == mavlink.MAV_RESULT_DENIED
    handle(server, command_long(400, 0, FORCE))                     # PX4's magic number: motors off
    fly(server, 0.1)
    assert not server.sim.armed and acks(cap, 400)[-1] == mavlink.MAV_RESULT_ACCEPTED
    handle(server, command_long(400, 0, 12345))                     # any other number is no force
    assert acks(cap, 400)[-1] == mavlink.MAV_RESULT_ACCEPTED        # (already disarmed: nothing to do)


def test_force_arm_arms_where_the_checks_refuse(vehicle):
    server, cap = vehicle
    # custom main mode 4 (Auto), sub mode 6 (Land): PX4 refuses to arm in Land
    handle(server, command_long(mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4, 6))
    fly(server, 0.1)
    handle(server, command_long(400, 1))
    fly(server, 0.1)
    assert not server.sim.armed and acks(cap, 400) == [mavlink.MAV_RESULT_TEMPORARILY_REJECTED]
    handle(server, command_long(400, 1, FORCE))
    fly(server, 0.1)
    assert server.sim.armed and acks(cap, 400)[-1] == mavlink.MAV_RESULT_ACCEPTED


# ------------------------------------------------------------------------------------------------ parameters
def test_param_request_read_by_name_and_by_index(vehicle):
    server, cap = vehicle
    names = server.params.names()
    handle(server, mavlink.MAVLink_param_request_read_message(1, 1, b"MPC_LAND_SPEED", -1))
    handle(server, mavlink.MAVLink_param_request_read_message(1, 1, b"", 3))
    handle(server, mavlink.MAVLink_param_request_read_message(1, 1, b"NO_SUCH_PARAM", -1))
    handle(server, mavlink.MAVLink_param_request_read_message(1, 1, b"", len(names)))    # past the end
    handle(server, mavlink.MAVLink_param_request_read_message(2, 1, b"MPC_LAND_SPEED", -1))  # another system
    values = cap.of("PARAM_VALUE")
    assert len(values) == 2
    by_name, by_index = values
    assert by_name.param_id == "MPC_LAND_SPEED" and by_name.param_value == pytest.approx(0.7)
    assert by_name.param_index == names.index("MPC_LAND_SPEED") and by_name.param_count == len(names)
    assert by_index.param_id == names[3] and by_index.param_index == 3
    assert by_index.param_type == mavlink.MAV_PARAM_TYPE_REAL32


@pytest.mark.parametrize("value, kind", [(3, mavlink.MAV_PARAM_TYPE_INT32), (4001, mavlink.MAV_PARAM_TYPE_UINT32),
                                         (-2, mavlink.MAV_PARAM_TYPE_INT8), (200, mavlink.MAV_PARAM_TYPE_UINT8),
                                         (-300, mavlink.MAV_PARAM_TYPE_INT16), (60000, mavlink.MAV_PARAM_TYPE_UINT16)])
def test_an_integer_parameter_travels_as_its_bytes_in_the_float_field(value, kind):
    size = {mavlink.MAV_PARAM_TYPE_INT8: 1, mavlink.MAV_PARAM_TYPE_UINT8: 1, mavlink.MAV_PARAM_TYPE_INT16: 2,
            mavlink.MAV_PARAM_TYPE_UINT16: 2}.get(kind, 4)
    field = struct.unpack("<f", value.to_bytes(size, "little", signed=value < 0).ljust(4, b"\0"))[0]
    assert param_float_as_int(field, kind) == value
    assert param_float_as_int(int_as_param_float(value), mavlink.MAV_PARAM_TYPE_INT32) == value
    assert int_as_param_float(1) == struct.unpack("<f", b"\x01\0\0\0")[0]          # 1.4e-45, not 1.0


def test_integer_parameters_take_whole_numbers_only_and_say_so(vehicle):
    server, cap = vehicle
    with pytest.raises(ParameterError, match="RTL_TYPE: 1.5 is not a whole number; it is an integer parameter"):
        server.params.set("RTL_TYPE", 1.5)
    assert server.params.set("RTL_TYPE", 2.0) == 2.0 and server.params.set("MIS_TAKEOFF_ALT", 1.5) == 1.5
    handle(server, mavlink.MAVLink_param_set_message(1, 1, b"RTL_TYPE", int_as_param_float(7),
                                                     mavlink.MAV_PARAM_TYPE_INT32))   # out of range: kept, echoed
    echo = cap.of("PARAM_VALUE")[-1]
    assert param_float_as_int(echo.param_value, echo.param_type) == 2 and server.params["RTL_TYPE"] == 2.0


# ------------------------------------------------------------------------------------------------ streams
def expected_global(home: Home, ned):
    """Flat earth around home, written out here: degrees of latitude per metre north, of longitude per metre
    east at home's latitude; altitude AMSL up."""
    lat = home.lat_deg + math.degrees(ned[0] / R_EARTH)
    lon = home.lon_deg + math.degrees(ned[1] / (R_EARTH * math.cos(math.radians(home.lat_deg))))
    return lat, lon, home.alt_m - ned[2]


def test_global_position_gps_vfr_hud_battery_and_system_time_report_the_state(vehicle):
    server, cap = vehicle
    handle(server, command_long(400, 1))
    fly(server, 0.1)
    handle(server, command_long(22, 0, 0, 0, math.nan, math.nan, math.nan, 402.0))
    fly(server, 1.0)                                      # climbing: a vertical speed to report
    t = server.telemetry()
    home = server.config.home
    lat, lon, alt = expected_global(home, t.position)
    msg = server.interface.build("GLOBAL_POSITION_INT", t)
    assert msg.lat == pytest.approx(lat * 1e7, abs=1) and msg.lon == pytest.approx(lon * 1e7, abs=1)
    assert msg.alt == pytest.approx(alt * 1000, abs=1) and msg.relative_alt == pytest.approx(-t.position[2] * 1000,
                                                                                             abs=1)
    assert (msg.vx, msg.vy, msg.vz) == pytest.approx(tuple(v * 100 for v in t.velocity), abs=1)
    assert msg.hdg == pytest.approx(math.degrees(t.euler[2]) % 360 * 100, abs=1)
    assert msg.time_boot_ms == int(t.time_s * 1000)
    gps = server.interface.build("GPS_RAW_INT", t)
    assert gps.fix_type == mavlink.GPS_FIX_TYPE_3D_FIX and gps.satellites_visible >= 6
    assert (gps.lat, gps.lon) == (msg.lat, msg.lon) and gps.alt == msg.alt
    assert gps.vel == pytest.approx(math.hypot(*t.velocity[:2]) * 100, abs=1)
    assert gps.time_usec == int(t.time_s * 1e6)
    hud = server.interface.build("VFR_HUD", t)
    assert hud.climb == pytest.approx(-t.velocity[2], abs=1e-4) and hud.climb > 0.2
    assert hud.alt == pytest.approx(alt, abs=1e-3) and hud.groundspeed == pytest.approx(math.hypot(*t.velocity[:2]),
                                                                                        abs=1e-4)
    assert 0 < hud.throttle <= 100 and hud.heading == int(math.degrees(t.euler[2]) % 360)
    battery = server.interface.build("BATTERY_STATUS", t)
    cells = [v for v in battery.voltages if v != 65535]
    assert len(cells) == 4 and all(3000 < v < 4300 for v in cells)           # a 4S LiPo, millivolts per cell
    assert battery.type == mavlink.MAV_BATTERY_TYPE_LIPO and 0 <= battery.battery_remaining <= 100
    assert battery.current_battery > 0                                     # armed: drawing current
    clock = server.interface.build("SYSTEM_TIME", t)
    assert clock.time_boot_ms == int(t.time_s * 1000)
    assert clock.time_unix_usec == pytest.approx((server.interface._boot_wall + t.time_s) * 1e6, abs=2)


# ------------------------------------------------------------------------------------------------ ports
@pytest.mark.parametrize("n", [0, 1, 7, 19])
def test_instance_ports_follow_px4(n):
    config = config_from_args(build_parser().parse_args(["--instance", str(n)]))
    assert config.gcs_local == ("0.0.0.0", 18570 + n) and config.gcs_remote == ("127.0.0.1", 14550)
    assert config.api_local == ("0.0.0.0", 14580 + n) and config.api_remote == ("127.0.0.1", 14540 + n)
    assert config.truth_remote == ("127.0.0.1", 14560 + n)

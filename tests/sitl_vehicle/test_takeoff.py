"""Takeoff as PX4's Navigator does it: never below MIS_TAKEOFF_ALT above home, never down, the yaw ignored,
zero or NaN coordinates meaning "where it is" — at the commander, at the MAVLink edge and over a loopback.

Every expected value follows from that rule and the test's own numbers (home at 488 m AMSL, PX4 SITL's
default; flat-earth metres per degree), never from the code under test.
"""

from __future__ import annotations

import math
import time

import pytest
from pymavlink.dialects.v20 import common as mavlink

from companion.link.base import StatusTextAssembler
from sitl_vehicle.commander import Commander, VehicleStatus
from sitl_vehicle.mavlink_io import Home, MavlinkVehicleInterface
from sitl_vehicle.modes import FlightMode
from sitl_vehicle.params import COMMANDER_PARAMS, ParameterStore
from support.mavclient import px4_mode_name, wait_sim

HOME_AMSL = 488.0  # Home()'s default altitude: the local origin, where the vehicles here arm
METRES_PER_DEG_LAT = 6_378_137.0 * math.pi / 180.0
MINIMUM_TEXT = "Using minimum takeoff altitude: {:.2f} m"
HIGHER_TEXT = "Already higher than takeoff altitude"
# MAVProxy's `takeoff 2.5`: NAV_TAKEOFF with zeros in params 1-6 and 2.5 (read as AMSL by PX4) in param7
MAVPROXY_TAKEOFF = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.5)


def on_ground(x=0.0, y=0.0, t=0.0, yaw=0.0) -> VehicleStatus:
    return VehicleStatus(time_s=t, position=(x, y, 0.0), velocity=(0.0, 0.0, 0.0), yaw=yaw, armed=False,
                         landed=True)


def flying(x, y, z, t, yaw=0.0) -> VehicleStatus:
    return VehicleStatus(time_s=t, position=(x, y, z), velocity=(0.0, 0.0, 0.0), yaw=yaw, armed=True, landed=False)


def armed_commander(minimum: float, where: VehicleStatus | None = None) -> Commander:
    commander = Commander(ParameterStore(COMMANDER_PARAMS))
    commander.params.set("MIS_TAKEOFF_ALT", minimum)
    assert commander.arm(where or on_ground()).accepted
    commander.messages.clear()
    return commander


def takeoff_texts(commander: Commander) -> list[tuple[int, str]]:
    return [(severity, text) for severity, text in commander.messages
            if text.startswith("Using minimum") or text == HIGHER_TEXT]


# ------------------------------------------------------------------------------------------- commander
@pytest.mark.parametrize("minimum", [2.5, 3.7])
def test_altitude_below_the_minimum_is_raised_with_a_critical_text(minimum):
    commander = armed_commander(minimum)
    reply = commander.takeoff(on_ground(t=0.1), 2.5 - HOME_AMSL)  # MAVProxy's 2.5 "AMSL": far below home
    assert reply.accepted
    assert takeoff_texts(commander) == [(mavlink.MAV_SEVERITY_CRITICAL, MINIMUM_TEXT.format(minimum))]
    out = commander.update(on_ground(t=0.2))
    assert out.mode is FlightMode.AUTO_TAKEOFF and out.setpoint.position == (0.0, 0.0, -minimum)
    out = commander.update(flying(0.0, 0.0, -minimum + 0.05, t=5.0))  # there (within NAV_ACC_RAD): Hold
    assert out.armed and out.mode is FlightMode.AUTO_LOITER and out.setpoint.position == (0.0, 0.0, -minimum)


@pytest.mark.parametrize("minimum", [2.5, 3.7])
def test_nan_altitude_flies_the_minimum_and_says_so_as_info(minimum):
    commander = armed_commander(minimum)
    assert commander.takeoff(on_ground(t=0.1), math.nan).accepted
    assert takeoff_texts(commander) == [(mavlink.MAV_SEVERITY_INFO, MINIMUM_TEXT.format(minimum))]
    assert commander.update(on_ground(t=0.2)).setpoint.position == (0.0, 0.0, -minimum)


def test_mode_switch_to_takeoff_flies_the_minimum():
    commander = armed_commander(3.0)
    assert commander.set_mode(FlightMode.AUTO_TAKEOFF, on_ground(t=0.1)).accepted
    assert commander.update(on_ground(t=0.2)).setpoint.position == (0.0, 0.0, -3.0)


def test_altitude_just_short_of_the_minimum_is_raised_silently():
    commander = armed_commander(2.5)
    assert commander.takeoff(on_ground(t=0.1), 2.5 - 0.09).accepted  # within PX4's 10 cm: no complaint
    assert takeoff_texts(commander) == []
    assert commander.update(on_ground(t=0.2)).setpoint.position == (0.0, 0.0, -2.5)


@pytest.mark.parametrize("altitude", [2.5, 4.0, 12.25])
def test_altitude_at_or_above_the_minimum_is_used_as_is(altitude):
    commander = armed_commander(2.5)
    assert commander.takeoff(on_ground(t=0.1), altitude).accepted
    assert takeoff_texts(commander) == []
    assert commander.update(on_ground(t=0.2)).setpoint.position == (0.0, 0.0, -altitude)


def test_altitude_is_measured_from_home_where_the_vehicle_armed():
    commander = armed_commander(2.5, VehicleStatus(0.0, (1.0, 2.0, -0.4), (0.0, 0.0, 0.0), 0.0, False, True))
    assert commander.takeoff(VehicleStatus(0.1, (1.0, 2.0, -0.4), (0.0, 0.0, 0.0), 0.0, True, True), 3.0).accepted
    assert commander.update(flying(1.0, 2.0, -0.4, t=0.2)).setpoint.position == (1.0, 2.0, -0.4 - 3.0)


def test_a_vehicle_already_higher_does_not_go_down():
    commander = armed_commander(2.5)
    commander.update(flying(0.0, 0.0, -6.0, t=5.0))
    assert commander.takeoff(flying(0.0, 0.0, -6.0, t=5.1), 3.0).accepted
    assert takeoff_texts(commander) == [(mavlink.MAV_SEVERITY_CRITICAL, HIGHER_TEXT)]
    out = commander.update(flying(0.0, 0.0, -6.0, t=5.2))  # already there: Takeoff completes where it is
    assert out.mode is FlightMode.AUTO_LOITER and out.setpoint.position == (0.0, 0.0, -6.0)


def test_a_horizontal_target_is_flown_to_before_takeoff_completes():
    commander = armed_commander(2.5)
    assert commander.takeoff(on_ground(t=0.1), 3.0, target_xy=(4.0, -1.0)).accepted
    assert commander.update(on_ground(t=0.2)).setpoint.position == (4.0, -1.0, -3.0)
    out = commander.update(flying(1.0, 0.0, -3.0, t=3.0))  # at the altitude, not yet there
    assert out.mode is FlightMode.AUTO_TAKEOFF
    out = commander.update(flying(4.0, -0.95, -3.0, t=6.0))
    assert out.mode is FlightMode.AUTO_LOITER and out.setpoint.position == (4.0, -1.0, -3.0)


def test_takeoff_still_needs_arming():
    commander = Commander(ParameterStore(COMMANDER_PARAMS))
    assert commander.takeoff(on_ground(), 3.0).result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED


def test_altitude_exactly_the_silent_margin_short_is_raised_silently():
    commander = armed_commander(2.5)
    assert commander.takeoff(on_ground(t=0.1), 2.5 - 0.1).accepted      # PX4 complains only beyond 10 cm
    assert takeoff_texts(commander) == []
    assert commander.update(on_ground(t=0.2)).setpoint.position == (0.0, 0.0, -2.5)


def test_a_vehicle_exactly_at_the_takeoff_altitude_is_not_higher():
    commander = armed_commander(2.5)
    commander.update(flying(0.0, 0.0, -3.0, t=5.0))
    assert commander.takeoff(flying(0.0, 0.0, -3.0, t=5.1), 3.0).accepted
    assert takeoff_texts(commander) == []
    assert commander.messages[-1] == (mavlink.MAV_SEVERITY_INFO, "Takeoff to 3.0 m above home")


@pytest.mark.parametrize("where, done", [
    ((4.0, -0.5, -2.5), True),       # 0.5 m low and 0.5 m off: exactly NAV_ACC_RAD on both
    ((1.0, -1.0, -3.0), False),      # at the altitude, 3 m south of the target
    ((4.0, 2.0, -3.0), False),       # at the altitude, 3 m east of the target
    ((4.0, -1.0, -2.4), False),      # over the target, 0.6 m low
])
def test_takeoff_to_a_point_completes_within_nav_acc_rad_of_it(where, done):
    commander = armed_commander(2.5)
    commander.params.set("NAV_ACC_RAD", 0.5)
    assert commander.takeoff(on_ground(t=0.1), 3.0, target_xy=(4.0, -1.0)).accepted
    out = commander.update(flying(*where, t=4.0))
    assert out.mode is (FlightMode.AUTO_LOITER if done else FlightMode.AUTO_TAKEOFF)


# ------------------------------------------------------------------------------------- MAVLink edge
class Edge:
    """The MAVLink interface over a commander, no sockets: ``takeoff(*params)`` runs NAV_TAKEOFF as it arrived
    in a COMMAND_LONG (COMMAND_INT's degE7 are already scaled by the receiving handler)."""

    def __init__(self, minimum: float = 2.5, x: float = 0.0, y: float = 0.0, yaw: float = 0.0):
        self.commander = armed_commander(minimum, on_ground(x, y, yaw=yaw))
        self.status = VehicleStatus(0.1, (x, y, 0.0), (0.0, 0.0, 0.0), yaw, True, True)
        self.interface = MavlinkVehicleInterface(self.commander, self.commander.params, Home(),
                                                 lambda: self.status, lambda: None)

    def takeoff(self, *params: float):
        reply = self.interface.execute(mavlink.MAV_CMD_NAV_TAKEOFF, params, None)
        return reply, self.commander.update(self.status).setpoint


def test_mavproxy_takeoff_at_the_edge_climbs_to_the_minimum():
    edge = Edge(minimum=2.5, x=1.0, y=2.0)
    reply, setpoint = edge.takeoff(*MAVPROXY_TAKEOFF)
    assert reply.accepted
    assert setpoint.position == (1.0, 2.0, -2.5)  # zero lat/lon: where it is
    assert takeoff_texts(edge.commander) == [(mavlink.MAV_SEVERITY_CRITICAL, MINIMUM_TEXT.format(2.5))]


@pytest.mark.parametrize("amsl, expected_up", [(math.nan, 2.5), (HOME_AMSL + 4.0, 4.0), (HOME_AMSL + 1.0, 2.5),
                                               (math.inf, 2.5)])
def test_edge_reads_param7_as_amsl(amsl, expected_up):
    reply, setpoint = Edge(minimum=2.5).takeoff(0, 0, 0, math.nan, math.nan, math.nan, amsl)
    assert reply.accepted and setpoint.position[2] == pytest.approx(-expected_up, abs=1e-9)


@pytest.mark.parametrize("lat, lon", [(0.0, 0.0), (math.nan, math.nan), (math.nan, 8.5), (47.4, math.nan)])
def test_edge_zero_or_nan_coordinates_mean_the_current_position(lat, lon):
    _, setpoint = Edge(x=-3.0, y=0.5).takeoff(0, 0, 0, math.nan, lat, lon, HOME_AMSL + 3.0)
    assert setpoint.position == (-3.0, 0.5, -3.0)


def test_edge_coordinates_move_the_target():
    home = Home()
    north, east = 6.0, -2.0
    lat = home.lat_deg + north / METRES_PER_DEG_LAT
    lon = home.lon_deg + east / (METRES_PER_DEG_LAT * math.cos(math.radians(home.lat_deg)))
    _, setpoint = Edge().takeoff(0, 0, 0, math.nan, lat, lon, HOME_AMSL + 3.0)
    assert setpoint.position == pytest.approx((north, east, -3.0), abs=1e-3)


@pytest.mark.parametrize("yaw_param", [math.radians(90.0), 1.0, -179.0, math.nan])
def test_edge_ignores_the_yaw_param(yaw_param):
    edge = Edge(yaw=0.4)
    _, setpoint = edge.takeoff(0, 0, 0, yaw_param, 0, 0, HOME_AMSL + 3.0)
    assert setpoint.yaw == 0.4  # PX4 forces the takeoff yaw to NaN on multicopters: the heading is kept


# ------------------------------------------------------------------------------------------- loopback
def command_and_texts(client, send, command: int, timeout: float = 5.0):
    """Send a command with ``send()``; the COMMAND_ACK and every STATUSTEXT (severity, text) seen meanwhile and
    for a little after, so a text queued on the next commander tick is not missed."""
    texts, assembler, ack = [], StatusTextAssembler(), None
    with client.lock:
        send()
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and not (ack and texts and any("Takeoff to" in t for _, t in texts)):
        msg = client.recv(["COMMAND_ACK", "STATUSTEXT"], max(0.0, deadline - time.monotonic()))
        if msg is None:
            break
        if msg.get_type() == "COMMAND_ACK" and msg.command == command:
            ack = msg
        elif msg.get_type() == "STATUSTEXT":
            text = assembler.add(msg.id, msg.chunk_seq, msg.text)
            if text is not None:
                texts.append((msg.severity, text))
    return ack, texts


def climbs_and_holds(client, server, target, timeout: float = 20.0) -> None:
    """The vehicle settles at ``target`` (local NED), Takeoff hands over to Hold, and it stays armed there."""
    settled = client.recv("LOCAL_POSITION_NED", timeout,
                          lambda m: math.dist((m.x, m.y, m.z), target) < 0.1 and math.hypot(m.vx, m.vy, m.vz) < 0.05)
    assert settled is not None, f"the vehicle did not settle at {target}: it is at {server.sim.truth.position}"
    hold = client.recv("HEARTBEAT", 5, lambda m: px4_mode_name(m) == "LOITER")
    assert hold is not None and hold.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    wait_sim(server, 2.0)  # a couple of simulated seconds later: still up there, still armed
    later = client.recv("HEARTBEAT", 3)
    assert later.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED and server.commander.armed
    assert math.dist(server.sim.truth.position, target) < 0.15


def test_mavproxy_takeoff_over_loopback_climbs_to_the_minimum_and_stays_armed(make_vehicle):
    server, client = make_vehicle()
    minimum = server.params["MIS_TAKEOFF_ALT"]
    assert client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == mavlink.MAV_RESULT_ACCEPTED
    home = server.commander.home
    ack, texts = command_and_texts(client, lambda: client.conn.mav.command_long_send(
        1, 1, mavlink.MAV_CMD_NAV_TAKEOFF, 0, *MAVPROXY_TAKEOFF), mavlink.MAV_CMD_NAV_TAKEOFF)
    assert ack is not None and ack.result == mavlink.MAV_RESULT_ACCEPTED
    assert (mavlink.MAV_SEVERITY_CRITICAL, MINIMUM_TEXT.format(minimum)) in texts
    climbs_and_holds(client, server, (home[0], home[1], home[2] - minimum))


def test_command_int_takeoff_with_coordinates_over_loopback(make_vehicle):
    server, client = make_vehicle()
    assert client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == mavlink.MAV_RESULT_ACCEPTED
    home, origin = server.commander.home, server.config.home
    north, east, up = 1.0, -0.5, server.params["MIS_TAKEOFF_ALT"] + 0.5
    lat_e7 = round((origin.lat_deg + north / METRES_PER_DEG_LAT) * 1e7)
    lon_e7 = round((origin.lon_deg + east / (METRES_PER_DEG_LAT * math.cos(math.radians(origin.lat_deg)))) * 1e7)
    ack, texts = command_and_texts(client, lambda: client.conn.mav.command_int_send(
        1, 1, mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, math.nan, lat_e7, lon_e7,
        origin.alt_m - home[2] + up), mavlink.MAV_CMD_NAV_TAKEOFF)
    assert ack is not None and ack.result == mavlink.MAV_RESULT_ACCEPTED
    assert not any(text.startswith("Using minimum") for _, text in texts)
    climbs_and_holds(client, server, (north, east, home[2] - up))

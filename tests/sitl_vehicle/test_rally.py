"""Rally points: plans of type RALLY checked at upload, and a Return that flies to the nearest safe point (home or a
rally point), as PX4's RTL_TYPE 0 does; uploaded, read back and flown over MAVLink."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.commander import Commander, VehicleStatus
from sitl_vehicle.geofence import RALLY, RALLY_POINT, nearest_safe_point, rally_item_from_message
from sitl_vehicle.mavlink_io import Home
from sitl_vehicle.mission import MissionError
from sitl_vehicle.modes import FlightMode
from sitl_vehicle.params import COMMANDER_PARAMS, ParameterStore
from support.mavclient import read_plan, upload_plan

HOME = Home()
REL_INT = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT


def rally_msg(seq, north, east, alt=5.0, command=RALLY_POINT, frame=REL_INT):
    lat, lon, _ = HOME.to_global((north, east, 0.0))
    return mavlink.MAVLink_mission_item_int_message(1, 1, seq, frame, command, 0, 1, 0.0, 0.0, 0.0, 0.0,
                                                    int(round(lat * 1e7)), int(round(lon * 1e7)), alt, RALLY)


def rally(seq, north, east):
    return rally_item_from_message(rally_msg(seq, north, east), HOME.to_local)


def test_a_rally_point_is_placed_locally_and_goes_back_as_it_came():
    point = rally(2, 12.0, -7.0)
    assert point.north == pytest.approx(12.0, abs=0.01) and point.east == pytest.approx(-7.0, abs=0.01)
    back = point.to_message(9, 8)
    assert (back.seq, back.command, back.frame, back.z, back.mission_type) == (2, RALLY_POINT, REL_INT, 5.0, RALLY)


@pytest.mark.parametrize("msg, result, text", [
    (rally_msg(0, 1.0, 1.0, command=mavlink.MAV_CMD_NAV_WAYPOINT), mavlink.MAV_MISSION_UNSUPPORTED,
     "rally point 0: command 16 is no rally point; use NAV_RALLY_POINT (5100)"),
    (rally_msg(0, 1.0, 1.0, frame=mavlink.MAV_FRAME_LOCAL_NED), mavlink.MAV_MISSION_UNSUPPORTED_FRAME,
     "rally point 0: frame 1 is not supported"),
    (rally_msg(0, 20_000.0, 0.0), mavlink.MAV_MISSION_INVALID_PARAM5_X, "is 20 km from home"),
])
def test_a_bad_rally_point_is_refused_with_the_reason(msg, result, text):
    with pytest.raises(MissionError) as info:
        rally_item_from_message(msg, HOME.to_local)
    assert info.value.result == result and text in str(info.value)


def test_the_nearest_safe_point_is_home_or_the_nearest_rally_point():
    points = (rally(0, 30.0, 0.0), rally(1, 8.0, 6.0))
    assert nearest_safe_point((10.0, 5.0, -3.0), (0.0, 0.0, 0.0), points)[1] == 1
    assert nearest_safe_point((2.0, 1.0, -3.0), (0.0, 0.0, 0.0), points) == ((0.0, 0.0), None)
    place, index = nearest_safe_point((28.0, 1.0, -3.0), (0.0, 0.0, 0.0), points)
    assert index == 0 and place == pytest.approx((30.0, 0.0), abs=0.01)
    assert nearest_safe_point((28.0, 1.0, -3.0), (1.0, 2.0, 0.0), ()) == ((1.0, 2.0), None)
    east_of_home = (rally(0, 5.0, 10.0),)                 # decided by the east: home 10 m away, the point 5 m
    assert nearest_safe_point((0.0, 10.0, -3.0), (0.0, 0.0, 0.0), east_of_home)[1] == 0
    assert nearest_safe_point((2.0, 1.0, -3.0), None, points)[1] == 1   # no home (RTL_TYPE 1): the nearest point


def status(t, pos, landed=False, armed=True) -> VehicleStatus:
    return VehicleStatus(time_s=t, position=pos, velocity=(0.0, 0.0, 0.0), yaw=0.0, armed=armed, landed=landed)


def test_a_return_flies_to_the_nearest_rally_point_and_lands_there():
    commander = Commander(ParameterStore(COMMANDER_PARAMS))
    for name, value in (("RTL_RETURN_ALT", 4.0), ("RTL_DESCEND_ALT", 2.0), ("RTL_LAND_DELAY", 0.0)):
        commander.params.set(name, value)
    commander.set_rally_points([rally(0, 40.0, 0.0), rally(1, 18.0, 5.0)])
    assert commander.arm(status(0.0, (0.0, 0.0, 0.0), landed=True, armed=False)).accepted
    assert commander.set_mode(FlightMode.AUTO_RTL, status(1.0, (20.0, 0.0, -3.0))).accepted
    assert commander.messages[-1][1] == "Return: flying to rally point 1 at 4.0 m above home"
    out = commander.update(status(2.0, (20.0, 0.0, -4.0)))                     # climbed: fly there
    assert out.setpoint.position == pytest.approx((18.0, 5.0, -4.0), abs=0.01)
    commander.update(status(3.0, (18.0, 5.0, -4.0)))                           # there: descend
    commander.update(status(4.0, (18.0, 5.0, -2.0)))                           # down: land, no wait
    assert commander.messages[-1][1] == "Return: landing at rally point 1"
    out = commander.update(status(5.0, (18.0, 5.0, -1.0)))
    assert out.setpoint.position[:2] == pytest.approx((18.0, 5.0), abs=0.01)
    commander.set_rally_points([])
    assert commander.set_mode(FlightMode.AUTO_LOITER, status(6.0, (18.0, 5.0, -1.0))).accepted
    assert commander.set_mode(FlightMode.AUTO_RTL, status(7.0, (18.0, 5.0, -1.0))).accepted
    assert commander.messages[-1][1] == "Return: flying home at 4.0 m above home"


def test_rally_points_are_uploaded_read_back_and_a_return_lands_at_one_over_mavlink(make_vehicle):
    from tests.sitl_vehicle.test_loopback import enter_offboard, fly_leg, take_off

    server, client = make_vehicle(params=(("RTL_RETURN_ALT", 2.0), ("RTL_DESCEND_ALT", 1.5),
                                          ("RTL_LAND_DELAY", 0.0)))
    points = [rally_msg(0, 3.0, 2.0), rally_msg(1, 30.0, 0.0)]
    assert upload_plan(client, points, RALLY) == mavlink.MAV_MISSION_ACCEPTED
    assert "Rally points accepted: 2 items" in client.statustext("Rally points accepted", 3)
    count, item = read_plan(client, RALLY, 1)
    assert count == 2 and (item.seq, item.command, item.mission_type) == (1, RALLY_POINT, RALLY)
    take_off(client)
    enter_offboard(client)
    fly_leg(client, (0.0, 0.0, -1.5), (3.0, 0.5, -1.5), settle_s=0.5)
    assert client.command(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH).result == mavlink.MAV_RESULT_ACCEPTED
    client.stop_stream()
    assert "Return: flying to rally point 0" in client.statustext("Return: flying", 3)
    assert client.wait_reading(lambda: not server.sim.armed, 30), "did not land and disarm"
    x, y, z = server.sim.truth.position
    assert math.hypot(x - 3.0, y - 2.0) < 0.15 and z > -0.05 and not server.sim.crashed
    with client.lock:
        client.conn.mav.mission_clear_all_send(1, 1, RALLY)
    assert client.recv("MISSION_ACK", 3, lambda m: m.mission_type == RALLY).type == mavlink.MAV_MISSION_ACCEPTED
    assert server.commander.rally_points == ()

"""Geofence: fence plans (MISSION_ITEM_INT of type FENCE) checked at upload, their zones, GF_ACTION on a breach,
arming outside the fence, and a fence uploaded, read back and breached over MAVLink."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.commander import Commander, VehicleStatus
from sitl_vehicle.geofence import (
    CIRCLE_EXCLUSION,
    CIRCLE_INCLUSION,
    FENCE,
    POLYGON_EXCLUSION,
    POLYGON_INCLUSION,
    RETURN_POINT,
    Geofence,
    Zone,
    fence_item_from_message,
    geofence_from_items,
)
from sitl_vehicle.mavlink_io import Home
from sitl_vehicle.mission import MissionError
from sitl_vehicle.modes import FlightMode
from sitl_vehicle.params import COMMANDER_PARAMS, ParameterStore
from support.mavclient import px4_mode_name, read_plan, upload_plan

HOME = Home()
GLOBAL_INT = mavlink.MAV_FRAME_GLOBAL_INT


def fence_msg(seq, command, north, east, param1, frame=GLOBAL_INT):
    lat, lon, _ = HOME.to_global((north, east, 0.0))
    return mavlink.MAVLink_mission_item_int_message(1, 1, seq, frame, command, 0, 1, param1, 0.0, 0.0, 0.0,
                                                    int(round(lat * 1e7)), int(round(lon * 1e7)), 0.0, FENCE)


def square(command, half: float, first_seq: int = 0, centre=(0.0, 0.0)):
    corners = [(-half, -half), (-half, half), (half, half), (half, -half)]
    return [fence_msg(first_seq + i, command, centre[0] + n, centre[1] + e, 4) for i, (n, e) in enumerate(corners)]


def fence(msgs) -> Geofence:
    return geofence_from_items([fence_item_from_message(m, HOME.to_local) for m in msgs])


# ----------------------------------------------------------------------------------------------- the zones

def test_a_polygon_holds_what_is_inside_it_even_where_it_is_concave():
    ell = Zone(True, vertices=((0.0, 0.0), (0.0, 4.0), (2.0, 4.0), (2.0, 2.0), (4.0, 2.0), (4.0, 0.0)))
    assert ell.contains(1.0, 1.0) and ell.contains(1.0, 3.5) and ell.contains(3.5, 1.0)
    assert not ell.contains(3.0, 3.0) and not ell.contains(-0.5, 1.0) and not ell.contains(1.0, 4.5)
    circle = Zone(False, centre=(1.0, -1.0), radius=2.0)
    assert circle.contains(1.0, 0.9) and not circle.contains(1.0, 1.1)


def test_inside_means_in_an_inclusion_zone_if_there_is_one_and_in_no_exclusion_zone():
    home = (0.0, 0.0, 0.0)
    inclusions = fence(square(POLYGON_INCLUSION, 5.0) + [fence_msg(4, CIRCLE_INCLUSION, 20.0, 0.0, 3.0)])
    assert inclusions.breach((0.0, 0.0, -2.0), home) is None
    assert inclusions.breach((21.0, 1.0, -2.0), home) is None                        # in the other one
    assert inclusions.breach((10.0, 0.0, -2.0), home) == "outside the geofence's inclusion zones"
    hole = fence(square(POLYGON_INCLUSION, 5.0) + square(POLYGON_EXCLUSION, 1.0, first_seq=4, centre=(3.0, 3.0)))
    assert hole.breach((3.0, 3.0, -2.0), home) == "inside a geofence exclusion zone"
    only_out = fence([fence_msg(0, CIRCLE_EXCLUSION, 5.0, 5.0, 2.0)])                 # no inclusion: all the rest
    assert only_out.breach((50.0, -50.0, -2.0), home) is None and only_out.breach((5.0, 6.0, -1.0), home)


def test_the_limits_from_home_count_where_set():
    empty, home = Geofence(), (10.0, 0.0, -1.0)
    assert empty.breach((40.0, 0.0, -30.0), home) is None                             # 0: no limit
    assert "over GF_MAX_HOR_DIST 20 m" in empty.breach((40.0, 0.0, -2.0), home, max_horizontal_m=20.0)
    assert empty.breach((29.0, 0.0, -2.0), home, max_horizontal_m=20.0) is None
    assert "12 m above home, over GF_MAX_VER_DIST 10 m" in empty.breach((10.0, 0.0, -13.0), home, max_vertical_m=10.0)


@pytest.mark.parametrize("msg, text", [
    (fence_msg(0, mavlink.MAV_CMD_NAV_WAYPOINT, 1.0, 1.0, 0.0), "is no fence item"),
    (fence_msg(0, CIRCLE_INCLUSION, 1.0, 1.0, 0.0), "radius (param1) is 0.0"),
    (fence_msg(0, POLYGON_INCLUSION, 1.0, 1.0, 2.0), "vertex count (param1) is 2.0"),
    (fence_msg(0, POLYGON_EXCLUSION, 1.0, 1.0, 3.5), "vertex count (param1) is 3.5"),
    (fence_msg(0, CIRCLE_EXCLUSION, 1.0, 1.0, 2.0, frame=mavlink.MAV_FRAME_LOCAL_NED), "frame 1 is not supported"),
    (fence_msg(0, CIRCLE_INCLUSION, 30_000.0, 0.0, 2.0), "km from home"),
])
def test_a_bad_fence_item_is_refused_with_the_reason(msg, text):
    with pytest.raises(MissionError, match=None) as info:
        fence_item_from_message(msg, HOME.to_local)
    assert text in str(info.value) and str(info.value).startswith("fence item 0: ")


def test_a_polygon_needs_its_vertices_in_a_row_and_the_return_point_is_no_zone():
    cut = square(POLYGON_INCLUSION, 5.0)[:3]
    with pytest.raises(MissionError, match="a polygon of 4 vertices needs 4 consecutive"):
        fence(cut)
    mixed = square(POLYGON_INCLUSION, 5.0)
    mixed[2] = fence_msg(2, POLYGON_EXCLUSION, 5.0, 5.0, 4)
    with pytest.raises(MissionError):
        fence(mixed)
    with_return = fence([fence_msg(0, RETURN_POINT, 1.0, 1.0, 0.0)] + square(POLYGON_INCLUSION, 5.0, first_seq=1))
    assert len(with_return.items) == 5 and len(with_return.zones) == 1 and with_return.zones[0].inclusion
    north, east = with_return.zones[0].vertices[0]
    assert north == pytest.approx(-5.0, abs=0.01) and east == pytest.approx(-5.0, abs=0.01)   # 1e-7 deg
    back = with_return.items[1].to_message(1, 1)
    assert (back.command, back.mission_type, back.param1) == (POLYGON_INCLUSION, FENCE, 4.0)


# ---------------------------------------------------------------------------------------- the commander

def status(t=0.0, pos=(0.0, 0.0, 0.0), landed=True, armed=False) -> VehicleStatus:
    return VehicleStatus(time_s=t, position=pos, velocity=(0.0, 0.0, 0.0), yaw=0.0, armed=armed, landed=landed)


def flying_in_hold(action: int, limit_m: float = 5.0) -> Commander:
    """Armed at home in Hold, airborne, with a circular inclusion zone of ``limit_m`` round home."""
    commander = Commander(ParameterStore(COMMANDER_PARAMS))
    commander.params.set("GF_ACTION", float(action))
    commander.set_geofence(fence([fence_msg(0, CIRCLE_INCLUSION, 0.0, 0.0, limit_m)]))
    assert commander.arm(status()).accepted
    commander.update(status(1.0, pos=(0.0, 0.0, -2.0), landed=False, armed=True))
    assert commander.mode is FlightMode.AUTO_LOITER and not commander.failsafe
    return commander


@pytest.mark.parametrize("action, mode", [(2, FlightMode.AUTO_LOITER), (3, FlightMode.AUTO_RTL),
                                          (5, FlightMode.AUTO_LAND)])
def test_leaving_the_fence_does_what_gf_action_says_once_a_breach(action, mode):
    commander = flying_in_hold(action)
    commander._enter(FlightMode.POSCTL, status(1.0, pos=(0.0, 0.0, -2.0), landed=False, armed=True))
    commander.update(status(2.0, pos=(6.0, 0.0, -2.0), landed=False, armed=True))
    assert commander.mode is mode and commander.failsafe
    assert (mavlink.MAV_SEVERITY_CRITICAL, "Geofence breached: outside the geofence's inclusion zones, switching "
            f"to {mode.label}") in commander.messages
    commander._enter(FlightMode.POSCTL, status(2.1, pos=(6.0, 0.0, -2.0), landed=False, armed=True))
    commander.update(status(2.2, pos=(6.5, 0.0, -2.0), landed=False, armed=True))
    assert commander.mode is FlightMode.POSCTL                       # the pilot's choice stands while still out
    commander.update(status(3.0, pos=(4.0, 0.0, -2.0), landed=False, armed=True))     # back inside
    commander.update(status(4.0, pos=(6.0, 0.0, -2.0), landed=False, armed=True))     # out again: acts again
    assert commander.mode is mode


def test_a_warning_only_warns_and_terminate_stops_the_motors():
    warned = flying_in_hold(1)
    warned.update(status(2.0, pos=(0.0, 7.0, -2.0), landed=False, armed=True))
    assert warned.mode is FlightMode.AUTO_LOITER and not warned.failsafe and warned.armed
    assert warned.messages[-1] == (mavlink.MAV_SEVERITY_CRITICAL, "Geofence breached: outside the geofence's "
                                   "inclusion zones")
    stopped = flying_in_hold(4)
    stopped.update(status(2.0, pos=(0.0, 7.0, -2.0), landed=False, armed=True))
    assert not stopped.armed and "flight terminated, motors stopped" in stopped.messages[-1][1]
    ignored = flying_in_hold(0)
    ignored.update(status(2.0, pos=(0.0, 7.0, -2.0), landed=False, armed=True))
    assert ignored.mode is FlightMode.AUTO_LOITER and ignored.armed and "Geofence" not in ignored.messages[-1][1]


def test_the_limits_from_home_and_a_fence_already_in_its_action_mode():
    commander = Commander(ParameterStore(COMMANDER_PARAMS))
    commander.params.set("GF_MAX_VER_DIST", 10.0)
    assert commander.arm(status(pos=(3.0, 0.0, 0.0))).accepted
    commander.update(status(1.0, pos=(3.0, 0.0, -9.0), landed=False, armed=True))
    assert not commander.failsafe                                    # 9 m above home, which arming set
    commander.update(status(2.0, pos=(3.0, 0.0, -11.0), landed=False, armed=True))
    assert commander.failsafe and commander.mode is FlightMode.AUTO_LOITER
    assert commander.messages[-1][1] == ("Geofence breached: 11 m above home, over GF_MAX_VER_DIST 10 m, "
                                         "continuing Hold")


def test_a_return_climbs_no_higher_than_the_fence_s_ceiling():
    commander = Commander(ParameterStore(COMMANDER_PARAMS))
    commander.params.set("GF_MAX_VER_DIST", 12.0)
    assert commander.arm(status()).accepted
    away = {"pos": (20.0, 0.0, -3.0), "landed": False, "armed": True}
    assert commander.set_mode(FlightMode.AUTO_RTL, status(1.0, **away)).accepted
    assert commander.messages[-1][1] == "Return: flying home at 11.0 m above home"   # not RTL_RETURN_ALT's 60 m
    commander.params.set("GF_MAX_VER_DIST", 0.0)
    assert commander.set_mode(FlightMode.AUTO_LOITER, status(2.0, **away)).accepted
    assert commander.set_mode(FlightMode.AUTO_RTL, status(3.0, **away)).accepted
    assert commander.messages[-1][1] == "Return: flying home at 60.0 m above home"


def test_arming_outside_the_fence_is_refused_unless_gf_action_is_none():
    commander = Commander(ParameterStore(COMMANDER_PARAMS))
    commander.set_geofence(fence([fence_msg(0, CIRCLE_EXCLUSION, 0.0, 0.0, 2.0)]))
    reply = commander.arm(status())
    assert not reply.accepted and reply.text == ("Arming denied: vehicle outside the geofence (inside a geofence "
                                                 "exclusion zone)")
    commander.params.set("GF_ACTION", 0.0)
    assert commander.arm(status()).accepted
    commander.set_geofence(Geofence())                               # cleared
    assert commander.geofence.zones == ()


# ------------------------------------------------------------------------------------------- over MAVLink

def test_a_fence_is_uploaded_read_back_cleared_and_breached_over_mavlink(make_vehicle):
    from tests.sitl_vehicle.test_loopback import take_off

    server, client = make_vehicle()
    assert upload_plan(client, square(POLYGON_INCLUSION, 3.0)[:3], FENCE) == mavlink.MAV_MISSION_INVALID_PARAM1
    assert "Geofence refused: fence item 0: a polygon of 4 vertices" in client.statustext("Geofence refused", 3)
    msgs = square(POLYGON_INCLUSION, 3.0) + [fence_msg(4, CIRCLE_EXCLUSION, 2.0, 2.0, 0.5)]
    assert upload_plan(client, msgs, FENCE) == mavlink.MAV_MISSION_ACCEPTED
    assert len(server.commander.geofence.zones) == 2 and server.commander.mission == ()
    count, item = read_plan(client, FENCE, 4)
    assert count == 5 and (item.seq, item.command, item.param1, item.mission_type) == (4, CIRCLE_EXCLUSION, 0.5, FENCE)
    take_off(client)
    with client.lock:                    # fly out of the fence's north side: Hold where it stops
        client.conn.mav.set_position_target_local_ned_send(0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, 0b1001_1111_1000,
                                                           6.0, 0.0, -1.5, 0, 0, 0, 0, 0, 0, 0.0, 0)
    client.stream((6.0, 0.0, -1.5))
    assert client.set_mode("OFFBOARD").result == mavlink.MAV_RESULT_ACCEPTED
    assert "Geofence breached: outside the geofence's inclusion zones, switching to Hold" in client.statustext(
        "Geofence breached", 15)
    assert client.recv("HEARTBEAT", 3, lambda m: px4_mode_name(m) == "LOITER") is not None
    client.stop_stream()
    assert client.wait_reading(lambda: abs(server.sim.truth.velocity[0]) < 0.1, 10)
    assert 3.0 < server.sim.truth.position[0] < 5.0 and not server.sim.crashed
    with client.lock:
        client.conn.mav.mission_clear_all_send(1, 1, FENCE)
    assert client.recv("MISSION_ACK", 3, lambda m: m.mission_type == FENCE).type == mavlink.MAV_MISSION_ACCEPTED
    assert server.commander.geofence.items == ()
    assert math.isfinite(server.sim.truth.position[0])


# ------------------------------------------------------------------------------- the details, one by one

def test_slanted_edges_and_the_boundary_follow_the_half_open_rule():
    """A diamond (edges at 45°): points a centimetre either side of an edge; on the boundary the even-odd rule
    is half open, as PX4's is: the south-west edges and corners count in, the north-east ones out."""
    diamond = Zone(True, vertices=((0.0, 2.0), (2.0, 4.0), (4.0, 2.0), (2.0, 0.0)))
    assert diamond.contains(1.0, 1.01) and diamond.contains(3.0, 2.99) and diamond.contains(1.0, 2.99)
    assert not diamond.contains(1.0, 0.99) and not diamond.contains(3.0, 3.01) and not diamond.contains(1.0, 3.01)
    assert diamond.contains(3.5, 2.0) and not diamond.contains(4.5, 2.0)
    assert diamond.contains(3.0, 1.5) is True and diamond.contains(5.0, 5.0) is False
    box = Zone(True, vertices=((0.0, 0.0), (0.0, 4.0), (4.0, 4.0), (4.0, 0.0)))
    assert box.contains(0.0, 2.0) and box.contains(2.0, 0.0)                      # on the south and west edges
    assert not box.contains(4.0, 2.0) and not box.contains(2.0, 4.0)              # on the north and east edges
    assert Zone(True, centre=(1.0, 1.0), radius=2.0).contains(3.0, 1.0)           # on the circle itself


def test_the_limits_from_home_measure_from_home_in_every_direction_and_include_the_limit():
    home = (1.0, -3.0, -2.0)
    empty = Geofence()
    assert "GF_MAX_HOR_DIST" in empty.breach((1.0, 8.0, -3.0), home, max_horizontal_m=10.0)        # 11 m east
    assert empty.breach((1.0, 7.0, -3.0), home, max_horizontal_m=10.0) is None                    # 10 m: the limit
    assert empty.breach((1.0, 7.0, -3.0), home, max_horizontal_m=0.5) is not None                 # under a metre
    assert empty.breach((1.0, -3.0, -12.0), home, max_vertical_m=10.0) is None                    # 10 m above
    assert empty.breach((1.0, -3.0, -2.6), home, max_vertical_m=0.5) is not None


def test_every_refusal_carries_its_mission_result_and_the_whole_reason():
    def refusal(msg):
        with pytest.raises(MissionError) as info:
            fence_item_from_message(msg, HOME.to_local)
        return info.value.result, str(info.value)

    result, text = refusal(fence_msg(3, mavlink.MAV_CMD_NAV_WAYPOINT, 1.0, 1.0, 0.0))
    assert result == mavlink.MAV_MISSION_UNSUPPORTED and text == (
        "fence item 3: command 16 is no fence item; use NAV_FENCE_POLYGON_VERTEX_INCLUSION (5001), "
        "NAV_FENCE_POLYGON_VERTEX_EXCLUSION (5002), NAV_FENCE_CIRCLE_INCLUSION (5003), NAV_FENCE_CIRCLE_EXCLUSION "
        "(5004), NAV_FENCE_RETURN_POINT (5000)")
    result, text = refusal(fence_msg(0, CIRCLE_INCLUSION, 1.0, 1.0, 2.0, frame=mavlink.MAV_FRAME_LOCAL_NED))
    assert result == mavlink.MAV_MISSION_UNSUPPORTED_FRAME and text.endswith(
        "use MAV_FRAME_GLOBAL_RELATIVE_ALT_INT (6) or MAV_FRAME_GLOBAL_INT (5)")
    result, text = refusal(fence_msg(0, CIRCLE_INCLUSION, 1.0, 1.0, -1.5))
    assert result == mavlink.MAV_MISSION_INVALID_PARAM1 and "radius (param1) is -1.5;" in text
    assert refusal(fence_msg(0, POLYGON_INCLUSION, 1.0, 1.0, 2.0))[0] == mavlink.MAV_MISSION_INVALID_PARAM1
    result, text = refusal(fence_msg(0, CIRCLE_INCLUSION, 7431.7, 7431.7, 2.0))               # 10.51 km north-east
    assert result == mavlink.MAV_MISSION_INVALID_PARAM5_X and "is 11 km from home; send coordinates near home" in text
    no_place = mavlink.MAVLink_mission_item_int_message(1, 1, 0, GLOBAL_INT, CIRCLE_INCLUSION, 0, 1, 2.0, 0, 0, 0,
                                                        0, 0, 0.0, FENCE)
    assert refusal(no_place) == (mavlink.MAV_MISSION_INVALID_PARAM5_X, "fence item 0: needs a latitude and longitude")
    lat, lon, _ = HOME.to_global((0.0, 0.0, 0.0))
    on_the_equator = mavlink.MAVLink_mission_item_message(1, 1, 0, mavlink.MAV_FRAME_GLOBAL, CIRCLE_INCLUSION, 0,
                                                          1, 2.0, 0, 0, 0, 0.0, lon, 0.0, FENCE)
    assert "km from home" in refusal(on_the_equator)[1]          # latitude 0 alone is a place, only far away
    nan_lat = mavlink.MAVLink_mission_item_message(1, 1, 0, mavlink.MAV_FRAME_GLOBAL, CIRCLE_INCLUSION, 0, 1, 2.0,
                                                   0, 0, 0, math.nan, lon, 0.0, FENCE)
    assert "needs a latitude and longitude" in refusal(nan_lat)[1]


def test_a_triangle_a_degree_form_item_and_unused_parameters_are_accepted():
    triangle = [fence_msg(i, POLYGON_EXCLUSION, n, e, 3) for i, (n, e) in enumerate([(0, 0), (4, 0), (0, 4)])]
    assert len(fence(triangle).zones) == 1
    lat, lon, _ = HOME.to_global((3.0, -2.0, 0.0))
    degrees = mavlink.MAVLink_mission_item_message(1, 1, 0, mavlink.MAV_FRAME_GLOBAL, CIRCLE_INCLUSION, 0, 1, 2.0,
                                                   math.nan, math.nan, math.nan, lat, lon, 0.0, FENCE)
    item = fence_item_from_message(degrees, HOME.to_local)
    assert item.north == pytest.approx(3.0, abs=1e-3) and item.east == pytest.approx(-2.0, abs=1e-3)
    square_nan = square(POLYGON_INCLUSION, 1.0)
    square_nan[0].param2 = math.nan                                  # the inclusion group, unused here
    assert len(fence(square_nan).zones) == 1


def test_consecutive_circles_a_trailing_return_point_and_the_item_limit():
    circles = [fence_msg(i, CIRCLE_EXCLUSION, 10.0 * i, 0.0, 1.0) for i in range(3)]
    assert len(fence(circles).zones) == 3
    tail = fence(square(POLYGON_INCLUSION, 5.0) + [fence_msg(4, RETURN_POINT, 1.0, 1.0, 0.0)])
    assert len(tail.zones) == 1 and len(tail.items) == 5
    many = [fence_item_from_message(fence_msg(0, CIRCLE_EXCLUSION, 5.0, 5.0, 1.0), HOME.to_local)] * 500
    assert len(geofence_from_items(many).zones) == 500
    with pytest.raises(MissionError) as info:
        geofence_from_items(many + many[:1])
    assert info.value.result == mavlink.MAV_MISSION_NO_SPACE and str(info.value) == "a fence of 501 items: at most 500"


def test_a_fence_item_goes_back_as_it_came_in_either_form():
    msg = fence_msg(7, CIRCLE_EXCLUSION, 3.0, -4.0, 2.5)
    msg.z = 12.0
    item = fence_item_from_message(msg, HOME.to_local)
    back = item.to_message(9, 8)
    assert back.get_type() == "MISSION_ITEM_INT"
    assert (back.target_system, back.target_component, back.seq, back.frame, back.command, back.current,
            back.autocontinue, back.param1, back.x, back.y, back.z, back.mission_type) == (
        9, 8, 7, GLOBAL_INT, CIRCLE_EXCLUSION, 0, 1, 2.5, msg.x, msg.y, 12.0, FENCE)
    old = item.to_message(9, 8, int_form=False)
    assert old.get_type() == "MISSION_ITEM"
    assert (old.target_system, old.target_component, old.seq, old.frame, old.command, old.current, old.autocontinue,
            old.param1, old.z, old.mission_type) == (9, 8, 7, mavlink.MAV_FRAME_GLOBAL, CIRCLE_EXCLUSION, 0, 1, 2.5,
                                                     12.0, FENCE)          # the float form names the float frame
    assert old.x == pytest.approx(msg.x * 1e-7) and old.y == pytest.approx(msg.y * 1e-7)


def test_the_failsafe_waits_for_the_air_and_for_arming_and_acts_on_a_new_fence_and_a_first_breach():
    commander = Commander(ParameterStore(COMMANDER_PARAMS))
    outside = fence([fence_msg(0, CIRCLE_INCLUSION, 50.0, 0.0, 1.0)])
    commander.set_geofence(outside)
    commander.update(status(0.5, pos=(0.0, 0.0, -2.0), landed=False))       # disarmed: nothing to do
    assert commander.mode is FlightMode.AUTO_LOITER and not commander.failsafe
    commander.set_geofence(Geofence())
    assert commander.arm(status()).accepted
    commander.set_geofence(outside)
    commander.update(status(1.0, armed=True))                                  # armed on the ground: nothing yet
    assert not commander.failsafe
    commander.update(status(1.5, pos=(0.0, 0.0, -1.0), landed=False, armed=True))    # the first frame in the air
    assert commander.failsafe and "Geofence breached" in commander.messages[-1][1]
    fresh = Commander(ParameterStore(COMMANDER_PARAMS))
    fresh.params.set("GF_MAX_HOR_DIST", 5.0)
    assert fresh.arm(status()).accepted
    fresh.update(status(1.0, pos=(6.0, 0.0, -1.0), landed=False, armed=True))       # out on the first update
    assert fresh.failsafe


def test_a_fence_uploaded_in_flight_acts_at_once_on_a_vehicle_outside_it():
    commander = flying_in_hold(2, limit_m=50.0)
    out = {"pos": (20.0, 0.0, -2.0), "landed": False, "armed": True}
    commander.update(status(1.1, **out))
    assert not commander.failsafe
    commander._enter(FlightMode.POSCTL, status(1.2, **out))
    commander.set_geofence(fence([fence_msg(0, CIRCLE_INCLUSION, 0.0, 0.0, 10.0)]))
    commander.update(status(1.3, **out))
    assert commander.failsafe and commander.mode is FlightMode.AUTO_LOITER


def test_still_outside_the_pilot_s_mode_stands_and_the_sticks_may_take_over_the_hold():
    from sitl_vehicle.manual import Sticks

    commander = flying_in_hold(2)
    commander.manual_control(Sticks(), 1.0)
    out = {"pos": (6.0, 0.0, -2.0), "landed": False, "armed": True}
    commander.update(status(1.1, **out))
    assert commander.mode is FlightMode.AUTO_LOITER and commander.failsafe
    commander.manual_control(Sticks(pitch=0.8), 1.2)                           # a push on the sticks
    commander.update(status(1.2, **out))
    assert commander.mode is FlightMode.POSCTL
    for t in (1.3, 1.4, 1.5):
        commander.manual_control(Sticks(pitch=0.8), t)
        commander.update(status(t, **out))
    assert commander.mode is FlightMode.POSCTL                                 # no new action while still out


def test_a_return_breach_while_landing_lands_on():
    commander = flying_in_hold(3)
    flying = {"landed": False, "armed": True}
    assert commander.set_mode(FlightMode.AUTO_LAND, status(1.5, pos=(0.0, 0.0, -2.0), **flying)).accepted
    commander.update(status(2.0, pos=(6.0, 0.0, -2.0), **flying))
    assert commander.mode is FlightMode.AUTO_LAND
    assert commander.messages[-1] == (mavlink.MAV_SEVERITY_CRITICAL, "Geofence breached: outside the geofence's "
                                      "inclusion zones, continuing Land")


def test_arming_measures_the_limits_from_where_it_arms():
    commander = Commander(ParameterStore(COMMANDER_PARAMS))
    commander.params.set("GF_MAX_HOR_DIST", 20.0)
    assert commander.arm(status(pos=(50.0, 0.0, 0.0))).accepted              # home moves here


def test_a_return_under_a_low_ceiling_does_not_climb():
    commander = Commander(ParameterStore(COMMANDER_PARAMS))
    commander.params.set("GF_MAX_VER_DIST", 0.5)
    assert commander.arm(status()).accepted
    assert commander.set_mode(FlightMode.AUTO_RTL, status(1.0, pos=(5.0, 0.0, -0.3), landed=False,
                                                          armed=True)).accepted
    assert commander.messages[-1][1] == "Return: flying home at 0.3 m above home"

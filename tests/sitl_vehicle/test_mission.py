"""Mission mode: items checked at upload, the MAVLink mission protocol (upload, download, clear, set current),
and missions flown from the ground to a landing, as PX4 flies them."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.commander import Commander, Reply, VehicleStatus
from sitl_vehicle.mavlink_io import Home
from sitl_vehicle.mission import NAV_LAND, NAV_TAKEOFF, NAV_WAYPOINT, MissionError, mission_item_from_message
from sitl_vehicle.modes import FlightMode
from sitl_vehicle.params import COMMANDER_PARAMS, ParameterStore
from support.mavclient import px4_mode_name, wait_until

HOME = Home()
REL = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT


def item_msg(seq, command, north=0.0, east=0.0, alt=2.0, frame=REL, params=(0.0, 0.0, 0.0, math.nan), here=False):
    lat, lon, _ = HOME.to_global((north, east, 0.0))
    x, y = (0, 0) if here else (int(round(lat * 1e7)), int(round(lon * 1e7)))
    return mavlink.MAVLink_mission_item_int_message(1, 1, seq, frame, command, 0, 1, *params, x, y, alt,
                                                    mavlink.MAV_MISSION_TYPE_MISSION)


def item(seq, command, **kw):
    return mission_item_from_message(item_msg(seq, command, **kw), HOME.to_local)


def test_home_round_trips_between_local_and_global():
    for ned in ((0.0, 0.0, 0.0), (120.0, -35.5, -12.0), (-800.0, 400.0, 3.0)):
        back = HOME.to_local(*HOME.to_global(ned))
        assert all(abs(a - b) < 1e-6 for a, b in zip(back, ned, strict=True))


def test_items_convert_to_the_local_frame_and_bad_ones_name_the_fix():
    wp = item(0, NAV_WAYPOINT, north=10.0, east=-5.0, alt=3.0, params=(2.0, 0.5, 0.0, 90.0))
    assert wp.north == pytest.approx(10.0, abs=0.01) and wp.east == pytest.approx(-5.0, abs=0.01)
    assert wp.down(home_down=-1.0) == pytest.approx(-4.0)      # relative: 3 m above a home 1 m up
    assert wp.hold_s == 2.0 and wp.acceptance_radius == 0.5 and wp.yaw == pytest.approx(math.pi / 2)
    amsl = item(1, NAV_WAYPOINT, alt=HOME.alt_m + 6.0, frame=mavlink.MAV_FRAME_GLOBAL_INT)
    assert amsl.down(home_down=-1.0) == pytest.approx(-6.0)    # above sea level: home does not matter
    takeoff = item(2, NAV_TAKEOFF, here=True)
    assert math.isnan(takeoff.north)                           # no coordinates: where the vehicle is
    nan_params = item(3, NAV_WAYPOINT, params=(math.nan,) * 4)  # MAVSDK sends NaN for "default"
    assert nan_params.hold_s == 0.0 and nan_params.acceptance_radius == 0.0 and math.isnan(nan_params.yaw)
    for msg, result, needle in (
            (item_msg(0, mavlink.MAV_CMD_CONDITION_DELAY), mavlink.MAV_MISSION_UNSUPPORTED, "command 112"),
            (item_msg(0, mavlink.MAV_CMD_DO_CHANGE_SPEED), mavlink.MAV_MISSION_INVALID_PARAM2,
             r"DO_CHANGE_SPEED's speed \(param2\) is 0.0; send m/s above 0, -1 \(no change\) or -2 \(the default\)"),
            (item_msg(0, NAV_WAYPOINT, frame=mavlink.MAV_FRAME_LOCAL_NED), mavlink.MAV_MISSION_UNSUPPORTED_FRAME,
             "frame 1"),
            (item_msg(0, NAV_WAYPOINT, here=True), mavlink.MAV_MISSION_INVALID_PARAM5_X, "needs a latitude"),
            (item_msg(0, NAV_WAYPOINT, north=50_000.0), mavlink.MAV_MISSION_INVALID_PARAM5_X, "50 km from home"),
            (item_msg(0, NAV_WAYPOINT, alt=math.nan), mavlink.MAV_MISSION_INVALID_PARAM7, "altitude is nan")):
        with pytest.raises(MissionError, match=needle) as err:
            mission_item_from_message(msg, HOME.to_local)
        assert err.value.result == result


def status(t, pos=(0.0, 0.0, 0.0), landed=True, armed=False):
    return VehicleStatus(time_s=t, position=pos, velocity=(0.0, 0.0, 0.0), yaw=0.0, armed=armed, landed=landed)


def test_commander_flies_takeoff_waypoint_hold_and_land_in_order():
    c = Commander(ParameterStore(COMMANDER_PARAMS))
    assert not c.set_mode(FlightMode.AUTO_MISSION, status(0)).accepted  # nothing uploaded yet
    c.set_mission([item(0, NAV_TAKEOFF, alt=2.0, here=True),
                   item(1, NAV_WAYPOINT, north=4.0, alt=2.0, params=(1.0, 0.0, 0.0, math.nan)),
                   item(2, NAV_LAND, north=4.0, east=2.0)], status(0))
    assert c.set_mode(FlightMode.AUTO_MISSION, status(0)).accepted and c.arm(status(0)).accepted
    sp = c.update(status(0.1, armed=True)).setpoint
    assert sp.position == pytest.approx((0.0, 0.0, -2.0))                       # climb where it stands
    sp = c.update(status(1.0, pos=(0.0, 0.0, -2.0), landed=False, armed=True)).setpoint
    assert list(c.mission_reached) == [0] and c.mission_seq == 1
    assert sp.position == pytest.approx((4.0, 0.0, -2.0), abs=0.01)
    c.update(status(2.0, pos=(4.0, 0.0, -2.0), landed=False, armed=True))
    assert list(c.mission_reached) == [0, 1] and c.mission_seq == 1             # reached, holding 1 s
    c.update(status(2.5, pos=(4.0, 0.0, -2.0), landed=False, armed=True))
    assert c.mission_seq == 1
    sp = c.update(status(3.1, pos=(4.0, 0.0, -2.0), landed=False, armed=True)).setpoint
    assert c.mission_seq == 2 and sp.position == pytest.approx((4.0, 2.0, -2.0), abs=0.01)  # to the land spot
    sp = c.update(status(4.0, pos=(4.0, 2.0, -2.0), landed=False, armed=True)).setpoint
    assert c.landing and sp.velocity[2] > 0 and sp.position[:2] == pytest.approx((4.0, 2.0), abs=0.01)
    c.update(status(6.0, pos=(4.0, 2.0, 0.0), landed=True, armed=True))
    assert c.mission_finished and list(c.mission_reached) == [0, 1, 2]
    assert not c.update(status(8.5, pos=(4.0, 2.0, 0.0), landed=True, armed=True)).armed  # COM_DISARM_LAND


def test_waypoint_mission_from_the_ground_climbs_first_and_holds_after_the_last_item():
    c = Commander(ParameterStore(COMMANDER_PARAMS))
    c.set_mission([item(0, NAV_WAYPOINT, north=3.0, alt=1.5)], status(0))
    assert c.start_mission(status(0)).accepted and c.arm(status(0)).accepted
    assert c.update(status(0.1, armed=True)).setpoint.position == pytest.approx((0.0, 0.0, -1.5))
    sp = c.update(status(1.0, pos=(0.0, 0.0, -1.5), landed=False, armed=True)).setpoint
    assert sp.position == pytest.approx((3.0, 0.0, -1.5), abs=0.01) and not c.mission_reached
    sp = c.update(status(2.0, pos=(3.0, 0.0, -1.5), landed=False, armed=True)).setpoint
    assert c.mission_finished and c.mode is FlightMode.AUTO_MISSION
    assert sp.position == pytest.approx((3.0, 0.0, -1.5), abs=0.01)            # loiters at the last item
    assert not c.set_mission_current(5, status(2.1)).accepted


def upload(client, msgs):
    client.conn.mav.mission_count_send(1, 1, len(msgs), mavlink.MAV_MISSION_TYPE_MISSION)
    while True:
        msg = client.recv(["MISSION_REQUEST_INT", "MISSION_ACK"], 3)
        assert msg is not None, "the vehicle stopped answering the upload"
        if msg.get_type() == "MISSION_ACK":
            return msg.type
        with client.lock:
            client.conn.mav.send(msgs[msg.seq])


def test_mission_upload_download_fly_and_land_over_mavlink(make_vehicle):
    server, client = make_vehicle()
    mission = [item_msg(0, NAV_TAKEOFF, alt=1.5, here=True), item_msg(1, NAV_WAYPOINT, north=2.0, alt=1.5),
               item_msg(2, NAV_WAYPOINT, north=2.0, east=1.5, alt=2.0), item_msg(3, NAV_LAND, here=True)]
    assert upload(client, mission) == mavlink.MAV_MISSION_ACCEPTED
    with client.lock:
        client.conn.mav.mission_request_list_send(1, 1, mavlink.MAV_MISSION_TYPE_MISSION)
    assert client.recv("MISSION_COUNT", 3).count == 4
    with client.lock:
        client.conn.mav.mission_request_int_send(1, 1, 2, mavlink.MAV_MISSION_TYPE_MISSION)
    down = client.recv("MISSION_ITEM_INT", 3)
    assert (down.seq, down.command, down.x, down.y, down.z) == (2, NAV_WAYPOINT, mission[2].x, mission[2].y, 2.0)
    with client.lock:       # the older float request gets the float item: degrees, and the non-_INT frame name
        client.conn.mav.mission_request_send(1, 1, 2, mavlink.MAV_MISSION_TYPE_MISSION)
    legacy = client.recv("MISSION_ITEM", 3)
    assert (legacy.seq, legacy.command, legacy.frame) == (2, NAV_WAYPOINT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT)
    degrees = (mission[2].x * 1e-7, mission[2].y * 1e-7, 2.0)
    assert (legacy.x, legacy.y, legacy.z) == pytest.approx(degrees, abs=1e-5)          # float32 degrees
    assert client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == mavlink.MAV_RESULT_ACCEPTED
    assert client.command(mavlink.MAV_CMD_MISSION_START, 0, 3).result == mavlink.MAV_RESULT_ACCEPTED
    assert client.recv("HEARTBEAT", 3, lambda m: px4_mode_name(m) == "MISSION") is not None
    reached = []
    while len(reached) < 3:
        msg = client.recv("MISSION_ITEM_REACHED", 20)
        assert msg is not None, f"mission stalled after items {reached}"
        reached.append(msg.seq)
        if msg.seq == 2:
            x, y, z = server.sim.truth.position
            assert math.dist((x, y, z), (2.0, 1.5, -2.0)) < 0.15
    assert reached == [0, 1, 2]
    assert client.recv("MISSION_ITEM_REACHED", 20, lambda m: m.seq == 3) is not None, "did not land"
    assert wait_until(lambda: not server.sim.armed, 20), "did not disarm after landing"
    x, y, z = server.sim.truth.position
    assert math.hypot(x - 2.0, y - 1.5) < 0.15 and z > -0.05 and not server.sim.crashed
    current = client.recv("MISSION_CURRENT", 3)
    assert current.seq == 3 and current.total == 4 and current.mission_state == mavlink.MISSION_STATE_COMPLETE


def test_bad_uploads_are_refused_with_the_reason_and_keep_the_old_mission(make_vehicle):
    server, client = make_vehicle()
    assert upload(client, [item_msg(0, NAV_WAYPOINT, north=1.0)]) == mavlink.MAV_MISSION_ACCEPTED
    bad = [item_msg(0, NAV_WAYPOINT, north=1.0), item_msg(1, mavlink.MAV_CMD_CONDITION_DELAY)]
    assert upload(client, bad) == mavlink.MAV_MISSION_UNSUPPORTED
    assert "command 112 is not supported" in client.statustext("Mission refused", 3)
    assert len(server.commander.mission) == 1
    with client.lock:
        client.conn.mav.mission_count_send(1, 1, 1, 7)                 # no such plan type
    assert client.recv("MISSION_ACK", 3).type == mavlink.MAV_MISSION_UNSUPPORTED
    assert "Mission type 7 is not supported" in client.statustext("Mission type", 3)
    with client.lock:  # ground stations read the rally points and the geofence on connecting: empty, not an error
        client.conn.mav.mission_request_list_send(1, 1, mavlink.MAV_MISSION_TYPE_RALLY)
    assert client.recv("MISSION_COUNT", 3).count == 0
    with client.lock:
        client.conn.mav.mission_request_list_send(1, 1, mavlink.MAV_MISSION_TYPE_FENCE)
    assert client.recv("MISSION_COUNT", 3).count == 0
    with client.lock:
        client.conn.mav.mission_clear_all_send(1, 1, mavlink.MAV_MISSION_TYPE_MISSION)
    assert client.recv("MISSION_ACK", 3).type == mavlink.MAV_MISSION_ACCEPTED
    assert server.commander.mission == ()
    assert client.set_mode("MISSION").result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED


def test_a_return_item_hands_over_to_return_mode_and_set_current_skips_ahead():
    from sitl_vehicle.mission import NAV_RETURN_TO_LAUNCH

    c = Commander(ParameterStore(COMMANDER_PARAMS))
    c.set_mission([item(0, NAV_WAYPOINT, north=3.0, alt=1.5), item(1, NAV_WAYPOINT, north=6.0, alt=1.5),
                   item(2, NAV_RETURN_TO_LAUNCH, here=True)], status(0))
    c.arm(status(0), force=True)
    assert c.set_mission_current(1, status(0.1)).accepted
    air = status(0.2, pos=(0.0, 0.0, -1.5), landed=False, armed=True)
    assert c.set_mode(FlightMode.AUTO_MISSION, air).accepted
    assert c.update(air).setpoint.position == pytest.approx((6.0, 0.0, -1.5), abs=0.01)  # item 1, not 0
    out = c.update(status(1.0, pos=(6.0, 0.0, -1.5), landed=False, armed=True))
    assert list(c.mission_reached) == [1, 2] and out.mode is FlightMode.AUTO_RTL


# ------------------------------------------------------------------- the commander's mission semantics
def local_item(seq, command, north=math.nan, east=math.nan, alt=2.0, hold_s=0.0, yaw_deg=math.nan):
    """An item at exact local coordinates (north/east NaN: where the vehicle is), ``alt`` above home."""
    from sitl_vehicle.mission import MissionItem

    return MissionItem(seq, command, REL, (hold_s, 0.0, 0.0, yaw_deg), math.nan, math.nan, alt, north, east,
                       True, math.nan)


def air(t, x=0.0, y=0.0, z=-2.0, vel=(0.0, 0.0, 0.0)):
    return VehicleStatus(time_s=t, position=(x, y, z), velocity=vel, yaw=0.0, armed=True, landed=False)


def flying_mission(items, at=None):
    """Armed on the ground, then Mission mode entered in the air at ``at`` (default 2 m over the origin)."""
    c = Commander(ParameterStore(COMMANDER_PARAMS))
    c.set_mission(items, status(0))
    assert c.arm(status(0)).accepted
    assert c.set_mode(FlightMode.AUTO_MISSION, at or air(0.5)).accepted
    return c


def test_an_upload_is_not_finished_and_outside_mission_mode_changes_nothing():
    c = Commander(ParameterStore(COMMANDER_PARAMS))
    c.arm(status(0))
    c.set_mode(FlightMode.AUTO_LOITER, air(1.0))
    c.messages.clear()
    c.set_mission([local_item(0, NAV_WAYPOINT, 3.0, 0.0)], air(1.5))
    assert c.mission_finished is False and not c.messages
    out = c.update(air(1.6, x=0.5))
    assert out.mode is FlightMode.AUTO_LOITER and out.setpoint.position == (0.0, 0.0, -2.0)


def test_a_new_mission_while_flying_one_holds_where_the_vehicle_stops():
    c = flying_mission([local_item(0, NAV_WAYPOINT, 10.0, 0.0)])
    moving = air(1.0, x=1.0, vel=(2.0, 0.0, 0.0))
    c.set_mission([local_item(0, NAV_WAYPOINT, -5.0, 0.0)], moving)
    assert c.messages[-1] == (mavlink.MAV_SEVERITY_WARNING, "Mission changed in flight: switching to Hold")
    out = c.update(moving)
    assert out.mode is FlightMode.AUTO_LOITER
    assert out.setpoint.position == pytest.approx((1.0 + 2.0 ** 2 / (2 * 2.0), 0.0, -2.0))    # v²/2a ahead
    assert c.mission_seq == 0 and c.mission_finished is False


def test_set_current_accepts_every_item_and_refuses_the_others_with_the_reason():
    c = Commander(ParameterStore(COMMANDER_PARAMS))
    c.set_mission([local_item(i, NAV_WAYPOINT, float(i), 0.0) for i in range(3)], status(0))
    for seq in (2, 0):
        assert c.set_mission_current(seq, status(0)).accepted and c.mission_seq == seq
    for seq in (3, -1):
        text = f"Mission item {seq} does not exist (the mission has 3 items)"
        assert c.set_mission_current(seq, status(0)) == Reply(mavlink.MAV_RESULT_DENIED, text, announced=True)
        assert c.messages[-1] == (mavlink.MAV_SEVERITY_CRITICAL, text) and c.mission_seq == 0


def test_set_current_jumps_at_once_in_mission_mode_and_leaves_other_modes_alone():
    c = Commander(ParameterStore(COMMANDER_PARAMS))
    c.set_mission([local_item(0, NAV_WAYPOINT, 3.0, 0.0), local_item(1, NAV_WAYPOINT, 6.0, 0.0, yaw_deg=90.0)],
                  status(0))
    c.arm(status(0))
    c.set_mode(FlightMode.AUTO_LOITER, air(1.0))
    assert c.set_mission_current(1, air(1.0)).accepted
    sp = c.update(air(1.1)).setpoint
    assert sp.position == (0.0, 0.0, -2.0) and sp.yaw == 0.0                # Hold is not disturbed
    assert c.set_mode(FlightMode.AUTO_MISSION, air(1.2)).accepted           # continues from item 1
    sp = c.update(air(1.3)).setpoint
    assert sp.position == (6.0, 0.0, -2.0) and sp.yaw == pytest.approx(math.pi / 2)   # param4: 90 deg
    assert c.set_mission_current(0, air(1.4)).accepted
    sp = c.update(air(1.5)).setpoint
    assert sp.position == (3.0, 0.0, -2.0) and sp.yaw == pytest.approx(math.pi / 2)   # no param4: heading kept


def test_mission_start_from_an_item_and_out_of_range():
    c = Commander(ParameterStore(COMMANDER_PARAMS))
    c.set_mission([local_item(0, NAV_WAYPOINT, 3.0, 0.0), local_item(1, NAV_WAYPOINT, 6.0, 0.0)], status(0))
    c.arm(status(0))
    reply = c.start_mission(air(1.0), 2)
    assert reply == Reply(mavlink.MAV_RESULT_DENIED, "Mission start denied: no item 2", announced=True)
    assert c.mode is FlightMode.AUTO_LOITER
    assert c.start_mission(air(1.0), 1).accepted and c.mission_finished is False
    assert c.update(air(1.1)).setpoint.position == (6.0, 0.0, -2.0)


def test_a_finished_mission_entered_again_starts_from_its_first_item():
    c = flying_mission([local_item(0, NAV_WAYPOINT, 3.0, 0.0), local_item(1, NAV_WAYPOINT, 6.0, 0.0)])
    c.update(air(1.0, x=3.0))
    c.update(air(2.0, x=6.0))
    assert c.mission_finished and c.mission_seq == 1
    assert c.messages[-1] == (mavlink.MAV_SEVERITY_INFO, "Mission finished, loitering")
    c.set_mode(FlightMode.AUTO_LOITER, air(3.0, x=6.0))
    assert c.set_mode(FlightMode.AUTO_MISSION, air(3.1, x=6.0)).accepted
    assert c.mission_seq == 0 and c.mission_finished is False
    assert c.update(air(3.2, x=6.0)).setpoint.position == (3.0, 0.0, -2.0)


def test_set_current_on_a_finished_mission_continues_from_that_item():
    c = flying_mission([local_item(0, NAV_WAYPOINT, 3.0, 0.0), local_item(1, NAV_WAYPOINT, 6.0, 0.0)])
    c.update(air(1.0, x=3.0))
    c.update(air(2.0, x=6.0))
    assert c.mission_finished
    assert c.set_mission_current(0, air(2.5, x=6.0)).accepted and c.mission_finished is False
    assert c.update(air(2.6, x=6.0)).setpoint.position == (3.0, 0.0, -2.0)


def test_a_return_item_on_the_ground_ends_the_mission_there():
    from sitl_vehicle.mission import NAV_RETURN_TO_LAUNCH

    c = Commander(ParameterStore(COMMANDER_PARAMS))
    c.set_mission([local_item(0, NAV_RETURN_TO_LAUNCH)], status(0))
    assert c.set_mode(FlightMode.AUTO_MISSION, status(0)).accepted
    assert c.mission_finished and c.landing                                  # at once: nothing to return from
    assert not any(text.startswith("Mission finished") for _, text in c.messages)
    assert c.arm(status(0)).accepted
    out = c.update(status(0.1, armed=True))
    assert c.mission_finished and out.mode is FlightMode.AUTO_MISSION and c.landing
    assert math.isnan(out.setpoint.position[2]) and out.setpoint.velocity[2] > 0        # idles on the ground


def test_a_land_item_without_coordinates_lands_at_once_where_the_last_item_was_reached():
    c = flying_mission([local_item(0, NAV_WAYPOINT, 3.0, 0.0), local_item(1, NAV_LAND)])
    sp = c.update(air(1.0, x=3.0)).setpoint
    assert c.mission_seq == 1 and c.landing
    assert sp.position[:2] == (3.0, 0.0) and math.isnan(sp.position[2]) and sp.velocity[2] == pytest.approx(0.7)
    c.update(status(3.0, pos=(3.0, 0.0, 0.0), landed=True, armed=True))
    assert c.mission_finished and list(c.mission_reached) == [0, 1]
    assert c.messages[-1] == (mavlink.MAV_SEVERITY_INFO, "Mission finished, landed")


def test_a_land_item_lands_on_its_coordinates_once_within_nav_acc_rad():
    c = flying_mission([local_item(0, NAV_LAND, 4.0, 2.0)])
    assert c.update(air(1.0)).setpoint.position == (4.0, 2.0, -2.0)         # fly there first, at this altitude
    sp = c.update(air(5.0, x=4.05, y=2.0)).setpoint                         # 5 cm off: within NAV_ACC_RAD
    assert c.landing and sp.position[:2] == (4.0, 2.0) and math.isnan(sp.position[2])


def test_mission_items_are_reached_within_nav_acc_rad_and_held_for_exactly_param1():
    c = Commander(ParameterStore(COMMANDER_PARAMS))
    c.params.set("NAV_ACC_RAD", 0.5)
    c.set_mission([local_item(0, NAV_TAKEOFF, alt=2.0), local_item(1, NAV_WAYPOINT, 4.0, 0.0, hold_s=1.0)],
                  status(0))
    assert c.set_mode(FlightMode.AUTO_MISSION, status(0)).accepted and c.arm(status(0)).accepted
    assert c.update(status(0.1, armed=True)).setpoint.position == (0.0, 0.0, -2.0)
    sp = c.update(air(1.0, z=-1.5)).setpoint                                  # 0.5 m short: climbed
    assert c.mission_seq == 1 and sp.position == (4.0, 0.0, -2.0)
    c.update(air(2.0, x=3.5))                                                 # 0.5 m short: reached
    assert list(c.mission_reached) == [0, 1] and not c.mission_finished
    c.update(air(2.9, x=4.0))
    assert not c.mission_finished
    c.update(air(3.0, x=4.0))                                                 # held 1 s: done
    assert c.mission_finished


def test_a_mission_left_for_another_mode_does_not_advance_meanwhile():
    c = flying_mission([local_item(0, NAV_WAYPOINT, 3.0, 0.0)])
    c.set_mode(FlightMode.AUTO_LOITER, air(1.0))
    out = c.update(air(2.0, x=3.0))                                           # flown over item 0 in Hold
    assert out.mode is FlightMode.AUTO_LOITER and not c.mission_reached and not c.mission_finished

"""MAV_CMD_DO_REPOSITION, as MAVSDK's goto_location sends it and PX4 flies it: Hold mode, flying to a place (a
part left out keeps the vehicle's own) at a speed, facing a heading, then holding there."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.commander import Commander
from sitl_vehicle.mavlink_io import Home
from sitl_vehicle.modes import FlightMode
from sitl_vehicle.params import COMMANDER_PARAMS, ParameterStore
from tests.sitl_vehicle.test_mission import air, status

NAN = math.nan


def flying() -> Commander:
    c = Commander(ParameterStore(COMMANDER_PARAMS))
    assert c.arm(status(0.0)).accepted
    c.update(air(0.5))
    return c


def test_a_reposition_holds_at_the_place_at_its_speed_and_heading():
    c = flying()
    reply = c.reposition(air(1.0, 1.0, 2.0, -2.0), (5.0, -3.0, -4.0), yaw=0.5, speed=1.5)
    assert reply.accepted and c.mode is FlightMode.AUTO_LOITER
    assert c.messages[-1] == (mavlink.MAV_SEVERITY_INFO, "Reposition: flying to 5.0 m north, -3.0 m east, 4.0 m "
                                                         "above home")
    sp = c.update(air(1.1, 1.0, 2.0, -2.0)).setpoint
    assert (sp.position, sp.yaw, sp.cruise_speed) == ((5.0, -3.0, -4.0), 0.5, 1.5)
    assert c.set_mode(FlightMode.AUTO_LOITER, air(2.0, 3.0, 0.0, -3.0)).accepted       # Hold again: its own stop,
    assert math.isnan(c.update(air(2.1, 3.0, 0.0, -3.0)).setpoint.cruise_speed)         # at the default speed
    for speed, flown in ((0.5, 0.5), (0.0, NAN), (-1.0, NAN)):                          # not above 0: the default
        assert c.reposition(air(3.0), (5.0, -3.0, -4.0), speed=speed).accepted
        assert c.update(air(3.1)).setpoint.cruise_speed == pytest.approx(flown, nan_ok=True)


def test_a_reposition_keeps_what_it_leaves_out_and_the_default_speed_for_none():
    c = flying()
    assert c.reposition(air(1.0, 1.0, 2.0, -2.0), (NAN, NAN, -6.0), speed=-1.0).accepted   # climb where it is
    sp = c.update(air(1.1, 1.0, 2.0, -2.0)).setpoint
    assert sp.position == (1.0, 2.0, -6.0) and sp.yaw == 0.0 and math.isnan(sp.cruise_speed)
    assert c.reposition(air(2.0, 1.0, 2.0, -6.0), (8.0, 8.0, NAN)).accepted              # the altitude it has
    assert c.update(air(2.1, 1.0, 2.0, -6.0)).setpoint.position == (8.0, 8.0, -6.0)


def test_a_reposition_on_the_ground_is_refused_with_the_reason():
    c = Commander(ParameterStore(COMMANDER_PARAMS))
    reply = c.reposition(status(0.0), (5.0, 0.0, -3.0))
    assert reply.result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    assert reply.text == "Reposition denied: not flying (take off first)"
    assert c.arm(status(0.0)).accepted and not c.reposition(status(0.1, armed=True), (5.0, 0.0, -3.0)).accepted


def test_a_reposition_ends_a_failsafes_delay_as_a_mode_choice_does():
    c = flying()
    c.failsafe, c._delayed_failsafe = True, (FlightMode.AUTO_RTL, 9.0)
    assert c.reposition(air(1.0), (2.0, 0.0, -2.0)).accepted
    assert not c.failsafe and c._delayed_failsafe is None


def reposition_int(client, north, east, alt, frame, speed=-1.0, yaw=NAN):
    lat, lon, _ = Home().to_global((north, east, 0.0))
    x, y = (int(round(lat * 1e7)), int(round(lon * 1e7))) if math.isfinite(north) else (2**31 - 1, 2**31 - 1)
    with client.lock:
        client.conn.mav.command_int_send(1, 1, frame, mavlink.MAV_CMD_DO_REPOSITION, 0, 0, speed,
                                         mavlink.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE, 0.0, yaw, x, y, alt)
    return client.recv("COMMAND_ACK", 3, lambda m: m.command == mavlink.MAV_CMD_DO_REPOSITION)


def test_a_reposition_over_mavlink_flies_there_and_holds(make_vehicle):
    from support.mavclient import px4_mode_name
    from tests.sitl_vehicle.test_loopback import take_off

    server, client = make_vehicle()
    assert reposition_int(client, 1.0, 0.0, 2.0, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT).result == \
        mavlink.MAV_RESULT_TEMPORARILY_REJECTED                                             # on the ground
    take_off(client)
    ack = reposition_int(client, 2.0, 1.0, 2.0, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, speed=0.8)
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    assert client.recv("HEARTBEAT", 3, lambda m: px4_mode_name(m) == "LOITER") is not None
    assert client.wait_reading(lambda: math.dist(server.sim.truth.position, (2.0, 1.0, -2.0)) < 0.1, 30), \
        "did not reach the place"
    home_amsl = Home().alt_m                                                            # AMSL, NaN place: up only
    ack = reposition_int(client, NAN, NAN, home_amsl + 3.0, mavlink.MAV_FRAME_GLOBAL_INT)
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    assert client.wait_reading(lambda: math.dist(server.sim.truth.position, (2.0, 1.0, -3.0)) < 0.1, 30)
    ack = reposition_int(client, 20_000.0, 0.0, 2.0, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)
    assert ack.result == mavlink.MAV_RESULT_DENIED and "20 km from home" in client.statustext("Reposition denied", 3)
    ack = reposition_int(client, 1.0, 0.0, 2.0, mavlink.MAV_FRAME_LOCAL_NED)
    assert ack.result == mavlink.MAV_RESULT_DENIED and "frame 1 is not supported" in client.statustext("frame 1", 3)


def test_a_speed_change_applies_to_the_mission_and_to_a_reposition_under_way():
    c = flying()
    assert c.reposition(air(1.0), (6.0, 0.0, -2.0), speed=1.0).accepted
    assert c.change_speed(2.5).accepted and c.update(air(1.1)).setpoint.cruise_speed == 2.5
    assert c.change_speed(NAN).accepted and math.isnan(c.update(air(1.2)).setpoint.cruise_speed)
    assert math.isnan(c._mission_speed)                              # the mission's default too


def test_flight_termination_stops_the_motors_in_the_air():
    c = flying()
    assert c.terminate().accepted and not c.armed
    assert c.messages[-1] == (mavlink.MAV_SEVERITY_INFO, "Flight terminated: motors stopped")


def test_a_home_sent_stays_home_when_the_vehicle_arms_and_one_set_here_moves_with_it():
    c = Commander(ParameterStore(COMMANDER_PARAMS))
    assert c.set_home((10.0, -4.0, -1.0)).accepted
    assert c.arm(status(0.0, pos=(2.0, 3.0, 0.0))).accepted and c.home == (10.0, -4.0, -1.0)   # kept, as PX4
    assert c.disarm(status(1.0, pos=(2.0, 3.0, 0.0), armed=True)).accepted
    assert c.set_home((2.0, 3.0, 0.0), manually=False).accepted                              # "here"
    assert c.arm(status(2.0, pos=(5.0, 1.0, 0.0))).accepted and c.home == (5.0, 1.0, 0.0)      # where it arms


def test_home_moves_and_return_goes_to_it():
    c = flying()
    assert c.set_home((10.0, -4.0, -1.0)).accepted and c.home == (10.0, -4.0, -1.0)
    assert c.set_mode(FlightMode.AUTO_RTL, air(1.0, 2.0, 0.0, -3.0)).accepted
    assert c.messages[-1][1] == "Return: flying home at 60.0 m above home"
    c.update(air(2.0, 2.0, 0.0, -61.0))
    assert c.update(air(3.0, 2.0, 0.0, -61.0)).setpoint.position == (10.0, -4.0, -61.0)


@pytest.mark.parametrize("command, params, text", [
    (mavlink.MAV_CMD_DO_FLIGHTTERMINATION, (0.0,), "Flight termination not activated: send param1 1"),
    (mavlink.MAV_CMD_DO_CHANGE_SPEED, (2.0, 1.0), "speed type 2.0 (a climb or descent speed) is not modelled"),
    (mavlink.MAV_CMD_DO_CHANGE_SPEED, (1.0, 0.0), "Speed change denied: speed 0.0; send m/s above 0"),
    (mavlink.MAV_CMD_DO_SET_HOME, (0.0, 0.0, 0.0, 0.0, NAN, NAN, NAN), "send param1 1 (here) or a latitude"),
    (mavlink.MAV_CMD_DO_SET_HOME, (0.0, 0.0, 0.0, 0.0, 48.0, 8.5456, 500.0), "km from home; send a place near home"),
])
def test_bad_speed_termination_and_home_commands_are_refused_with_the_reason(make_vehicle, command, params, text):
    server, client = make_vehicle()
    assert client.command(command, *params).result == mavlink.MAV_RESULT_DENIED
    assert text in client.statustext(text[:12], 3)
    assert server.commander.armed is False and server.commander.home == (0.0, 0.0, 0.0)


def test_set_home_here_and_a_ground_speed_over_mavlink(make_vehicle):
    server, client = make_vehicle()
    assert client.command(mavlink.MAV_CMD_DO_SET_HOME, 1.0).result == mavlink.MAV_RESULT_ACCEPTED
    assert math.dist(server.commander.home, server.sim.estimate.position) < 0.05        # where it is now
    assert client.command(mavlink.MAV_CMD_DO_CHANGE_SPEED, 1.0, 3.0).result == mavlink.MAV_RESULT_ACCEPTED
    assert server.commander._mission_speed == 3.0
    assert client.command(mavlink.MAV_CMD_DO_CHANGE_SPEED, 0.0, -1.0).result == mavlink.MAV_RESULT_ACCEPTED
    assert server.commander._mission_speed == 3.0                                        # -1: no change
    assert client.command(mavlink.MAV_CMD_DO_CHANGE_SPEED, 0.0, -2.0).result == mavlink.MAV_RESULT_ACCEPTED
    assert math.isnan(server.commander._mission_speed)                                   # -2: the default

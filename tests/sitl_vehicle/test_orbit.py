"""Orbit mode (MAV_CMD_DO_ORBIT, MAVSDK's do_orbit) as PX4's multicopter orbit flies it: a circle's radius, speed,
direction, centre, altitude and yaw behaviour; the circle Orbit starts with; the approach from off the circle; what
the sticks change."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.commander import Commander, VehicleStatus
from sitl_vehicle.mavlink_io import Home
from sitl_vehicle.modes import FlightMode, mode_from_custom
from sitl_vehicle.orbit import (
    YAW_FRONT_TANGENT,
    YAW_FRONT_TO_CENTER,
    YAW_HOLD_INITIAL_HEADING,
    YAW_RC_CONTROLLED,
    YAW_UNCONTROLLED,
    Orbit,
    approach_point,
    circle_setpoint,
    commanded_orbit,
    facing_centre,
    feasible,
    on_circle,
    starting_orbit,
    stick_adjusted,
)
from sitl_vehicle.params import COMMANDER_PARAMS, ParameterStore
from tests.sitl_vehicle.test_mission import air, status
from tests.sitl_vehicle.test_reposition import flying

NAN = math.nan


def test_the_radius_and_speed_are_held_to_what_px4_allows():
    assert feasible(0.2, 0.5, 1000.0) == (1.0, 0.5)                 # at least 1 m
    assert feasible(1500.0, 4.0, 1000.0) == (1000.0, 4.0)           # at most MC_ORBIT_RAD_MAX
    assert feasible(100.0, 12.0, 1000.0) == (100.0, 10.0)           # at most 10 m/s, either way round
    assert feasible(100.0, -12.0, 1000.0) == (100.0, -10.0)
    radius, speed = feasible(2.0, -3.0, 1000.0)                     # 4.5 m/s² > 2: slower, the radius kept
    assert radius == 2.0 and speed == pytest.approx(-2.0)
    assert feasible(8.0, 3.9, 1000.0) == (8.0, 3.9)                 # 1.9 m/s²: as asked


def test_orbit_starts_on_a_1_m_circle_round_the_vehicle_and_a_command_changes_what_it_names():
    start = starting_orbit((1.0, 2.0, -3.0), 0.4, 1000.0)
    assert start == Orbit((1.0, 2.0, -3.0), 1.0, 1.0, YAW_FRONT_TO_CENTER, 0.4)
    o = commanded_orbit(start, 0.7, 1000.0, radius=-5.0, speed=2.0)   # the radius's sign: counter-clockwise
    assert (o.centre, o.radius, o.speed, o.initial_yaw) == ((1.0, 2.0, -3.0), 5.0, -2.0, 0.7)
    o = commanded_orbit(o, 0.7, 1000.0, speed=1.5, yaw_behaviour=float(YAW_FRONT_TANGENT))   # direction kept
    assert (o.radius, o.speed, o.yaw_behaviour) == (5.0, -1.5, YAW_FRONT_TANGENT)
    o = commanded_orbit(o, 0.7, 1000.0, radius=6.0, centre_ne=(10.0, -4.0), down=-8.0)       # speed kept
    assert (o.centre, o.radius, o.speed) == ((10.0, -4.0, -8.0), 6.0, 1.5)
    o = commanded_orbit(o, 0.7, 1000.0, radius=6.0, speed=-1.0)          # a negative speed turns it round
    assert o.speed == -1.0
    assert commanded_orbit(o, 0.7, 1000.0, centre_ne=(NAN, 3.0)).centre == o.centre   # half a place: none


def test_the_circle_is_flown_by_its_tangent_with_a_pull_back_to_the_radius():
    o = Orbit((0.0, 0.0, -2.0), 4.0, 2.0)                                 # clockwise seen from above
    sp = circle_setpoint(o, (4.0, 0.0, -2.1))                             # due north of the centre, on it
    assert all(math.isnan(c) for c in sp.position[:2])
    assert sp.position[2] == -2.0 and math.isnan(sp.velocity[2])
    assert sp.velocity[:2] == pytest.approx((0.0, 2.0))                  # heading east: clockwise
    assert sp.acceleration[:2] == pytest.approx((-1.0, 0.0))             # v²/r towards the centre
    assert abs(sp.yaw) == pytest.approx(math.pi) and sp.yaw_rate == pytest.approx(0.5)   # facing the centre
    assert circle_setpoint(o, (5.0, 0.0, -2.0)).velocity[:2] == pytest.approx((-1.0, 2.0))  # 1 m out: back in
    assert circle_setpoint(o, (0.0, -3.0, -2.0)).velocity[:2] == pytest.approx((2.0, -1.0))  # 1 m in, west
    ccw = Orbit((0.0, 0.0, -2.0), 4.0, -2.0)
    assert circle_setpoint(ccw, (4.0, 0.0, -2.0)).velocity[:2] == pytest.approx((0.0, -2.0))
    at_centre = circle_setpoint(o, (0.0, 0.0, -2.0))                     # no direction there, as on PX4
    assert at_centre.velocity[:2] == (0.0, 0.0)


@pytest.mark.parametrize("behaviour, speed, yaw, yaw_rate", [
    (YAW_FRONT_TO_CENTER, 2.0, -math.pi / 2, 0.5),      # due east of the centre: facing west
    (YAW_FRONT_TANGENT, 2.0, math.pi, 0.5),             # clockwise there: heading south
    (YAW_FRONT_TANGENT, -2.0, 0.0, -0.5),               # counter-clockwise: north
    (YAW_HOLD_INITIAL_HEADING, 2.0, 0.3, NAN),
    (YAW_UNCONTROLLED, 2.0, NAN, NAN),
    (YAW_RC_CONTROLLED, 2.0, NAN, NAN),                 # no sticks flown in Orbit: the heading is held
])
def test_the_yaw_behaviours(behaviour, speed, yaw, yaw_rate):
    sp = circle_setpoint(Orbit((0.0, 0.0, -2.0), 4.0, speed, behaviour, 0.3), (0.0, 4.0, -2.0))
    assert sp.yaw == pytest.approx(yaw, nan_ok=True, abs=1e-9)
    assert sp.yaw_rate == pytest.approx(yaw_rate, nan_ok=True)


def test_on_the_circle_means_within_2_m_of_it_and_of_its_altitude():
    o = Orbit((0.0, 0.0, -2.0), 5.0, 1.0)
    assert on_circle(o, (6.9, 0.0, -2.0), 0.8) and on_circle(o, (0.0, -3.1, -2.7), 0.8)
    assert not on_circle(o, (7.1, 0.0, -2.0), 0.8) and not on_circle(o, (2.9, 0.0, -2.0), 0.8)
    assert not on_circle(o, (5.0, 0.0, -2.9), 0.8) and on_circle(o, (5.0, 0.0, -2.9), 1.0)
    assert approach_point(o, (0.0, 20.0, -6.0)) == pytest.approx((0.0, 5.0, -2.0))   # the nearest point
    assert approach_point(o, (0.0, 0.0, -6.0)) == pytest.approx((5.0, 0.0, -2.0))    # from the centre: north
    assert facing_centre(o, (0.0, 20.0, -6.0)) == pytest.approx(-math.pi / 2)
    assert facing_centre(o, (0.0, 0.0, -6.0)) == 0.0


def test_a_command_enters_orbit_approaches_the_circle_then_flies_round_it():
    c = flying()
    reply = c.orbit(air(1.0, 0.0, 20.0, -2.0), radius=5.0, speed=2.0, centre_ne=(0.0, 0.0), down=-4.0)
    assert reply.accepted and c.mode is FlightMode.ORBIT and c.orbit_flown.radius == 5.0
    assert c.messages[-1] == (mavlink.MAV_SEVERITY_INFO, "Orbit: 5.0 m round 0.0 m north, 0.0 m east, 4.0 m above "
                                                         "home, 2.0 m/s clockwise")
    sp = c.update(air(1.1, 0.0, 20.0, -2.0)).setpoint                   # off it: straight to its nearest point
    assert sp.position == pytest.approx((0.0, 5.0, -4.0)) and sp.yaw == pytest.approx(-math.pi / 2)
    sp = c.update(air(2.0, 0.5, 12.0, -3.0)).setpoint                   # blown aside: the same point
    assert sp.position == pytest.approx((0.0, 5.0, -4.0))
    sp = c.update(air(5.0, 0.0, 5.5, -3.5)).setpoint                    # on it: round it
    assert all(math.isnan(v) for v in sp.position[:2]) and sp.velocity[:2] == pytest.approx((-2.0, -0.5))
    sp = c.update(air(6.0, 0.0, 8.0, -4.0)).setpoint                    # off it again: a new approach
    assert sp.position == pytest.approx((0.0, 5.0, -4.0))
    assert c.set_mode(FlightMode.AUTO_LOITER, air(7.0)).accepted and c.orbit_flown is None


def test_orbit_entered_as_a_mode_starts_round_the_vehicle_and_a_command_then_keeps_its_centre():
    c = flying()
    assert c.set_mode(FlightMode.ORBIT, air(1.0, 3.0, 4.0, -2.5)).accepted
    assert c.orbit_flown == Orbit((3.0, 4.0, -2.5), 1.0, 1.0, YAW_FRONT_TO_CENTER, 0.0)
    assert c.orbit(air(2.0, 3.2, 4.0, -2.5), radius=3.0).accepted
    assert (c.orbit_flown.centre, c.orbit_flown.radius, c.orbit_flown.speed) == ((3.0, 4.0, -2.5), 3.0, 1.0)


def test_orbit_on_the_ground_is_refused_and_orbit_mode_does_not_arm():
    c = Commander(ParameterStore(COMMANDER_PARAMS))
    reply = c.orbit(status(0.0), radius=3.0)
    assert reply.result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    assert reply.text == "Orbit denied: not flying (take off first)"
    assert not c.set_mode(FlightMode.ORBIT, status(0.1)).accepted and c.mode is FlightMode.AUTO_LOITER
    c = flying()
    assert c.orbit(air(1.0), radius=3.0).accepted and c.terminate().accepted
    assert c.arm(status(2.0)).text == "Arming denied: Orbit mode is not armable; switch to Hold or Offboard"


def test_a_command_ends_a_failsafes_delay_as_a_mode_choice_does():
    c = flying()
    c.failsafe, c._delayed_failsafe = True, (FlightMode.AUTO_RTL, 9.0)
    assert c.orbit(air(1.0), radius=3.0).accepted
    assert not c.failsafe and c._delayed_failsafe is None


def test_orbit_is_position_mode_s_sub_mode_and_an_auto_mode():
    assert mode_from_custom(3, 1) is FlightMode.ORBIT and mode_from_custom(3, 2) is FlightMode.POSCTL
    assert FlightMode.ORBIT.custom_mode == (3 << 16) | (1 << 24) and not FlightMode.ORBIT.manual
    flags = FlightMode.ORBIT.base_mode_flags
    assert flags & mavlink.MAV_MODE_FLAG_AUTO_ENABLED and not flags & mavlink.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED


def orbit_command(client, radius, speed, behaviour, north, east, alt, frame=mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT):
    lat, lon, _ = Home().to_global((north, east, 0.0))
    x, y = (int(round(lat * 1e7)), int(round(lon * 1e7))) if math.isfinite(north) else (2**31 - 1, 2**31 - 1)
    with client.lock:
        client.conn.mav.command_int_send(1, 1, frame, mavlink.MAV_CMD_DO_ORBIT, 0, 0, radius, speed, behaviour, NAN,
                                         x, y, alt)
    return client.recv("COMMAND_ACK", 3, lambda m: m.command == mavlink.MAV_CMD_DO_ORBIT)


def test_an_orbit_over_mavlink_flies_the_circle_and_reports_it(make_vehicle):
    from support.mavclient import px4_mode_name
    from tests.sitl_vehicle.test_loopback import take_off

    server, client = make_vehicle()
    amsl = Home().alt_m + 2.0                       # above sea level in any frame, as PX4 and MAVSDK's do_orbit read it
    assert orbit_command(client, 2.0, 1.5, 0, 2.0, 0.0, amsl).result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    take_off(client)
    assert orbit_command(client, 2.0, 1.5, 7, 2.0, 0.0, amsl).result == mavlink.MAV_RESULT_DENIED
    assert "yaw behaviour 7 is not one of" in client.statustext("Orbit denied", 3)
    assert orbit_command(client, 2.0, 1.5, 0, 2.0, 0.0, 2.0).result == mavlink.MAV_RESULT_DENIED   # a height
    assert "altitude 2 m is below home (488.0 m above sea level)" in client.statustext("Orbit denied", 3)
    assert orbit_command(client, -2.0, 1.5, 0, 2.0, 0.0, amsl).result == mavlink.MAV_RESULT_ACCEPTED
    assert client.recv("HEARTBEAT", 3, lambda m: px4_mode_name(m) == "POSCTL" and m.custom_mode >> 24 == 1)
    status = client.recv("ORBIT_EXECUTION_STATUS", 3)
    lat, lon, _ = Home().to_global((2.0, 0.0, -2.0))
    assert (status.radius, status.frame) == (-2.0, mavlink.MAV_FRAME_GLOBAL)
    assert (status.x, status.y, status.z) == (round(lat * 1e7), round(lon * 1e7), pytest.approx(amsl, abs=0.01))
    def on_circle_at_2_m(p):                                            # 2 m round, up from 1.5 m to 2 m
        return abs(math.dist(p[:2], (2.0, 0.0)) - 2.0) < 0.15 and abs(p[2] + 2.0) < 0.05

    assert client.wait_reading(lambda: on_circle_at_2_m(server.sim.truth.position), 20)
    turned, last, samples = 0.0, None, []
    while turned > -2.0 * math.pi:                                     # a whole lap, counter-clockwise
        assert len(samples) < 3000, "did not fly round"
        north, east, down = server.sim.truth.position
        bearing = math.atan2(east, north - 2.0)
        if last is not None:
            turned += math.remainder(bearing - last, 2.0 * math.pi)
        last = bearing
        samples.append((math.hypot(north - 2.0, east), math.hypot(*server.sim.truth.velocity[:2]), down,
                        math.remainder(server.sim.truth.euler()[2] - (bearing + math.pi), 2.0 * math.pi)))
        client.wait_reading(lambda: False, 0.02)
    radii, speeds, downs, facing = zip(*samples, strict=True)
    assert max(abs(r - 2.0) for r in radii) < 0.15 and max(abs(d + 2.0) for d in downs) < 0.1
    assert sorted(speeds)[len(speeds) // 2] == pytest.approx(1.5, abs=0.1)
    assert max(abs(f) for f in facing) < 0.15                           # facing the centre all round
    client.command(mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4, 3)   # Hold
    assert client.recv("HEARTBEAT", 3, lambda m: px4_mode_name(m) == "LOITER") is not None
    with client.lock:                                                   # no orbit to report outside Orbit
        client.conn.mav.command_long_send(1, 1, mavlink.MAV_CMD_REQUEST_MESSAGE, 0,
                                          mavlink.MAVLINK_MSG_ID_ORBIT_EXECUTION_STATUS, 0, 0, 0, 0, 0, 0)
    ack = client.recv("COMMAND_ACK", 3, lambda m: m.command == mavlink.MAV_CMD_REQUEST_MESSAGE)
    assert ack.result == mavlink.MAV_RESULT_DENIED


def test_the_geometry_off_the_origin_and_near_the_centre():
    """A centre away from the origin, a vehicle off both axes, and one within a metre of the centre."""
    o = Orbit((3.0, -2.0, -4.0), 5.0, 2.0, YAW_FRONT_TANGENT)
    here = (6.0, 2.0, -4.0)                                          # 3 m north and 4 m east of it: on the circle
    assert on_circle(o, here, 0.8) and not on_circle(o, (9.0, 6.0, -4.0), 0.8)
    sp = circle_setpoint(o, here)
    assert sp.velocity[:2] == pytest.approx((-1.6, 1.2))             # the tangent, clockwise
    assert sp.acceleration[:2] == pytest.approx((-0.48, -0.64))      # v²/r = 0.8 m/s² towards the centre
    assert (sp.yaw, sp.yaw_rate) == (pytest.approx(math.atan2(1.2, -1.6)), pytest.approx(0.4))   # along it
    assert approach_point(o, (-7.0, -2.0, 0.0)) == pytest.approx((-2.0, -2.0, -4.0))     # from due south
    assert approach_point(o, (3.0, -1.5, 0.0)) == pytest.approx((3.0, 3.0, -4.0))        # 0.5 m east of the centre
    assert facing_centre(o, (3.0, -1.5, 0.0)) == pytest.approx(-math.pi / 2)
    assert facing_centre(o, (8.0, -2.0, 0.0)) == pytest.approx(math.pi)                  # due north: face south
    assert facing_centre(o, (6.0, 2.0, 0.0)) == pytest.approx(math.atan2(-4.0, -3.0))
    small = Orbit((3.0, -2.0, -4.0), 1.0, 1.0)
    assert circle_setpoint(small, (3.0, -1.5, -4.0)).velocity[:2] == pytest.approx((-1.0, 0.5))   # out, and round
    edge = Orbit((0.0, 0.0, -2.0), 5.0, 1.0)
    assert not on_circle(edge, (7.0, 0.0, -2.0), 0.8)                # exactly 2 m off: not on it
    assert not on_circle(edge, (5.0, 0.0, -2.5), 0.5)                # exactly the acceptance below: not on it


def test_a_command_keeps_or_sets_the_direction_as_px4_does():
    slow = Orbit((0.0, 0.0, -2.0), 4.0, 0.5)
    assert commanded_orbit(slow, 0.0, 1000.0, speed=1.0).speed == 1.0              # clockwise stays clockwise
    assert commanded_orbit(slow, 0.0, 1000.0, radius=0.5, speed=1.0).speed == 1.0  # a radius above 0: clockwise
    assert commanded_orbit(slow, 0.0, 1000.0, radius=0.0, speed=1.0).speed == -1.0  # 0: counter-clockwise
    stopped = commanded_orbit(slow, 0.0, 1000.0, speed=0.0)
    assert stopped.speed == 0.0 and commanded_orbit(stopped, 0.0, 1000.0, speed=1.0).speed == -1.0


def test_the_commander_s_orbit_in_its_words_and_setpoints():
    c = flying()
    here = air(1.0, 0.0, 0.0, -2.0)
    assert c.orbit(VehicleStatus(time_s=1.0, position=(0.0, 0.0, -2.0), velocity=(0.0, 0.0, 0.0), yaw=0.7,
                                 armed=True, landed=False), radius=-3.0, speed=0.5, centre_ne=(3.0, -2.0),
                   yaw_behaviour=float(YAW_HOLD_INITIAL_HEADING)).accepted
    assert c.messages[-1][1] == ("Orbit: 3.0 m round 3.0 m north, -2.0 m east, 2.0 m above home, 0.5 m/s "
                                 "counter-clockwise")
    sp = c.update(air(2.0, 3.0, 1.0, -2.0)).setpoint                   # on the circle: the heading commanded at
    assert sp.yaw == pytest.approx(0.7)
    assert c.orbit(here, radius=3.0, speed=0.5).accepted and c.messages[-1][1].endswith("0.5 m/s clockwise")
    assert c.orbit(here, speed=0.0).accepted and c.messages[-1][1].endswith("0.0 m/s counter-clockwise")
    assert c.set_mode(FlightMode.AUTO_LOITER, air(3.0, 3.0, 1.0, -2.0)).accepted
    hold = c.update(air(3.1, 3.0, 1.0, -2.0)).setpoint                 # Hold after Orbit: its own place
    assert hold.position == pytest.approx((3.0, 1.0, -2.0)) and math.isnan(hold.velocity[0])
    assert c.set_mode(FlightMode.ORBIT, air(4.0, 3.0, 4.0, -2.5)).accepted
    sp = c.update(air(5.0, 3.0, 8.0, -2.5)).setpoint                   # blown 4 m off its 1 m circle: back to it
    assert sp.position == pytest.approx((3.0, 5.0, -2.5))


def test_orbit_mode_is_refused_armed_on_the_ground_in_words():
    c = Commander(ParameterStore(COMMANDER_PARAMS))
    assert c.arm(status(0.0)).accepted
    for request in (lambda: c.set_mode(FlightMode.ORBIT, status(0.1, armed=True)),
                    lambda: c.orbit(status(0.1, armed=True), radius=3.0)):
        reply = request()
        assert reply.result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED
        assert "not flying (take off first)" in reply.text and c.mode is FlightMode.AUTO_LOITER
    assert c.set_mode(FlightMode.ORBIT, status(0.1)).text == ("Switching to Orbit is currently not possible: not "
                                                              "flying (take off first)")


def test_the_sticks_change_the_radius_and_speed_as_px4_s_do():
    o = Orbit((0.0, 0.0, -2.0), 20.0, 1.0)                              # facing the centre, clockwise
    assert stick_adjusted(o, 1.0, 0.0, 1.0, 1000.0, 2.0, 3.0).radius == pytest.approx(18.0)   # pitch in: smaller
    assert stick_adjusted(o, -0.5, 0.0, 1.0, 1000.0, 2.0, 3.0).radius == pytest.approx(21.0)
    assert stick_adjusted(o, 0.0, 0.5, 1.0, 1000.0, 2.0, 3.0).speed == pytest.approx(2.5)     # roll right: clockwise
    assert stick_adjusted(o, 0.0, -1.0, 2.0, 1000.0, 2.0, 3.0).speed == pytest.approx(-5.0)   # through a stop
    assert stick_adjusted(o, 0.0, 1.0, 2.0, 1000.0, 2.0, 3.0).speed == pytest.approx(math.sqrt(40.0))  # 2 m/s²
    small = stick_adjusted(o, 1.0, 0.0, 19.5, 1000.0, 2.0, 3.0)
    assert (small.radius, small.speed) == pytest.approx((1.0, 1.0))      # the radius held to 1 m
    assert stick_adjusted(o, -1.0, 0.0, 10.0, 30.0, 2.0, 3.0).radius == 30.0   # and to MC_ORBIT_RAD_MAX
    tangent = Orbit((0.0, 0.0, -2.0), 20.0, 1.0, YAW_FRONT_TANGENT)     # nose along the tangent: roll and pitch swap
    assert stick_adjusted(tangent, 0.0, 1.0, 1.0, 1000.0, 2.0, 3.0).radius == pytest.approx(18.0)
    assert stick_adjusted(tangent, 1.0, 0.0, 1.0, 1000.0, 2.0, 3.0).speed == pytest.approx(4.0)
    ccw = commanded_orbit(tangent, 0.0, 1000.0, radius=-20.0, speed=1.0)   # counter-clockwise: the centre on the left
    assert not ccw.started_clockwise and ccw.speed == -1.0
    assert stick_adjusted(ccw, 0.0, -1.0, 1.0, 1000.0, 2.0, 3.0).radius == pytest.approx(18.0)
    assert stick_adjusted(ccw, 1.0, 0.0, 1.0, 1000.0, 2.0, 3.0).speed == pytest.approx(-4.0)
    turned = stick_adjusted(ccw, -1.0, 0.0, 2.0, 1000.0, 2.0, 3.0)     # slowed through a stop: clockwise now, and
    assert turned.speed == pytest.approx(5.0) and not turned.started_clockwise   # the sticks keep their sense
    assert commanded_orbit(turned, 0.0, 1000.0, radius=20.0).started_clockwise is True   # a command sets it again


def test_live_sticks_fly_the_orbit_s_radius_speed_and_altitude():
    from sitl_vehicle.manual import Sticks

    c = flying()
    assert c.orbit(air(1.0, 0.0, 10.0, -2.0), radius=10.0, speed=1.0, centre_ne=(0.0, 0.0), down=-2.0).accepted
    c.update(air(1.1, 0.0, 10.0, -2.0))                                 # no sticks: the circle as commanded
    c.manual_control(Sticks(pitch=1.0), 1.1)
    c.update(air(1.3, 0.0, 10.0, -2.0))
    assert c.orbit_flown.radius == pytest.approx(10.0 - 0.2 * 2.0)      # MPC_XY_CRUISE per second at full stick
    c.manual_control(Sticks(roll=1.0), 1.3)
    c.update(air(1.5, 0.0, 9.6, -2.0))
    assert (c.orbit_flown.radius, c.orbit_flown.speed) == pytest.approx((9.6, 1.0 + 0.2 * 3.0))   # MPC_ACC_HOR
    c.manual_control(Sticks(throttle=1.0), 1.5)                         # full throttle: climbing at its speed
    sp = c.update(air(1.6, 0.0, 9.6, -2.5)).setpoint
    assert math.isnan(sp.position[2]) and sp.velocity[2] == pytest.approx(-3.0)
    assert c.orbit_flown.centre == (0.0, 0.0, -2.5)                     # the circle climbs with the vehicle
    c.manual_control(Sticks(), 1.6)                                     # centred: the altitude held where it is
    sp = c.update(air(1.7, 0.0, 9.6, -2.6)).setpoint
    assert sp.position[2] == -2.5 and math.isnan(sp.velocity[2]) and c.orbit_flown.radius == pytest.approx(9.6)


def test_sticks_over_mavlink_draw_the_circle_in_and_climb_it(make_vehicle):
    """MANUAL_CONTROL in Orbit, as a ground station's joystick sends it: pitch forward draws the circle in (the
    ORBIT_EXECUTION_STATUS radius follows), the throttle climbs it, centred sticks hold the circle where they left
    it, and the vehicle flies that circle."""
    from tests.sitl_vehicle.test_loopback import take_off

    server, client = make_vehicle()
    take_off(client)
    assert orbit_command(client, 5.0, 1.0, 0, 5.0, 0.0, Home().alt_m + 2.0).result == mavlink.MAV_RESULT_ACCEPTED
    client.stream_sticks(x=1000)
    assert client.wait_reading(lambda: server.commander.orbit_flown.radius < 3.0, 10)
    client.stream_sticks(z=1000)
    assert client.wait_reading(lambda: server.sim.truth.position[2] < -3.0, 10)
    client.stream_sticks()
    client.wait_reading(lambda: False, 0.5)
    orbit = server.commander.orbit_flown
    assert 1.0 <= orbit.radius < 3.0 and orbit.centre[2] < -3.0     # (how far past depends on the machine's load)

    def on_it(p):
        return abs(math.dist(p[:2], orbit.centre[:2]) - orbit.radius) < 0.2 and abs(p[2] - orbit.centre[2]) < 0.2

    assert client.wait_reading(lambda: on_it(server.sim.truth.position), 20)
    assert client.recv("ORBIT_EXECUTION_STATUS", 3).radius == pytest.approx(orbit.radius)
    assert server.commander.orbit_flown == orbit                        # centred sticks change nothing


def test_the_orbit_sticks_follow_the_vehicle_s_parameters_and_lost_sticks_do_nothing():
    from sitl_vehicle.manual import Sticks
    from sitl_vehicle.params import ParamSpec

    bound = [ParamSpec("MPC_XY_CRUISE", 4.0, 0.1, 20.0, "m/s", "planned speed"),
             ParamSpec("MPC_ACC_HOR", 1.0, 0.1, 20.0, "m/s^2", "planned acceleration")]
    c = Commander(ParameterStore(COMMANDER_PARAMS + bound))
    assert c.arm(status(0.0)).accepted
    c.update(air(0.5))
    c.manual_control(Sticks(pitch=1.0, roll=1.0), 0.9)                  # live sticks as Orbit is entered: no step
    assert c.orbit(air(1.0, 0.0, 20.0, -2.0), radius=5.0, speed=1.0, centre_ne=(0.0, 0.0), down=-2.0).accepted
    assert c.update(air(1.0, 0.0, 20.0, -2.0)).setpoint.position == pytest.approx((0.0, 5.0, -2.0))   # approach
    sp = c.update(air(1.25, 0.0, 19.0, -2.0)).setpoint                  # 0.25 s of full sticks, at the parameters'
    assert (c.orbit_flown.radius, c.orbit_flown.speed) == pytest.approx((5.0 - 0.25 * 4.0, 1.0 + 0.25 * 1.0))
    assert sp.position == pytest.approx((0.0, 4.0, -2.0))               # the smaller circle approached afresh
    c.update(air(2.0, 0.0, 19.0, -2.0))                                 # the sticks not heard for 1.1 s: lost,
    assert c.mode is FlightMode.AUTO_LOITER                             # the failsafe's Hold
    assert c.orbit(air(2.1, 0.0, 19.0, -2.0), radius=4.0).accepted       # Orbit again: the lost sticks do nothing
    c.update(air(2.2, 0.0, 19.0, -2.0))
    c.update(air(2.7, 0.0, 19.0, -2.0))
    assert (c.orbit_flown.radius, c.orbit_flown.speed) == pytest.approx((4.0, 1.0))     # (Orbit starts at 1 m/s)

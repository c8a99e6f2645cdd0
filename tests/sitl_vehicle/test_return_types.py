"""Return's RTL_TYPE 0-3, as PX4 chooses where to go and by which path: home, rally points, the mission's landing
(DO_LAND_START) and the mission's own path, ahead or back; and MAV_CMD_DO_LAND_START."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.commander import Commander
from sitl_vehicle.mission import (
    DO_LAND_START,
    NAV_LAND,
    NAV_TAKEOFF,
    NAV_WAYPOINT,
    MissionError,
    mission_item_from_message,
    mission_landing,
)
from sitl_vehicle.modes import FlightMode
from sitl_vehicle.params import COMMANDER_PARAMS, ParameterStore
from sitl_vehicle.return_plan import plan_return
from support.mavclient import upload_plan
from tests.sitl_vehicle.test_mission import HOME, air, item_msg, local_item, status
from tests.sitl_vehicle.test_rally import rally

HOME_NED = (0.0, 0.0, 0.0)
MISSION = (local_item(0, NAV_TAKEOFF, alt=5.0), local_item(1, NAV_WAYPOINT, 10.0, 0.0, alt=5.0),
           local_item(2, NAV_WAYPOINT, 20.0, 0.0, alt=6.0), local_item(3, DO_LAND_START),
           local_item(4, NAV_WAYPOINT, 30.0, 5.0, alt=4.0), local_item(5, NAV_LAND, 30.0, 10.0))
NO_LANDING = MISSION[:3]


def flat(path) -> list[float]:
    return [value for point in path for value in point]


def approx_path(points):
    return pytest.approx(flat(points), nan_ok=True)


def test_the_mission_landing_starts_at_its_marker_else_at_its_land_item():
    assert mission_landing(MISSION) == (3, 5)
    assert mission_landing(MISSION[:4]) is None                            # a marker with no Land after it
    assert mission_landing(MISSION[:3] + MISSION[5:]) == (3, 3)            # no marker: the Land item
    land_first = (local_item(0, NAV_LAND), local_item(1, DO_LAND_START), local_item(2, NAV_LAND, 1.0, 1.0))
    assert mission_landing(land_first) == (1, 2)                          # the marker's Land, not the first one
    assert mission_landing(()) is None


def test_type_0_goes_home_or_to_the_nearest_rally_point_never_to_the_mission_landing():
    plan = plan_return(0, (29.0, 5.0, -5.0), HOME_NED, (), MISSION)
    assert (plan.destination, plan.path, plan.mission_landing, plan.flying) == ((0.0, 0.0), (), False, "flying home")
    plan = plan_return(0, (29.0, 5.0, -5.0), HOME_NED, (rally(0, 25.0, 0.0),), MISSION)
    assert plan.destination == pytest.approx((25.0, 0.0), abs=0.01) and plan.landing == "landing at rally point 0"


def test_type_1_flies_to_the_nearer_of_rally_point_and_mission_landing_and_home_only_with_neither():
    plan = plan_return(1, (26.0, 0.0, -5.0), HOME_NED, (rally(0, 5.0, 0.0),), MISSION)
    assert plan.flying == "flying to the mission landing at item 3" and plan.landing == "landing at mission item 5"
    assert flat(plan.path) == approx_path(((30.0, 5.0, math.nan), (30.0, 5.0, -4.0)))
    assert (plan.destination, plan.mission_landing, plan.climb) == ((30.0, 10.0), True, True)
    plan = plan_return(1, (6.0, 0.0, -5.0), HOME_NED, (rally(0, 5.0, 0.0), rally(1, 50.0, 0.0)), MISSION)
    assert plan.flying == "flying to rally point 0" and not plan.mission_landing and plan.path == ()
    plan = plan_return(1, (0.5, 0.0, -5.0), HOME_NED, (), MISSION)        # home nearer, but type 1 lands as planned
    assert plan.mission_landing and plan.destination == (30.0, 10.0)
    plan = plan_return(1, (0.5, 0.0, -5.0), HOME_NED, (rally(0, 50.0, 0.0),), NO_LANDING)
    assert plan.flying == "flying to rally point 0"                       # home nearer, but a rally point is there
    assert plan_return(1, (0.5, 0.0, -5.0), HOME_NED, (), NO_LANDING).flying == "flying home"


def test_type_3_flies_to_the_nearest_of_home_rally_points_and_mission_landing():
    assert plan_return(3, (2.0, 0.0, -5.0), HOME_NED, (), MISSION).flying == "flying home"
    assert plan_return(3, (28.0, 0.0, -5.0), HOME_NED, (), MISSION).mission_landing
    near_rally = plan_return(3, (20.0, 0.0, -5.0), HOME_NED, (rally(0, 21.0, 0.0),), MISSION)
    assert near_rally.flying == "flying to rally point 0"
    assert plan_return(3, (28.0, 0.0, -5.0), HOME_NED, (rally(0, 21.0, 0.0),), MISSION).mission_landing
    placed_marker = MISSION[:3] + (local_item(3, DO_LAND_START, 24.0, 0.0),) + MISSION[4:]
    plan = plan_return(3, (23.0, 0.0, -5.0), HOME_NED, (), placed_marker)  # the marker's place starts the landing
    assert flat(plan.path) == approx_path(((24.0, 0.0, math.nan), (30.0, 5.0, -4.0)))
    unplaced = MISSION[:3] + (local_item(3, DO_LAND_START), local_item(4, NAV_LAND))
    assert plan_return(3, (29.0, 0.0, -5.0), HOME_NED, (), unplaced).flying == "flying home"   # nowhere to fly to


def test_type_2_follows_the_mission_ahead_to_its_landing_from_mission_mode_without_climbing():
    plan = plan_return(2, (15.0, 0.0, -5.5), HOME_NED, (rally(0, 15.0, 0.0),), MISSION, mission_seq=2)
    assert plan.flying == "following the mission from item 2 to its landing" and not plan.climb
    assert flat(plan.path) == approx_path(((20.0, 0.0, -6.0), (30.0, 5.0, -4.0))) and plan.destination == (30.0, 10.0)
    plan = plan_return(2, (12.0, 1.0, -3.0), HOME_NED, (), MISSION)       # from another mode: the nearest item
    assert plan.climb and plan.flying == "following the mission from item 1 to its landing"
    assert flat(plan.path) == approx_path(((10.0, 0.0, math.nan), (10.0, 0.0, -5.0), (20.0, 0.0, -6.0),
                                       (30.0, 5.0, -4.0)))
    past_the_land = MISSION + (local_item(6, NAV_WAYPOINT, 40.0, 0.0),)
    plan = plan_return(2, (39.0, 0.0, -3.0), HOME_NED, (), past_the_land)
    assert plan.flying == "following the mission from item 3 to its landing"


def test_type_2_without_a_landing_flies_the_mission_back_and_then_home():
    plan = plan_return(2, (18.0, 0.0, -6.0), HOME_NED, (), NO_LANDING, mission_seq=2)
    assert plan.flying == "flying the mission back from item 1, then home" and plan.landing == "landing at home"
    assert flat(plan.path) == approx_path(((10.0, 0.0, -5.0),)) and not plan.climb and not plan.mission_landing
    plan = plan_return(2, (19.0, 0.0, -3.0), HOME_NED, (rally(0, 19.0, 0.0),), NO_LANDING)
    assert flat(plan.path) == approx_path(((20.0, 0.0, math.nan), (20.0, 0.0, -6.0), (10.0, 0.0, -5.0)))
    assert plan.destination == (0.0, 0.0)                                   # rally points are not considered
    assert plan_return(2, (0.0, 0.0, -3.0), HOME_NED, (), NO_LANDING, mission_seq=0).path == ()
    assert plan_return(2, (5.0, 5.0, -3.0), HOME_NED, (rally(0, 5.0, 5.0),), ()).flying == "flying home"


def commander_with(rtl_type: int, mission=MISSION) -> Commander:
    commander = Commander(ParameterStore(COMMANDER_PARAMS))
    for name, value in (("RTL_TYPE", rtl_type), ("RTL_RETURN_ALT", 8.0), ("RTL_DESCEND_ALT", 2.0),
                        ("RTL_LAND_DELAY", 0.0)):
        commander.params.set(name, value)
    commander.set_mission(list(mission), status(0.0))
    assert commander.arm(status(0.0)).accepted
    return commander


def test_a_return_to_the_mission_landing_climbs_flies_its_items_and_lands_on_its_land_item():
    c = commander_with(1)
    assert c.set_mode(FlightMode.AUTO_RTL, air(1.0, 26.0, 0.0, -5.0)).accepted
    assert c.messages[-1][1] == "Return: flying to the mission landing at item 3 at 8.0 m above home"
    legs = [((26.0, 0.0, -5.0), (26.0, 0.0, -8.0)),       # climbs where it is
            ((26.0, 0.0, -8.0), (30.0, 5.0, -8.0)),       # to the landing's first item, at the return altitude
            ((30.0, 5.0, -8.0), (30.0, 5.0, -4.0)),       # down to the item's altitude
            ((30.0, 5.0, -4.0), (30.0, 10.0, -4.0))]      # on to the Land item at that altitude
    for t, (at, target) in enumerate(legs, start=2):
        assert c.update(air(float(t), *at)).setpoint.position == pytest.approx(target), at
    assert not c.landing
    c.update(air(6.0, 30.0, 10.0, -4.0))
    assert c.landing and c.messages[-1][1] == "Return: landing at mission item 5"
    out = c.update(air(7.0, 30.0, 10.0, -2.0))                 # straight down: no descent leg, no wait
    assert out.setpoint.position[:2] == pytest.approx((30.0, 10.0)) and out.setpoint.velocity[2] > 0


def test_a_return_from_mission_mode_follows_the_mission_from_its_current_item():
    c = commander_with(2)
    assert c.set_mode(FlightMode.AUTO_MISSION, air(0.5, 0.0, 0.0, -5.0)).accepted
    assert c.set_mission_current(2, air(0.6, 12.0, 0.0, -5.0)).accepted
    assert c.set_mode(FlightMode.AUTO_RTL, air(1.0, 15.0, 0.0, -5.5)).accepted
    assert c.messages[-1][1] == "Return: following the mission from item 2 to its landing"
    out = c.update(air(2.0, 15.0, 0.0, -5.5))                  # no climb: on to item 2 at its own altitude
    assert out.setpoint.position == pytest.approx((20.0, 0.0, -6.0))
    out = c.update(air(3.0, 20.0, 0.0, -6.0))
    assert out.setpoint.position == pytest.approx((30.0, 5.0, -4.0))


def test_a_return_flying_the_mission_back_ends_as_a_return_home():
    c = commander_with(2, NO_LANDING)
    assert c.set_mode(FlightMode.AUTO_MISSION, air(0.5, 0.0, 0.0, -5.0)).accepted
    assert c.set_mission_current(2, air(0.6, 12.0, 0.0, -5.0)).accepted
    assert c.set_mode(FlightMode.AUTO_RTL, air(1.0, 18.0, 0.0, -6.0)).accepted
    assert c.update(air(2.0, 18.0, 0.0, -6.0)).setpoint.position == pytest.approx((10.0, 0.0, -5.0))
    assert c.update(air(3.0, 10.0, 0.0, -5.0)).setpoint.position == pytest.approx((0.0, 0.0, -5.0))  # home, there
    c.update(air(4.0, 0.0, 0.0, -5.0))                          # then down to RTL_DESCEND_ALT
    assert c.update(air(5.0, 0.0, 0.0, -5.0)).setpoint.position == pytest.approx((0.0, 0.0, -2.0))
    c.update(air(6.0, 0.0, 0.0, -2.0))
    assert c.landing and c.messages[-1][1] == "Return: landing at home"


def test_mission_mode_flies_past_the_landing_marker_and_do_land_start_jumps_to_it():
    c = commander_with(0)
    assert c.set_mode(FlightMode.AUTO_MISSION, air(0.5, 0.0, 0.0, -5.0)).accepted
    assert c.set_mission_current(3, air(0.6)).accepted                 # the marker: reached, then item 4
    assert c.mission_seq == 4 and list(c.mission_reached)[-1] == 3
    assert c.update(air(1.0, 20.0, 0.0, -6.0)).setpoint.position == pytest.approx((30.0, 5.0, -4.0))
    c = commander_with(0, MISSION[:4])                                 # a marker last: held where it is reached
    assert c.set_mode(FlightMode.AUTO_MISSION, air(0.5, 0.0, 0.0, -5.0)).accepted
    assert c.set_mission_current(3, air(0.6, 21.0, 1.0, -6.0)).accepted and c.mission_finished
    assert c.update(air(0.7, 21.0, 1.0, -6.0)).setpoint.position == pytest.approx((21.0, 1.0, -6.0))
    c = commander_with(0)
    assert c.start_mission_landing(air(1.0)).accepted and c.mode is FlightMode.AUTO_MISSION and c.mission_seq == 4
    c = commander_with(0, NO_LANDING)
    reply = c.start_mission_landing(air(1.0))
    assert not reply.accepted and reply.result == mavlink.MAV_RESULT_DENIED
    assert reply.text == ("Landing sequence denied: the mission has no landing (upload one with DO_LAND_START or "
                          "NAV_LAND)")


def test_do_land_start_is_uploaded_placed_or_as_a_bare_marker_and_other_frames_are_refused():
    marker = mission_item_from_message(item_msg(3, DO_LAND_START, here=True, frame=mavlink.MAV_FRAME_MISSION),
                                       HOME.to_local)
    assert marker.name == "DO_LAND_START" and math.isnan(marker.north)
    assert marker.to_message(False, 1, 1).frame == mavlink.MAV_FRAME_MISSION
    placed = mission_item_from_message(item_msg(3, DO_LAND_START, north=12.0, east=3.0), HOME.to_local)
    assert (placed.north, placed.east) == pytest.approx((12.0, 3.0), abs=0.01)
    with pytest.raises(MissionError, match="frame 1 is not supported"):
        mission_item_from_message(item_msg(3, DO_LAND_START, frame=mavlink.MAV_FRAME_LOCAL_NED), HOME.to_local)
    with pytest.raises(MissionError, match="frame 2 is not supported"):   # only the marker goes without a place
        mission_item_from_message(item_msg(3, NAV_WAYPOINT, frame=mavlink.MAV_FRAME_MISSION), HOME.to_local)


def test_a_return_of_type_1_lands_on_the_mission_landing_over_mavlink(make_vehicle):
    server, client = make_vehicle(params=(("RTL_TYPE", 1.0), ("RTL_RETURN_ALT", 2.0), ("RTL_LAND_DELAY", 0.0)))
    mission = [item_msg(0, NAV_TAKEOFF, alt=1.5, here=True), item_msg(1, NAV_WAYPOINT, north=1.0, alt=1.5),
               item_msg(2, DO_LAND_START, here=True, frame=mavlink.MAV_FRAME_MISSION),
               item_msg(3, NAV_WAYPOINT, north=2.5, east=1.0, alt=1.0), item_msg(4, NAV_LAND, north=2.5, east=2.0)]
    assert upload_plan(client, mission, mavlink.MAV_MISSION_TYPE_MISSION) == mavlink.MAV_MISSION_ACCEPTED
    assert client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == mavlink.MAV_RESULT_ACCEPTED
    assert client.command(mavlink.MAV_CMD_MISSION_START, 0, 4).result == mavlink.MAV_RESULT_ACCEPTED
    assert client.recv("MISSION_ITEM_REACHED", 20, lambda m: m.seq == 1) is not None, "mission stalled"
    assert client.command(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH).result == mavlink.MAV_RESULT_ACCEPTED
    assert "Return: flying to the mission landing at item 2" in client.statustext("Return: flying", 3)
    assert "Return: landing at mission item 4" in client.statustext("Return: landing", 30)
    assert client.wait_reading(lambda: not server.sim.armed, 30), "did not land and disarm"
    x, y, z = server.sim.truth.position
    assert math.hypot(x - 2.5, y - 2.0) < 0.15 and z > -0.05 and not server.sim.crashed


# ---------------------------------------------------------------- choices decided by east, by ties, by where home is
ELSEWHERE = (4.0, -3.0, -1.0)                                           # home away from the origin, 1 m up


def test_home_is_where_home_is_and_the_mission_back_ends_there():
    plan = plan_return(2, (0.0, 0.0, -3.0), ELSEWHERE, (), NO_LANDING, mission_seq=0)   # nothing behind: home
    assert (plan.destination, plan.flying, plan.landing, plan.climb) == ((4.0, -3.0), "flying home",
                                                                         "landing at home", True)
    plan = plan_return(2, (11.0, 0.0, -3.0), ELSEWHERE, (), NO_LANDING, mission_seq=1)  # item 0 is behind it
    assert plan.flying == "flying the mission back from item 0, then home" and plan.path == ()
    plan = plan_return(2, (18.0, 0.0, -6.0), ELSEWHERE, (), NO_LANDING, mission_seq=2)
    assert plan.destination == (4.0, -3.0) and flat(plan.path) == approx_path(((10.0, 0.0, -6.0),))
    plan = plan_return(2, (19.0, 0.0, -3.0), ELSEWHERE, (), NO_LANDING)                  # from another mode
    assert plan.climb is True and plan.destination == (4.0, -3.0)
    assert plan_return(0, (19.0, 0.0, -3.0), ELSEWHERE, (), MISSION).destination == (4.0, -3.0)


def test_a_return_beside_the_land_item_goes_straight_down_on_it():
    plan = plan_return(2, (31.0, 10.5, -3.0), HOME_NED, (), MISSION)        # the Land item is the nearest
    assert (plan.flying, plan.path, plan.destination) == ("following the mission from item 5 to its landing", (),
                                                          (30.0, 10.0))


def test_a_land_item_without_a_place_lands_where_the_path_ends_or_where_the_vehicle_is():
    unplaced_land = MISSION[:5] + (local_item(5, NAV_LAND),)
    plan = plan_return(2, (15.0, 0.0, -6.0), HOME_NED, (), unplaced_land, mission_seq=2)
    assert flat(plan.path) == approx_path(((20.0, 0.0, -6.0), (30.0, 5.0, -4.0))) and plan.destination == (30.0, 5.0)
    plan = plan_return(2, (29.0, 5.0, -4.0), HOME_NED, (), unplaced_land, mission_seq=4)
    assert plan.destination == (30.0, 5.0)
    plan = plan_return(2, (29.0, 6.0, -4.0), HOME_NED, (), unplaced_land, mission_seq=5)
    assert plan.path == () and plan.destination == (29.0, 6.0)


def test_the_nearest_item_and_rally_point_are_nearest_across_as_well_as_along():
    across = (local_item(0, NAV_WAYPOINT, 10.0, 0.0, alt=5.0), local_item(1, NAV_WAYPOINT, 12.0, 8.0, alt=5.0),
              local_item(2, NAV_LAND, 14.0, 8.0))
    assert plan_return(2, (10.5, 7.0, -3.0), HOME_NED, (), across).flying == \
        "following the mission from item 1 to its landing"
    spread = (rally(0, 30.0, 7.0), rally(1, 15.0, 8.0), rally(2, 10.0, 30.0))
    assert plan_return(1, (10.0, 7.0, -3.0), HOME_NED, spread, ()).flying == "flying to rally point 1"
    assert plan_return(1, (-10.0, -7.0, -3.0), HOME_NED, (rally(0, -12.0, -9.0), rally(1, 12.0, 9.0)),
                       ()).flying == "flying to rally point 0"


def test_a_tie_between_a_safe_point_and_the_landing_goes_to_the_landing():
    assert plan_return(3, (15.0, 2.5, -3.0), HOME_NED, (), MISSION).mission_landing     # 15.2 m either way
    near = plan_return(3, (15.0, 2.4, -3.0), HOME_NED, (), MISSION)
    assert near.destination == (0.0, 0.0) and not near.mission_landing
    plan = plan_return(3, (20.0, 0.0, -5.0), HOME_NED, (rally(0, 21.0, 1.0),), MISSION)
    assert plan.destination == pytest.approx((21.0, 1.0), abs=0.01)


def test_a_return_from_another_mode_follows_the_mission_from_the_nearest_item():
    c = commander_with(2)
    assert c.set_mode(FlightMode.AUTO_LOITER, air(0.5, 12.0, 1.0, -5.0)).accepted
    assert c.set_mode(FlightMode.AUTO_RTL, air(1.0, 12.0, 1.0, -5.0)).accepted
    assert c.messages[-1] == (mavlink.MAV_SEVERITY_INFO,
                              "Return: following the mission from item 1 to its landing at 8.0 m above home")


def test_a_return_on_the_land_item_from_mission_mode_flies_no_path_and_keeps_its_altitude():
    c = commander_with(2)
    assert c.set_mode(FlightMode.AUTO_MISSION, air(0.5, 0.0, 0.0, -5.0)).accepted
    assert c.set_mission_current(5, air(0.6, 29.0, 9.0, -4.5)).accepted
    assert c.set_mode(FlightMode.AUTO_RTL, air(1.0, 29.0, 9.0, -4.5)).accepted
    assert c.messages[-1] == (mavlink.MAV_SEVERITY_INFO, "Return: following the mission from item 5 to its landing")
    assert c.update(air(2.0, 29.0, 9.0, -4.5)).setpoint.position == pytest.approx((30.0, 10.0, -4.5))


def test_a_path_point_is_reached_at_exactly_nav_acc_rad():
    c = commander_with(1)
    c.params.set("NAV_ACC_RAD", 0.5)
    assert c.set_mode(FlightMode.AUTO_RTL, air(1.0, 26.0, 0.0, -8.0)).accepted
    assert c.update(air(2.0, 26.0, 0.0, -8.0)).setpoint.position == pytest.approx((30.0, 5.0, -8.0))
    assert c.update(air(3.0, 30.0, 5.5, -8.0)).setpoint.position == pytest.approx((30.0, 5.0, -4.0))

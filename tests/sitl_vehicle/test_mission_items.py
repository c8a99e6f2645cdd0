"""The mission items beyond the flight path that MAVSDK's Mission plugin and QGroundControl add: DO_CHANGE_SPEED
(the speed of the items after it), NAV_DELAY and NAV_LOITER_TIME (holds), and camera and gimbal items, which the
vehicle, carrying no payload, flies past and says so."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.commander import Commander
from sitl_vehicle.mission import (
    DO_CHANGE_SPEED,
    DO_JUMP,
    DO_SET_ROI_LOCATION,
    DO_SET_ROI_NONE,
    NAV_DELAY,
    NAV_LOITER_TIME,
    NAV_LOITER_UNLIM,
    NAV_TAKEOFF,
    NAV_WAYPOINT,
    MissionError,
    MissionItem,
    check_mission,
    mission_item_from_message,
    passed_items_note,
)
from sitl_vehicle.modes import FlightMode
from sitl_vehicle.params import COMMANDER_PARAMS, ParameterStore
from sitl_vehicle.sim import Setpoint, VehicleConfig, VehicleSim
from tests.sitl_vehicle.test_mission import HOME, air, item_msg, local_item, status

MISSION_FRAME = mavlink.MAV_FRAME_MISSION


def command_item(seq, command, params, alt=math.nan):
    """A placeless item as MAVSDK sends it: MAV_FRAME_MISSION, no coordinates, altitude NaN."""
    return mission_item_from_message(item_msg(seq, command, alt=alt, frame=MISSION_FRAME, params=params, here=True),
                                     HOME.to_local)


def speed_item(seq, speed, kind=1.0) -> MissionItem:
    return command_item(seq, DO_CHANGE_SPEED, (kind, speed, -1.0, 0.0))


def test_speed_delay_loiter_and_payload_items_are_read_as_px4_reads_them():
    assert speed_item(1, 3.0).speed == 3.0 and speed_item(1, 3.0, kind=0.0).speed == 3.0   # ground or air speed
    assert math.isnan(speed_item(1, -2.0).speed)                                          # back to the default
    assert speed_item(1, -1.0).speed is None and speed_item(1, 3.0, kind=2.0).speed is None   # no change; climb
    assert local_item(0, NAV_WAYPOINT, 1.0, 1.0).speed is None
    delay = command_item(2, NAV_DELAY, (2.5, -1.0, -1.0, -1.0))
    assert delay.hold_s == 2.5 and math.isnan(delay.north) and math.isnan(delay.yaw)
    loiter = mission_item_from_message(item_msg(3, NAV_LOITER_TIME, north=4.0, params=(3.0, 0.0, 0.0, 1.0)),
                                       HOME.to_local)
    assert loiter.hold_s == 3.0 and loiter.north == pytest.approx(4.0, abs=0.01) and math.isnan(loiter.yaw)
    photo = command_item(4, mavlink.MAV_CMD_IMAGE_START_CAPTURE, (0.0, 0.0, 1.0, 0.0))
    assert photo.name == "IMAGE_START_CAPTURE" and math.isnan(photo.north)
    back = photo.to_message(False, 1, 1)
    assert (back.command, back.frame, back.x, back.y) == (mavlink.MAV_CMD_IMAGE_START_CAPTURE, MISSION_FRAME, 0, 0)


@pytest.mark.parametrize("msg, result, text", [
    (item_msg(0, DO_CHANGE_SPEED, frame=MISSION_FRAME, params=(1.0, 0.0, -1.0, 0.0), here=True),
     mavlink.MAV_MISSION_INVALID_PARAM2, "DO_CHANGE_SPEED's speed (param2) is 0.0; send m/s above 0"),
    (item_msg(0, DO_CHANGE_SPEED, frame=MISSION_FRAME, params=(1.0, math.nan, -1.0, 0.0), here=True),
     mavlink.MAV_MISSION_INVALID_PARAM2, "DO_CHANGE_SPEED's speed (param2) is nan"),
    (item_msg(0, NAV_DELAY, frame=MISSION_FRAME, params=(-1.0, 12.0, 30.0, 0.0), here=True),
     mavlink.MAV_MISSION_INVALID_PARAM1, "a time of day to wait for is not supported"),
    (item_msg(0, NAV_LOITER_TIME, frame=MISSION_FRAME, params=(3.0, 0.0, 0.0, 0.0), here=True),
     mavlink.MAV_MISSION_UNSUPPORTED_FRAME, "frame 2 is not supported"),      # a loiter has a place
    (item_msg(0, NAV_LOITER_TIME, params=(3.0, 0.0, 0.0, 0.0), here=True),
     mavlink.MAV_MISSION_INVALID_PARAM5_X, "NAV_LOITER_TIME needs a latitude and longitude"),
    (item_msg(0, NAV_WAYPOINT, north=1.0, alt=math.nan), mavlink.MAV_MISSION_INVALID_PARAM7, "altitude is nan"),
    (item_msg(0, DO_SET_ROI_LOCATION, here=True), mavlink.MAV_MISSION_INVALID_PARAM5_X,
     "DO_SET_ROI_LOCATION needs a latitude and longitude"),                   # a region of interest is a place
])
def test_bad_items_are_refused_with_the_reason(msg, result, text):
    with pytest.raises(MissionError) as info:
        mission_item_from_message(msg, HOME.to_local)
    assert info.value.result == result and text in str(info.value)


def test_an_upload_says_which_items_it_flies_past():
    items = [local_item(0, NAV_WAYPOINT, 1.0, 0.0), speed_item(1, 2.0),
             command_item(2, mavlink.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, (-30.0, 0.0, math.nan, math.nan)),
             command_item(3, mavlink.MAV_CMD_IMAGE_START_CAPTURE, (0.0, 0.0, 1.0, 0.0)),
             command_item(4, mavlink.MAV_CMD_IMAGE_START_CAPTURE, (0.0, 2.0, 0.0, 0.0)), speed_item(5, 1.0, kind=2.0)]
    assert passed_items_note(items) == (
        "Mission: 4 items with nothing to act on here (no camera, gimbal or climb speed model), flown past: "
        "DO_CHANGE_SPEED of a climb or descent speed, DO_GIMBAL_MANAGER_PITCHYAW, IMAGE_START_CAPTURE")
    assert passed_items_note(items[:2]) is None
    assert passed_items_note(items[:3]).startswith("Mission: 1 item with nothing")


def flying(items) -> Commander:
    c = Commander(ParameterStore(COMMANDER_PARAMS))
    c.set_mission(items, status(0))
    assert c.arm(status(0)).accepted
    assert c.set_mode(FlightMode.AUTO_MISSION, air(0.5)).accepted
    return c


def test_a_speed_change_sets_the_speed_of_the_items_after_it_until_changed_back():
    c = flying([local_item(0, NAV_WAYPOINT, 2.0, 0.0), speed_item(1, 0.8), local_item(2, NAV_WAYPOINT, 4.0, 0.0),
                speed_item(3, -1.0), local_item(4, NAV_WAYPOINT, 6.0, 0.0), speed_item(5, -2.0),
                local_item(6, NAV_WAYPOINT, 8.0, 0.0)])
    assert math.isnan(c.update(air(1.0)).setpoint.cruise_speed)                   # the default to the first item
    out = c.update(air(2.0, x=2.0))                                               # reached; the speed item acts
    assert out.setpoint.position == (4.0, 0.0, -2.0) and out.setpoint.cruise_speed == 0.8
    assert list(c.mission_reached) == [0, 1]
    assert c.update(air(3.0, x=4.0)).setpoint.cruise_speed == 0.8                 # -1: no change
    out = c.update(air(4.0, x=6.0))
    assert out.setpoint.position == (8.0, 0.0, -2.0) and math.isnan(out.setpoint.cruise_speed)   # -2: default
    c.update(air(5.0, x=8.0))
    assert c.mission_finished
    c.set_mission([local_item(0, NAV_WAYPOINT, 2.0, 0.0), speed_item(1, 0.8)], air(6.0, x=8.0))
    assert c.set_mode(FlightMode.AUTO_MISSION, air(6.5, x=8.0)).accepted
    c.update(air(7.0, x=2.0))                                                     # the last item is a speed
    assert c.mission_finished and c.update(air(7.5, x=2.0)).setpoint.position == (2.0, 0.0, -2.0)
    assert c.update(air(8.0, x=2.0)).setpoint.cruise_speed == 0.8
    assert c.set_mode(FlightMode.AUTO_MISSION, air(8.5)).accepted                 # entered again: from item 0,
    assert math.isnan(c.update(air(9.0)).setpoint.cruise_speed)                    # at the default speed


def test_a_delay_holds_at_the_item_before_it_for_param1_seconds():
    c = flying([local_item(0, NAV_WAYPOINT, 2.0, 0.0), command_item(1, NAV_DELAY, (1.5, -1.0, -1.0, -1.0)),
                local_item(2, NAV_WAYPOINT, 4.0, 0.0)])
    out = c.update(air(1.0, x=1.95))                                              # within NAV_ACC_RAD: the delay
    assert out.setpoint.position == (2.0, 0.0, -2.0) and list(c.mission_reached) == [0, 1]
    assert c.update(air(2.4, x=1.95)).setpoint.position == (2.0, 0.0, -2.0)       # 1.4 s
    assert c.update(air(2.5, x=1.95)).setpoint.position == (4.0, 0.0, -2.0)       # 1.5 s: on
    c = flying([command_item(0, NAV_DELAY, (1.0, -1.0, -1.0, -1.0)), local_item(1, NAV_WAYPOINT, 4.0, 0.0)])
    assert c.update(air(1.0, x=0.3)).setpoint.position == (0.0, 0.0, -2.0)        # first: where Mission began


def test_a_loiter_time_flies_to_its_place_and_holds_there():
    c = flying([local_item(0, NAV_TAKEOFF, alt=2.0), MissionItem(1, NAV_LOITER_TIME, 6, (2.0, 0.0, 0.0, 0.0),
                                                                 0.0, 0.0, 3.0, 3.0, 1.0, True, math.nan)])
    out = c.update(air(1.0))
    assert out.setpoint.position == (3.0, 1.0, -3.0) and math.isnan(out.setpoint.yaw) is False
    c.update(air(2.0, 3.0, 1.0, -3.0))
    c.update(air(3.9, 3.0, 1.0, -3.0))
    assert not c.mission_finished
    c.update(air(4.0, 3.0, 1.0, -3.0))
    assert c.mission_finished


def test_the_vehicle_cruises_at_a_setpoints_speed_capped_at_mpc_xy_vel_max():
    from tests.sitl_vehicle.test_sim import _stream

    def top_speed(setpoint: Setpoint, config: VehicleConfig | None = None) -> float:
        """The median horizontal speed over seconds 4-8 of the move: its cruise."""
        sim = VehicleSim(config or VehicleConfig(noise=None), initial_position=(0.0, 0.0, -2.0))
        sim.set_armed(True)
        flown = _stream(sim, setpoint, 8.0)
        return float(np.median(np.hypot(flown[len(flown) // 2:, 3], flown[len(flown) // 2:, 4])))

    far = (30.0, 0.0, -2.0)
    default = top_speed(Setpoint(position=far))
    assert default == pytest.approx(VehicleConfig().planner.v_max_xy, rel=0.05)        # MPC_XY_CRUISE
    assert top_speed(Setpoint(position=far, cruise_speed=0.8)) == pytest.approx(0.8, rel=0.05)
    capped = VehicleConfig(noise=None)
    capped = replace(capped, control=replace(capped.control, vel_max_xy=1.2))
    assert top_speed(Setpoint(position=far, cruise_speed=5.0), capped) == pytest.approx(1.2, rel=0.05)


def test_a_new_cruise_speed_applies_to_the_move_under_way_as_px4s_do_change_speed_does():
    from tests.sitl_vehicle.test_sim import _stream

    sim = VehicleSim(VehicleConfig(noise=None), initial_position=(0.0, 0.0, -2.0))
    sim.set_armed(True)
    far = (30.0, 0.0, -2.0)
    _stream(sim, Setpoint(position=far), 4.0)                           # cruising at MPC_XY_CRUISE
    assert sim.truth.velocity[0] == pytest.approx(VehicleConfig().planner.v_max_xy, rel=0.05)
    flown = _stream(sim, Setpoint(position=far, cruise_speed=0.7), 4.0)  # the same target, slower
    assert np.hypot(flown[-40:, 3], flown[-40:, 4]) == pytest.approx(0.7, rel=0.05)


def test_payload_items_last_hold_at_the_waypoint_before_them_as_mavsdk_missions_end():
    c = flying([local_item(0, NAV_WAYPOINT, 2.0, 0.0),
                command_item(1, mavlink.MAV_CMD_IMAGE_START_CAPTURE, (0.0, 0.0, 1.0, 0.0)),
                command_item(2, mavlink.MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE, (-3.0, -3.0, -1.0, -1.0))])
    out = c.update(air(1.0, x=1.95))                                  # within NAV_ACC_RAD, still moving
    assert c.mission_finished and list(c.mission_reached) == [0, 1, 2]
    assert out.setpoint.position == (2.0, 0.0, -2.0)                  # on to the waypoint, not stopped short


def jump_item(seq, target, repeat):
    return command_item(seq, DO_JUMP, (float(target), float(repeat), 0.0, 0.0))


def test_a_jump_goes_back_its_repeat_count_then_on_and_again_when_the_mission_restarts():
    c = flying([local_item(0, NAV_WAYPOINT, 2.0, 0.0), local_item(1, NAV_WAYPOINT, 4.0, 0.0), jump_item(2, 0, 2),
                local_item(3, NAV_WAYPOINT, 6.0, 0.0)])
    targets = []
    for t, x in enumerate((2.0, 4.0, 2.0, 4.0, 2.0, 4.0, 6.0), start=1):
        targets.append(c.update(air(float(t), x=x)).setpoint.position[0])
    assert targets == [4.0, 2.0, 4.0, 2.0, 4.0, 6.0, 6.0] and c.mission_finished      # back twice, then on
    assert c.set_mode(FlightMode.AUTO_MISSION, air(8.0)).accepted                     # a new run: the count anew
    assert [c.update(air(float(t), x=x)).setpoint.position[0] for t, x in ((9, 2.0), (10, 4.0))] == [4.0, 2.0]
    c = flying([local_item(0, NAV_WAYPOINT, 2.0, 0.0), jump_item(1, 0, 1), local_item(2, NAV_WAYPOINT, 6.0, 0.0)])
    assert [c.update(air(float(t), x=2.0)).setpoint.position[0] for t in (1, 2)] == [2.0, 6.0]   # back once


def test_a_loiter_unlimited_holds_at_its_place_until_told_otherwise():
    loiter = MissionItem(1, NAV_LOITER_UNLIM, 6, (0.0, 0.0, 0.0, 90.0), 0.0, 0.0, 3.0, 3.0, 1.0, True, math.nan)
    assert math.isinf(loiter.hold_s) and loiter.yaw == pytest.approx(math.pi / 2)
    c = flying([local_item(0, NAV_TAKEOFF, alt=2.0), loiter, local_item(2, NAV_WAYPOINT, 6.0, 0.0)])
    assert c.update(air(1.0)).setpoint.position == (3.0, 1.0, -3.0)
    for t in (2.0, 100.0, 10_000.0):
        assert c.update(air(t, 3.0, 1.0, -3.0)).setpoint.position == (3.0, 1.0, -3.0)
    assert c.mission_seq == 1 and not c.mission_finished
    assert c.set_mission_current(2, air(10_001.0, 3.0, 1.0, -3.0)).accepted          # told to go on
    assert c.update(air(10_002.0, 3.0, 1.0, -3.0)).setpoint.position == (6.0, 0.0, -2.0)


@pytest.mark.parametrize("items, text", [
    ([local_item(0, NAV_WAYPOINT, 1.0, 0.0), jump_item(1, 5, 1)],
     "mission item 1: DO_JUMP to item 5, which the 2-item mission lacks; send the index of another item"),
    ([local_item(0, NAV_WAYPOINT, 1.0, 0.0), jump_item(1, 1, 1)],
     "mission item 1: DO_JUMP to item 1, which is the jump itself; send the index of another item"),
    ([local_item(0, NAV_WAYPOINT, 1.0, 0.0), speed_item(1, 2.0), jump_item(2, 1, 3)],
     "mission item 2: DO_JUMP back to item 1 passes no item that flies (it would loop in place); jump to a waypoint"),
])
def test_a_jump_nowhere_or_in_place_refuses_the_mission(items, text):
    with pytest.raises(MissionError) as info:
        check_mission(items)
    assert info.value.result == mavlink.MAV_MISSION_INVALID_SEQUENCE and str(info.value) == text


def test_jumps_forward_and_back_over_a_waypoint_pass_the_check():
    check_mission([jump_item(0, 2, 1), local_item(1, NAV_WAYPOINT, 1.0, 0.0), jump_item(2, 1, 0)])
    with pytest.raises(MissionError, match="send whole numbers, 0 or more"):
        command_item(0, DO_JUMP, (1.5, 1.0, 0.0, 0.0))
    with pytest.raises(MissionError, match=r"DO_JUMP's item \(param1\) and repeat count \(param2\) are 1.0 and -1.0"):
        command_item(0, DO_JUMP, (1.0, -1.0, 0.0, 0.0))


def test_a_mission_with_a_jump_nowhere_is_refused_over_mavlink_and_the_old_one_kept(make_vehicle):
    from tests.sitl_vehicle.test_mission import upload

    server, client = make_vehicle()
    assert upload(client, [item_msg(0, NAV_WAYPOINT, north=1.0)]) == mavlink.MAV_MISSION_ACCEPTED
    jump = item_msg(1, DO_JUMP, frame=MISSION_FRAME, params=(7.0, 1.0, 0.0, 0.0), here=True)
    assert upload(client, [item_msg(0, NAV_WAYPOINT, north=2.0), jump]) == mavlink.MAV_MISSION_INVALID_SEQUENCE
    assert "DO_JUMP to item 7, which the 2-item mission lacks" in client.statustext("Mission refused", 3)
    assert len(server.commander.mission) == 1 and server.commander.mission[0].north == pytest.approx(1.0, abs=0.01)


def test_a_region_of_interest_turns_the_vehicle_to_it_until_cleared():
    """DO_SET_ROI_LOCATION (as QGroundControl plans it, in a global frame) turns the vehicle to face its place for
    the items after it, the waypoints' own headings overridden; DO_SET_ROI_NONE ends it, the heading kept."""
    roi = mission_item_from_message(item_msg(1, DO_SET_ROI_LOCATION, north=2.0, east=10.0, alt=0.0), HOME.to_local)
    assert roi.name == "DO_SET_ROI_LOCATION" and (roi.north, roi.east) == pytest.approx((2.0, 10.0), abs=0.02)
    # DO_SET_ROI_NONE sent with a place, which it does not use
    none = mission_item_from_message(item_msg(3, DO_SET_ROI_NONE, north=6.0, east=-5.0), HOME.to_local)
    c = flying([local_item(0, NAV_WAYPOINT, 2.0, 0.0), roi, local_item(2, NAV_WAYPOINT, 6.0, 0.0, yaw_deg=180.0),
                none, local_item(4, NAV_WAYPOINT, 8.0, 0.0), local_item(5, NAV_WAYPOINT, 2.0, 10.0)])
    assert c.update(air(1.0)).setpoint.yaw == 0.0                                  # no region yet: as it was
    out = c.update(air(2.0, x=2.0))                                               # reached; the region is set
    assert out.setpoint.position == (6.0, 0.0, -2.0) and out.setpoint.yaw == pytest.approx(math.pi / 2, abs=0.01)
    facing = c.update(air(3.0, x=4.0, y=1.0)).setpoint.yaw
    assert facing == pytest.approx(math.atan2(9.0, -2.0), abs=0.01)               # still facing it, not param4
    out = c.update(air(4.0, x=6.0))                                               # reached; the region cleared
    assert out.setpoint.position == (8.0, 0.0, -2.0) and out.setpoint.yaw == facing   # the heading kept
    assert c.update(air(5.0, x=7.0)).setpoint.yaw == facing
    c.set_mission([local_item(0, NAV_WAYPOINT, 2.0, 0.0), roi, local_item(2, NAV_WAYPOINT, 2.0, 10.0)], air(6.0))
    assert c.set_mode(FlightMode.AUTO_MISSION, air(6.5)).accepted
    c.update(air(7.0, x=2.0))
    assert c.update(air(8.0, x=2.0, y=9.99)).setpoint.yaw == pytest.approx(math.pi / 2, abs=0.01)   # over it: kept
    assert c.update(air(8.5, x=0.0, y=10.0)).setpoint.yaw == pytest.approx(0.0, abs=0.01)    # 2 m south: north
    c.set_mission([local_item(0, NAV_WAYPOINT, 2.0, 0.0)], air(9.0))             # a new mission: no region
    from sitl_vehicle.commander_types import VehicleStatus

    turned = VehicleStatus(time_s=9.5, position=(0.0, 0.0, -2.0), velocity=(0.0, 0.0, 0.0), yaw=0.3, armed=True,
                           landed=False)
    assert c.set_mode(FlightMode.AUTO_MISSION, turned).accepted
    assert c.update(air(10.0, x=1.0)).setpoint.yaw == pytest.approx(0.3)

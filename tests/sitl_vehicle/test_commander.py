"""The commander's PX4 semantics, case by case, with no vehicle and no sockets."""

from __future__ import annotations

import math

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.commander import Commander, Reply, VehicleStatus
from sitl_vehicle.modes import FlightMode, UnsupportedMode, decode_custom_mode, mode_from_custom
from sitl_vehicle.params import COMMANDER_PARAMS, ParameterError, ParameterStore
from sitl_vehicle.sim import Setpoint


def status(t=0.0, z=0.0, landed=True, vel=(0.0, 0.0, 0.0), **kw) -> VehicleStatus:
    return VehicleStatus(time_s=t, position=(0.0, 0.0, z), velocity=vel, yaw=0.0, armed=kw.pop("armed", False),
                         landed=landed, **kw)


@pytest.fixture
def commander():
    return Commander(ParameterStore(COMMANDER_PARAMS))


def test_boots_disarmed_in_hold(commander):
    out = commander.update(status())
    assert not out.armed and out.mode is FlightMode.AUTO_LOITER


@pytest.mark.parametrize("kwargs, reason", [
    (dict(crashed=True), "crashed"),
    (dict(position_valid=False), "position estimate"),
    (dict(landed=False, z=-1.0), "not landed"),
])
def test_arming_refused_with_reason(commander, kwargs, reason):
    reply = commander.arm(status(**kwargs))
    assert reply.result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED and reason in reply.text
    assert not commander.armed and any(reason in text for _, text in commander.messages)


def test_force_arm_skips_checks(commander):
    assert commander.arm(status(position_valid=False), force=True).accepted and commander.armed


def test_disarm_in_air_denied_unless_forced(commander):
    commander.arm(status())
    assert commander.disarm(status(landed=False, z=-2)).result == mavlink.MAV_RESULT_DENIED
    assert commander.disarm(status(landed=False, z=-2), force=True).accepted and not commander.armed


def test_takeoff_requires_arming_and_uses_mis_takeoff_alt(commander):
    assert commander.takeoff(status(), math.nan).result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    commander.arm(status())
    assert commander.takeoff(status(), math.nan).accepted
    out = commander.update(status(t=0.1))
    assert out.mode is FlightMode.AUTO_TAKEOFF and out.setpoint.position == (0.0, 0.0, -2.5)
    # Reaching the altitude (within NAV_ACC_RAD) switches to Hold at the takeoff point.
    out = commander.update(status(t=3.0, z=-2.45, landed=False))
    assert out.mode is FlightMode.AUTO_LOITER and out.setpoint.position == (0.0, 0.0, -2.5)


def test_offboard_needs_a_live_stream(commander):
    reply = commander.set_mode(FlightMode.OFFBOARD, status(t=5.0))
    assert reply.result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    sp = Setpoint(position=(1.0, 0.0, -1.0))
    commander.offboard_setpoint(sp, 4.5)
    assert commander.set_mode(FlightMode.OFFBOARD, status(t=5.0)).accepted
    assert commander.update(status(t=5.2)).setpoint == sp


@pytest.mark.parametrize("action, expected", [(5.0, FlightMode.AUTO_LOITER), (4.0, FlightMode.AUTO_LAND),
                                              (3.0, FlightMode.AUTO_RTL), (0.0, FlightMode.AUTO_LOITER)])
def test_offboard_loss_failsafe_action(commander, action, expected):
    commander.params.set("COM_OBL_RC_ACT", action)
    commander.offboard_setpoint(Setpoint(position=(0.0, 0.0, -1.0)), 0.0)
    commander.arm(status())
    commander.set_mode(FlightMode.OFFBOARD, status(t=0.1))
    assert commander.update(status(t=0.9, z=-1, landed=False)).mode is FlightMode.OFFBOARD
    out = commander.update(status(t=1.05, z=-1, landed=False))  # 1.05 s > COM_OF_LOSS_T since the last one
    assert out.mode is expected and commander.failsafe
    assert any("Failsafe" in text for _, text in commander.messages)


def test_hold_stops_ahead_instead_of_going_back(commander):
    commander.arm(status())
    commander.set_mode(FlightMode.AUTO_LOITER, status(t=1.0, z=-1.0, landed=False, vel=(2.0, 0.0, 0.0)))
    out = commander.update(status(t=1.0, z=-1.0, landed=False, vel=(2.0, 0.0, 0.0)))
    assert out.setpoint.position[0] == pytest.approx(1.0)  # v²/2a with a = 2 m/s²


def test_land_descends_then_auto_disarms(commander):
    commander.arm(status())
    commander.update(status(t=0.5, z=-1.0, landed=False))
    commander.land(status(t=1.0, z=-1.0, landed=False))
    out = commander.update(status(t=1.0, z=-1.0, landed=False))
    assert math.isnan(out.setpoint.position[2]) and out.setpoint.velocity[2] == pytest.approx(0.7)
    commander.update(status(t=3.0, landed=True))
    assert commander.armed  # COM_DISARM_LAND = 2 s not yet over
    out = commander.update(status(t=5.01, landed=True))
    assert not out.armed


def at(t, x, y, z, landed=False, **kw) -> VehicleStatus:
    return VehicleStatus(time_s=t, position=(x, y, z), velocity=(0.0, 0.0, 0.0), yaw=0.0, armed=True,
                         landed=landed, **kw)


def test_home_is_where_the_vehicle_armed(commander):
    commander.arm(at(0.0, 1.0, 2.0, -0.01, landed=True))
    assert commander.home == (1.0, 2.0, -0.01)
    commander.takeoff(at(0.1, 1.0, 2.0, -0.01, landed=True), math.nan)
    assert commander.update(at(0.2, 1.0, 2.0, -0.01, landed=True)).setpoint.position == (1.0, 2.0, -2.51)


def test_return_climbs_flies_home_descends_waits_and_lands(commander):
    for name, value in (("RTL_RETURN_ALT", 5.0), ("RTL_DESCEND_ALT", 3.0), ("RTL_LAND_DELAY", 1.0)):
        commander.params.set(name, value)
    commander.arm(at(0.0, 0.0, 0.0, 0.0, landed=True))
    assert commander.return_to_launch(at(0.5, 0.0, 0.0, 0.0, landed=True)).result == \
        mavlink.MAV_RESULT_TEMPORARILY_REJECTED                  # on the ground: nothing to return from
    assert commander.return_to_launch(at(10.0, 4.0, 3.0, -2.0)).accepted
    legs = [
        (at(10.1, 4.0, 3.0, -2.0), (4.0, 3.0, -5.0)),           # climb where it is
        (at(13.0, 4.0, 3.0, -4.95), (0.0, 0.0, -5.0)),          # at altitude: fly home
        (at(16.0, 2.0, 1.5, -5.0), (0.0, 0.0, -5.0)),
        (at(19.0, 0.05, 0.0, -5.0), (0.0, 0.0, -3.0)),          # over home: descend to RTL_DESCEND_ALT
        (at(21.0, 0.0, 0.0, -3.02), (0.0, 0.0, -3.0)),          # there: wait RTL_LAND_DELAY
        (at(21.9, 0.0, 0.0, -3.0), (0.0, 0.0, -3.0)),
    ]
    for state, target in legs:
        out = commander.update(state)
        assert out.mode is FlightMode.AUTO_RTL and out.setpoint.position == pytest.approx(target), state
        assert not commander.landing
    out = commander.update(at(22.1, 0.0, 0.0, -3.0))
    assert commander.landing and math.isnan(out.setpoint.position[2]) and out.setpoint.position[:2] == (0.0, 0.0)
    assert out.setpoint.velocity[2] == pytest.approx(0.7)
    texts = [text for _, text in commander.messages]
    assert any("Return: flying home at 5.0 m" in t for t in texts) and "Return: landing at home" in texts
    commander.update(at(26.0, 0.0, 0.0, 0.0, landed=True))
    assert not commander.update(at(28.1, 0.0, 0.0, 0.0, landed=True)).armed          # COM_DISARM_LAND
    assert "Return mode is not armable" in commander.arm(at(30.0, 0.0, 0.0, 0.0, landed=True)).text


def test_return_from_above_the_return_altitude_keeps_it_and_never_climbs_to_descend(commander):
    commander.params.set("RTL_RETURN_ALT", 5.0)
    commander.params.set("RTL_DESCEND_ALT", 30.0)           # higher than the return altitude: stay at 8 m
    commander.arm(at(0.0, 0.0, 0.0, 0.0, landed=True))
    commander.set_mode(FlightMode.AUTO_RTL, at(1.0, 3.0, 0.0, -8.0))
    assert commander.update(at(1.1, 3.0, 0.0, -8.0)).setpoint.position == (0.0, 0.0, -8.0)
    out = commander.update(at(5.0, 0.0, 0.0, -8.0))        # home, already at the descend altitude and
    assert commander.landing and out.setpoint.position[:2] == (0.0, 0.0)   # RTL_LAND_DELAY 0: land now


@pytest.mark.parametrize("action, mode", [(1.0, FlightMode.AUTO_LOITER), (2.0, FlightMode.AUTO_RTL),
                                          (3.0, FlightMode.AUTO_LAND)])
def test_data_link_loss_failsafe_after_com_dl_loss_t(commander, action, mode):
    commander.params.set("NAV_DLL_ACT", action)
    commander.params.set("COM_FAIL_ACT_T", 0.0)                         # act at once (the delay: below)
    commander.arm(at(0.0, 0.0, 0.0, 0.0, landed=True))
    commander.offboard_setpoint(Setpoint(position=(1.0, 0.0, -2.0)), 0.5)
    commander.set_mode(FlightMode.OFFBOARD, at(0.5, 0.0, 0.0, 0.0, landed=True))
    commander.gcs_heartbeat(1.0)
    for t in (2.0, 5.0, 11.0):
        commander.offboard_setpoint(Setpoint(position=(1.0, 0.0, -2.0)), t)
        assert commander.update(at(t, 1.0, 0.0, -2.0)).mode is FlightMode.OFFBOARD      # 10 s not yet over
    commander.offboard_setpoint(Setpoint(position=(1.0, 0.0, -2.0)), 11.1)
    out = commander.update(at(11.1, 1.0, 0.0, -2.0))
    assert out.mode is mode and commander.failsafe
    texts = [text for _, text in commander.messages]
    assert "Connection to ground station lost" in texts and any("data link lost" in t for t in texts)
    commander.gcs_heartbeat(12.0)
    assert commander.messages[-1][1] == "Data link regained"
    assert commander.update(at(12.1, 1.0, 0.0, -2.0)).mode is mode      # PX4 stays in the failsafe mode


def _hold_with_return_on_link_loss_and_land_on_stick_loss(commander) -> None:
    """Armed and holding at 2 m, a ground station heard at t=0; data-link loss acts Return, manual-control loss Land."""
    commander.params.set("NAV_DLL_ACT", 2.0)                            # Return
    commander.params.set("NAV_RCL_ACT", 3.0)                            # Land
    commander.arm(at(0.0, 0.0, 0.0, 0.0, landed=True))
    commander.gcs_heartbeat(0.0)
    commander.set_mode(FlightMode.AUTO_LOITER, at(0.0, 0.0, 0.0, -2.0))


def test_data_link_loss_holds_com_fail_act_t_first_and_the_worse_of_two_losses_wins(commander):
    from sitl_vehicle.manual import Sticks

    _hold_with_return_on_link_loss_and_land_on_stick_loss(commander)
    out = commander.update(at(10.5, 0.0, 0.0, -2.0))                   # data link lost: Return in 5 s
    assert out.mode is FlightMode.AUTO_LOITER and commander.failsafe
    assert commander.messages[-1][1] == "Failsafe: data link lost, switching to Return in 5 s (Hold until then)"
    commander.manual_control(Sticks(), 11.0)                            # sticks heard, then silent: Land is worse
    out = commander.update(at(12.0, 0.0, 0.0, -2.0))
    assert out.mode is FlightMode.AUTO_LOITER
    assert commander.messages[-1][1] == "Failsafe: manual control lost, switching to Land in 4 s"
    assert commander.update(at(15.4, 0.0, 0.0, -2.0)).mode is FlightMode.AUTO_LOITER
    assert commander.update(at(15.6, 0.0, 0.0, -2.0)).mode is FlightMode.AUTO_LAND   # the first deadline
    assert commander.messages[-1][1] == "Failsafe: switching to Land"


def test_offboard_loss_does_not_wait_com_fail_act_t(commander):
    commander.params.set("COM_OBL_RC_ACT", 3.0)                         # Return
    commander.arm(at(0.0, 0.0, 0.0, 0.0, landed=True))
    commander.offboard_setpoint(Setpoint(position=(1.0, 0.0, -2.0)), 0.5)
    commander.set_mode(FlightMode.OFFBOARD, at(0.5, 0.0, 0.0, 0.0, landed=True))
    assert commander.update(at(2.0, 1.0, 0.0, -2.0)).mode is FlightMode.AUTO_RTL  # PX4: a mode fallback


def test_data_link_loss_is_only_reported_when_disabled_never_connected_or_landed(commander):
    commander.arm(at(0.0, 0.0, 0.0, 0.0, landed=True))
    commander.set_mode(FlightMode.AUTO_LOITER, at(0.0, 0.0, 0.0, -2.0))
    assert commander.update(at(60.0, 0.0, 0.0, -2.0)).mode is FlightMode.AUTO_LOITER   # no GCS ever: nothing
    assert not commander.messages or "ground station" not in commander.messages[-1][1]
    commander.gcs_heartbeat(60.0)
    out = commander.update(at(71.0, 0.0, 0.0, -2.0))                   # NAV_DLL_ACT 0 (PX4's default)
    assert out.mode is FlightMode.AUTO_LOITER and not commander.failsafe
    assert commander.messages[-1][1] == "Connection to ground station lost"
    commander.params.set("NAV_DLL_ACT", 6.0)                            # disarm, but only in the air
    commander.gcs_heartbeat(72.0)
    assert commander.update(at(83.0, 0.0, 0.0, 0.0, landed=True)).armed
    commander.gcs_heartbeat(84.0)
    assert not commander.update(at(95.0, 0.0, 0.0, -2.0)).armed


def test_data_link_loss_never_acts_in_land_nor_in_modes_com_dll_except_excepts(commander):
    commander.params.set("NAV_DLL_ACT", 2.0)                            # Return
    commander.arm(at(0.0, 0.0, 0.0, 0.0, landed=True))
    commander.gcs_heartbeat(0.0)
    commander.land(at(1.0, 0.0, 0.0, -2.0))
    out = commander.update(at(11.0, 0.0, 0.0, -2.0))
    assert out.mode is FlightMode.AUTO_LAND and not commander.failsafe
    assert commander.messages[-1][1] == "Connection to ground station lost"

    excepted = Commander(ParameterStore(COMMANDER_PARAMS))
    excepted.params.set("NAV_DLL_ACT", 3.0)                             # Land
    excepted.params.set("COM_FAIL_ACT_T", 0.0)
    excepted.params.set("COM_DLL_EXCEPT", 4.0)                          # but not in Offboard
    excepted.arm(at(0.0, 0.0, 0.0, 0.0, landed=True))
    excepted.gcs_heartbeat(0.0)
    for t in (0.5, 11.0):
        excepted.offboard_setpoint(Setpoint(position=(1.0, 0.0, -2.0)), t)
        if t == 0.5:
            assert excepted.set_mode(FlightMode.OFFBOARD, at(t, 0.0, 0.0, 0.0, landed=True)).accepted
        assert excepted.update(at(t, 1.0, 0.0, -2.0)).mode is FlightMode.OFFBOARD and not excepted.failsafe
    assert excepted.set_mode(FlightMode.AUTO_LOITER, at(11.1, 1.0, 0.0, -2.0)).accepted
    assert excepted.update(at(11.2, 1.0, 0.0, -2.0)).mode is FlightMode.AUTO_LAND and excepted.failsafe


def test_preflight_auto_disarm_without_takeoff(commander):
    commander.arm(status(t=0.0))
    assert commander.update(status(t=9.9)).armed
    assert not commander.update(status(t=10.0)).armed


def test_crash_disarms(commander):
    commander.arm(status())
    out = commander.update(status(t=1.0, z=-1.0, landed=False, crashed=True))
    assert not out.armed


def test_px4_mode_encoding_matches_pymavlink():
    for mode in FlightMode:
        main, sub = decode_custom_mode(mode.custom_mode)
        assert mode_from_custom(main, sub) is mode
    names = {FlightMode.AUTO_TAKEOFF: "TAKEOFF", FlightMode.AUTO_LOITER: "LOITER", FlightMode.AUTO_LAND: "LAND",
             FlightMode.AUTO_RTL: "RTL", FlightMode.OFFBOARD: "OFFBOARD", FlightMode.ACRO: "ACRO"}
    for mode, name in names.items():
        assert mavutil.interpret_px4_mode(mode.base_mode_flags, mode.custom_mode) == name
        base, main, sub = mavutil.px4_map[name]
        assert mode_from_custom(main, sub) is mode
    with pytest.raises(UnsupportedMode):
        mode_from_custom(8, 0)  # Rattitude, which PX4 has since removed, is not flown


def test_parameter_store_checks_names_and_ranges():
    params = ParameterStore(COMMANDER_PARAMS)
    seen = []
    params.on_change(lambda name, value: seen.append((name, value)))
    assert params.set("MIS_TAKEOFF_ALT", 1.5) == 1.5 and seen == [("MIS_TAKEOFF_ALT", 1.5)]
    for name, value in (("NOPE", 1.0), ("MIS_TAKEOFF_ALT", -1.0), ("COM_OF_LOSS_T", math.nan)):
        with pytest.raises(ParameterError):
            params.set(name, value)
    assert params["MIS_TAKEOFF_ALT"] == 1.5


@pytest.mark.parametrize("velocity", [(2.0, 0.0, 0.0), (-2.0, 0.0, 0.0), (0.0, 1.5, 0.0), (0.0, -1.5, 0.0),
                                      (0.0, 0.0, -1.2), (0.0, 0.0, 0.8), (1.2, -0.8, -0.5)])
def test_hold_stops_ahead_in_every_direction_flown(commander, velocity):
    """Braking at 2 m/s² from v covers v²/(2·2) m along v on each axis: ahead of the vehicle, flying north,
    south, east, west, climbing, descending or diagonally, never behind it."""
    here = (3.0, -1.0, -2.0)
    commander.arm(status())
    flying = VehicleStatus(time_s=1.0, position=here, velocity=velocity, yaw=0.0, armed=True, landed=False)
    commander.set_mode(FlightMode.AUTO_LOITER, flying)
    stop = commander.update(flying).setpoint.position
    for p, v, s in zip(here, velocity, stop, strict=True):
        expected = p + math.copysign(v ** 2 / 4.0, v)
        assert s == pytest.approx(expected)
        assert (s - p) * v >= 0.0                     # ahead along the motion, or where it is


def test_offboard_loss_on_the_ground_holds_instead_of_returning(commander):
    """PX4 has nothing to return from on the ground: a Return failsafe there becomes Hold."""
    commander.params.set("COM_OBL_RC_ACT", 3.0)                         # Return
    commander.arm(at(0.0, 0.0, 0.0, 0.0, landed=True))
    commander.offboard_setpoint(Setpoint(position=(0.0, 0.0, 0.0)), 0.5)
    commander.set_mode(FlightMode.OFFBOARD, at(0.5, 0.0, 0.0, 0.0, landed=True))
    out = commander.update(at(2.0, 0.0, 0.0, 0.0, landed=True))         # setpoints stopped: offboard lost
    assert commander.failsafe and out.mode is FlightMode.AUTO_LOITER
    assert commander.messages[-1][1] == "Failsafe: offboard lost, switching to Hold"


def test_a_delayed_return_failsafe_that_falls_due_on_the_ground_holds(commander):
    """Data link lost in the air (Return after COM_FAIL_ACT_T); landed by the deadline: Hold, not Return."""
    commander.params.set("NAV_DLL_ACT", 2.0)                            # Return
    commander.params.set("COM_DISARM_LAND", -1.0)                       # stay armed on the ground
    commander.arm(at(0.0, 0.0, 0.0, 0.0, landed=True))
    commander.gcs_heartbeat(0.0)
    commander.set_mode(FlightMode.AUTO_LOITER, at(0.0, 0.0, 0.0, -2.0))
    assert commander.update(at(10.5, 0.0, 0.0, -2.0)).mode is FlightMode.AUTO_LOITER   # Return in 5 s
    commander.update(at(12.0, 0.0, 0.0, 0.0, landed=True))              # set down meanwhile
    out = commander.update(at(15.6, 0.0, 0.0, 0.0, landed=True))        # the deadline, on the ground
    assert out.mode is FlightMode.AUTO_LOITER and commander.armed
    assert not any(text == "Failsafe: switching to Return" for _, text in commander.messages)


# ----------------------------------------------------------------------- texts, replies, flags and timing
INFO, WARNING, CRITICAL = mavlink.MAV_SEVERITY_INFO, mavlink.MAV_SEVERITY_WARNING, mavlink.MAV_SEVERITY_CRITICAL


def headed(t, yaw, pos=(0.0, 0.0, -3.0), landed=False) -> VehicleStatus:
    return VehicleStatus(time_s=t, position=pos, velocity=(0.0, 0.0, 0.0), yaw=yaw, armed=True, landed=landed)


def test_boots_disarmed_without_a_failsafe_at_mission_item_0(commander):
    out = commander.update(status())
    assert out.armed is False and commander.failsafe is False  # booleans: the server compares and reports them
    assert commander.mission_seq == 0 and commander.mission_finished is False  # MISSION_CURRENT.seq with no mission


@pytest.mark.parametrize("kwargs, text", [
    (dict(crashed=True), "Arming denied: vehicle crashed; restart the simulation"),
    (dict(position_valid=False), "Arming denied: position estimate not valid yet"),
    (dict(landed=False, z=-1.0), "Arming denied: vehicle is not landed"),
])
def test_a_refusal_is_announced_once_as_a_critical_statustext(commander, kwargs, text):
    reply = commander.arm(status(**kwargs))
    assert reply == Reply(mavlink.MAV_RESULT_TEMPORARILY_REJECTED, text, announced=True)
    assert list(commander.messages) == [(CRITICAL, text)]


def test_arming_and_disarming_say_why(commander):
    assert commander.arm(status()).accepted
    assert commander.messages[-1] == (INFO, "Armed by external command")
    reply = commander.disarm(status(t=1.0, landed=False, z=-2.0))
    assert reply == Reply(mavlink.MAV_RESULT_DENIED, "Disarming denied: not landed", announced=True)
    assert commander.messages[-1] == (CRITICAL, "Disarming denied: not landed")
    assert commander.disarm(status(t=2.0)).accepted and commander.armed is False
    assert commander.messages[-1] == (INFO, "Disarmed by external command")


def test_refused_commands_name_the_reason(commander):
    rejected = mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    replies = [commander.set_mode(FlightMode.OFFBOARD, status()),
               commander.set_mode(FlightMode.AUTO_MISSION, status()),
               commander.set_mode(FlightMode.POSCTL, status()),
               commander.takeoff(status(), 3.0),
               commander.return_to_launch(status())]
    texts = ["Switching to Offboard is currently not possible: no setpoint stream",
             "Switching to Mission is currently not possible: no mission (upload one first)",
             "Switching to Position is currently not possible: no manual control input (send MANUAL_CONTROL)",
             "Takeoff denied: arm first",
             "Return denied: not flying"]
    assert replies == [Reply(rejected, text, announced=True) for text in texts]
    assert list(commander.messages) == [(CRITICAL, text) for text in texts]


def test_arming_in_offboard_needs_the_stream_still_alive(commander):
    commander.offboard_setpoint(Setpoint(position=(0.0, 0.0, -2.0)), 0.5)
    assert commander.set_mode(FlightMode.OFFBOARD, status(t=1.5)).accepted   # exactly COM_OF_LOSS_T old: alive
    assert commander.update(status(t=1.5)).mode is FlightMode.OFFBOARD
    reply = commander.arm(status(t=1.6))                                     # 1.1 s old: lost
    assert reply.text == "Arming denied: no offboard setpoint stream" and not commander.armed


def test_a_crash_disarms_and_says_so(commander):
    commander.arm(status())
    assert commander.update(status(t=1.0, z=-1.0, landed=False, crashed=True)).armed is False
    assert commander.messages[-1] == (INFO, "Crash detected: motors stopped")


def test_offboard_stream_loss_while_disarmed_falls_back_to_hold(commander):
    """PX4 leaves Offboard once its setpoints stop, armed or not (also after a disarm in Offboard)."""
    commander.offboard_setpoint(Setpoint(position=(1.0, 0.0, -1.0)), 0.0)
    assert commander.set_mode(FlightMode.OFFBOARD, status(t=0.0)).accepted
    out = commander.update(status(t=1.5))
    assert out.mode is FlightMode.AUTO_LOITER and not out.armed
    assert commander.messages[-1] == (CRITICAL, "Failsafe: offboard lost, switching to Hold")

    commander.offboard_setpoint(Setpoint(position=(1.0, 0.0, -1.0)), 2.0)
    assert commander.set_mode(FlightMode.OFFBOARD, status(t=2.0)).accepted and commander.arm(status(t=2.0)).accepted
    assert commander.disarm(status(t=2.1)).accepted
    out = commander.update(status(t=3.5))
    assert out.mode is FlightMode.AUTO_LOITER and not out.armed
    assert commander.messages[-1] == (CRITICAL, "Failsafe: offboard lost, switching to Hold")


def test_offboard_loss_holds_where_the_vehicle_stops_not_at_the_last_offboard_setpoint(commander):
    commander.offboard_setpoint(Setpoint(position=(5.0, 0.0, -1.0)), 0.0)
    commander.set_mode(FlightMode.OFFBOARD, status())
    commander.arm(status())
    out = commander.update(at(1.5, 2.0, 0.0, -1.0))
    assert out.mode is FlightMode.AUTO_LOITER and out.setpoint.position == (2.0, 0.0, -1.0)  # at rest: here


def test_a_mode_choice_or_a_return_command_ends_the_failsafe_state(commander):
    commander.offboard_setpoint(Setpoint(position=(0.0, 0.0, -2.0)), 0.0)
    commander.set_mode(FlightMode.OFFBOARD, status())
    commander.arm(status())
    commander.update(at(1.5, 0.0, 0.0, -2.0))                            # offboard lost: Hold, failsafe
    assert commander.failsafe
    assert commander.return_to_launch(at(1.6, 0.0, 0.0, -2.0)).accepted
    assert commander.failsafe is False and commander.mode is FlightMode.AUTO_RTL

    commander.offboard_setpoint(Setpoint(position=(0.0, 0.0, -2.0)), 2.0)
    commander.set_mode(FlightMode.OFFBOARD, at(2.0, 0.0, 0.0, -2.0))
    commander.update(at(3.5, 0.0, 0.0, -2.0))
    assert commander.failsafe
    assert commander.set_mode(FlightMode.AUTO_LOITER, at(3.6, 0.0, 0.0, -2.0)).accepted
    assert commander.failsafe is False


def test_takeoff_announces_its_altitude_and_completion_and_then_lets_other_modes_fly(commander):
    commander.arm(status())
    commander.takeoff(status(t=0.1), math.nan)
    assert commander.messages[-1] == (INFO, "Takeoff to 2.5 m above home")
    out = commander.update(status(t=3.0, z=-2.5, landed=False))
    assert out.mode is FlightMode.AUTO_LOITER and commander.messages[-1] == (INFO, "Takeoff complete: holding")
    commander.land(status(t=4.0, z=-2.5, landed=False))
    out = commander.update(status(t=4.0, z=-2.5, landed=False))        # still at the takeoff point: landing
    assert out.mode is FlightMode.AUTO_LAND
    assert math.isnan(out.setpoint.position[2]) and out.setpoint.velocity[2] == pytest.approx(0.7)


def test_hold_land_and_return_keep_the_heading_they_were_entered_with(commander):
    commander.arm(status())
    for mode, yaw in ((FlightMode.AUTO_LOITER, 0.7), (FlightMode.AUTO_LAND, -1.2), (FlightMode.AUTO_RTL, 2.0)):
        assert commander.set_mode(mode, headed(1.0, yaw)).accepted
        out = commander.update(headed(1.1, yaw + 0.3))                 # the vehicle turned meanwhile
        assert out.mode is mode and out.setpoint.yaw == yaw


def test_land_descends_where_it_was_commanded_even_if_it_drifts(commander):
    commander.arm(status())
    commander.land(at(1.0, 1.0, 2.0, -3.0))
    out = commander.update(at(2.0, 1.5, 2.2, -2.5))
    assert out.setpoint.position[:2] == (1.0, 2.0) and out.setpoint.velocity[2] == pytest.approx(0.7)


def test_disarmed_on_the_ground_in_hold_the_setpoint_idles(commander):
    """Landed and not yet flown (or disarmed after a flight): keep pressing down, so the thrust stays at idle."""
    assert commander.set_mode(FlightMode.AUTO_LOITER, status()).accepted
    sp = commander.update(status(t=0.1)).setpoint
    assert math.isnan(sp.position[2]) and sp.velocity[2] == pytest.approx(0.7)      # MPC_LAND_SPEED
    commander.arm(status(t=0.2))
    sp = commander.update(status(t=0.3)).setpoint                                  # armed, not yet flown
    assert math.isnan(sp.position[2]) and sp.velocity[2] == pytest.approx(0.7)
    commander.takeoff(status(t=0.4), math.nan)
    commander.update(status(t=3.0, z=-2.5, landed=False))                          # Hold at 2.5 m
    commander.update(status(t=4.0, landed=True))                                   # set down in Hold
    assert not commander.update(status(t=6.0, landed=True)).armed                  # COM_DISARM_LAND
    sp = commander.update(status(t=6.1, landed=True)).setpoint
    assert math.isnan(sp.position[2]) and sp.velocity[2] == pytest.approx(0.7)


def test_hold_after_a_flight_keeps_its_point_through_a_ground_contact(commander):
    """Hold's target stays the setpoint when the land detector says landed (a bounce, a gust pushing it down):
    only Land or the auto-disarm wind the thrust down."""
    commander.arm(status())
    commander.takeoff(status(t=0.1), math.nan)
    assert commander.update(status(t=3.0, z=-2.5, landed=False)).mode is FlightMode.AUTO_LOITER
    out = commander.update(status(t=3.5, z=0.0, landed=True))
    assert out.armed and out.setpoint.position == (0.0, 0.0, -2.5)


# ------------------------------------------------------------------------------------ land detector
def test_landing_is_announced_and_disarms_exactly_com_disarm_land_later(commander):
    commander.arm(status())
    commander.update(status(t=1.0, z=-1.0, landed=False))
    commander.update(status(t=3.0, landed=True))
    assert commander.messages[-1] == (INFO, "Landing detected")
    assert commander.update(status(t=4.9, landed=True)).armed
    assert not commander.update(status(t=5.0, landed=True)).armed              # 2 s, PX4's COM_DISARM_LAND
    assert commander.messages[-1] == (INFO, "Disarmed by landing")


@pytest.mark.parametrize("delay", [0.0, 0.5])
def test_com_disarm_land_below_a_second_disarms_that_soon(commander, delay):
    commander.params.set("COM_DISARM_LAND", delay)
    commander.arm(status())
    commander.update(status(t=1.0, z=-1.0, landed=False))
    if delay > 0:
        assert commander.update(status(t=3.0, landed=True)).armed
    assert not commander.update(status(t=3.0 + delay, landed=True)).armed


def test_preflight_auto_disarm_counts_from_arming_and_says_why(commander):
    commander.arm(status(t=100.0))
    assert commander.update(status(t=109.9)).armed
    assert not commander.update(status(t=110.0)).armed                        # COM_DISARM_PRFLT 10 s
    assert commander.messages[-1] == (INFO, "Disarmed: no takeoff after arming")


@pytest.mark.parametrize("delay", [0.0, 0.5])
def test_com_disarm_prflt_below_a_second_disarms_that_soon(commander, delay):
    commander.params.set("COM_DISARM_PRFLT", delay)
    commander.arm(status(t=100.0))
    if delay > 0:
        assert commander.update(status(t=100.4)).armed
    assert not commander.update(status(t=100.0 + delay)).armed


# -------------------------------------------------------------------------------------------- Return
def test_return_legs_switch_within_nav_acc_rad_of_a_home_away_from_the_origin(commander):
    for name, value in (("RTL_RETURN_ALT", 5.0), ("RTL_DESCEND_ALT", 3.0), ("RTL_LAND_DELAY", 1.0),
                        ("NAV_ACC_RAD", 0.5)):
        commander.params.set(name, value)
    commander.arm(at(0.0, 2.0, -3.0, 0.0, landed=True))                  # home (2, -3, 0)
    assert commander.return_to_launch(at(10.0, 6.0, 1.0, -2.0)).accepted
    assert commander.messages[-1] == (INFO, "Return: flying home at 5.0 m above home")
    legs = [
        (at(10.1, 6.0, 1.0, -4.0), (6.0, 1.0, -5.0)),        # climbing, 1 m short
        (at(11.0, 6.0, 1.0, -4.5), (2.0, -3.0, -5.0)),       # 0.5 m short: NAV_ACC_RAD, fly home
        (at(12.0, 2.0, 1.0, -5.0), (2.0, -3.0, -5.0)),       # 4 m east of home: not there yet
        (at(13.0, -2.0, -3.0, -5.0), (2.0, -3.0, -5.0)),     # 4 m south of home
        (at(14.0, 2.0, -2.5, -5.0), (2.0, -3.0, -3.0)),      # 0.5 m from home: descend
        (at(15.0, 2.0, -3.0, -3.5), (2.0, -3.0, -3.0)),      # 0.5 m above the descend altitude: wait 1 s
    ]
    for state, target in legs:
        out = commander.update(state)
        assert out.mode is FlightMode.AUTO_RTL and out.setpoint.position == target, state
        assert not commander.landing
    out = commander.update(at(16.0, 2.3, -3.0, -3.5))        # RTL_LAND_DELAY over: land at home
    assert commander.landing and out.setpoint.position[:2] == (2.0, -3.0)
    assert commander.messages[-1] == (INFO, "Return: landing at home")


def test_a_return_left_during_its_wait_does_not_land_later(commander):
    commander.params.set("RTL_RETURN_ALT", 5.0)
    commander.params.set("RTL_DESCEND_ALT", 5.0)
    commander.params.set("RTL_LAND_DELAY", 10.0)
    commander.arm(at(0.0, 0.0, 0.0, 0.0, landed=True))
    commander.return_to_launch(at(1.0, 0.0, 0.0, -5.0))
    commander.update(at(1.1, 0.0, 0.0, -5.0))                # at home, at altitude: waiting 10 s
    commander.set_mode(FlightMode.AUTO_LOITER, at(2.0, 0.0, 0.0, -5.0))
    out = commander.update(at(20.0, 0.0, 0.0, -5.0))
    assert out.mode is FlightMode.AUTO_LOITER and out.setpoint.position == (0.0, 0.0, -5.0)
    assert not any("landing at home" in text for _, text in commander.messages)


# ------------------------------------------------------------------------------------- link losses
def test_data_link_loss_needs_a_ground_station_first_and_its_messages_are_graded(commander):
    commander.params.set("NAV_DLL_ACT", 2.0)                            # Return
    commander.arm(at(0.0, 0.0, 0.0, 0.0, landed=True))
    commander.set_mode(FlightMode.AUTO_LOITER, at(0.0, 0.0, 0.0, -2.0))
    out = commander.update(at(60.0, 0.0, 0.0, -2.0))                   # no ground station ever: nothing
    assert out.mode is FlightMode.AUTO_LOITER and not commander.failsafe
    commander.messages.clear()
    commander.gcs_heartbeat(60.0)                                       # connecting is no "regained"
    assert not commander.messages
    commander.update(at(70.5, 0.0, 0.0, -2.0))
    assert (CRITICAL, "Connection to ground station lost") in commander.messages
    commander.gcs_heartbeat(71.0)
    assert commander.messages[-1] == (INFO, "Data link regained")


def test_a_second_loss_at_the_deadline_reports_the_seconds_left_rounded(commander):
    from sitl_vehicle.manual import Sticks

    _hold_with_return_on_link_loss_and_land_on_stick_loss(commander)
    commander.update(at(10.5, 0.0, 0.0, -2.0))                          # data link lost: Return at 15.5
    assert commander.messages[-1] == (CRITICAL, "Failsafe: data link lost, switching to Return in 5 s "
                                                "(Hold until then)")
    commander.manual_control(Sticks(), 14.8)
    assert commander.update(at(15.4, 0.0, 0.0, -2.0)).mode is FlightMode.AUTO_LOITER   # sticks lost, 0.1 s left
    assert (CRITICAL, "Manual control lost") in commander.messages
    assert commander.messages[-1] == (CRITICAL, "Failsafe: manual control lost, switching to Land in 0 s")
    assert commander.update(at(15.5, 0.0, 0.0, -2.0)).mode is FlightMode.AUTO_LAND
    assert commander.messages[-1] == (CRITICAL, "Failsafe: switching to Land")


def test_a_failsafe_acting_at_once_says_so_critically(commander):
    commander.params.set("COM_OBL_RC_ACT", 4.0)                         # Land
    commander.offboard_setpoint(Setpoint(position=(0.0, 0.0, -2.0)), 0.0)
    commander.set_mode(FlightMode.OFFBOARD, status())
    commander.arm(status())
    assert commander.update(at(1.5, 0.0, 0.0, -2.0)).mode is FlightMode.AUTO_LAND
    assert commander.messages[-1] == (CRITICAL, "Failsafe: offboard lost, switching to Land")


# ------------------------------------------------------------------------------------------- the log
def test_the_log_records_mode_changes_statustexts_and_mission_items_reached(caplog):
    import logging

    from sitl_vehicle.mission import NAV_WAYPOINT, MissionItem

    caplog.set_level(logging.INFO, logger="sitl_vehicle.commander")
    commander = Commander(ParameterStore(COMMANDER_PARAMS))
    commander.arm(status())
    commander.set_mode(FlightMode.AUTO_LOITER, at(0.5, 0.0, 0.0, -2.0))     # Hold again: no mode change
    wp = MissionItem(0, NAV_WAYPOINT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, (0.0, 0.0, 0.0, math.nan),
                     0.0, 0.0, 2.0, 3.0, 0.0, True, math.nan)
    commander.set_mission([wp], at(0.5, 0.0, 0.0, -2.0))
    commander.set_mode(FlightMode.AUTO_MISSION, at(1.0, 0.0, 0.0, -2.0))
    commander.update(at(2.5, 3.0, 0.0, -2.0))
    lines = [record.getMessage() for record in caplog.records if record.name == "sitl_vehicle.commander"]
    assert lines == ["Armed by external command", "mode Hold -> Mission", "mission item 0 reached at t=2.50 s",
                     "Mission finished, loitering"]

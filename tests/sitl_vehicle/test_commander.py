"""The commander's PX4 semantics, case by case, with no vehicle and no sockets."""

from __future__ import annotations

import math

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.commander import Commander, VehicleStatus
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
                                              (0.0, FlightMode.AUTO_LOITER)])
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
             FlightMode.OFFBOARD: "OFFBOARD"}
    for mode, name in names.items():
        assert mavutil.interpret_px4_mode(mode.base_mode_flags, mode.custom_mode) == name
        base, main, sub = mavutil.px4_map[name]
        assert mode_from_custom(main, sub) is mode
    with pytest.raises(UnsupportedMode):
        mode_from_custom(1, 0)  # MANUAL needs RC


def test_parameter_store_checks_names_and_ranges():
    params = ParameterStore(COMMANDER_PARAMS)
    seen = []
    params.on_change(lambda name, value: seen.append((name, value)))
    assert params.set("MIS_TAKEOFF_ALT", 1.5) == 1.5 and seen == [("MIS_TAKEOFF_ALT", 1.5)]
    for name, value in (("NOPE", 1.0), ("MIS_TAKEOFF_ALT", -1.0), ("COM_OF_LOSS_T", math.nan)):
        with pytest.raises(ParameterError):
            params.set(name, value)
    assert params["MIS_TAKEOFF_ALT"] == 1.5

"""Acro: the sticks set the body rates (MC_ACRO_* through PX4's SuperExpo curve) and the throttle the thrust; the
vehicle holds whatever attitude centred sticks leave it at."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.commander import Commander, VehicleStatus
from sitl_vehicle.manual import AcroShape, Sticks, acro_rates, superexpo
from sitl_vehicle.modes import FlightMode, decode_custom_mode, mode_from_custom
from sitl_vehicle.params import COMMANDER_PARAMS, ParameterStore
from sitl_vehicle.sim import AttitudeSetpoint, RateSetpoint, Setpoint, VehicleConfig, VehicleSim


def status(t=0.0, landed=True, armed=False) -> VehicleStatus:
    return VehicleStatus(time_s=t, position=(0.0, 0.0, 0.0 if landed else -2.0), velocity=(0.0, 0.0, 0.0), yaw=0.0,
                         armed=armed, landed=landed)


@pytest.fixture
def commander():
    return Commander(ParameterStore(COMMANDER_PARAMS))


def test_superexpo_keeps_the_ends_and_bends_the_middle_as_px4s_does():
    for e, g in ((0.69, 0.7), (0.0, 0.0), (1.0, 0.95)):
        assert superexpo(0.0, e, g) == 0.0
        assert superexpo(1.0, e, g) == pytest.approx(1.0) and superexpo(-1.0, e, g) == pytest.approx(-1.0)
        assert superexpo(-0.3, e, g) == pytest.approx(-superexpo(0.3, e, g))
    # PX4's defaults at half stick: (0.31·0.5 + 0.69·0.125)·0.3 / (1 - 0.5·0.7)
    assert superexpo(0.5, 0.69, 0.7) == pytest.approx(0.24125 * 0.3 / 0.65)
    assert superexpo(0.5, 0.0, 0.0) == pytest.approx(0.5)                  # no expo: linear
    assert superexpo(0.5, 0.69, 0.0) == pytest.approx(0.24125)             # plain expo
    assert superexpo(2.0, 0.69, 0.7) == pytest.approx(1.0)                 # the stick clamped to full
    assert superexpo(0.5, 2.0, 0.0) == pytest.approx(0.125)                # expo clamped to 1: cubic
    assert superexpo(0.5, 0.0, 5.0) == pytest.approx(0.5 * 0.01 / (1 - 0.5 * 0.99))  # g clamped to 0.99
    assert superexpo(0.5, -1.0, -1.0) == pytest.approx(0.5)                # both clamped to 0
    halves = [superexpo(v / 10, 0.69, 0.7) for v in range(11)]
    assert all(b > a for a, b in zip(halves, halves[1:], strict=False))     # monotonic


def test_full_sticks_ask_for_the_rate_maxima_with_px4s_signs():
    shape = AcroShape()
    roll, pitch, yaw = acro_rates(Sticks(roll=1.0, pitch=1.0, yaw=1.0, throttle=0.5), shape)
    assert roll == pytest.approx(math.radians(720.0))        # roll stick right: roll right
    assert pitch == pytest.approx(-math.radians(720.0))      # pitch stick forward: nose down
    assert yaw == pytest.approx(math.radians(540.0))         # yaw stick right: clockwise from above
    assert acro_rates(Sticks(roll=-1.0, pitch=-1.0, yaw=-1.0), shape) == pytest.approx(
        (-math.radians(720.0), math.radians(720.0), -math.radians(540.0)))
    assert acro_rates(Sticks(), shape) == (0.0, 0.0, 0.0)
    linear = AcroShape(roll_rate_max=2.0, pitch_rate_max=3.0, yaw_rate_max=4.0, expo=0.0, expo_yaw=0.0,
                       superexpo=0.0, superexpo_yaw=0.0)
    assert acro_rates(Sticks(roll=0.5, pitch=0.25, yaw=-0.5), linear) == pytest.approx((1.0, -0.75, -2.0))
    yaw_only = replace(linear, expo_yaw=1.0)
    assert acro_rates(Sticks(roll=0.5, yaw=0.5), yaw_only) == pytest.approx((1.0, 0.0, 0.5))   # yaw's own expo


def test_acro_encodes_like_px4_and_is_flown_on_request():
    mode = FlightMode.ACRO
    assert decode_custom_mode(mode.custom_mode) == (5, 0) and mode_from_custom(5, 0) is mode
    assert mavutil.interpret_px4_mode(mode.base_mode_flags, mode.custom_mode) == "ACRO"
    assert mode.base_mode_flags == mavutil.px4_map["ACRO"][0]   # manual input, custom mode, no stabilize
    assert not mode.base_mode_flags & mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
    assert FlightMode.STABILIZED.base_mode_flags & mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
    assert mode.manual and mode.rates_from_sticks and mode.thrust_from_throttle and not mode.attitude_from_sticks
    assert FlightMode.STABILIZED.thrust_from_throttle and not FlightMode.POSCTL.thrust_from_throttle


def test_acro_needs_the_sticks_and_a_low_throttle_to_arm(commander):
    reply = commander.set_mode(FlightMode.ACRO, status())
    assert not reply.accepted and "no manual control input" in reply.text
    commander.manual_control(Sticks(throttle=0.21), 0.0)
    assert commander.set_mode(FlightMode.ACRO, status()).accepted
    reply = commander.arm(status())
    assert not reply.accepted and "throttle not low" in reply.text
    commander.manual_control(Sticks(throttle=0.2), 0.1)
    assert commander.arm(status(0.1)).accepted


def test_acro_sticks_become_rates_and_the_throttle_the_thrust_on_the_ground_too(commander):
    commander.manual_control(Sticks(throttle=0.0), 0.0)
    assert commander.set_mode(FlightMode.ACRO, status()).accepted and commander.arm(status()).accepted
    assert commander.update(status(0.1, armed=True)).setpoint == RateSetpoint()        # idles on the ground
    for name, value in (("MC_ACRO_R_MAX", 90.0), ("MC_ACRO_P_MAX", 180.0), ("MC_ACRO_Y_MAX", 360.0),
                        ("MC_ACRO_EXPO", 0.0), ("MC_ACRO_EXPO_Y", 0.0), ("MC_ACRO_SUPEXPO", 0.0),
                        ("MC_ACRO_SUPEXPOY", 0.0)):
        commander.params.set(name, value)         # every MC_ACRO_* parameter, away from its default: linear
    commander.manual_control(Sticks(roll=0.5, pitch=-0.5, yaw=0.5, throttle=0.65), 0.2)
    sp = commander.update(status(0.2, landed=False, armed=True)).setpoint
    assert sp == RateSetpoint(roll_rate=pytest.approx(math.radians(45.0)), pitch_rate=pytest.approx(math.radians(90.0)),
                              yaw_rate=pytest.approx(math.radians(180.0)), thrust=0.65)


def test_acro_holds_a_tilt_where_stabilized_levels():
    """A roll-rate pulse leaves the vehicle banked in Acro (centred sticks hold the rates at zero); the same
    sticks in Stabilized level it again. The thrust is the throttle as it is."""
    sim = VehicleSim(replace(VehicleConfig(), noise=None))
    sim.set_armed(True)
    sim.set_setpoint(Setpoint(position=(0.0, 0.0, -2.0)))
    sim.run(4.0)
    hover = sim.airframe.hover_thrust
    sim.set_setpoint(RateSetpoint(roll_rate=1.0, thrust=hover))
    sim.run(0.2)
    sim.set_setpoint(RateSetpoint(thrust=hover))
    sim.run(0.3)
    roll, pitch, _ = sim.truth.euler()
    assert roll == pytest.approx(0.2, abs=0.06) and abs(pitch) < 0.03
    assert max(abs(w) for w in sim.truth.angular_velocity) < 0.05
    sim.run(0.2)
    assert sim.truth.euler()[0] == pytest.approx(roll, abs=0.02)          # held, not levelled
    assert sim.truth.velocity[1] > 0.1                                      # banked right: drifting east
    sim.set_setpoint(RateSetpoint(yaw_rate=0.5, thrust=hover))
    sim.run(0.4)
    yaw = sim.truth.euler()[2]
    sim.set_setpoint(AttitudeSetpoint(throttle=0.5))                        # Stabilized: levels, keeps the heading
    sim.run(1.0)
    roll, _, yaw_after = sim.truth.euler()
    assert abs(roll) < 0.03 and yaw_after == pytest.approx(yaw, abs=0.05) and abs(yaw) > 0.1
    sim.set_setpoint(RateSetpoint(thrust=1.0))
    z = sim.truth.position[2]
    sim.run(0.5)
    assert sim.truth.position[2] < z - 0.3 and not sim.crashed              # full throttle: full thrust, climbing

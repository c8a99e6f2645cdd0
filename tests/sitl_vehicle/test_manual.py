"""Position and Altitude modes: MANUAL_CONTROL sticks, their shaping, the commander's stick setpoints and the
manual-control-loss failsafe."""

from __future__ import annotations

import math

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.commander import Commander, VehicleStatus
from sitl_vehicle.manual import INT16_MAX, ManualControlError, Sticks, expo_deadzone, sticks_from_manual_control
from sitl_vehicle.modes import FlightMode
from sitl_vehicle.params import COMMANDER_PARAMS, ParameterStore

CENTRED = Sticks()


def status(t=0.0, pos=(0.0, 0.0, 0.0), vel=(0.0, 0.0, 0.0), yaw=0.0, landed=True, armed=False) -> VehicleStatus:
    return VehicleStatus(time_s=t, position=pos, velocity=vel, yaw=yaw, armed=armed, landed=landed)


def flying(t, pos=(0.0, 0.0, -2.0), **kw) -> VehicleStatus:
    return status(t, pos=pos, landed=False, armed=True, **kw)


@pytest.fixture
def commander():
    return Commander(ParameterStore(COMMANDER_PARAMS))


def airborne_in(commander, mode: FlightMode, t: float = 1.0) -> Commander:
    """Armed in ``mode`` with centred sticks, then in the air at 2 m."""
    commander.manual_control(CENTRED, 0.0)
    assert commander.set_mode(mode, status()).accepted
    assert commander.arm(status()).accepted
    commander.manual_control(CENTRED, t)
    commander.update(flying(t))
    return commander


def test_manual_control_axes_map_like_px4():
    s = sticks_from_manual_control(1000, -500, 750, 250)
    assert (s.pitch, s.roll, s.throttle, s.yaw) == (1.0, -0.5, 0.75, 0.25)
    unused = sticks_from_manual_control(INT16_MAX, INT16_MAX, INT16_MAX, INT16_MAX)
    assert unused == CENTRED
    for bad, name in (((1001, 0, 500, 0), "x=1001"), ((0, 0, -1, 0), "z=-1"), ((0, 0, 500, -2000), "r=-2000")):
        with pytest.raises(ManualControlError, match=name):
            sticks_from_manual_control(*bad)


def test_stick_shaping_has_a_dead_zone_full_range_and_expo():
    assert expo_deadzone(0.09, 0.6, 0.1) == 0.0
    assert expo_deadzone(1.0, 0.6, 0.1) == pytest.approx(1.0)
    assert expo_deadzone(-1.0, 0.6, 0.1) == pytest.approx(-1.0)
    assert expo_deadzone(0.55, 0.0, 0.1) == pytest.approx(0.5)          # linear without expo
    assert 0.0 < expo_deadzone(0.55, 1.0, 0.1) == pytest.approx(0.125)  # cubic with full expo
    values = [expo_deadzone(v / 100, 0.6, 0.1) for v in range(-100, 101)]
    assert all(b >= a for a, b in zip(values, values[1:], strict=False))


@pytest.mark.parametrize("mode", [FlightMode.POSCTL, FlightMode.ALTCTL])
def test_stick_modes_need_live_manual_control(commander, mode):
    reply = commander.set_mode(mode, status())
    assert not reply.accepted and "no manual control input" in reply.text and mode.label in reply.text
    commander.manual_control(CENTRED, 0.0)
    assert commander.set_mode(mode, status(0.2)).accepted
    reply = commander.arm(status(t=5.0))  # sticks silent for longer than COM_RC_LOSS_T
    assert not reply.accepted and "manual control lost" in reply.text


def test_arming_in_position_mode_needs_the_throttle_at_or_below_centre(commander):
    commander.manual_control(Sticks(throttle=0.9), 0.0)
    assert commander.set_mode(FlightMode.POSCTL, status()).accepted
    reply = commander.arm(status())
    assert not reply.accepted and "throttle above center" in reply.text
    commander.manual_control(CENTRED, 0.1)
    assert commander.arm(status(0.1)).accepted


def test_position_mode_on_the_ground_idles_until_the_throttle_is_raised(commander):
    commander.manual_control(CENTRED, 0.0)
    commander.set_mode(FlightMode.POSCTL, status())
    commander.arm(status())
    sp = commander.update(status(0.1, armed=True)).setpoint
    assert sp.velocity[2] > 0  # pressing down: the thrust winds down to idle
    commander.manual_control(Sticks(throttle=1.0), 0.2)
    sp = commander.update(status(0.2, armed=True)).setpoint
    assert sp.velocity[2] == pytest.approx(-3.0) and math.isnan(sp.position[2])  # full throttle: MPC_Z_VEL_MAX_UP


def test_position_mode_sticks_fly_velocity_in_the_heading_frame_and_centred_sticks_hold(commander):
    airborne_in(commander, FlightMode.POSCTL)
    yaw = math.pi / 2  # facing east: forward stick flies east, right stick flies south
    commander.manual_control(Sticks(pitch=1.0), 1.1)
    sp = commander.update(flying(1.1, yaw=yaw)).setpoint
    assert sp.velocity[0] == pytest.approx(0.0, abs=1e-9) and sp.velocity[1] == pytest.approx(10.0)
    assert math.isnan(sp.position[0]) and sp.position[2] == pytest.approx(-2.0)  # throttle centred: altitude held
    commander.manual_control(Sticks(roll=1.0), 1.2)
    sp = commander.update(flying(1.2, yaw=yaw)).setpoint
    assert sp.velocity[0] == pytest.approx(-10.0) and sp.velocity[1] == pytest.approx(0.0, abs=1e-9)
    diagonal = Sticks(pitch=1.0, roll=1.0)
    commander.manual_control(diagonal, 1.3)
    sp = commander.update(flying(1.3)).setpoint
    assert math.hypot(sp.velocity[0], sp.velocity[1]) == pytest.approx(10.0)  # MPC_VEL_MANUAL, not 14 m/s
    # centred while flying north at 4 m/s: hold where the vehicle stops, ahead, not where the stick was let go
    commander.manual_control(CENTRED, 1.4)
    sp = commander.update(flying(1.4, pos=(5.0, 0.0, -2.0), vel=(4.0, 0.0, 0.0))).setpoint
    assert sp.position[0] > 5.0 and sp.position[1] == pytest.approx(0.0) and math.isnan(sp.velocity[0])
    held = sp.position
    sp = commander.update(flying(1.5, pos=(6.0, 0.0, -2.0), vel=(2.0, 0.0, 0.0))).setpoint
    assert sp.position == held  # the hold point stays put


def test_yaw_stick_turns_at_a_rate_and_releasing_it_holds_the_heading(commander):
    airborne_in(commander, FlightMode.POSCTL)
    commander.manual_control(Sticks(yaw=1.0), 1.1)
    sp = commander.update(flying(1.1)).setpoint
    assert sp.yaw_rate == pytest.approx(math.radians(150.0)) and math.isnan(sp.yaw)  # MPC_MAN_Y_MAX
    commander.manual_control(CENTRED, 1.2)
    sp = commander.update(flying(1.2, yaw=0.7)).setpoint
    assert sp.yaw == pytest.approx(0.7) and math.isnan(sp.yaw_rate)


def test_throttle_stick_climbs_and_descends_at_the_manual_limits(commander):
    airborne_in(commander, FlightMode.POSCTL)
    commander.manual_control(Sticks(throttle=0.0), 1.1)
    sp = commander.update(flying(1.1)).setpoint
    assert sp.velocity[2] == pytest.approx(1.5) and math.isnan(sp.position[2])  # MPC_Z_VEL_MAX_DN
    commander.manual_control(Sticks(throttle=0.52), 1.2)  # inside the dead zone: hold
    sp = commander.update(flying(1.2, pos=(0.0, 0.0, -1.0))).setpoint
    assert sp.position[2] == pytest.approx(-1.0) and math.isnan(sp.velocity[2])


def test_altitude_mode_sticks_tilt_and_centred_sticks_level_without_holding_position(commander):
    airborne_in(commander, FlightMode.ALTCTL)
    commander.manual_control(Sticks(pitch=1.0), 1.1)
    sp = commander.update(flying(1.1)).setpoint
    assert sp.acceleration[0] == pytest.approx(9.80665 * math.tan(math.radians(35.0)))  # MPC_MAN_TILT_MAX
    assert math.isnan(sp.position[0]) and math.isnan(sp.velocity[0]) and sp.position[2] == pytest.approx(-2.0)
    commander.manual_control(CENTRED, 1.2)
    sp = commander.update(flying(1.2, vel=(3.0, 0.0, 0.0))).setpoint
    assert sp.acceleration[:2] == (0.0, 0.0) and math.isnan(sp.position[0]) and math.isnan(sp.velocity[0])


@pytest.mark.parametrize("action, mode", [(2.0, FlightMode.AUTO_RTL), (3.0, FlightMode.AUTO_LAND),
                                          (1.0, FlightMode.AUTO_LOITER), (0.0, FlightMode.AUTO_LOITER)])
def test_manual_control_loss_fails_safe_as_nav_rcl_act_says(commander, action, mode):
    commander.params.set("NAV_RCL_ACT", action)
    airborne_in(commander, FlightMode.POSCTL)
    out = commander.update(flying(1.4))  # 0.4 s of silence: within COM_RC_LOSS_T
    assert out.mode is FlightMode.POSCTL and not commander.failsafe
    out = commander.update(flying(1.6))  # lost: Hold first, for COM_FAIL_ACT_T (5 s)
    assert out.mode is FlightMode.AUTO_LOITER and commander.failsafe and out.armed
    texts = [t for _, t in commander.messages]
    assert "Manual control lost" in texts and any(f"switching to {mode.label}" in t for t in texts)
    assert commander.update(flying(6.5)).mode is FlightMode.AUTO_LOITER
    assert commander.update(flying(6.7)).mode is mode and commander.failsafe
    commander.manual_control(CENTRED, 7.0)
    assert commander.messages[-1][1] == "Manual control regained"


def test_manual_control_loss_can_stop_the_motors(commander):
    commander.params.set("NAV_RCL_ACT", 6.0)
    airborne_in(commander, FlightMode.POSCTL)
    assert not commander.update(flying(2.0)).armed
    assert any("motors stopped" in t for _, t in commander.messages)


def _hold_with_sticks_then_silent(commander, t_lost=2.0):
    """Sticks heard, armed in Hold on the ground, in the air; the sticks stop. Returns the update at t_lost."""
    commander.manual_control(CENTRED, 0.0)
    assert commander.arm(status()).accepted
    return commander.update(flying(t_lost))


def test_manual_control_loss_acts_in_every_mode_com_rcl_except_does_not_except(commander):
    commander.params.set("COM_FAIL_ACT_T", 0.0)                  # act at once (the delay has its own tests)
    out = _hold_with_sticks_then_silent(commander)              # PX4 acts in Hold too (COM_RCL_EXCEPT 0)
    assert out.mode is FlightMode.AUTO_RTL and commander.failsafe
    texts = [t for _, t in commander.messages]
    assert "Manual control lost" in texts and "Failsafe: manual control lost, switching to Return" in texts
    # once per loss: the pilot may take over by switching mode, and the failsafe does not come back
    assert commander.set_mode(FlightMode.AUTO_LOITER, flying(2.1)).accepted
    assert commander.update(flying(3.0)).mode is FlightMode.AUTO_LOITER

    excepted = Commander(ParameterStore(COMMANDER_PARAMS))
    excepted.params.set("COM_FAIL_ACT_T", 0.0)
    excepted.params.set("COM_RCL_EXCEPT", 2.0)                   # Hold and the other auto modes
    out = _hold_with_sticks_then_silent(excepted)
    assert out.mode is FlightMode.AUTO_LOITER and not excepted.failsafe
    assert excepted.messages[-1][1] == "Manual control lost"
    # leaving the excepted mode while the sticks are still lost acts on the loss there
    from sitl_vehicle.sim import Setpoint
    excepted.offboard_setpoint(Setpoint(position=(0.0, 0.0, -2.0)), 2.1)
    assert excepted.set_mode(FlightMode.OFFBOARD, flying(2.1)).accepted
    assert excepted.update(flying(2.2)).mode is FlightMode.AUTO_RTL and excepted.failsafe


def test_manual_control_loss_is_ignored_when_armed_without_sticks_until_they_return(commander):
    commander.params.set("COM_FAIL_ACT_T", 0.0)                  # act at once
    commander.manual_control(CENTRED, 0.0)
    commander.update(status(1.0))                                # lost before arming
    assert commander.messages[-1][1] == "Manual control lost"
    assert commander.arm(status(1.0)).accepted
    assert commander.update(flying(5.0)).mode is FlightMode.AUTO_LOITER and not commander.failsafe
    commander.manual_control(CENTRED, 5.1)                       # back: a later loss counts
    assert commander.messages[-1][1] == "Manual control regained"
    assert commander.update(flying(5.2)).mode is FlightMode.AUTO_LOITER
    assert commander.update(flying(6.0)).mode is FlightMode.AUTO_RTL and commander.failsafe
    never = Commander(ParameterStore(COMMANDER_PARAMS))          # no sticks ever (the companion's flights)
    never.arm(status())
    assert never.update(flying(60.0)).mode is FlightMode.AUTO_LOITER and not never.messages[-1][1].startswith(
        "Manual control")


def test_a_link_loss_failsafe_holds_com_fail_act_t_first_and_a_mode_choice_meanwhile_ends_it(commander):
    airborne_in(commander, FlightMode.POSCTL)
    commander.params.set("COM_FAIL_ACT_T", 3.0)
    out = commander.update(flying(2.0))                          # NAV_RCL_ACT 2: Return, in 3 s
    assert out.mode is FlightMode.AUTO_LOITER and commander.failsafe
    assert commander.messages[-1][1] == "Failsafe: manual control lost, switching to Return in 3 s (Hold until then)"
    commander.manual_control(CENTRED, 3.0)                       # back before the deadline: PX4 still returns
    assert commander.update(flying(4.9)).mode is FlightMode.AUTO_LOITER
    assert commander.update(flying(5.0)).mode is FlightMode.AUTO_RTL
    assert commander.messages[-1][1].startswith("Return: flying home")
    assert any(t == "Failsafe: switching to Return" for _, t in commander.messages)

    pilot = airborne_in(Commander(ParameterStore(COMMANDER_PARAMS)), FlightMode.POSCTL)
    pilot.update(flying(2.0))                                    # lost: Hold, Return in 5 s
    pilot.manual_control(CENTRED, 2.5)
    assert pilot.set_mode(FlightMode.POSCTL, flying(2.5)).accepted   # the pilot takes over by choosing a mode
    for t in (2.6, 7.5, 10.0):
        pilot.manual_control(CENTRED, t)
        assert pilot.update(flying(t)).mode is FlightMode.POSCTL and not pilot.failsafe


def test_stopping_the_motors_and_a_zero_delay_do_not_wait(commander):
    commander.params.set("NAV_RCL_ACT", 5.0)                     # terminate: at once, whatever COM_FAIL_ACT_T
    airborne_in(commander, FlightMode.POSCTL)
    assert not commander.update(flying(2.0)).armed
    at_once = airborne_in(Commander(ParameterStore(COMMANDER_PARAMS)), FlightMode.POSCTL)
    at_once.params.set("COM_FAIL_ACT_T", 0.1)                    # PX4: 0.1 s or less is no delay
    assert at_once.update(flying(2.0)).mode is FlightMode.AUTO_RTL


def _stream(commander, samples, t0, dt=0.05):
    """Send each of ``samples`` (Sticks) ``dt`` apart from ``t0``, updating the commander after each; the modes."""
    modes = []
    for i, sticks in enumerate(samples):
        t = t0 + i * dt
        commander.manual_control(sticks, t)
        modes.append(commander.update(flying(t)).mode)
    return modes


def test_moving_the_sticks_in_an_auto_mode_takes_over_into_position_mode(commander):
    commander.manual_control(CENTRED, 0.0)
    assert commander.arm(status()).accepted                      # Hold, sticks centred
    drift = [Sticks(pitch=0.004 * i) for i in range(60)]         # 0.24 in 3 s: slow, no takeover
    jitter = [Sticks(roll=0.05 * (-1) ** i) for i in range(20)]
    assert set(_stream(commander, drift + jitter, 0.1)) == {FlightMode.AUTO_LOITER}
    push = [Sticks(), Sticks(pitch=0.2), Sticks(pitch=0.4)]      # 40 % in 0.1 s (COM_RC_STICK_OV 30 %)
    assert _stream(commander, push, 5.0)[-1] is FlightMode.POSCTL
    assert commander.messages[-1][1] == "Sticks moved: pilot takes over from Hold, switching to Position"


def test_offboard_is_taken_over_by_the_sticks_only_when_com_rc_override_says_so():
    from sitl_vehicle.sim import Setpoint

    for bits, taken_over in ((1.0, False), (3.0, True)):
        commander = Commander(ParameterStore(COMMANDER_PARAMS))
        commander.params.set("COM_RC_OVERRIDE", bits)
        commander.manual_control(CENTRED, 0.0)
        commander.offboard_setpoint(Setpoint(position=(0.0, 0.0, -2.0)), 0.0)
        assert commander.set_mode(FlightMode.OFFBOARD, status()).accepted and commander.arm(status()).accepted
        commander.offboard_setpoint(Setpoint(position=(0.0, 0.0, -2.0)), 0.1)
        mode = _stream(commander, [CENTRED, Sticks(throttle=0.8)], 0.1)[-1]   # throttle counts double: 60 %
        assert (mode is FlightMode.POSCTL) is taken_over


def test_the_sticks_take_over_from_a_failsafe_only_after_its_delay(commander):
    commander.params.set("NAV_DLL_ACT", 2.0)                     # data link lost: Return, after 5 s in Hold
    commander.manual_control(CENTRED, 0.0)
    commander.gcs_heartbeat(0.0)
    assert commander.arm(status()).accepted
    _stream(commander, [CENTRED] * 3, 10.0)
    assert commander.update(flying(10.2)).mode is FlightMode.AUTO_LOITER and commander.failsafe   # COM_DL_LOSS_T
    push = [CENTRED, Sticks(roll=-0.6)]
    assert _stream(commander, push, 11.0)[-1] is FlightMode.AUTO_LOITER        # in the delay: no takeover
    assert _stream(commander, [Sticks(roll=-0.6)] * 4, 15.1)[-1] is FlightMode.AUTO_RTL
    assert _stream(commander, push, 16.0)[-1] is FlightMode.POSCTL and not commander.failsafe

    at_once = Commander(ParameterStore(COMMANDER_PARAMS))        # COM_FAIL_ACT_T 0: PX4 allows a mode switch only
    at_once.params.set("NAV_DLL_ACT", 2.0)
    at_once.params.set("COM_FAIL_ACT_T", 0.0)
    at_once.manual_control(CENTRED, 0.0)
    at_once.gcs_heartbeat(0.0)
    assert at_once.arm(status()).accepted
    _stream(at_once, [CENTRED] * 6, 10.0)
    assert _stream(at_once, push, 11.0)[-1] is FlightMode.AUTO_RTL

    offboard = Commander(ParameterStore(COMMANDER_PARAMS))        # offboard loss: the sticks take over at once
    offboard.params.set("COM_OBL_RC_ACT", 3.0)
    offboard.params.set("COM_FAIL_ACT_T", 0.0)
    from sitl_vehicle.sim import Setpoint
    offboard.manual_control(CENTRED, 0.0)
    offboard.offboard_setpoint(Setpoint(position=(0.0, 0.0, -2.0)), 0.0)
    assert offboard.set_mode(FlightMode.OFFBOARD, status()).accepted and offboard.arm(status()).accepted
    assert _stream(offboard, [CENTRED] * 3, 2.0)[-1] is FlightMode.AUTO_RTL and offboard.failsafe
    assert _stream(offboard, push, 3.0)[-1] is FlightMode.POSCTL


@pytest.mark.parametrize("mode", [FlightMode.AUTO_LAND, FlightMode.AUTO_RTL])
def test_manual_control_loss_does_not_turn_a_landing_or_a_return_into_a_new_return(commander, mode):
    commander.manual_control(CENTRED, 0.0)
    assert commander.arm(status()).accepted
    assert commander.set_mode(mode, flying(0.1)).accepted
    before = commander.update(flying(0.2)).setpoint
    out = commander.update(flying(2.0))                          # NAV_RCL_ACT 2: Return
    assert out.mode is mode and commander.failsafe and out.setpoint == before
    assert commander.messages[-1][1] == f"Failsafe: manual control lost, continuing {mode.label}"


def test_stick_modes_encode_like_px4():
    for mode, name in ((FlightMode.POSCTL, "POSCTL"), (FlightMode.ALTCTL, "ALTCTL")):
        assert mavutil.interpret_px4_mode(mode.base_mode_flags, mode.custom_mode) == name
        assert mode.base_mode_flags & mavlink.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
        assert not mode.base_mode_flags & mavlink.MAV_MODE_FLAG_AUTO_ENABLED
    assert FlightMode.POSCTL.base_mode_flags & mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
    assert not FlightMode.AUTO_LOITER.base_mode_flags & mavlink.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED


@pytest.mark.parametrize("mode", [FlightMode.STABILIZED, FlightMode.MANUAL])
def test_stabilized_and_manual_sticks_set_the_attitude_and_the_throttle_the_thrust(commander, mode):
    from sitl_vehicle.sim import AttitudeSetpoint

    commander.manual_control(Sticks(throttle=0.5), 0.0)
    assert commander.set_mode(mode, status()).accepted
    reply = commander.arm(status())
    assert not reply.accepted and "throttle not low" in reply.text
    commander.manual_control(Sticks(throttle=0.0), 0.1)
    assert commander.arm(status(0.1)).accepted
    assert commander.update(status(0.2, armed=True)).setpoint == AttitudeSetpoint(throttle=0.0)  # idles
    commander.manual_control(Sticks(pitch=1.0, roll=-1.0, yaw=1.0, throttle=0.7), 0.3)
    sp = commander.update(flying(0.3)).setpoint
    tilt = math.radians(35.0)
    assert sp == AttitudeSetpoint(roll=-tilt, pitch=-tilt, yaw_rate=math.radians(150.0), throttle=0.7)
    assert mode.base_mode_flags & mavlink.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
    assert not mode.base_mode_flags & mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
    assert mavutil.interpret_px4_mode(mode.base_mode_flags, mode.custom_mode) == mode.name


# ------------------------------------------------------------------ arming limits, loss timing and texts
INFO, CRITICAL = mavlink.MAV_SEVERITY_INFO, mavlink.MAV_SEVERITY_CRITICAL


@pytest.mark.parametrize("mode, limit, text", [
    (FlightMode.STABILIZED, 0.2, "Arming denied: throttle not low; pull it down to arm"),  # PX4: low throttle
    (FlightMode.MANUAL, 0.2, "Arming denied: throttle not low; pull it down to arm"),
    (FlightMode.POSCTL, 0.6, "Arming denied: throttle above center"),                      # PX4: not above 60 %
    (FlightMode.ALTCTL, 0.6, "Arming denied: throttle above center"),
])
def test_arming_throttle_limits_are_inclusive_and_the_refusal_says_why(commander, mode, limit, text):
    commander.manual_control(Sticks(throttle=limit + 0.01), 0.0)
    assert commander.set_mode(mode, status()).accepted
    reply = commander.arm(status())
    assert reply.text == text and commander.messages[-1] == (CRITICAL, text) and not commander.armed
    commander.manual_control(Sticks(throttle=limit), 0.1)
    assert commander.arm(status(0.1)).accepted


def test_sticks_exactly_com_rc_loss_t_old_are_still_alive(commander):
    commander.manual_control(CENTRED, 0.0)
    assert not commander.messages                                  # the first sticks are no "regained"
    assert commander.set_mode(FlightMode.POSCTL, status(0.5)).accepted   # 0.5 s old: COM_RC_LOSS_T
    commander.arm(status(0.5), force=True)
    assert commander.update(flying(0.5)).mode is FlightMode.POSCTL
    assert not any(text == "Manual control lost" for _, text in commander.messages)


def test_manual_control_loss_and_return_are_graded_critical_and_info(commander):
    airborne_in(commander, FlightMode.POSCTL)
    commander.update(flying(1.6))
    assert (CRITICAL, "Manual control lost") in commander.messages
    assert commander.messages[-1] == (CRITICAL, "Failsafe: manual control lost, switching to Return in 5 s "
                                                "(Hold until then)")
    commander.manual_control(CENTRED, 2.0)
    assert commander.messages[-1] == (INFO, "Manual control regained")
    commander.update(flying(6.6))
    assert commander.messages[-2] == (CRITICAL, "Failsafe: switching to Return")


def test_a_failsafe_in_the_mode_it_wants_continues_and_says_so_critically(commander):
    commander.params.set("NAV_RCL_ACT", 1.0)                     # Hold
    commander.manual_control(CENTRED, 0.0)
    assert commander.arm(status()).accepted                      # Hold
    out = commander.update(flying(2.0))
    assert out.mode is FlightMode.AUTO_LOITER and commander.failsafe
    assert commander.messages[-1] == (CRITICAL, "Failsafe: manual control lost, continuing Hold")


def test_re_arming_after_a_motor_stop_failsafe_clears_it(commander):
    commander.params.set("NAV_RCL_ACT", 6.0)                     # disarm
    airborne_in(commander, FlightMode.POSCTL)
    assert not commander.update(flying(2.0)).armed and commander.failsafe
    assert commander.messages[-1] == (INFO, "Failsafe: manual control lost, motors stopped")
    commander.manual_control(CENTRED, 3.0)
    assert commander.arm(status(3.0)).accepted
    assert commander.failsafe is False


def test_the_stick_modes_act_on_a_manual_control_loss_whatever_com_rcl_except_says(commander):
    commander.params.set("COM_RCL_EXCEPT", 7.0)                  # every excepted mode: Mission, auto, Offboard
    commander.params.set("COM_FAIL_ACT_T", 0.0)
    airborne_in(commander, FlightMode.POSCTL)
    out = commander.update(flying(2.0))
    assert out.mode is FlightMode.AUTO_RTL and commander.failsafe


def test_a_com_fail_act_t_of_0_1_s_acts_at_once_and_the_sticks_do_not_take_over(commander):
    commander.params.set("NAV_DLL_ACT", 2.0)                     # data link lost: Return
    commander.params.set("COM_FAIL_ACT_T", 0.1)                  # PX4: 0.1 s or less is no delay
    commander.manual_control(CENTRED, 0.0)
    commander.gcs_heartbeat(0.0)
    assert commander.arm(status()).accepted
    _stream(commander, [CENTRED] * 6, 10.0)
    assert commander.mode is FlightMode.AUTO_RTL
    assert _stream(commander, [CENTRED, Sticks(roll=-0.6)], 11.0)[-1] is FlightMode.AUTO_RTL


# -------------------------------------------------------------------------------- stick takeover
def _armed_in_hold(commander, sticks=CENTRED):
    commander.manual_control(sticks, 0.0)
    assert commander.arm(status()).accepted
    return commander


def test_a_takeover_says_so_and_ends_the_failsafe(commander):
    commander.params.set("COM_OBL_RC_ACT", 5.0)                  # offboard lost: Hold, the sticks may take over
    from sitl_vehicle.sim import Setpoint
    commander.manual_control(CENTRED, 0.0)
    commander.offboard_setpoint(Setpoint(position=(0.0, 0.0, -2.0)), 0.0)
    assert commander.set_mode(FlightMode.OFFBOARD, status()).accepted and commander.arm(status()).accepted
    assert _stream(commander, [CENTRED] * 3, 2.0)[-1] is FlightMode.AUTO_LOITER and commander.failsafe
    assert _stream(commander, [CENTRED, Sticks(pitch=0.5)], 3.0)[-1] is FlightMode.POSCTL
    assert commander.failsafe is False
    assert commander.messages[-1] == (INFO, "Sticks moved: pilot takes over from Hold, switching to Position")


def test_a_push_exactly_one_window_after_the_last_sample_still_counts(commander):
    _armed_in_hold(commander)
    commander.manual_control(CENTRED, 10.0)
    assert commander.update(flying(10.0)).mode is FlightMode.AUTO_LOITER
    commander.manual_control(Sticks(pitch=0.4), 11.0)            # 1 s later (STICK_MOVE_WINDOW_S): still within
    assert commander.update(flying(11.0)).mode is FlightMode.POSCTL


def test_the_yaw_stick_takes_over_too(commander):
    _armed_in_hold(commander, Sticks(yaw=-0.2))
    assert _stream(commander, [Sticks(yaw=-0.2), Sticks(yaw=0.2)], 5.0)[-1] is FlightMode.POSCTL   # 40 % > 30 %


def test_the_throttle_counts_double_but_no_more(commander):
    _armed_in_hold(commander)
    assert _stream(commander, [CENTRED, Sticks(throttle=0.62)], 5.0)[-1] is FlightMode.AUTO_LOITER  # 24 % < 30 %
    assert _stream(commander, [CENTRED, Sticks(throttle=0.66)], 7.0)[-1] is FlightMode.POSCTL       # 32 % > 30 %


def test_a_push_of_exactly_com_rc_stick_ov_is_not_a_takeover(commander):
    commander.params.set("COM_RC_STICK_OV", 50.0)
    _armed_in_hold(commander)
    assert _stream(commander, [CENTRED, Sticks(pitch=0.5)], 5.0)[-1] is FlightMode.AUTO_LOITER       # not more
    assert _stream(commander, [CENTRED, Sticks(pitch=0.55)], 7.0)[-1] is FlightMode.POSCTL


def test_a_push_before_arming_does_not_take_over_but_moving_back_after_arming_does(commander):
    commander.manual_control(CENTRED, 0.0)
    commander.update(status(0.0))
    commander.manual_control(Sticks(pitch=0.4), 0.05)
    assert commander.update(status(0.05)).mode is FlightMode.AUTO_LOITER         # disarmed: nothing to take
    assert commander.arm(status(0.1)).accepted
    commander.manual_control(CENTRED, 0.15)                                       # 40 % back within 1 s
    assert commander.update(status(0.15, armed=True)).mode is FlightMode.POSCTL


@pytest.mark.parametrize("bits", [0.0, 2.0])
def test_without_com_rc_override_bit_1_the_sticks_never_take_over_an_auto_mode(commander, bits):
    commander.params.set("COM_RC_OVERRIDE", bits)
    _armed_in_hold(commander)
    assert _stream(commander, [CENTRED, Sticks(pitch=1.0), CENTRED], 5.0) == [FlightMode.AUTO_LOITER] * 3


# ------------------------------------------------------------------------------ stick shaping params
def test_position_mode_follows_the_dead_zone_expo_and_speed_parameters(commander):
    commander.params.set("MPC_HOLD_DZ", 0.3)
    commander.params.set("MPC_XY_MAN_EXPO", 0.0)                 # linear
    commander.params.set("MPC_VEL_MANUAL", 8.0)
    airborne_in(commander, FlightMode.POSCTL)
    commander.manual_control(Sticks(pitch=0.65), 1.1)
    sp = commander.update(flying(1.1)).setpoint
    assert sp.velocity[0] == pytest.approx((0.65 - 0.3) / (1.0 - 0.3) * 8.0)       # 4 m/s north


def test_throttle_and_yaw_sticks_follow_their_expo_and_the_yaw_rate_parameter(commander):
    commander.params.set("MPC_HOLD_DZ", 0.2)
    commander.params.set("MPC_Z_MAN_EXPO", 0.0)
    commander.params.set("MPC_YAW_EXPO", 0.0)
    commander.params.set("MPC_MAN_Y_MAX", 100.0)
    airborne_in(commander, FlightMode.POSCTL)
    commander.manual_control(Sticks(throttle=0.8, yaw=0.6), 1.1)
    sp = commander.update(flying(1.1)).setpoint
    up = ((2 * 0.8 - 1) - 0.2) / (1.0 - 0.2)                     # 0.5 of full climb, linear
    assert sp.velocity[2] == pytest.approx(-up * 3.0)            # MPC_Z_VEL_MAX_UP's default, 3 m/s
    assert sp.yaw_rate == pytest.approx((0.6 - 0.2) / (1.0 - 0.2) * math.radians(100.0))


def test_stabilized_tilts_to_mpc_man_tilt_max_at_full_stick(commander):
    commander.params.set("MPC_MAN_TILT_MAX", 20.0)
    commander.manual_control(Sticks(throttle=0.0), 0.0)
    assert commander.set_mode(FlightMode.STABILIZED, status()).accepted and commander.arm(status()).accepted
    commander.manual_control(Sticks(pitch=1.0, throttle=0.5), 0.1)
    assert commander.update(flying(0.1)).setpoint.pitch == pytest.approx(-math.radians(20.0))


def test_the_climb_and_descent_limits_come_from_the_vehicles_velocity_limits():
    """The server's parameter store also holds the controller's MPC_Z_VEL_MAX_UP/DN: full throttle climbs at
    the one, zero throttle descends at the other."""
    from sitl_vehicle.params import ParamSpec

    limits = [ParamSpec("MPC_Z_VEL_MAX_UP", 3.0, 0.1, 10.0, "m/s", "Climb velocity limit"),
              ParamSpec("MPC_Z_VEL_MAX_DN", 1.5, 0.1, 10.0, "m/s", "Descent velocity limit")]
    commander = Commander(ParameterStore(COMMANDER_PARAMS + limits))
    commander.params.set("MPC_Z_VEL_MAX_UP", 2.0)
    commander.params.set("MPC_Z_VEL_MAX_DN", 1.0)
    airborne_in(commander, FlightMode.POSCTL)
    commander.manual_control(Sticks(throttle=1.0), 1.1)
    assert commander.update(flying(1.1)).setpoint.velocity[2] == pytest.approx(-2.0)
    commander.manual_control(Sticks(throttle=0.0), 1.2)
    assert commander.update(flying(1.2)).setpoint.velocity[2] == pytest.approx(1.0)


# ------------------------------------------------------------------------------------ heading hold
def test_a_released_yaw_stick_holds_the_heading_it_was_released_at(commander):
    airborne_in(commander, FlightMode.POSCTL)
    commander.manual_control(Sticks(yaw=1.0), 1.1)
    commander.update(flying(1.1))
    commander.manual_control(CENTRED, 1.2)
    assert commander.update(flying(1.2, yaw=0.7)).setpoint.yaw == pytest.approx(0.7)
    commander.manual_control(CENTRED, 1.3)
    assert commander.update(flying(1.3, yaw=0.9)).setpoint.yaw == pytest.approx(0.7)   # held, not followed


def test_entering_position_mode_holds_the_heading_it_was_entered_at(commander):
    commander.manual_control(CENTRED, 0.0)
    assert commander.arm(status()).accepted
    commander.manual_control(CENTRED, 0.5)
    commander.update(flying(0.5))
    assert commander.set_mode(FlightMode.POSCTL, flying(0.5, yaw=0.3)).accepted
    commander.manual_control(CENTRED, 0.6)
    out = commander.update(flying(0.6, yaw=0.5))
    assert out.mode is FlightMode.POSCTL and out.setpoint.yaw == pytest.approx(0.3)


@pytest.mark.parametrize("mode", [FlightMode.POSCTL, FlightMode.ALTCTL])
def test_moving_sticks_turn_with_the_yaw_stick_or_hold_the_heading(commander, mode):
    airborne_in(commander, mode)
    commander.manual_control(Sticks(pitch=1.0, yaw=1.0), 1.1)
    sp = commander.update(flying(1.1)).setpoint
    assert math.isnan(sp.yaw) and sp.yaw_rate == pytest.approx(math.radians(150.0))     # MPC_MAN_Y_MAX
    commander.manual_control(Sticks(pitch=1.0), 1.2)
    sp = commander.update(flying(1.2, yaw=0.4)).setpoint
    assert sp.yaw == pytest.approx(0.4) and math.isnan(sp.yaw_rate)


def test_altitude_mode_throttle_climbs_at_a_velocity(commander):
    airborne_in(commander, FlightMode.ALTCTL)
    commander.manual_control(Sticks(throttle=1.0), 1.1)
    sp = commander.update(flying(1.1)).setpoint
    assert sp.velocity[2] == pytest.approx(-3.0) and math.isnan(sp.position[2])         # MPC_Z_VEL_MAX_UP

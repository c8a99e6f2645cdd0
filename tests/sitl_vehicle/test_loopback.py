"""Loopback acceptance tests: the vehicle in-process on ephemeral ports, a pymavlink client over UDP."""

from __future__ import annotations

import math
import random
import time

import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.mavlink_io import int_as_param_float, param_float_as_int
from support.mavclient import MavClient, px4_mode_name, wait_sim, wait_streamed, wait_until

ALT = 1.5
SQUARE = [(2.0, 0.0), (2.0, 2.0), (0.0, 2.0), (0.0, 0.0)]


def take_off(client, altitude: float = ALT):
    # PX4 never takes off below MIS_TAKEOFF_ALT (2.5 m): lower it first, as MAVSDK's set_takeoff_altitude does
    with client.lock:
        client.conn.mav.param_set_send(1, 1, b"MIS_TAKEOFF_ALT", altitude, mavlink.MAV_PARAM_TYPE_REAL32)
    echo = client.recv("PARAM_VALUE", 3, lambda m: m.param_id == "MIS_TAKEOFF_ALT")
    assert echo is not None and abs(echo.param_value - altitude) < 1e-6
    ack = client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert ack is not None and ack.result == mavlink.MAV_RESULT_ACCEPTED
    ack = client.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, 488.0 + altitude)
    assert ack is not None and ack.result == mavlink.MAV_RESULT_ACCEPTED
    msg = client.recv("LOCAL_POSITION_NED", 20, lambda m: abs(m.z + altitude) < 0.05 and abs(m.vz) < 0.05)
    assert msg is not None, "takeoff did not reach its altitude"


def enter_offboard(client, hold=(0.0, 0.0, -ALT)):
    client.stream(hold)
    wait_streamed(client, 8)  # PX4 wants the stream running before the switch
    ack = client.set_mode("OFFBOARD")
    assert ack is not None and ack.result == mavlink.MAV_RESULT_ACCEPTED


def fly_leg(client, start, corner, settle_s: float = 2.5):
    """Stream ``corner`` until the vehicle has settled there; return the LOCAL_POSITION_NED samples."""
    client.stream(corner)
    samples = []
    t_start = None
    while True:
        msg = client.recv("LOCAL_POSITION_NED", 2.0)
        assert msg is not None, "telemetry stopped"
        t = msg.time_boot_ms / 1000.0
        t_start = t if t_start is None else t_start
        samples.append((t, (msg.x, msg.y, msg.z), (msg.vx, msg.vy, msg.vz)))
        settled = math.dist(samples[-1][1], corner) < 0.02 and math.hypot(msg.vx, msg.vy, msg.vz) < 0.02
        if (settled and t - t_start > settle_s) or t - t_start > 12.0:
            return samples


def leg_metrics(samples, start, corner):
    direction = [c - s for c, s in zip(corner, start, strict=True)]
    length = math.hypot(*direction)
    unit = [d / length for d in direction]
    peak = max(math.hypot(v[0], v[1], v[2]) for _, _, v in samples)
    overshoot = max(sum((p[i] - corner[i]) * unit[i] for i in range(3)) for _, p, _ in samples)
    final_error = math.dist(samples[-1][1], corner)
    return peak, overshoot, final_error


def test_offboard_square_flight_tracks_within_bounds(make_vehicle):
    server, client = make_vehicle()
    take_off(client)
    enter_offboard(client)
    v_max = server.config.vehicle.planner.v_max_xy
    start = (0.0, 0.0, -ALT)
    for x, y in SQUARE:
        corner = (x, y, -ALT)
        peak, overshoot, final_error = leg_metrics(fly_leg(client, start, corner), start, corner)
        assert final_error < 0.05, f"leg to {corner}: final error {final_error:.3f} m"
        assert abs(peak - v_max) <= 0.05 * v_max, f"leg to {corner}: peak {peak:.3f} m/s vs v_max {v_max}"
        assert overshoot <= 0.10, f"leg to {corner}: overshoot {overshoot:.3f} m"
        start = corner
    ack = client.command(mavlink.MAV_CMD_NAV_LAND)
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    client.stop_stream()
    disarmed = client.recv("HEARTBEAT", 30, lambda m: not m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
    assert disarmed is not None, "vehicle did not auto-disarm after landing"
    assert server.sim.truth.position[2] > -0.05 and not server.sim.crashed


def test_offboard_refused_without_setpoint_stream(make_vehicle):
    _, client = make_vehicle()
    ack = client.set_mode("OFFBOARD")
    assert ack.result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    text = client.statustext("Offboard", 3)
    assert text is not None and "not possible: no setpoint stream" in text
    hb = client.recv("HEARTBEAT", 3)
    assert px4_mode_name(hb) != "OFFBOARD"


def test_arming_refused_with_reason_in_land_mode(make_vehicle):
    _, client = make_vehicle()
    assert client.set_mode("LAND").result == mavlink.MAV_RESULT_ACCEPTED
    ack = client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert ack.result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    text = client.statustext("Arming denied", 3)
    assert text is not None and "Land mode is not armable" in text
    assert client.statustext("Arming denied", 1.0) is None  # said once, as PX4 says it


def _offboard_hover(make_vehicle, **params):
    server, client = make_vehicle(params=tuple(params.items()))
    take_off(client)
    enter_offboard(client)
    client.stream((0.5, 0.0, -ALT))
    assert client.recv("LOCAL_POSITION_NED", 10, lambda m: abs(m.x - 0.5) < 0.05) is not None
    return server, client


def test_offboard_loss_fails_safe_to_hold(make_vehicle):
    server, client = _offboard_hover(make_vehicle)
    client.stop_stream()
    text = client.statustext("Failsafe", 5)
    assert text is not None and "Hold" in text
    hb = client.recv("HEARTBEAT", 3, lambda m: px4_mode_name(m) == "LOITER")
    assert hb is not None and hb.system_status == mavlink.MAV_STATE_CRITICAL
    # Hold keeps the vehicle in the air where it was.
    wait_sim(server, 4.0)
    assert abs(server.sim.truth.position[2] + ALT) < 0.1 and abs(server.sim.truth.position[0] - 0.5) < 0.15


def test_offboard_loss_lands_when_configured(make_vehicle):
    server, client = _offboard_hover(make_vehicle, COM_OBL_RC_ACT=4.0)
    client.stop_stream()
    assert client.recv("HEARTBEAT", 5, lambda m: px4_mode_name(m) == "LAND") is not None
    assert wait_until(lambda: not server.sim.armed, 30), "vehicle did not land and disarm"
    assert not server.sim.crashed


def test_offboard_loss_returns_home_when_configured(make_vehicle):
    server, client = _offboard_hover(make_vehicle, COM_OBL_RC_ACT=3.0, RTL_RETURN_ALT=2.5, RTL_DESCEND_ALT=2.0)
    client.stop_stream()
    assert client.recv("HEARTBEAT", 5, lambda m: px4_mode_name(m) == "RTL") is not None
    assert wait_until(lambda: not server.sim.armed, 40), "vehicle did not return, land and disarm"
    x, y, z = server.sim.truth.position
    assert math.hypot(x, y) < 0.15 and z > -0.05 and not server.sim.crashed


def test_ground_station_link_loss_lands_when_configured(make_vehicle):
    server, client = make_vehicle(params=(("NAV_DLL_ACT", 3.0), ("COM_DL_LOSS_T", 2.0)))
    take_off(client)
    with client.lock:   # a ground station says hello once, then goes quiet
        client.conn.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
    text = client.statustext("Failsafe: data link lost", 5)
    assert text is not None and "Land" in text
    assert client.recv("HEARTBEAT", 3, lambda m: px4_mode_name(m) == "LAND") is not None
    assert wait_until(lambda: not server.sim.armed, 30), "vehicle did not land and disarm"
    assert not server.sim.crashed


def test_return_to_launch_command_flies_home_over_the_return_altitude(make_vehicle):
    server, client = make_vehicle(params=(("RTL_RETURN_ALT", 3.0), ("RTL_DESCEND_ALT", 2.0),
                                          ("RTL_LAND_DELAY", 0.5)))
    take_off(client)
    home = client.recv("HOME_POSITION", 3)
    assert home is not None and abs(home.x) < 0.05 and abs(home.y) < 0.05 and abs(home.altitude - 488000) < 50
    enter_offboard(client)
    fly_leg(client, (0.0, 0.0, -ALT), (1.5, 1.0, -ALT), settle_s=0.5)
    ack = client.command(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH)
    assert ack is not None and ack.result == mavlink.MAV_RESULT_ACCEPTED
    client.stop_stream()
    text = client.statustext("Return: flying home", 3)
    assert text is not None and "3.0 m above home" in text
    highest, samples = 0.0, []
    while server.sim.armed:
        msg = client.recv("LOCAL_POSITION_NED", 2.0)
        assert msg is not None, "telemetry stopped"
        samples.append((msg.x, msg.y, msg.z))
        highest = max(highest, -msg.z)
        assert len(samples) < 60 * 50, "no landing within a minute"
    assert highest == pytest.approx(3.0, abs=0.1)                  # climbed to RTL_RETURN_ALT before going home
    leaving = [p for p in samples if math.hypot(p[0] - 1.5, p[1] - 1.0) > 0.2]
    assert leaving and all(-p[2] > 2.8 for p in leaving[:5])        # ... and only left at that altitude
    x, y, z = server.sim.truth.position
    assert math.hypot(x, y) < 0.15 and z > -0.05 and not server.sim.crashed


def test_nan_and_unsupported_frame_setpoints_are_rejected_with_statustext(make_vehicle):
    server, client = make_vehicle()
    mask = 0b1001_1111_1000
    with client.lock:
        client.conn.mav.set_position_target_local_ned_send(0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, mask,
                                                           math.nan, 0, -1, 0, 0, 0, 0, 0, 0, 0, 0)
    text = client.statustext("rejected", 3)
    assert text is not None and "position x is nan" in text and "type_mask" in text
    wait_sim(server, 1.1)  # the vehicle rate-limits this warning to one a second of simulation
    with client.lock:
        client.conn.mav.set_position_target_local_ned_send(0, 1, 1, mavlink.MAV_FRAME_LOCAL_ENU, mask,
                                                           0, 0, -1, 0, 0, 0, 0, 0, 0, 0, 0)
    text = client.statustext("frame", 3)
    assert text is not None and "MAV_FRAME_LOCAL_NED" in text
    assert server.interface.setpoints_rejected == 2 and server.interface.setpoints_received == 0
    # Rejected setpoints do not count as a stream: offboard stays unavailable.
    assert client.set_mode("OFFBOARD").result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED


def test_garbage_and_truncated_packets_never_stop_the_vehicle(make_vehicle):
    server, client = make_vehicle()
    rng = random.Random(7)
    sock = client.conn.port
    target = server.address("api")
    valid = mavlink.MAVLink_command_long_message(1, 1, mavlink.MAV_CMD_REQUEST_MESSAGE, 0, 148, 0, 0, 0, 0, 0, 0)
    packet = valid.pack(mavlink.MAVLink(None, 255, 190))
    for i in range(300):
        if i % 3 == 0:
            data = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 300)))
        elif i % 3 == 1:
            data = packet[: rng.randrange(1, len(packet))]  # truncated
        else:
            data = bytes([0xFD]) + bytes(rng.randrange(256) for _ in range(rng.randrange(0, 40)))
        sock.sendto(data, target)
        if i % 25 == 24:
            time.sleep(0.005)  # a flood, but not one the kernel's UDP buffer must drop most of
    # Still alive and still answering commands. UDP may drop a datagram under a flood, so the command is
    # retried as real clients (MAVSDK, QGroundControl) retry theirs.
    for _ in range(3):
        ack = client.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION, timeout=2)
        if ack is not None:
            break
    assert ack is not None and ack.result == mavlink.MAV_RESULT_ACCEPTED
    assert client.recv("AUTOPILOT_VERSION", 3) is not None
    assert server.links[1].malformed_datagrams >= 100  # every garbage datagram that arrived was counted


def test_parameters_list_set_and_takeoff_altitude(make_vehicle):
    server, client = make_vehicle()
    with client.lock:
        client.conn.mav.param_request_list_send(1, 1)
    types = {}
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline and len(types) < len(server.params):
        msg = client.recv("PARAM_VALUE", 1)
        if msg:
            types[msg.param_id] = msg.param_type
            assert msg.param_count == len(server.params)
    assert set(types) == set(server.params.names())
    integers = {name for name, kind in types.items() if kind == mavlink.MAV_PARAM_TYPE_INT32}
    assert {"RTL_TYPE", "NAV_DLL_ACT", "COM_RC_OVERRIDE", "SYS_AUTOSTART", "COM_DL_LOSS_T"} <= integers   # as PX4's
    assert "MIS_TAKEOFF_ALT" not in integers and set(types.values()) == {mavlink.MAV_PARAM_TYPE_INT32,
                                                                          mavlink.MAV_PARAM_TYPE_REAL32}
    with client.lock:
        client.conn.mav.param_set_send(1, 1, b"MIS_TAKEOFF_ALT", 1.2, mavlink.MAV_PARAM_TYPE_REAL32)
    echo = client.recv("PARAM_VALUE", 3, lambda m: m.param_id == "MIS_TAKEOFF_ALT")
    assert echo is not None and abs(echo.param_value - 1.2) < 1e-6
    with client.lock:  # out of range: refused, the stored value echoed back
        client.conn.mav.param_set_send(1, 1, b"MIS_TAKEOFF_ALT", -5.0, mavlink.MAV_PARAM_TYPE_REAL32)
    echo = client.recv("PARAM_VALUE", 3, lambda m: m.param_id == "MIS_TAKEOFF_ALT")
    assert abs(echo.param_value - 1.2) < 1e-6
    # Integers travel as PX4 sends them: their bytes in the float field; the wrong type is refused with the fix.
    with client.lock:
        client.conn.mav.param_set_send(1, 1, b"RTL_TYPE", int_as_param_float(3), mavlink.MAV_PARAM_TYPE_INT32)
    echo = client.recv("PARAM_VALUE", 3, lambda m: m.param_id == "RTL_TYPE")
    assert echo.param_type == mavlink.MAV_PARAM_TYPE_INT32 and param_float_as_int(echo.param_value, 6) == 3
    assert server.params["RTL_TYPE"] == 3.0
    for name, value, kind in ((b"RTL_TYPE", 1.0, mavlink.MAV_PARAM_TYPE_REAL32),
                              (b"MIS_TAKEOFF_ALT", int_as_param_float(2), mavlink.MAV_PARAM_TYPE_INT32)):
        with client.lock:
            client.conn.mav.param_set_send(1, 1, name, value, kind)
        fix = "send MAV_PARAM_TYPE_INT32" if kind == mavlink.MAV_PARAM_TYPE_REAL32 else "send MAV_PARAM_TYPE_REAL32"
        assert fix in client.statustext(f"{name.decode()} is a", 3)
    assert server.params["RTL_TYPE"] == 3.0 and server.params["MIS_TAKEOFF_ALT"] == pytest.approx(1.2)
    # Controller and planner parameters reach the vehicle core at once (PX4 names, PX4 units).
    with client.lock:
        client.conn.mav.param_set_send(1, 1, b"MPC_XY_CRUISE", 1.25, mavlink.MAV_PARAM_TYPE_REAL32)
        client.conn.mav.param_set_send(1, 1, b"MPC_TILTMAX_AIR", 30.0, mavlink.MAV_PARAM_TYPE_REAL32)
    assert client.recv("PARAM_VALUE", 3, lambda m: m.param_id == "MPC_TILTMAX_AIR") is not None
    assert server.sim.config.planner.v_max_xy == 1.25
    assert math.degrees(server.sim.config.control.tilt_max_rad) == pytest.approx(30.0)
    assert client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == mavlink.MAV_RESULT_ACCEPTED
    ack = client.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, math.nan)
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    assert client.recv("HEARTBEAT", 20, lambda m: px4_mode_name(m) == "LOITER") is not None
    assert abs(server.sim.truth.position[2] + 1.2) < 0.1


def test_protocol_services_answer_like_px4(make_vehicle):
    _, client = make_vehicle()
    hb = client.recv("HEARTBEAT", 3)
    assert hb.autopilot == mavlink.MAV_AUTOPILOT_PX4 and hb.type == mavlink.MAV_TYPE_QUADROTOR
    assert hb.base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED and px4_mode_name(hb) == "LOITER"
    sys_status = client.recv("SYS_STATUS", 3)
    assert sys_status.onboard_control_sensors_health & mavlink.MAV_SYS_STATUS_PREARM_CHECK
    assert client.command(4242).result == mavlink.MAV_RESULT_UNSUPPORTED
    with client.lock:
        client.conn.mav.mission_request_list_send(1, 1)
    assert client.recv("MISSION_COUNT", 3).count == 0
    with client.lock:
        client.conn.mav.ping_send(123456, 7, 0, 0)
    pong = client.recv("PING", 3)
    assert pong.seq == 7 and pong.target_system == 255
    with client.lock:
        client.conn.mav.timesync_send(0, 987654321)
    ts = client.recv("TIMESYNC", 3, lambda m: m.ts1 == 987654321)
    assert ts is not None and ts.tc1 > 0
    ack = client.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_ATTITUDE, -1)
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    client.conn.recv_match(type="ATTITUDE", blocking=True, timeout=0.5)  # drain one in flight
    assert client.recv("ATTITUDE", 1.0) is None, "ATTITUDE still streams after interval -1"
    ack = client.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAVLINK_MSG_ID_ATTITUDE, 0)
    assert client.recv("ATTITUDE", 2.0) is not None


def test_ground_truth_stream_carries_the_true_pose_at_50_hz_or_more(make_vehicle):
    truth = MavClient()
    server, client = make_vehicle(truth_remote=("127.0.0.1", truth.port))
    take_off(client, 1.0)
    hovering_since_us = server.sim.time_s * 1e6  # the socket still holds samples from the climb: skip them
    samples = []
    deadline = time.monotonic() + 5
    while len(samples) < 60 and time.monotonic() < deadline:
        msg = truth.recv("ODOMETRY", 1, lambda m: m.time_usec >= hovering_since_us)
        if msg is not None:
            samples.append(msg)
    truth.close()
    assert len(samples) >= 60
    assert all(m.frame_id == mavlink.MAV_FRAME_LOCAL_NED and m.estimator_type == mavlink.MAV_ESTIMATOR_TYPE_MOCAP
               for m in samples)
    span_s = (samples[-1].time_usec - samples[0].time_usec) * 1e-6
    assert (len(samples) - 1) / span_s >= 50.0  # in simulation time
    last = samples[-1]
    assert abs(last.z + 1.0) < 0.05 and abs(math.hypot(*last.q) - 1.0) < 1e-6


def test_telemetry_reports_the_noisy_estimate_not_the_truth(make_vehicle):
    import dataclasses

    from sitl_vehicle.sim import VehicleConfig

    server, client = make_vehicle(vehicle=VehicleConfig(), seed=3)  # default config: sensor noise on
    take_off(client, 1.0)
    errors = []
    for _ in range(20):
        msg = client.recv("LOCAL_POSITION_NED", 2)
        truth = server.sim.truth.position
        errors.append(math.dist((msg.x, msg.y, msg.z), truth))
    assert max(errors) < 0.15, "estimate far from truth"
    assert max(errors) > 1e-4, "telemetry equals the truth although noise is on"
    assert dataclasses.replace(server.config.vehicle).noise is not None


def test_position_mode_flies_with_joystick_input_and_fails_safe_when_it_stops(make_vehicle):
    """QGroundControl's virtual joystick: MANUAL_CONTROL at 20 Hz, Position mode, arm, climb, fly, hold."""
    server, client = make_vehicle(params=(("COM_RC_LOSS_T", 1.5), ("NAV_RCL_ACT", 3.0)))
    ack = client.set_mode("POSCTL")
    assert ack.result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED  # no joystick yet
    client.stream_sticks()
    wait_streamed(client, 6)
    assert client.set_mode("POSCTL").result == mavlink.MAV_RESULT_ACCEPTED
    assert client.recv("HEARTBEAT", 3, lambda m: px4_mode_name(m) == "POSCTL") is not None
    assert client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == mavlink.MAV_RESULT_ACCEPTED
    client.stream_sticks(z=900)  # throttle up: take off and climb
    assert client.recv("LOCAL_POSITION_NED", 15, lambda m: m.z < -1.5) is not None, "did not climb"
    client.stream_sticks()  # centred: hold the altitude where the climb stops
    assert client.recv("LOCAL_POSITION_NED", 10, lambda m: abs(m.vz) < 0.05) is not None
    z_hold = server.sim.truth.position[2]
    client.stream_sticks(x=700)  # forward (north, heading 0)
    assert client.recv("LOCAL_POSITION_NED", 10, lambda m: m.x > 2.0) is not None, "did not fly forward"
    client.stream_sticks()
    stopped = client.recv("LOCAL_POSITION_NED", 10, lambda m: math.hypot(m.vx, m.vy) < 0.05)
    assert stopped is not None, "did not stop when the sticks were centred"
    wait_sim(server, 4.0)  # the position holds
    x, y, z = server.sim.truth.position
    assert abs(x - stopped.x) < 0.1 and abs(y) < 0.1 and abs(z - z_hold) < 0.15
    client.stop_stream()
    text = client.statustext("Failsafe: manual control lost", 5)
    assert text is not None and "Land" in text
    assert wait_until(lambda: not server.sim.armed, 30), "vehicle did not land and disarm"
    assert not server.sim.crashed


def test_malformed_manual_control_is_rejected_with_statustext(make_vehicle):
    server, client = make_vehicle()
    client.stream_sticks(z=1500)
    text = client.statustext("Manual control rejected", 5)
    assert text is not None and "z=1500" in text
    client.stop_stream()
    assert server.interface.manual_rejected > 0
    assert client.set_mode("POSCTL").result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED  # none was used


def armed_with_sticks_in(make_vehicle, mode: str):
    """A vehicle armed on the ground in the stick mode ``mode``, the throttle low, the sticks streaming."""
    server, client = make_vehicle(params=(("COM_RC_LOSS_T", 1.5),))
    client.stream_sticks(z=0)
    wait_streamed(client, 6)
    assert client.set_mode(mode).result == mavlink.MAV_RESULT_ACCEPTED
    assert client.recv("HEARTBEAT", 3, lambda m: px4_mode_name(m) == mode) is not None
    assert client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == mavlink.MAV_RESULT_ACCEPTED
    return server, client


def test_stabilized_mode_flies_on_the_throttle_and_position_mode_catches_it(make_vehicle):
    server, client = armed_with_sticks_in(make_vehicle, "STABILIZED")
    client.stream_sticks(z=650)  # above hover thrust: climbs, with nothing holding the altitude
    assert client.recv("LOCAL_POSITION_NED", 10, lambda m: m.z < -1.5) is not None, "did not climb"
    client.stream_sticks()       # centred sticks in Position mode hold where the vehicle stops
    assert client.set_mode("POSCTL").result == mavlink.MAV_RESULT_ACCEPTED
    assert client.recv("LOCAL_POSITION_NED", 10, lambda m: abs(m.vz) < 0.05 and abs(m.vx) < 0.05) is not None
    z = server.sim.truth.position[2]
    wait_sim(server, 2.0)
    assert abs(server.sim.truth.position[2] - z) < 0.1
    assert client.command(mavlink.MAV_CMD_NAV_LAND).result == mavlink.MAV_RESULT_ACCEPTED
    assert wait_until(lambda: not server.sim.armed, 30) and not server.sim.crashed
    client.stop_stream()


def test_acro_mode_flies_body_rates_from_the_sticks_and_holds_a_bank(make_vehicle):
    """Acro over MAVLink as a ground station flies it: the throttle is the thrust, a roll stick rolls at a rate,
    and centred sticks stop the rotation with the vehicle still banked (nothing levels it); Position mode
    catches it."""
    server, client = armed_with_sticks_in(make_vehicle, "ACRO")
    client.stream_sticks(z=600)  # 60 % thrust, above the 50 % hover: climbs
    assert client.recv("LOCAL_POSITION_NED", 10, lambda m: m.z < -1.5) is not None, "did not climb"
    client.stream_sticks(y=400, z=520)
    assert client.recv("ATTITUDE", 5, lambda m: m.rollspeed > 0.5) is not None, "did not roll"
    client.stream_sticks(z=520)
    banked = client.recv("ATTITUDE", 5, lambda m: abs(m.rollspeed) < 0.05 and m.roll > 0.05)
    assert banked is not None, "the roll did not stop with the vehicle banked"
    wait_sim(server, 0.3)
    assert server.sim.truth.euler()[0] > 0.05                      # still banked: Acro does not level
    client.stream_sticks()
    assert client.set_mode("POSCTL").result == mavlink.MAV_RESULT_ACCEPTED
    assert client.recv("LOCAL_POSITION_NED", 15, lambda m: abs(m.vy) < 0.05 and abs(m.vz) < 0.05) is not None
    assert client.command(mavlink.MAV_CMD_NAV_LAND).result == mavlink.MAV_RESULT_ACCEPTED
    assert wait_until(lambda: not server.sim.armed, 30) and not server.sim.crashed
    client.stop_stream()


def test_each_link_numbers_its_messages_in_sequence(make_vehicle):
    """PX4 numbers every message it sends on a link (mod 256); ground stations count link loss from the gaps."""
    _, client = make_vehicle()
    seqs = []
    while len(seqs) < 300:
        msg = client.recv(["HEARTBEAT", "ATTITUDE", "LOCAL_POSITION_NED", "SYS_STATUS", "ATTITUDE_QUATERNION",
                           "GLOBAL_POSITION_INT", "GPS_RAW_INT", "VFR_HUD", "EXTENDED_SYS_STATE", "BATTERY_STATUS",
                           "SYSTEM_TIME", "HOME_POSITION", "MISSION_CURRENT", "STATUSTEXT"], 2.0)
        assert msg is not None
        seqs.append(msg.get_seq())
    steps = [(b - a) % 256 for a, b in zip(seqs, seqs[1:], strict=False)]
    assert steps.count(1) >= 0.98 * len(steps), steps[:40]      # loopback loses nothing; every step is one

"""The streams sent only when a client asks for them, as MAVSDK's Telemetry.set_rate_* and QGroundControl do: the
IMU, altitudes, the estimate as ODOMETRY, the ground truth and the motors; RC_CHANNELS and DISTANCE_SENSOR accepted
but sent never (no RC receiver, no rangefinder), as PX4 SITL does without them."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.requested_streams import EARTH_FIELD_GAUSS, pressure_hpa
from sitl_vehicle.telemetry import Home
from tests.sitl_vehicle.test_loopback import ALT, take_off


def ask(client, name: str, hz: float = 20.0):
    msg_id = getattr(mavlink, f"MAVLINK_MSG_ID_{name}")
    return client.command(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / hz).result


def test_the_atmosphere_s_pressure():
    assert pressure_hpa(0.0) == pytest.approx(1013.25)
    assert pressure_hpa(488.0) == pytest.approx(956.0, abs=0.1)       # PX4 SITL's home, Zurich
    assert pressure_hpa(1500.0) == pytest.approx(845.6, abs=0.1)


def test_imu_and_altitude_read_what_the_vehicle_does(make_vehicle):
    server, client = make_vehicle()
    assert client.recv("HIGHRES_IMU", 1.0) is None                    # not streamed unless asked for
    for name in ("HIGHRES_IMU", "SCALED_IMU", "ALTITUDE"):
        assert ask(client, name) == mavlink.MAV_RESULT_ACCEPTED
    at_rest = client.recv("HIGHRES_IMU", 3)
    assert (at_rest.xacc, at_rest.yacc, at_rest.zacc) == pytest.approx((0.0, 0.0, -9.81), abs=0.02)
    assert (at_rest.xmag, at_rest.ymag, at_rest.zmag) == pytest.approx(EARTH_FIELD_GAUSS, abs=0.01)
    assert at_rest.abs_pressure == pytest.approx(pressure_hpa(Home().alt_m), abs=0.05)
    assert at_rest.fields_updated & 0b111_1111_1111 == 0b011_1111_1111   # no differential pressure
    scaled = client.recv("SCALED_IMU", 3)
    assert scaled.zacc == pytest.approx(-1000, abs=3) and abs(scaled.xgyro) < 5      # mG, mrad/s
    take_off(client)
    altitude = client.recv("ALTITUDE", 3, lambda m: abs(m.altitude_relative - ALT) < 0.05)
    assert altitude.altitude_amsl == pytest.approx(Home().alt_m + ALT, abs=0.05)
    assert altitude.altitude_local == pytest.approx(ALT, abs=0.05) and math.isnan(altitude.altitude_terrain)


def test_odometry_ground_truth_and_motor_outputs(make_vehicle):
    server, client = make_vehicle()
    for name in ("ODOMETRY", "HIL_STATE_QUATERNION", "ACTUATOR_OUTPUT_STATUS", "SERVO_OUTPUT_RAW"):
        assert ask(client, name) == mavlink.MAV_RESULT_ACCEPTED
    stopped = client.recv("SERVO_OUTPUT_RAW", 3)
    assert (stopped.servo1_raw, stopped.servo4_raw, stopped.servo5_raw) == (1000, 1000, 0)
    take_off(client)
    client.command(mavlink.MAV_CMD_DO_REPOSITION, -1, 0, 0, math.nan, *Home().to_global((3.0, 0.0, -ALT)))
    moving = client.recv("ODOMETRY", 10, lambda m: m.vx > 0.5)        # body FRD: flying nose first, north
    assert (moving.frame_id, moving.child_frame_id) == (mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_BODY_FRD)
    assert abs(moving.vy) < 0.1 and moving.z == pytest.approx(-ALT, abs=0.1) and math.isnan(moving.pose_covariance[0])
    truth = client.recv("HIL_STATE_QUATERNION", 3)
    lat, lon, alt = Home().to_global(server.sim.truth.position)
    assert truth.lat == pytest.approx(lat * 1e7, abs=200) and truth.lon == pytest.approx(lon * 1e7, abs=300)
    assert truth.alt == pytest.approx(alt * 1000, abs=100) and truth.zacc == pytest.approx(-1000, abs=150)
    flying = client.recv("ACTUATOR_OUTPUT_STATUS", 3)
    assert flying.active == 0b1111 and all(0.2 < u < 0.9 for u in flying.actuator[:4])
    assert not any(flying.actuator[4:])
    servos = client.recv("SERVO_OUTPUT_RAW", 3)
    assert all(1200 < pwm < 1900 for pwm in (servos.servo1_raw, servos.servo2_raw, servos.servo3_raw,
                                              servos.servo4_raw))


def test_streams_without_data_are_accepted_and_never_sent(make_vehicle):
    server, client = make_vehicle()
    for name in ("RC_CHANNELS", "DISTANCE_SENSOR"):
        assert ask(client, name) == mavlink.MAV_RESULT_ACCEPTED
    assert client.recv(["RC_CHANNELS", "DISTANCE_SENSOR"], 1.0) is None
    ack = client.command(mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_RC_CHANNELS)
    assert ack.result == mavlink.MAV_RESULT_DENIED
    assert ask(client, "RAW_IMU") == mavlink.MAV_RESULT_DENIED            # PX4 has no such stream either

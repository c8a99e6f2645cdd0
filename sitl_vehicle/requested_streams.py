"""The messages PX4 streams that this vehicle sends only when a client asks (SET_MESSAGE_INTERVAL, as MAVSDK's
``Telemetry.set_rate_*`` does, or REQUEST_MESSAGE): the IMU, the altitudes, the estimate as ODOMETRY, the simulator's
ground truth, and the motors' outputs.

PX4 knows some streams it has no data for here: a client may set their interval (PX4 accepts it) and gets nothing,
as from PX4 SITL without an RC receiver or a rangefinder (:data:`STREAMS_WITHOUT_DATA`).
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.airframes import GRAVITY
from sitl_vehicle.control.qmath import qrotate_inv

STREAMS_WITHOUT_DATA = ("RC_CHANNELS", "DISTANCE_SENSOR")

# the Earth's magnetic field at PX4 SITL's default home (Zurich), NED, gauss: what the magnetometer reads, rotated
EARTH_FIELD_GAUSS = (0.216, 0.006, 0.424)
# International Standard Atmosphere at sea level, and the IMU's temperature
SEA_LEVEL_HPA = 1013.25
TEMPERATURE_C = 25.0
# HIGHRES_IMU.fields_updated: accelerometer, gyroscope, magnetometer, absolute pressure, pressure altitude and
# temperature (no differential pressure: a multicopter has no airspeed sensor)
HIGHRES_FIELDS = 0b1_1011_1111_1111


def pressure_hpa(altitude_amsl_m: float) -> float:
    """The International Standard Atmosphere's pressure at an altitude above sea level (troposphere)."""
    return SEA_LEVEL_HPA * (1.0 - 2.25577e-5 * altitude_amsl_m) ** 5.25588


def _int16(value: float) -> int:
    return int(max(-32768, min(32767, round(value))))


def requested_message(name: str, t, home, home_down: float):
    """One of these messages from a telemetry snapshot ``t`` (:class:`sitl_vehicle.telemetry.Telemetry`), the
    local frame's place on the globe ``home`` and home's local down (m, the commander's); None for any other name."""
    usec = int(t.time_s * 1e6)
    if name in ("HIGHRES_IMU", "SCALED_IMU"):
        accel, gyro = t.imu
        mag = qrotate_inv(t.attitude, EARTH_FIELD_GAUSS)
        if name == "SCALED_IMU":   # mG, mrad/s, mgauss, centi-degrees
            return mavlink.MAVLink_scaled_imu_message(
                int(t.time_s * 1000) & 0xFFFFFFFF, *(_int16(a / GRAVITY * 1000) for a in accel),
                *(_int16(g * 1000) for g in gyro), *(_int16(m * 1000) for m in mag), _int16(TEMPERATURE_C * 100))
        amsl = home.to_global(t.position)[2]
        return mavlink.MAVLink_highres_imu_message(usec, *accel, *gyro, *mag, pressure_hpa(amsl), 0.0, amsl,
                                                   TEMPERATURE_C, HIGHRES_FIELDS, 0)
    if name == "ALTITUDE":
        amsl = home.to_global(t.position)[2]
        return mavlink.MAVLink_altitude_message(usec, amsl, amsl, -t.position[2], home_down - t.position[2],
                                                math.nan, math.nan)
    if name == "ODOMETRY":         # the estimate as PX4 sends it: the velocity in the body frame
        return mavlink.MAVLink_odometry_message(
            usec, mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_BODY_FRD, *t.position, list(t.attitude),
            *qrotate_inv(t.attitude, t.velocity), *t.angular_velocity, [math.nan] + [0.0] * 20,
            [math.nan] + [0.0] * 20, 0, mavlink.MAV_ESTIMATOR_TYPE_GPS_INS, 100)
    if name == "HIL_STATE_QUATERNION":       # the simulator's ground truth (MAVSDK's ground_truth)
        truth = t.truth
        lat, lon, alt = home.to_global(truth.position)
        speed_cm = _int16(math.hypot(*truth.velocity) * 100)
        return mavlink.MAVLink_hil_state_quaternion_message(
            usec, list(truth.attitude), *truth.angular_velocity, int(round(lat * 1e7)), int(round(lon * 1e7)),
            int(round(alt * 1000)), *(_int16(v * 100) for v in truth.velocity), speed_cm, speed_cm,
            *(_int16(a / GRAVITY * 1000) for a in t.true_specific_force))
    if name == "ACTUATOR_OUTPUT_STATUS":
        outputs = list(t.motors) + [0.0] * (32 - len(t.motors))
        return mavlink.MAVLink_actuator_output_status_message(usec, (1 << len(t.motors)) - 1, outputs)
    if name == "SERVO_OUTPUT_RAW":           # PWM, 1000 µs stopped to 2000 µs full, as PX4's default outputs
        pwm = [int(round(1000 + 1000 * min(max(u, 0.0), 1.0))) for u in t.motors][:8]
        return mavlink.MAVLink_servo_output_raw_message(usec & 0xFFFFFFFF, 0, *(pwm + [0] * (8 - len(pwm))))
    return None

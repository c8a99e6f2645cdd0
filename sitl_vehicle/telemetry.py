"""What the vehicle reports, and when: the telemetry snapshot, each link's stream schedule and the stream messages.

``Telemetry`` is the estimate as a real autopilot reports it, ``StreamSchedule`` one link's message intervals
(PX4's defaults, changed by MAV_CMD_SET_MESSAGE_INTERVAL), ``Home`` the local frame's place on the globe, and
:func:`stream_message` encodes one stream message from a snapshot. Apart from the protocol
(``sitl_vehicle.mavlink_io``) because none of it handles a message: it is the vehicle's side of the streams.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.airframes import GRAVITY
from sitl_vehicle.commander import Commander
from sitl_vehicle.modes import FlightMode
from sitl_vehicle.requested_streams import requested_message
from sitl_vehicle.sim import VehicleState

EARTH_RADIUS_M = 6_378_137.0


# Default stream rates (Hz) per link, close to PX4's "onboard" profile but lighter.
DEFAULT_STREAMS_HZ = {
    "HEARTBEAT": 1.0,
    "SYS_STATUS": 2.0,
    "EXTENDED_SYS_STATE": 2.0,
    "ATTITUDE": 20.0,
    "ATTITUDE_QUATERNION": 20.0,
    "LOCAL_POSITION_NED": 30.0,
    "GLOBAL_POSITION_INT": 10.0,
    "GPS_RAW_INT": 2.0,
    "HOME_POSITION": 0.5,
    "BATTERY_STATUS": 1.0,
    "SYSTEM_TIME": 1.0,
    "VFR_HUD": 4.0,
    "MISSION_CURRENT": 1.0,
    "ORBIT_EXECUTION_STATUS": 2.0,  # in Orbit mode only, as PX4 sends it
}


@dataclass
class StreamSchedule:
    """Per-link message intervals and next-due times, in simulation seconds."""

    interval_s: dict[str, float] = field(default_factory=lambda: {k: 1.0 / v for k, v in DEFAULT_STREAMS_HZ.items()})
    next_due: dict[str, float] = field(default_factory=dict)

    def due(self, now: float) -> list[str]:
        out = []
        for name, interval in self.interval_s.items():
            if interval <= 0:
                continue
            if now >= self.next_due.get(name, 0.0):
                out.append(name)
                # Keep the phase but never fall more than one interval behind.
                self.next_due[name] = max(self.next_due.get(name, 0.0) + interval, now)
        return out


@dataclass(frozen=True)
class Home:
    lat_deg: float = 47.397742  # PX4 SITL's default home (Zurich)
    lon_deg: float = 8.545594
    alt_m: float = 488.0  # AMSL

    def to_global(self, ned: tuple[float, float, float]) -> tuple[float, float, float]:
        """Flat-earth NED → (lat°, lon°, alt AMSL m); exact enough over a simulation's few hundred metres."""
        lat = self.lat_deg + math.degrees(ned[0] / EARTH_RADIUS_M)
        lon = self.lon_deg + math.degrees(ned[1] / (EARTH_RADIUS_M * math.cos(math.radians(self.lat_deg))))
        return lat, lon, self.alt_m - ned[2]

    def to_local(self, lat_deg: float, lon_deg: float, alt_m: float) -> tuple[float, float, float]:
        """(lat°, lon°, alt AMSL m) → flat-earth NED, the inverse of ``to_global``."""
        north = math.radians(lat_deg - self.lat_deg) * EARTH_RADIUS_M
        east = math.radians(lon_deg - self.lon_deg) * EARTH_RADIUS_M * math.cos(math.radians(self.lat_deg))
        return north, east, self.alt_m - alt_m


@dataclass
class Telemetry:
    """The snapshot the streams are built from (the estimate, as a real autopilot reports)."""

    time_s: float
    position: tuple[float, float, float]
    velocity: tuple[float, float, float]
    attitude: tuple[float, float, float, float]
    angular_velocity: tuple[float, float, float]
    euler: tuple[float, float, float]
    armed: bool
    landed: bool
    crashed: bool
    mode: FlightMode
    failsafe: bool
    throttle: float = 0.0
    # for the streams a client asks for (sitl_vehicle.requested_streams)
    imu: tuple[tuple[float, float, float], tuple[float, float, float]] = ((0.0, 0.0, -GRAVITY), (0.0, 0.0, 0.0))
    motors: tuple[float, ...] = ()
    truth: VehicleState | None = None           # the simulator's ground truth
    true_specific_force: tuple[float, float, float] = (0.0, 0.0, -GRAVITY)   # body FRD, m/s²


SENSORS_PRESENT = (mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
                   | mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG | mavlink.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
                   | mavlink.MAV_SYS_STATUS_SENSOR_GPS | mavlink.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
                   | mavlink.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION | mavlink.MAV_SYS_STATUS_SENSOR_YAW_POSITION
                   | mavlink.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
                   | mavlink.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL | mavlink.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
                   | mavlink.MAV_SYS_STATUS_AHRS | mavlink.MAV_SYS_STATUS_SENSOR_BATTERY)


def stream_message(name: str, t: Telemetry, home: Home, commander: Commander, boot_wall: float):
    """Encode one stream message from a telemetry snapshot (None if this vehicle cannot send it).

    ``home`` places the local frame on the globe, ``commander`` says where home is and whether it is landing, and
    ``boot_wall`` is the wall time the vehicle booted at (SYSTEM_TIME). MISSION_CURRENT is the mission
    protocol's (``sitl_vehicle.mission_protocol``); the streams sent only on request are built in
    ``sitl_vehicle.requested_streams``.
    """
    boot_ms = int(t.time_s * 1000) & 0xFFFFFFFF
    if name == "HEARTBEAT":
        base = t.mode.base_mode_flags | (mavlink.MAV_MODE_FLAG_SAFETY_ARMED if t.armed else 0)
        if t.crashed:
            state = mavlink.MAV_STATE_EMERGENCY
        elif t.failsafe:
            state = mavlink.MAV_STATE_CRITICAL
        else:
            state = mavlink.MAV_STATE_ACTIVE if t.armed else mavlink.MAV_STATE_STANDBY
        return mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4,
                                                 base, t.mode.custom_mode, state, 3)
    if name == "SYS_STATUS":
        present = SENSORS_PRESENT
        healthy = present if t.crashed else present | mavlink.MAV_SYS_STATUS_PREARM_CHECK
        if t.crashed:
            healthy &= ~mavlink.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
        return mavlink.MAVLink_sys_status_message(present, present, healthy, 300 if t.armed else 50,
                                                  16200, 1000 if t.armed else 50, 90, 0, 0, 0, 0, 0, 0)
    if name == "EXTENDED_SYS_STATE":
        landed = mavlink.MAV_LANDED_STATE_ON_GROUND if t.landed else mavlink.MAV_LANDED_STATE_IN_AIR
        if not t.landed and t.mode is FlightMode.AUTO_TAKEOFF:
            landed = mavlink.MAV_LANDED_STATE_TAKEOFF
        elif not t.landed and commander.landing:
            landed = mavlink.MAV_LANDED_STATE_LANDING
        return mavlink.MAVLink_extended_sys_state_message(mavlink.MAV_VTOL_STATE_UNDEFINED, landed)
    if name == "ATTITUDE":
        return mavlink.MAVLink_attitude_message(boot_ms, *t.euler, *t.angular_velocity)
    if name == "ATTITUDE_QUATERNION":
        return mavlink.MAVLink_attitude_quaternion_message(boot_ms, *t.attitude, *t.angular_velocity,
                                                           [0.0, 0.0, 0.0, 0.0])
    if name == "LOCAL_POSITION_NED":
        return mavlink.MAVLink_local_position_ned_message(boot_ms, *t.position, *t.velocity)
    if name in ("GLOBAL_POSITION_INT", "GPS_RAW_INT", "VFR_HUD"):
        lat, lon, alt = home.to_global(t.position)
        ground_speed = math.hypot(t.velocity[0], t.velocity[1])
        heading_cdeg = int(math.degrees(t.euler[2]) % 360 * 100)
        if name == "GLOBAL_POSITION_INT":
            return mavlink.MAVLink_global_position_int_message(
                boot_ms, int(lat * 1e7), int(lon * 1e7), int(alt * 1000), int(-t.position[2] * 1000),
                *(int(v * 100) for v in t.velocity), heading_cdeg)
        if name == "GPS_RAW_INT":
            return mavlink.MAVLink_gps_raw_int_message(
                int(t.time_s * 1e6), mavlink.GPS_FIX_TYPE_3D_FIX, int(lat * 1e7), int(lon * 1e7),
                int(alt * 1000), 70, 90, int(ground_speed * 100), heading_cdeg // 1 % 36000, 12)
        return mavlink.MAVLink_vfr_hud_message(ground_speed, ground_speed, int(math.degrees(t.euler[2]) % 360),
                                               int(t.throttle * 100), alt, -t.velocity[2])
    if name == "HOME_POSITION":
        hx, hy, hz = commander.home             # where the vehicle last armed, in the local frame
        lat, lon, alt = home.to_global((hx, hy, hz))
        return mavlink.MAVLink_home_position_message(
            int(lat * 1e7), int(lon * 1e7), int(alt * 1000),
            hx, hy, hz, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, int(t.time_s * 1e6))
    if name == "ORBIT_EXECUTION_STATUS":
        orbit = commander.orbit_flown
        if orbit is None:
            return None
        lat, lon, alt = home.to_global(orbit.centre)     # PX4: MAV_FRAME_GLOBAL, the altitude above sea level
        return mavlink.MAVLink_orbit_execution_status_message(
            int(t.time_s * 1e6), math.copysign(orbit.radius, orbit.speed), mavlink.MAV_FRAME_GLOBAL,
            int(round(lat * 1e7)), int(round(lon * 1e7)), alt)
    if name == "BATTERY_STATUS":
        voltages = [4050] * 4 + [65535] * 6
        return mavlink.MAVLink_battery_status_message(
            0, mavlink.MAV_BATTERY_FUNCTION_ALL, mavlink.MAV_BATTERY_TYPE_LIPO, 2500, voltages,
            1000 if t.armed else 50, -1, -1, 90)
    if name == "SYSTEM_TIME":
        return mavlink.MAVLink_system_time_message(int((boot_wall + t.time_s) * 1e6), boot_ms)
    if name == "AUTOPILOT_VERSION":
        caps = (mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
                | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
                | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT)
        # flight_sw_version 1.15.0 official, as PX4 encodes it (major<<24 | minor<<16 | patch<<8 | type)
        version = (1 << 24) | (15 << 16) | (0 << 8) | 255
        return mavlink.MAVLink_autopilot_version_message(caps, version, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8,
                                                         0, 0, 0x464C4F57)
    return requested_message(name, t, home, commander.home[2])


def truth_odometry(time_s: float, position, attitude, velocity_ned, angular_velocity):
    """The simulation-only ground-truth pose stream: ODOMETRY in LOCAL_NED with body FRD rates.

    Velocity is sent in the NED frame (child frame LOCAL_NED for velocity, as the ODOMETRY definition
    allows via child_frame_id) so a camera consumer needs no rotation; estimator_type MOCAP marks it as
    an external, exact source rather than the autopilot's estimate.
    """
    return mavlink.MAVLink_odometry_message(
        int(time_s * 1e6), mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_LOCAL_NED,
        *position, list(attitude), *velocity_ned, *angular_velocity,
        [math.nan] + [0.0] * 20, [math.nan] + [0.0] * 20, 0, mavlink.MAV_ESTIMATOR_TYPE_MOCAP, 100)

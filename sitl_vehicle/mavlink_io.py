"""MAVLink over UDP, the way PX4 SITL speaks it.

``UdpLink`` is one UDP endpoint: it sends first to a default remote (PX4: 127.0.0.1:14550 for the ground
station, 127.0.0.1:14540 for the offboard API) and locks onto the first peer that answers. Each datagram
is parsed on its own, so random bytes or a truncated packet cost that datagram only; they are counted
and reported, never raised. ``MavlinkVehicleInterface`` is the protocol: streams, commands, parameters,
the (empty) mission protocol and offboard setpoints, translated into calls on the commander.
"""

from __future__ import annotations

import errno
import logging
import math
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.commander import Commander, Reply, VehicleStatus
from sitl_vehicle.link_signing import LinkSigning
from sitl_vehicle.manual import ManualControlError, sticks_from_manual_control
from sitl_vehicle.mission import MAX_ITEMS, MissionError, MissionItem, mission_item_from_message
from sitl_vehicle.modes import FlightMode, UnsupportedMode, mode_from_custom
from sitl_vehicle.params import ParameterError, ParameterStore
from sitl_vehicle.sim import Setpoint

log = logging.getLogger(__name__)

SYSTEM_ID = 1
COMPONENT_ID = mavlink.MAV_COMP_ID_AUTOPILOT1
FORCE_ARM_MAGIC = 21196  # PX4: param2 of MAV_CMD_COMPONENT_ARM_DISARM that forces (dis)arming
EARTH_RADIUS_M = 6_378_137.0


class PortInUseError(OSError):
    """A UDP port the vehicle must bind is taken by another process."""


def parse_hostport(text: str) -> tuple[str, int]:
    """'host:port' or ':port' → (host, port); raises ValueError with a usable message."""
    host, sep, port = text.rpartition(":")
    if not sep or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ValueError(f"address {text!r} must look like HOST:PORT, e.g. 127.0.0.1:14540")
    return host or "0.0.0.0", int(port)


class UdpLink:
    """One MAVLink UDP endpoint with PX4 SITL's send-first, lock-on-first-answer behaviour."""

    def __init__(self, name: str, local: tuple[str, int], remote: tuple[str, int] | None,
                 system_id: int = SYSTEM_ID, component_id: int = COMPONENT_ID):
        self.name = name
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.bind(local)
        except OSError as exc:
            self.sock.close()
            if exc.errno == errno.EADDRINUSE:
                raise PortInUseError(
                    f"UDP port {local[1]} ({name} link) is already in use: stop the other vehicle or pass "
                    f"another port (see --help, e.g. --instance N)") from None
            raise
        self.sock.setblocking(False)
        self.local_address = self.sock.getsockname()
        self.remote = remote
        self.peer_locked = False
        self.mav = mavlink.MAVLink(None, system_id, component_id)       # packs (and signs) what we send
        # a parser of its own: with a key set, pymavlink would also check signatures on receipt, which the
        # vehicle does itself (sitl_vehicle.signing: PX4's allowlist, the signature before the timestamp)
        self.parser = mavlink.MAVLink(None, system_id, component_id)
        self.parser.robust_parsing = True
        self._signing_clock = None
        self.malformed_datagrams = 0
        self.packets_in = 0
        self.packets_out = 0

    def fileno(self) -> int:
        return self.sock.fileno()

    def sign_outgoing(self, secret: bytes | None, link_id: int, clock) -> None:
        """Sign every message sent from now on with ``secret`` (None: send unsigned) and ``link_id``, never with a
        timestamp behind ``clock()`` (the vehicle's signing clock)."""
        signing = self.mav.signing
        signing.secret_key = secret
        signing.sign_outgoing = secret is not None
        signing.link_id = link_id
        self._signing_clock = clock if secret is not None else None
        if clock is not None:
            signing.timestamp = max(signing.timestamp, clock())

    def signing_timestamp(self) -> int:
        """The timestamp the next signed message will carry."""
        return self.mav.signing.timestamp

    def send(self, msg) -> None:
        if self.remote is None:
            return
        if self._signing_clock is not None:
            self.mav.signing.timestamp = max(self.mav.signing.timestamp, self._signing_clock())
        data = msg.pack(self.mav)
        # a sequence number per link and message, as PX4's: ground stations count link loss from its gaps
        self.mav.seq = (self.mav.seq + 1) % 256
        try:
            self.sock.sendto(data, self.remote)
            self.packets_out += 1
        except OSError as exc:
            # Nobody listening (ECONNREFUSED via ICMP) is normal before a client starts.
            if exc.errno not in (errno.ECONNREFUSED, errno.EAGAIN, errno.ENETUNREACH):
                log.debug("%s link: send failed: %s", self.name, exc)

    def receive(self) -> list:
        """All messages waiting on the socket; malformed datagrams are counted and dropped."""
        out = []
        while True:
            try:
                data, address = self.sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return out
            except OSError as exc:
                if exc.errno == errno.ECONNREFUSED:
                    continue
                raise
            messages = self._parse_datagram(data)
            if messages and not self.peer_locked:
                self.remote = address
                self.peer_locked = True
                log.info("%s link: peer %s:%d connected", self.name, *address)
            out.extend(messages)

    def _parse_datagram(self, data: bytes) -> list:
        mav = self.parser
        mav.buf = bytearray()
        mav.buf_index = 0
        mav.expected_length = mavlink.HEADER_LEN_V1 + 2
        try:
            parsed = mav.parse_buffer(data) or []
        except Exception as exc:  # noqa: BLE001 — a hostile datagram must never stop the vehicle
            parsed = []
            log.debug("%s link: unparsable datagram (%s)", self.name, exc)
            self._count_malformed(len(data))
            return []
        good = [m for m in parsed if m.get_type() != "BAD_DATA"]
        if len(good) != len(parsed) or mav.buf_len() > 0:
            self._count_malformed(len(data))
        self.packets_in += len(good)
        return good

    def _count_malformed(self, size: int) -> None:
        self.malformed_datagrams += 1
        n = self.malformed_datagrams
        if n & (n - 1) == 0:  # log the 1st, 2nd, 4th, 8th … so a flood cannot flood the log
            log.warning("%s link: dropped malformed or truncated MAVLink datagram (%d bytes); %d so far",
                        self.name, size, n)

    def close(self) -> None:
        self.sock.close()


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


def _finite(values) -> bool:
    return all(math.isfinite(v) for v in values)


TYPE_MASK_POSITION = 0b111
TYPE_MASK_VELOCITY = 0b111 << 3
TYPE_MASK_ACCEL = 0b111 << 6
TYPE_MASK_FORCE = 1 << 9
TYPE_MASK_YAW = 1 << 10
TYPE_MASK_YAW_RATE = 1 << 11
SUPPORTED_FRAMES = {mavlink.MAV_FRAME_LOCAL_NED: "LOCAL_NED", mavlink.MAV_FRAME_BODY_NED: "BODY_NED"}


class SetpointError(ValueError):
    """A SET_POSITION_TARGET_LOCAL_NED that cannot be flown; the message says why and how to fix it."""


def setpoint_from_message(msg, yaw_now: float) -> Setpoint:
    """SET_POSITION_TARGET_LOCAL_NED → Setpoint with full type_mask semantics (ignored field = NaN).

    MAV_FRAME_BODY_NED follows the MAVLink definition: positions as in LOCAL_NED, velocities and
    accelerations in the vehicle's heading frame (rotated by the current yaw).
    """
    if msg.coordinate_frame not in SUPPORTED_FRAMES:
        raise SetpointError(f"setpoint frame {msg.coordinate_frame} not supported: use MAV_FRAME_LOCAL_NED (1) "
                            f"or MAV_FRAME_BODY_NED (8)")
    mask = msg.type_mask
    if mask & TYPE_MASK_FORCE and (mask & TYPE_MASK_ACCEL) != TYPE_MASK_ACCEL:
        # The force flag only changes what afx..afz mean; with accelerations ignored it is harmless.
        raise SetpointError("force setpoints (type_mask bit 10) are not supported: send accelerations")

    def axes(bits_offset: int, values: tuple[float, float, float]) -> tuple[float, float, float]:
        return tuple(math.nan if mask & (1 << (bits_offset + i)) else float(v) for i, v in enumerate(values))

    position = axes(0, (msg.x, msg.y, msg.z))
    velocity = axes(3, (msg.vx, msg.vy, msg.vz))
    acceleration = axes(6, (msg.afx, msg.afy, msg.afz))
    yaw = math.nan if mask & TYPE_MASK_YAW else float(msg.yaw)
    yaw_rate = math.nan if mask & TYPE_MASK_YAW_RATE else float(msg.yaw_rate)
    for label, values, offset in (("position", position, 0), ("velocity", velocity, 3),
                                  ("acceleration", acceleration, 6)):
        for i, v in enumerate(values):
            if not (mask & (1 << (offset + i))) and not math.isfinite(v):
                raise SetpointError(f"setpoint {label} {'xyz'[i]} is {v}: set type_mask bit {offset + i} "
                                    f"to leave that axis uncontrolled instead of sending NaN")
    for label, v, bit in (("yaw", yaw, TYPE_MASK_YAW), ("yaw_rate", yaw_rate, TYPE_MASK_YAW_RATE)):
        if not (mask & bit) and not math.isfinite(v):
            raise SetpointError(f"setpoint {label} is {v}: set type_mask bit {bit.bit_length()} to ignore it")
    if all(math.isnan(v) for v in position + velocity + acceleration):
        raise SetpointError("setpoint ignores every position, velocity and acceleration axis: nothing to fly")
    if msg.coordinate_frame == mavlink.MAV_FRAME_BODY_NED:
        c, s = math.cos(yaw_now), math.sin(yaw_now)
        velocity = (c * velocity[0] - s * velocity[1], s * velocity[0] + c * velocity[1], velocity[2])
        acceleration = (c * acceleration[0] - s * acceleration[1], s * acceleration[0] + c * acceleration[1],
                        acceleration[2])
    return Setpoint(position=position, velocity=velocity, acceleration=acceleration, yaw=yaw, yaw_rate=yaw_rate)


class MavlinkVehicleInterface:
    """PX4's MAVLink behaviour for one vehicle over any number of links.

    ``status_fn`` returns the commander's VehicleStatus and ``telemetry_fn`` the stream snapshot; both
    read the vehicle core, which this class never touches directly.
    """

    def __init__(self, commander: Commander, params: ParameterStore, home: Home,
                 status_fn: Callable[[], VehicleStatus], telemetry_fn: Callable[[], Telemetry],
                 system_id: int = SYSTEM_ID, signing: LinkSigning | None = None):
        self.commander = commander
        self.params = params
        self.home = home
        self.status_fn = status_fn
        self.telemetry_fn = telemetry_fn
        self.system_id = system_id
        self.links: list[UdpLink] = []
        self.schedules: dict[str, StreamSchedule] = {}
        self.setpoints_received = 0
        self.setpoints_rejected = 0
        self.manual_rejected = 0
        self._last_warning: dict[str, float] = {}  # per kind of rejected message, when it was last reported
        self._upload: dict | None = None  # the mission upload under way: link, count, items so far
        self._boot_wall = time.time()
        self._statustext_id = 0
        self._after_ack: list = []  # messages a command asked for, sent right after its COMMAND_ACK
        self.signing = signing if signing is not None else LinkSigning()

    def add_link(self, link: UdpLink) -> None:
        self.links.append(link)
        self.schedules[link.name] = StreamSchedule()
        self.signing.attach(link)

    # ----------------------------------------------------------------------------------- sending
    def broadcast(self, msg) -> None:
        for link in self.links:
            link.send(msg)

    def statustext(self, severity: int, text: str, link: UdpLink | None = None) -> None:
        """Send a STATUSTEXT to one link or all; texts over 50 bytes go as MAVLink 2 chunks (id, chunk_seq)."""
        self._statustext_id = (self._statustext_id % 65535) + 1
        for msg in statustext_messages(severity, text, self._statustext_id):
            if link is None:
                self.broadcast(msg)
            else:
                link.send(msg)

    def send_streams(self, now: float) -> None:
        reached = self.commander.mission_reached
        while reached:  # as they happen, then the new current item
            self.broadcast(mavlink.MAVLink_mission_item_reached_message(reached.popleft()))
            self.broadcast(self._mission_current())
        telemetry = None
        for link in self.links:
            names = self.schedules[link.name].due(now)
            if not names:
                continue
            telemetry = telemetry or self.telemetry_fn()
            for name in names:
                msg = self.build(name, telemetry)
                if msg is not None:
                    link.send(msg)

    def heartbeat(self, links: list[UdpLink]) -> None:
        """One HEARTBEAT now on ``links``, outside the streams (a lockstep vehicle held between releases)."""
        msg = self.build("HEARTBEAT", self.telemetry_fn())
        for link in links:
            link.send(msg)

    def build(self, name: str, t: Telemetry):
        """Encode one stream message from a telemetry snapshot (None if this vehicle cannot send it)."""
        if name == "MISSION_CURRENT":
            return self._mission_current()
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
            elif not t.landed and self.commander.landing:
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
            lat, lon, alt = self.home.to_global(t.position)
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
            hx, hy, hz = self.commander.home             # where the vehicle last armed, in the local frame
            lat, lon, alt = self.home.to_global((hx, hy, hz))
            return mavlink.MAVLink_home_position_message(
                int(lat * 1e7), int(lon * 1e7), int(alt * 1000),
                hx, hy, hz, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, int(t.time_s * 1e6))
        if name == "BATTERY_STATUS":
            voltages = [4050] * 4 + [65535] * 6
            return mavlink.MAVLink_battery_status_message(
                0, mavlink.MAV_BATTERY_FUNCTION_ALL, mavlink.MAV_BATTERY_TYPE_LIPO, 2500, voltages,
                1000 if t.armed else 50, -1, -1, 90)
        if name == "SYSTEM_TIME":
            return mavlink.MAVLink_system_time_message(int((self._boot_wall + t.time_s) * 1e6), boot_ms)
        if name == "AUTOPILOT_VERSION":
            caps = (mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                    | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
                    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
                    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT)
            # flight_sw_version 1.15.0 official, as PX4 encodes it (major<<24 | minor<<16 | patch<<8 | type)
            version = (1 << 24) | (15 << 16) | (0 << 8) | 255
            return mavlink.MAVLink_autopilot_version_message(caps, version, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8,
                                                             0, 0, 0x464C4F57)
        return None

    # --------------------------------------------------------------------------------- receiving
    def poll(self, links: list[UdpLink] | None = None) -> None:
        """Handle every message waiting on ``links`` (default: all of them)."""
        for link in self.links if links is None else links:
            for msg in link.receive():
                self.receive(msg, link)

    def receive(self, msg, link: UdpLink) -> None:
        """One message as it arrived on ``link``: through the signing check, then handled."""
        if not self.signing.admit(msg, link):
            report = self.signing.pending_report()
            if report is not None:
                self.statustext(mavlink.MAV_SEVERITY_WARNING, report[1], report[0])
            return
        try:
            self.handle(msg, link)
        except Exception:  # noqa: BLE001 — one bad message must not stop the vehicle (the fuzz tests hunt these)
            log.exception("error handling %s from %s link", msg.get_type(), link.name)

    def handle(self, msg, link: UdpLink) -> None:
        kind = msg.get_type()
        handler = getattr(self, f"_on_{kind.lower()}", None)
        if handler is not None:
            handler(msg, link)

    def _for_me(self, msg) -> bool:
        target = getattr(msg, "target_system", 0)
        return target in (0, self.system_id)

    def _ack(self, link: UdpLink, msg, command: int, reply: Reply) -> None:
        ack = mavlink.MAVLink_command_ack_message(command, reply.result, 0, 0,
                                                  msg.get_srcSystem(), msg.get_srcComponent())
        link.send(ack)
        for follow_up in self._after_ack:
            link.send(follow_up)
        self._after_ack.clear()
        if reply.text and not reply.accepted and not reply.announced:  # one STATUSTEXT per refusal, as PX4
            self.statustext(mavlink.MAV_SEVERITY_CRITICAL, reply.text, link)

    def _on_setup_signing(self, msg, link: UdpLink) -> None:
        """PX4 v1.18: for this autopilot only; unsigned only while no key is set (the signing check has already
        dropped an unsigned one otherwise); never while armed; a blank key turns signing off."""
        if msg.target_system not in (0, self.system_id) or msg.target_component not in (0, COMPONENT_ID):
            return
        # the commander's word, not the airframe's: an ARM accepted a moment ago has not reached the motors yet
        applied, text = self.signing.setup(msg, self.commander.armed)
        self.statustext(mavlink.MAV_SEVERITY_INFO if applied else mavlink.MAV_SEVERITY_CRITICAL, text, link)

    def _on_heartbeat(self, msg, link: UdpLink) -> None:
        if msg.type == mavlink.MAV_TYPE_GCS:
            self.commander.gcs_heartbeat(self.status_fn().time_s)

    def _on_command_long(self, msg, link: UdpLink) -> None:
        if not self._for_me(msg) or msg.target_component not in (0, COMPONENT_ID):
            return
        params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7)
        self._ack(link, msg, msg.command, self.execute(msg.command, params, link))

    def _on_command_int(self, msg, link: UdpLink) -> None:
        if not self._for_me(msg) or msg.target_component not in (0, COMPONENT_ID):
            return
        params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.x * 1e-7, msg.y * 1e-7, msg.z)
        self._ack(link, msg, msg.command, self.execute(msg.command, params, link))

    def execute(self, command: int, p: tuple, link: UdpLink) -> Reply:
        """Run one MAV_CMD; NaN parameters mean 'use the default', as PX4 treats them."""
        status = self.status_fn()
        c = self.commander
        if command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            force = math.isfinite(p[1]) and int(p[1]) == FORCE_ARM_MAGIC
            return c.arm(status, force) if p[0] == 1.0 else c.disarm(status, force)
        if command == mavlink.MAV_CMD_NAV_TAKEOFF:
            # PX4: param7 is AMSL (NaN: the minimum, MIS_TAKEOFF_ALT above home; the commander raises lower ones);
            # param4, the yaw, is ignored on multicopters; params 5/6 are lat/lon, and NaN or both exactly 0
            # (zero-initialised, as MAVProxy's `takeoff` sends them; PX4 PR #28792) mean "where it is"
            home_amsl = self.home.to_global(c.home)[2]
            above_home = p[6] - home_amsl if math.isfinite(p[6]) else math.nan
            lat, lon = p[4], p[5]
            target_xy = None
            if math.isfinite(lat) and math.isfinite(lon) and not (lat == 0.0 and lon == 0.0):
                target_xy = self.home.to_local(lat, lon, home_amsl)[:2]
            return c.takeoff(status, above_home, target_xy)
        if command == mavlink.MAV_CMD_NAV_LAND:
            return c.land(status)
        if command == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            return c.return_to_launch(status)
        if command == mavlink.MAV_CMD_DO_SET_MODE:
            if not math.isfinite(p[0]) or not int(p[0]) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
                return Reply(mavlink.MAV_RESULT_DENIED, "Mode change denied: set MAV_MODE_FLAG_CUSTOM_MODE_ENABLED")
            try:
                mode = mode_from_custom(int(_nan_to(p[1], 0)), int(_nan_to(p[2], 0)))
            except UnsupportedMode as exc:
                return Reply(mavlink.MAV_RESULT_DENIED, f"Mode change denied: {exc}")
            return c.set_mode(mode, status)
        if command == mavlink.MAV_CMD_MISSION_START:
            return c.start_mission(status, int(_nan_to(p[0], 0)))
        if command == mavlink.MAV_CMD_DO_SET_MISSION_CURRENT:
            return c.set_mission_current(int(_nan_to(p[0], 0)), status)
        if command in (mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAV_CMD_REQUEST_MESSAGE) \
                and not (math.isfinite(p[0]) and 0 <= p[0] < 1 << 24):
            # found by fuzzing: int(NaN) raised here; a message id is a 24-bit number
            return Reply(mavlink.MAV_RESULT_DENIED, f"Command {command} denied: message id {p[0]} is not a "
                                                    f"MAVLink message id (0..16777215)")
        if command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            return self._set_interval(link, int(p[0]), p[1])
        if command == mavlink.MAV_CMD_REQUEST_MESSAGE:
            return self._send_requested(link, int(p[0]))
        if command == mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            return self._send_requested(link, mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
        return Reply(mavlink.MAV_RESULT_UNSUPPORTED)

    def _set_interval(self, link: UdpLink, msg_id: int, interval_us: float) -> Reply:
        name = _msg_name(msg_id)
        if name is None or (name not in DEFAULT_STREAMS_HZ and self.build(name, self.telemetry_fn()) is None):
            return Reply(mavlink.MAV_RESULT_DENIED, f"Message id {msg_id} cannot be streamed")
        schedule = self.schedules[link.name]
        if interval_us == 0 or not math.isfinite(interval_us):
            default = DEFAULT_STREAMS_HZ.get(name)
            schedule.interval_s[name] = 1.0 / default if default else -1.0
        elif interval_us < 0:
            schedule.interval_s[name] = -1.0
        else:
            schedule.interval_s[name] = max(interval_us * 1e-6, 0.002)
        schedule.next_due[name] = 0.0
        return Reply(mavlink.MAV_RESULT_ACCEPTED)

    def _send_requested(self, link: UdpLink, msg_id: int) -> Reply:
        name = _msg_name(msg_id)
        msg = self.build(name, self.telemetry_fn()) if name else None
        if msg is None:
            return Reply(mavlink.MAV_RESULT_DENIED)
        self._after_ack.append(msg)  # clients wait for the ACK first, then for the message
        return Reply(mavlink.MAV_RESULT_ACCEPTED)

    def _on_set_position_target_local_ned(self, msg, link: UdpLink) -> None:
        if not self._for_me(msg):
            return
        status = self.status_fn()
        try:
            setpoint = setpoint_from_message(msg, status.yaw)
        except SetpointError as exc:
            self.setpoints_rejected += 1
            self._report_rejected("Setpoint", exc, link, status.time_s)
            return
        self.setpoints_received += 1
        self.commander.offboard_setpoint(setpoint, status.time_s)

    def _on_manual_control(self, msg, link: UdpLink) -> None:
        if msg.target not in (0, self.system_id):
            return
        status = self.status_fn()
        try:
            sticks = sticks_from_manual_control(msg.x, msg.y, msg.z, msg.r)
        except ManualControlError as exc:
            self.manual_rejected += 1
            self._report_rejected("Manual control", exc, link, status.time_s)
            return
        self.commander.manual_control(sticks, status.time_s)

    def _report_rejected(self, kind: str, exc: Exception, link: UdpLink, now: float) -> None:
        """Log and STATUSTEXT a rejected streamed message (``kind``: "Setpoint", ...), at most once a second
        per kind: streams arrive at 20-50 Hz and one line a second names the problem."""
        if now - self._last_warning.get(kind, -math.inf) >= 1.0:
            self._last_warning[kind] = now
            log.warning("%s rejected: %s", kind, exc)
            self.statustext(mavlink.MAV_SEVERITY_WARNING, f"{kind} rejected: {exc}", link)

    def _on_param_request_list(self, msg, link: UdpLink) -> None:
        if self._for_me(msg):
            for name in self.params.names():
                link.send(self._param_value(name))

    def _on_param_request_read(self, msg, link: UdpLink) -> None:
        if not self._for_me(msg):
            return
        name = _param_id(msg.param_id)
        names = self.params.names()
        if msg.param_index >= 0:
            name = names[msg.param_index] if msg.param_index < len(names) else None
        if name in self.params:
            link.send(self._param_value(name))

    def _on_param_set(self, msg, link: UdpLink) -> None:
        if not self._for_me(msg):
            return
        name = _param_id(msg.param_id)
        try:
            self.params.set(name, msg.param_value)
        except ParameterError as exc:
            log.warning("PARAM_SET refused: %s", exc)
            self.statustext(mavlink.MAV_SEVERITY_ERROR, f"Param: {exc}", link)
            if name not in self.params:
                return
        link.send(self._param_value(name))  # the stored value, as PX4 answers both success and refusal

    def _param_value(self, name: str):
        return mavlink.MAVLink_param_value_message(name.encode(), self.params[name], mavlink.MAV_PARAM_TYPE_REAL32,
                                                   len(self.params), self.params.index(name))

    # ------------------------------------------------------------------ missions (the MAVLink mission protocol)
    def _mission_ack(self, link: UdpLink, msg, result: int, mission_type: int = mavlink.MAV_MISSION_TYPE_MISSION):
        link.send(mavlink.MAVLink_mission_ack_message(msg.get_srcSystem(), msg.get_srcComponent(), result,
                                                      mission_type))

    def _mission_type_ok(self, msg, link: UdpLink, reply: bool = True) -> bool:
        """Only plans of type MISSION are kept (no geofence or rally points): uploading others is refused
        clearly (their lists read as empty, and clearing them succeeds)."""
        mission_type = getattr(msg, "mission_type", mavlink.MAV_MISSION_TYPE_MISSION)
        if mission_type == mavlink.MAV_MISSION_TYPE_MISSION:
            return True
        if reply:
            self._mission_ack(link, msg, mavlink.MAV_MISSION_UNSUPPORTED, mission_type)
            self.statustext(mavlink.MAV_SEVERITY_WARNING, f"Mission type {mission_type} (geofence or rally points) "
                                                          "is not supported: only missions", link)
        return False

    def _mission_current(self):
        c = self.commander
        if not c.mission:
            state = mavlink.MISSION_STATE_NO_MISSION
        elif c.mission_finished:
            state = mavlink.MISSION_STATE_COMPLETE
        elif c.mode is FlightMode.AUTO_MISSION:
            state = mavlink.MISSION_STATE_ACTIVE
        else:
            state = mavlink.MISSION_STATE_NOT_STARTED if c.mission_seq == 0 else mavlink.MISSION_STATE_PAUSED
        return mavlink.MAVLink_mission_current_message(c.mission_seq, len(c.mission), state, 0)

    def _on_mission_count(self, msg, link: UdpLink) -> None:
        if not self._for_me(msg) or not self._mission_type_ok(msg, link):
            return
        if msg.count > MAX_ITEMS:
            self._mission_ack(link, msg, mavlink.MAV_MISSION_NO_SPACE)
            self.statustext(mavlink.MAV_SEVERITY_WARNING, f"Mission of {msg.count} items refused: at most "
                                                          f"{MAX_ITEMS}", link)
            return
        if msg.count == 0:
            self._upload = None
            self.commander.set_mission([], self.status_fn())
            self._mission_ack(link, msg, mavlink.MAV_MISSION_ACCEPTED)
            return
        self._upload = {"link": link, "count": msg.count, "items": []}  # a new COUNT restarts any upload
        self._request_item(link, msg, 0)

    def _request_item(self, link: UdpLink, msg, seq: int) -> None:
        link.send(mavlink.MAVLink_mission_request_int_message(msg.get_srcSystem(), msg.get_srcComponent(), seq,
                                                              mavlink.MAV_MISSION_TYPE_MISSION))

    def _on_mission_item_int(self, msg, link: UdpLink) -> None:
        if not self._for_me(msg) or not self._mission_type_ok(msg, link, reply=False):
            return
        upload = self._upload
        if upload is None or upload["link"] is not link:
            self._mission_ack(link, msg, mavlink.MAV_MISSION_DENIED)  # no upload under way: send MISSION_COUNT
            return
        expected = len(upload["items"])
        if msg.seq != expected:  # a repeat or a gap: ask again for the one we need
            self._request_item(link, msg, expected)
            return
        try:
            item = mission_item_from_message(msg, self.home.to_local)
        except MissionError as exc:
            self._upload = None
            log.warning("mission upload refused: %s", exc)
            self._mission_ack(link, msg, exc.result)
            self.statustext(mavlink.MAV_SEVERITY_WARNING, f"Mission refused: {exc}", link)
            return
        upload["items"].append(item)
        if len(upload["items"]) < upload["count"]:
            self._request_item(link, msg, expected + 1)
            return
        self._upload = None
        self.commander.set_mission(upload["items"], self.status_fn())
        self._mission_ack(link, msg, mavlink.MAV_MISSION_ACCEPTED)
        self.statustext(mavlink.MAV_SEVERITY_INFO, f"Mission accepted: {len(upload['items'])} items", link)

    _on_mission_item = _on_mission_item_int  # the older float form (lat/lon in degrees) is read the same way

    def _on_mission_request_list(self, msg, link: UdpLink) -> None:
        if not self._for_me(msg):
            return
        mission_type = getattr(msg, "mission_type", mavlink.MAV_MISSION_TYPE_MISSION)
        count = len(self.commander.mission) if mission_type == mavlink.MAV_MISSION_TYPE_MISSION else 0  # no fence
        link.send(mavlink.MAVLink_mission_count_message(msg.get_srcSystem(), msg.get_srcComponent(), count,
                                                        mission_type))

    def _on_mission_request_int(self, msg, link: UdpLink) -> None:
        if not self._for_me(msg) or not self._mission_type_ok(msg, link):
            return
        mission: tuple[MissionItem, ...] = self.commander.mission
        if not 0 <= msg.seq < len(mission):
            self._mission_ack(link, msg, mavlink.MAV_MISSION_INVALID_SEQUENCE)
            return
        # the float MISSION_REQUEST is answered in its own form, MISSION_ITEM, as the mission protocol says
        link.send(mission[msg.seq].to_message(msg.seq == self.commander.mission_seq, msg.get_srcSystem(),
                                              msg.get_srcComponent(), int_form=msg.get_type() != "MISSION_REQUEST"))

    _on_mission_request = _on_mission_request_int

    def _on_mission_clear_all(self, msg, link: UdpLink) -> None:
        if not self._for_me(msg):
            return
        mission_type = getattr(msg, "mission_type", mavlink.MAV_MISSION_TYPE_MISSION)
        if mission_type in (mavlink.MAV_MISSION_TYPE_MISSION, mavlink.MAV_MISSION_TYPE_ALL):
            self._upload = None
            self.commander.set_mission([], self.status_fn())
        self._mission_ack(link, msg, mavlink.MAV_MISSION_ACCEPTED, mission_type)  # no geofence or rally to clear

    def _on_mission_set_current(self, msg, link: UdpLink) -> None:
        if self._for_me(msg):
            if self.commander.set_mission_current(msg.seq, self.status_fn()).accepted:  # else it says why
                link.send(self._mission_current())

    def _on_ping(self, msg, link: UdpLink) -> None:
        if msg.target_system == 0:
            link.send(mavlink.MAVLink_ping_message(msg.time_usec, msg.seq, msg.get_srcSystem(),
                                                   msg.get_srcComponent()))

    def _on_timesync(self, msg, link: UdpLink) -> None:
        if msg.tc1 == 0:
            now_ns = int(self.status_fn().time_s * 1e9)
            link.send(mavlink.MAVLink_timesync_message(now_ns, msg.ts1))


SENSORS_PRESENT = (mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
                   | mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG | mavlink.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
                   | mavlink.MAV_SYS_STATUS_SENSOR_GPS | mavlink.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
                   | mavlink.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION | mavlink.MAV_SYS_STATUS_SENSOR_YAW_POSITION
                   | mavlink.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
                   | mavlink.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL | mavlink.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
                   | mavlink.MAV_SYS_STATUS_AHRS | mavlink.MAV_SYS_STATUS_SENSOR_BATTERY)


def statustext_messages(severity: int, text: str, text_id: int) -> list:
    """STATUSTEXT for ``text``: one message when it fits in 50 bytes, else chunks sharing ``text_id``."""
    data = text.encode()
    if len(data) <= 50:
        return [mavlink.MAVLink_statustext_message(severity, data, 0, 0)]
    chunks = [data[i:i + 50] for i in range(0, len(data), 50)]
    if len(chunks[-1]) == 50:
        chunks.append(b"")  # an exactly full last chunk needs an empty terminator (MAVLink spec)
    return [mavlink.MAVLink_statustext_message(severity, chunk, text_id, seq) for seq, chunk in enumerate(chunks)]


def _msg_name(msg_id: int) -> str | None:
    cls = mavlink.mavlink_map.get(msg_id)
    return cls.msgname if cls is not None else None


def _param_id(raw) -> str:
    if isinstance(raw, bytes):
        raw = raw.decode(errors="replace")
    return raw.split("\x00", 1)[0]


def _nan_to(value: float, default: float) -> float:
    return value if math.isfinite(value) else default


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


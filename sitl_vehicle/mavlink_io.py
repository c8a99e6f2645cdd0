"""MAVLink, the way PX4 SITL speaks it: ``MavlinkVehicleInterface``, the protocol for one vehicle.

Streams, commands, parameters and offboard and manual-control input, translated into calls on the commander,
over any number of links. Its parts that stand apart live in modules of their own: the UDP endpoint
(``sitl_vehicle.udp_link``), the telemetry snapshot, stream schedule and stream messages
(``sitl_vehicle.telemetry``), setpoint parsing (``sitl_vehicle.setpoint_messages``) and the mission protocol
(``sitl_vehicle.mission_protocol``, a mixin of the interface). Their names are importable from here too, as
before the split.
"""

from __future__ import annotations

import logging
import math
import struct
import time
from collections.abc import Callable

from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.commander import Commander, Reply, VehicleStatus
from sitl_vehicle.link_signing import LinkSigning
from sitl_vehicle.manual import ManualControlError, sticks_from_manual_control
from sitl_vehicle.mission import MAX_DISTANCE_M, SPEED_TYPES_HORIZONTAL, speed_change, valid_speed
from sitl_vehicle.mission_protocol import MissionProtocol
from sitl_vehicle.modes import UnsupportedMode, mode_from_custom
from sitl_vehicle.orbit import YAW_BEHAVIOURS
from sitl_vehicle.params import ParameterError, ParameterStore
from sitl_vehicle.requested_streams import STREAMS_WITHOUT_DATA
from sitl_vehicle.setpoint_messages import (
    SUPPORTED_FRAMES,
    TYPE_MASK_ACCEL,
    TYPE_MASK_FORCE,
    TYPE_MASK_POSITION,
    TYPE_MASK_VELOCITY,
    TYPE_MASK_YAW,
    TYPE_MASK_YAW_RATE,
    SetpointError,
    setpoint_from_message,
)
from sitl_vehicle.telemetry import (
    DEFAULT_STREAMS_HZ,
    EARTH_RADIUS_M,
    SENSORS_PRESENT,
    Home,
    StreamSchedule,
    Telemetry,
    stream_message,
    truth_odometry,
)
from sitl_vehicle.udp_link import COMPONENT_ID, SYSTEM_ID, PortInUseError, UdpLink, parse_hostport

__all__ = [
    "COMPONENT_ID", "DEFAULT_STREAMS_HZ", "EARTH_RADIUS_M", "FORCE_ARM_MAGIC", "SENSORS_PRESENT", "SUPPORTED_FRAMES",
    "SYSTEM_ID", "TYPE_MASK_ACCEL", "TYPE_MASK_FORCE", "TYPE_MASK_POSITION", "TYPE_MASK_VELOCITY", "TYPE_MASK_YAW",
    "TYPE_MASK_YAW_RATE", "Home", "MavlinkVehicleInterface", "PortInUseError", "SetpointError", "StreamSchedule",
    "Telemetry", "UdpLink", "parse_hostport", "setpoint_from_message", "statustext_messages", "stream_message",
    "truth_odometry",
]

log = logging.getLogger(__name__)

FORCE_ARM_MAGIC = 21196  # PX4: param2 of MAV_CMD_COMPONENT_ARM_DISARM that forces (dis)arming


class MavlinkVehicleInterface(MissionProtocol):
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
        return stream_message(name, t, self.home, self.commander, self._boot_wall)

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
        self._ack(link, msg, msg.command, self.execute(msg.command, params, link, msg.frame))

    def execute(self, command: int, p: tuple, link: UdpLink, frame: int = mavlink.MAV_FRAME_GLOBAL) -> Reply:
        """Run one MAV_CMD; NaN parameters mean 'use the default', as PX4 treats them. ``frame``: COMMAND_INT's,
        for a place's altitude (COMMAND_LONG's are above mean sea level)."""
        status = self.status_fn()
        c = self.commander
        if command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            force = math.isfinite(p[1]) and int(p[1]) == FORCE_ARM_MAGIC
            return c.arm(status, force) if p[0] == 1.0 else c.disarm(status, force)
        if command == mavlink.MAV_CMD_NAV_TAKEOFF:
            # PX4: param7 is AMSL (NaN: the minimum, MIS_TAKEOFF_ALT above home; the commander raises lower ones);
            # param4, the yaw, is ignored on multicopters; params 5/6 are lat/lon, and NaN or both exactly 0
            # (zero-initialised, as MAVProxy's `takeoff` sends them; PX4 PR #28792) mean "where it is"
            home_amsl = self._home_amsl()
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
        if command == mavlink.MAV_CMD_DO_REPOSITION:
            return self._reposition_command(p, frame, status)
        if command == mavlink.MAV_CMD_DO_ORBIT:
            return self._orbit_command(p, frame, status)
        if command == mavlink.MAV_CMD_DO_FLIGHTTERMINATION:
            if not p[0] > 0.5:   # (NaN too)
                return Reply(mavlink.MAV_RESULT_DENIED, "Flight termination not activated: send param1 1 to stop the "
                                                        "motors")
            return c.terminate()
        if command == mavlink.MAV_CMD_DO_CHANGE_SPEED:
            return self._change_speed_command(p)
        if command == mavlink.MAV_CMD_DO_SET_HOME:
            return self._set_home_command(p, status)
        if command == mavlink.MAV_CMD_DO_LAND_START:
            return c.start_mission_landing(status)
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

    def _change_speed_command(self, p: tuple) -> Reply:
        """DO_CHANGE_SPEED: param1 the speed's type (0 air, 1 ground: a multicopter's the same), param2 the speed
        (m/s; -1 no change, -2 the default), as in a mission item."""
        kind, speed = p[0], p[1]
        if kind not in SPEED_TYPES_HORIZONTAL:
            return Reply(mavlink.MAV_RESULT_DENIED, f"Speed change denied: speed type {kind} (a climb or descent "
                                                    "speed) is not modelled; send 1, a ground speed")
        if not valid_speed(speed):
            return Reply(mavlink.MAV_RESULT_DENIED, f"Speed change denied: speed {speed}; send m/s above 0, -1 (no "
                                                    "change) or -2 (the default)")
        new = speed_change(kind, speed)
        return Reply(mavlink.MAV_RESULT_ACCEPTED) if new is None else self.commander.change_speed(new)

    def _set_home_command(self, p: tuple, status: VehicleStatus) -> Reply:
        """DO_SET_HOME: param1 1 for where the vehicle is, else param5-7 the place (AMSL, as PX4 reads it)."""
        if p[0] > 0.5:
            return self.commander.set_home(status.position, manually=False)
        lat, lon, alt = p[4], p[5], p[6]
        if not (_is_lat_lon(lat, lon) and math.isfinite(alt)):
            return Reply(mavlink.MAV_RESULT_DENIED, "Set home denied: send param1 1 (here) or a latitude, longitude "
                                                    "and altitude")
        north, east, down = self.home.to_local(lat, lon, alt)
        return _far_from_home("Set home", lat, lon, north, east) or self.commander.set_home((north, east, down))

    def _reposition_command(self, p: tuple, frame: int, status: VehicleStatus) -> Reply:
        """DO_REPOSITION: param1 the ground speed (-1: default), param4 the yaw (rad), param5-7 the place (NaN, or
        a latitude or longitude out of range such as COMMAND_INT's INT32_MAX: keep the vehicle's own)."""
        target, refusal = self._command_place("Reposition", p, frame)
        return refusal or self.commander.reposition(status, target, p[3], p[0])

    def _orbit_command(self, p: tuple, frame: int, status: VehicleStatus) -> Reply:
        """DO_ORBIT: param1 the radius (m, its sign the direction: + clockwise), param2 the speed (m/s; negative
        turns the direction round, as on PX4), param3 the yaw behaviour (ORBIT_YAW_BEHAVIOUR), param5-7 the centre
        and its altitude above sea level (NaN: keep; an altitude below home is refused)."""
        behaviour = p[2]
        if math.isfinite(behaviour) and behaviour not in YAW_BEHAVIOURS:
            return Reply(mavlink.MAV_RESULT_DENIED, f"Orbit denied: yaw behaviour {behaviour:g} is not one of "
                                                    "ORBIT_YAW_BEHAVIOUR's 0-4")
        # PX4 reads DO_ORBIT's altitude above sea level whatever COMMAND_INT's frame says (MAVSDK's do_orbit sends
        # one in MAV_FRAME_GLOBAL_RELATIVE_ALT), so a height above home sent instead would fly into the ground
        target, refusal = self._command_place("Orbit", p, mavlink.MAV_FRAME_GLOBAL_INT)
        home_amsl = self._home_amsl()
        if refusal is None and p[6] < home_amsl:
            refusal = Reply(mavlink.MAV_RESULT_DENIED, f"Orbit denied: altitude {p[6]:g} m is below home "
                                                       f"({home_amsl:.1f} m above sea level); DO_ORBIT's altitude is "
                                                       "above sea level")
        return refusal or self.commander.orbit(status, p[0], p[1], behaviour, target[:2], target[2])

    def _command_place(self, what: str, p: tuple, frame: int) -> tuple[tuple[float, float, float], Reply | None]:
        """A command's place (param5-7) in the local frame, NaN where it leaves a part out, or the refusal of a
        frame it cannot be read in or of a place too far from home."""
        nowhere = (math.nan, math.nan, math.nan)
        if frame not in (mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_INT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
                         mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT):
            return nowhere, Reply(mavlink.MAV_RESULT_DENIED, f"{what} denied: frame {frame} is not supported; send "
                                                             "MAV_FRAME_GLOBAL_INT (5) or "
                                                             "MAV_FRAME_GLOBAL_RELATIVE_ALT_INT (6)")
        lat, lon, alt = p[4], p[5], p[6]
        placed = _is_lat_lon(lat, lon)
        relative = frame in (mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)
        home_amsl = self._home_amsl()
        amsl = alt + home_amsl if relative else alt
        north, east, down = self.home.to_local(lat if placed else self.home.lat_deg,
                                               lon if placed else self.home.lon_deg, amsl)
        far = _far_from_home(what, lat, lon, north, east) if placed else None
        if far:
            return nowhere, far
        return (north if placed else math.nan, east if placed else math.nan,
                down if math.isfinite(alt) else math.nan), None

    def _home_amsl(self) -> float:
        """Home's altitude above sea level (m): where the commander's home is, on the globe."""
        return self.home.to_global(self.commander.home)[2]

    def _set_interval(self, link: UdpLink, msg_id: int, interval_us: float) -> Reply:
        name = _msg_name(msg_id)
        if name is None or (name not in DEFAULT_STREAMS_HZ and name not in STREAMS_WITHOUT_DATA
                            and self.build(name, self.telemetry_fn()) is None):
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
        sent_integer = msg.param_type in INTEGER_PARAM_BYTES
        try:
            integer = name in self.params and self.params.spec(name).integer
            if name in self.params and integer != sent_integer:
                # PX4 would read the bytes as its own type and keep a wrong value: refuse instead
                raise ParameterError(f"{name} is an integer: send MAV_PARAM_TYPE_INT32, the value's bytes in the "
                                     "float field (PX4's bytewise encoding)" if integer
                                     else f"{name} is a float: send MAV_PARAM_TYPE_REAL32")
            self.params.set(name, param_float_as_int(msg.param_value, msg.param_type) if sent_integer
                            else msg.param_value)
        except ParameterError as exc:
            log.warning("PARAM_SET refused: %s", exc)
            self.statustext(mavlink.MAV_SEVERITY_ERROR, f"Param: {exc}", link)
            if name not in self.params:
                return
        link.send(self._param_value(name))  # the stored value, as PX4 answers both success and refusal

    def _param_value(self, name: str):
        value, kind = self.params[name], mavlink.MAV_PARAM_TYPE_REAL32
        if self.params.spec(name).integer:
            value, kind = int_as_param_float(int(value)), mavlink.MAV_PARAM_TYPE_INT32
        return mavlink.MAVLink_param_value_message(name.encode(), value, kind, len(self.params),
                                                   self.params.index(name))

    def _on_ping(self, msg, link: UdpLink) -> None:
        if msg.target_system == 0:
            link.send(mavlink.MAVLink_ping_message(msg.time_usec, msg.seq, msg.get_srcSystem(),
                                                   msg.get_srcComponent()))

    def _on_timesync(self, msg, link: UdpLink) -> None:
        if msg.tc1 == 0:
            now_ns = int(self.status_fn().time_s * 1e9)
            link.send(mavlink.MAVLink_timesync_message(now_ns, msg.ts1))


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


def _is_lat_lon(lat: float, lon: float) -> bool:
    """A command's latitude and longitude name a place (not NaN, nor out of range as COMMAND_INT's INT32_MAX is)."""
    return math.isfinite(lat) and math.isfinite(lon) and abs(lat) <= 90 and abs(lon) <= 180


def _far_from_home(what: str, lat: float, lon: float, north: float, east: float) -> Reply | None:
    """A command's refusal for a place farther from home than a mission's may be (coordinates sent wrong)."""
    distance = math.hypot(north, east)
    if distance <= MAX_DISTANCE_M:
        return None
    return Reply(mavlink.MAV_RESULT_DENIED, f"{what} denied: {lat:.7f}, {lon:.7f} is {distance / 1000:.0f} km from "
                                            "home; send a place near home")


# MAV_PARAM_TYPE of an integer -> (its size in bytes, signed), for PX4's bytewise encoding in the float field
INTEGER_PARAM_BYTES = {mavlink.MAV_PARAM_TYPE_UINT8: (1, False), mavlink.MAV_PARAM_TYPE_INT8: (1, True),
                       mavlink.MAV_PARAM_TYPE_UINT16: (2, False), mavlink.MAV_PARAM_TYPE_INT16: (2, True),
                       mavlink.MAV_PARAM_TYPE_UINT32: (4, False), mavlink.MAV_PARAM_TYPE_INT32: (4, True)}


def int_as_param_float(value: int) -> float:
    """An INT32 parameter as PX4 sends it in PARAM_VALUE's float field: its four bytes, unchanged."""
    return struct.unpack("<f", struct.pack("<i", value))[0]


def param_float_as_int(field: float, param_type: int) -> int:
    """The integer of type ``param_type`` whose bytes a PARAM_SET's float field carries (the inverse of
    :func:`int_as_param_float`; smaller types in the low bytes)."""
    size, signed = INTEGER_PARAM_BYTES[param_type]
    return int.from_bytes(struct.pack("<f", field)[:size], "little", signed=signed)


def _param_id(raw) -> str:
    if isinstance(raw, bytes):
        raw = raw.decode(errors="replace")
    return raw.split("\x00", 1)[0]


def _nan_to(value: float, default: float) -> float:
    return value if math.isfinite(value) else default


"""The pymavlink backend: one receiver, one 20 Hz setpoint thread, acked commands, a .tlog.

Only the receiver reads the connection (a thread on the wall clock; in lockstep the clock calls it after
each release), so no lock is ever held across a blocking receive and the setpoint stream never waits on
perception or telemetry.  Every wait and rate runs on the link's clock (:mod:`companion.clock`).  Modes are
set by name through pymavlink's tables (PX4: ``px4_map``; ArduPilot: ``mode_mapping_byname``), so PX4 and
ArduPilot both fly.
"""

from __future__ import annotations

import logging
import math
import struct
import threading
from pathlib import Path

from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from companion.link.base import AutopilotLink, LinkError, StatusTextAssembler, parse_endpoint
from companion.link.tlog import TlogWriter

log = logging.getLogger(__name__)

POSITION_YAW_MASK = 0b1001_1111_1000  # SET_POSITION_TARGET_LOCAL_NED: use x, y, z and yaw only
FORCE_ARM = 21196
RESULT_NAMES = {v: k for k, v in vars(mavlink).items() if k.startswith("MAV_RESULT_") and isinstance(v, int)}
# The offboard-style mode and the hold mode, per autopilot family.
OFFBOARD_MODE = {"px4": "OFFBOARD", "ardupilot": "GUIDED"}
HOLD_MODE = {"px4": "LOITER", "ardupilot": "BRAKE"}


class PymavlinkLink(AutopilotLink):
    name = "pymavlink"

    def __init__(self, url: str, tlog_path: Path | None = None, setpoint_hz: float = 20.0,
                 source_system: int = 1, source_component: int = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER,
                 clock=None, signing_key=None):
        super().__init__(clock)
        self.signing_key = signing_key      # a companion.link.signing.CompanionKey, or None: unsigned
        self.endpoint = parse_endpoint(url)
        self.setpoint_hz = setpoint_hz
        self._source = (source_system, source_component)
        self._tlog = TlogWriter(tlog_path) if tlog_path else None
        self._conn = None
        self._send_lock = threading.Lock()
        self._acks: dict[int, tuple[int, float]] = {}
        self._params: dict[str, tuple[float, float]] = {}   # PARAM_VALUE echoes: name -> (value, when)
        self._stream = None          # the setpoint thread (a companion.clock.ClockThread)
        self._detach = None          # detaches the receiver from the clock
        self.messages_sent = 0
        self._target: tuple[float, float, float, float] | None = None  # x, y, z, yaw
        self._streamed = 0  # setpoints sent since the current target was set
        self._target_system = 1
        self._target_component = 1
        self._autopilot_mav = None
        self._vehicle_type = None
        self._texts = StatusTextAssembler()
        self.setpoint_times: list[float] = []  # monotonic send times, for rate checks

    # ---------------------------------------------------------------------------- lifecycle
    def connect(self, timeout_s: float = 30.0) -> None:
        ep = self.endpoint
        kwargs = {"baud": ep.port} if ep.scheme == "serial" else {}
        try:
            self._conn = mavutil.mavlink_connection(ep.mavutil, source_system=self._source[0],
                                                    source_component=self._source[1], dialect="common",
                                                    autoreconnect=True, **kwargs)
        except OSError as exc:
            raise LinkError(f"cannot open {ep.mavutil}: {exc}") from None
        self._conn.mav.set_send_callback(self._sent)
        if self.signing_key is not None:
            from companion.link.signing import accept_unsigned

            self._conn.setup_signing(self.signing_key.secret, sign_outgoing=True,
                                     allow_unsigned_callback=accept_unsigned,
                                     initial_timestamp=self.signing_key.initial_timestamp())
            log.info("MAVLink signing on: every message sent is signed, unsigned replies are dropped")
        self._detach = self.clock.attach_link(self._receive_some, lambda: self.messages_sent, "link-rx")
        if ep.scheme == "udpout" or ep.scheme == "tcp":
            self._send(mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_ONBOARD_CONTROLLER,
                                                         mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3))
        if not self.clock.wait_for(self.alive, timeout_s, 0.05):
            raise LinkError(f"no autopilot heartbeat on {ep.mavutil} within {timeout_s:.0f} s: is the "
                            f"vehicle running and sending to this address?")
        log.info("connected to %s autopilot (system %d) on %s", self.telemetry.autopilot, self._target_system,
                 ep.mavutil)
        self._stream = self.clock.spawn(self._stream_loop, "link-setpoints")
        # Acknowledged requests, retried on a lossy link; neither is needed to fly (home falls back to
        # MIS_TAKEOFF_ALT, attitude to its default rate), so a refusal or silence is only logged.
        for what, params in (("home position", (mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAVLINK_MSG_ID_HOME_POSITION)),
                             # attitude at 50 Hz: the companion derotates flow with the attitude at each capture
                             ("attitude at 50 Hz", (mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
                                                    mavlink.MAVLINK_MSG_ID_ATTITUDE, 20000))):
            try:
                self.command(*params)
            except LinkError as exc:
                log.warning("request for the %s not answered (%s); flying without it", what, exc)

    def close(self) -> None:
        if self._stream is not None:
            self._stream.stop()
            self._stream.join(timeout=2)
        if self._detach is not None:
            self._detach()
        if self._conn is not None:
            self._conn.close()
        if self._tlog:
            self._tlog.close()

    def _sent(self, msg) -> None:
        self.messages_sent += 1
        if self._tlog:
            self._tlog.write(msg.get_msgbuf())

    # ------------------------------------------------------------------------------ receive
    def _receive_some(self, timeout_s: float) -> int:
        """Read what has arrived (waiting at most ``timeout_s`` for the first message); how many were read."""
        count = 0
        while True:
            try:
                msg = self._conn.recv_match(blocking=count == 0 and timeout_s > 0, timeout=timeout_s)
            except (OSError, ValueError) as exc:  # socket closed under us, or a mangled packet
                log.debug("receive error: %s", exc)
                return count
            if msg is None:
                return count
            count += 1
            if msg.get_type() == "BAD_DATA":
                continue
            if self._tlog:
                self._tlog.write(msg.get_msgbuf())
            try:
                self._update_cache(msg)
            except Exception:  # noqa: BLE001 — a strange message must not kill the link
                log.exception("could not interpret %s", msg.get_type())

    def _update_cache(self, msg) -> None:
        kind = msg.get_type()
        t = self.telemetry
        if (self._autopilot_mav is not None and msg.get_srcSystem() == self._target_system
                and msg.get_srcComponent() == self._target_component):
            # anything the autopilot sends shows the link is alive: on a lossy radio a few lost heartbeats
            # in a row are common while its 30 Hz position stream still gets through
            with t.lock:
                t.last_heartbeat = self.clock.now()
        if kind == "HEARTBEAT":
            if msg.type in (mavlink.MAV_TYPE_GCS, mavlink.MAV_TYPE_ONBOARD_CONTROLLER) \
                    or msg.autopilot == mavlink.MAV_AUTOPILOT_INVALID:
                return
            self._target_system, self._target_component = msg.get_srcSystem(), msg.get_srcComponent()
            self._autopilot_mav, self._vehicle_type = msg.autopilot, msg.type
            with t.lock:
                t.last_heartbeat = self.clock.now()
                t.armed = bool(msg.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
                t.mode = mavutil.mode_string_v10(msg)
                t.autopilot = "px4" if msg.autopilot == mavlink.MAV_AUTOPILOT_PX4 else (
                    "ardupilot" if msg.autopilot == mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA else "other")
        elif kind == "LOCAL_POSITION_NED":
            with t.lock:
                t.position = (msg.x, msg.y, msg.z)
                t.position_history.append((msg.time_boot_ms * 1e-3, msg.x, msg.y, msg.z))
                t.velocity = (msg.vx, msg.vy, msg.vz)
                t.position_time = self.clock.now()
            t.notify(msg.time_boot_ms * 1e-3, position=(msg.x, msg.y, msg.z))
        elif kind == "ATTITUDE":
            with t.lock:
                t.attitude_euler = (msg.roll, msg.pitch, msg.yaw)
                t.attitude_history.append((msg.time_boot_ms * 1e-3, msg.roll, msg.pitch, msg.yaw))
            t.notify(msg.time_boot_ms * 1e-3, attitude=(msg.roll, msg.pitch, msg.yaw))
        elif kind == "EXTENDED_SYS_STATE":
            with t.lock:
                if msg.landed_state != mavlink.MAV_LANDED_STATE_UNDEFINED:
                    t.landed = msg.landed_state == mavlink.MAV_LANDED_STATE_ON_GROUND
        elif kind == "HOME_POSITION":
            with t.lock:
                t.home = (msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3)
        elif kind == "STATUSTEXT":
            text = self._texts.add(getattr(msg, "id", 0), getattr(msg, "chunk_seq", 0), msg.text)
            if text is not None:
                log.info("autopilot: %s", text)
                with t.lock:
                    t.statustexts.append((msg.severity, text))
        elif kind == "COMMAND_ACK":
            self._acks[msg.command] = (msg.result, self.clock.now())
        elif kind == "PARAM_VALUE":
            name = msg.param_id if isinstance(msg.param_id, str) else msg.param_id.decode(errors="replace")
            self._params[name.rstrip("\x00")] = (msg.param_value, self.clock.now())

    # -------------------------------------------------------------------------------- send
    def _send(self, msg) -> None:
        with self._send_lock:
            self._conn.mav.send(msg)

    def _stream_loop(self, thread) -> None:
        period = 1.0 / self.setpoint_hz
        next_time = self.clock.now()
        next_heartbeat = next_time
        while not thread.stopped.is_set():
            now = self.clock.now()
            if now >= next_heartbeat:
                next_heartbeat = now + 1.0
                self._send(mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_ONBOARD_CONTROLLER,
                                                             mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0, 4))
            target = self._target
            if target is not None:
                x, y, z, yaw = target
                self._send(mavlink.MAVLink_set_position_target_local_ned_message(
                    int(now * 1000) & 0xFFFFFFFF, self._target_system, self._target_component,
                    mavlink.MAV_FRAME_LOCAL_NED, POSITION_YAW_MASK, x, y, z, 0, 0, 0, 0, 0, 0, yaw, 0))
                self._streamed += 1
                self.setpoint_times.append(now)
                del self.setpoint_times[:-2000]
            next_time += period
            self.clock.sleep_until(next_time)

    def command(self, command: int, *params: float, timeout_s: float = 1.0, retries: int = 10) -> None:
        """COMMAND_LONG with retransmission; raises LinkError naming the result and the autopilot's reason.

        Ten tries a second apart: a try needs the command and its ACK both through, 49 % of tries on a link that
        loses 30 % each way, so three tries would fail one command in eight there; ten fail one in a thousand."""
        p = [float(v) for v in params] + [0.0] * (7 - len(params))
        for attempt in range(retries):
            sent = self.clock.now()
            with self.telemetry.lock:
                texts_before = len(self.telemetry.statustexts)
            self._send(mavlink.MAVLink_command_long_message(self._target_system, self._target_component,
                                                            command, attempt, *p))
            got = self.clock.wait_for(lambda sent=sent: self._acks.get(command, (None, -math.inf))[1] >= sent,
                                      timeout_s, 0.005)
            result = self._acks.get(command, (None, 0))[0] if got else None
            if result is None:
                self.check_alive()
                continue
            if result in (mavlink.MAV_RESULT_ACCEPTED, mavlink.MAV_RESULT_IN_PROGRESS):
                return
            self.clock.sleep(0.05)  # the reason arrives as a STATUSTEXT right after the ACK
            with self.telemetry.lock:
                reasons = [text for _, text in self.telemetry.statustexts[texts_before:]]
            reason = f": {reasons[-1]}" if reasons else ""
            raise LinkError(f"command {command} refused with {RESULT_NAMES.get(result, result)}{reason}")
        raise LinkError(f"command {command}: no COMMAND_ACK after {retries} tries")

    def set_mode(self, name: str) -> None:
        if self._autopilot_mav == mavlink.MAV_AUTOPILOT_PX4:
            base, main, sub = mavutil.px4_map[name]
            self.command(mavlink.MAV_CMD_DO_SET_MODE, base, main, sub)
        else:
            mapping = mavutil.mode_mapping_byname(self._vehicle_type) or {}
            if name not in mapping:
                raise LinkError(f"mode {name!r} unknown for this autopilot; known: {sorted(mapping)}")
            self.command(mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mapping[name])

    # ---------------------------------------------------------------------------- commands
    def arm(self) -> None:
        self.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)

    def set_takeoff_altitude(self, altitude_m: float) -> None:
        # PX4 never takes off lower than MIS_TAKEOFF_ALT ("Using minimum takeoff altitude"), and flies it when
        # the altitude is NaN: set it before arming, as MAVSDK's set_takeoff_altitude does, so that a slow link's
        # retries do not eat into the time PX4 waits before disarming an armed vehicle on the ground
        if self.telemetry.autopilot != "ardupilot":
            self.set_parameter("MIS_TAKEOFF_ALT", altitude_m)

    def takeoff(self, altitude_m: float) -> None:
        family = self.telemetry.autopilot
        if family == "ardupilot":
            self.set_mode("GUIDED")
            self.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, 0, 0, altitude_m)
            return
        home = self.telemetry.home
        amsl = home[2] + altitude_m if home else math.nan
        self.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, amsl)

    def set_parameter(self, name: str, value: float, timeout_s: float = 1.0, retries: int = 10) -> None:
        """PARAM_SET, resent until the autopilot's PARAM_VALUE echoes ``value`` (float32); LinkError names the
        value it kept (a refusal) or the silence."""
        want = struct.unpack("<f", struct.pack("<f", value))[0]
        for _ in range(retries):
            sent = self.clock.now()
            self._send(mavlink.MAVLink_param_set_message(self._target_system, self._target_component,
                                                         name.encode(), value, mavlink.MAV_PARAM_TYPE_REAL32))
            if self.clock.wait_for(lambda sent=sent: self._params.get(name, (None, -math.inf))[1] >= sent,
                                   timeout_s, 0.005):
                kept = self._params[name][0]
                if kept == want:
                    return
                raise LinkError(f"parameter {name}: the autopilot kept {kept:g}, not {value:g}")
            self.check_alive()
        raise LinkError(f"parameter {name}: no PARAM_VALUE after {retries} tries")

    def start_offboard(self, position, yaw: float) -> None:
        self.set_position_target(position, yaw)
        # PX4 only accepts Offboard while setpoints stream: send them for at least a second first.
        def streamed() -> bool:
            self.check_alive()
            return self._streamed >= self.setpoint_hz

        self.clock.wait_for(streamed, 5.0)
        self.set_mode(OFFBOARD_MODE.get(self.telemetry.autopilot, "OFFBOARD"))

    def set_position_target(self, position, yaw: float) -> None:
        if not all(math.isfinite(v) for v in (*position, yaw)):
            raise ValueError(f"setpoint {position}, yaw {yaw} is not finite")
        new = (float(position[0]), float(position[1]), float(position[2]), float(yaw))
        if new != self._target:
            self._target = new
            self._streamed = 0

    def hold(self) -> None:
        self._target = None
        self.set_mode(HOLD_MODE.get(self.telemetry.autopilot, "LOITER"))

    def land(self) -> None:
        self._target = None
        if self.telemetry.autopilot == "ardupilot":
            self.set_mode("LAND")
        else:
            self.command(mavlink.MAV_CMD_NAV_LAND, 0, 0, 0, math.nan, math.nan, math.nan, math.nan)

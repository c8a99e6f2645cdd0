"""Loopback test support: a pymavlink offboard client and small waiting helpers."""

from __future__ import annotations

import math
import threading
import time

from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from companion.link.base import StatusTextAssembler
from tools.square import recv_unlocked


class MavClient:
    """A minimal offboard client over pymavlink, as a companion computer would write one."""

    def __init__(self):
        self.conn = mavutil.mavlink_connection("udpin:127.0.0.1:0", source_system=255, source_component=190,
                                               dialect="common")
        self.port = self.conn.port.getsockname()[1]
        self._stream_stop = threading.Event()
        self._stream_thread: threading.Thread | None = None
        self.setpoint: tuple | None = None
        self.sticks: tuple | None = None
        self.sent_setpoints = 0
        self.streamed = 0          # messages the stream thread has sent (setpoints or sticks)
        self.lock = threading.Lock()

    def wait_heartbeat(self, timeout: float = 10.0):
        hb = self.conn.wait_heartbeat(timeout=timeout)
        assert hb is not None, "no HEARTBEAT from the vehicle"
        self.conn.target_system, self.conn.target_component = 1, 1
        return hb

    def recv(self, kind: str | list[str], timeout: float = 5.0, condition=None):
        kinds = {kind} if isinstance(kind, str) else set(kind)
        return recv_unlocked(self.conn, self.lock,
                             lambda m: m.get_type() in kinds and (condition is None or condition(m)), timeout)

    def wait_reading(self, predicate, timeout: float) -> bool:
        """Wait for ``predicate()`` while reading (and dropping) what the vehicle sends: a client that stops reading
        fills its socket's buffer with telemetry, and the kernel then drops what comes next (an ACK)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if predicate():
                return True
            recv_unlocked(self.conn, self.lock, lambda m: True, 0.02)
        return predicate()

    def statustext(self, fragment: str, timeout: float = 5.0) -> str | None:
        """The first STATUSTEXT containing ``fragment``, reassembled from MAVLink 2 chunks (id, chunk_seq)."""
        deadline = time.monotonic() + timeout
        texts = StatusTextAssembler()
        while time.monotonic() < deadline:
            msg = self.recv("STATUSTEXT", max(0.0, deadline - time.monotonic()))
            if msg is None:
                return None
            text = texts.add(msg.id, msg.chunk_seq, msg.text)
            if text is not None and fragment in text:
                return text
        return None

    def command(self, command: int, *params: float, timeout: float = 5.0):
        p = list(params) + [0.0] * (7 - len(params))
        with self.lock:
            self.conn.mav.command_long_send(1, 1, command, 0, *p)
        return self.recv("COMMAND_ACK", timeout, lambda m: m.command == command)

    def set_mode(self, name: str):
        base, main, sub = mavutil.px4_map[name]
        return self.command(mavlink.MAV_CMD_DO_SET_MODE, base, main, sub)

    def send_position(self, x: float, y: float, z: float, yaw: float = 0.0, frame=mavlink.MAV_FRAME_LOCAL_NED):
        mask = 0b1001_1111_1000  # position + yaw
        with self.lock:
            self.conn.mav.set_position_target_local_ned_send(0, 1, 1, frame, mask, x, y, z, 0, 0, 0, 0, 0, 0, yaw, 0)
        self.sent_setpoints += 1

    def stream(self, setpoint: tuple | None, hz: float = 20.0):
        """Keep re-sending ``setpoint`` (x, y, z) at ``hz`` from a thread, as MAVSDK's offboard does."""
        self.setpoint = setpoint
        self._start_stream(hz)

    def stream_sticks(self, x: int = 0, y: int = 0, z: int = 500, r: int = 0, hz: float = 20.0):
        """Keep sending MANUAL_CONTROL (x pitch, y roll, r yaw -1000..1000, z throttle 0..1000 with 500 the
        centre) at ``hz``, as QGroundControl's virtual joystick does."""
        self.sticks = (x, y, z, r)
        self._start_stream(hz)

    def _start_stream(self, hz: float):
        if self._stream_thread is None:
            def loop():
                while not self._stream_stop.wait(1.0 / hz):
                    if self.setpoint is not None:
                        self.send_position(*self.setpoint)
                        self.streamed += 1
                    if self.sticks is not None:
                        with self.lock:
                            self.conn.mav.manual_control_send(1, *self.sticks, 0)
                        self.streamed += 1
            self._stream_thread = threading.Thread(target=loop, daemon=True)
            self._stream_thread.start()

    def stop_stream(self):
        self._stream_stop.set()
        if self._stream_thread:
            self._stream_thread.join()
        self._stream_thread = None
        self._stream_stop.clear()

    def close(self):
        self.stop_stream()
        self.conn.close()


def upload_plan(client, msgs, mission_type: int) -> int:
    """Upload ``msgs`` as a plan of ``mission_type`` (fence, rally points), answering the vehicle's item requests
    as MAVSDK and QGroundControl do; every request and the final MISSION_ACK must name that type.  The ACK's type."""
    with client.lock:
        client.conn.mav.mission_count_send(1, 1, len(msgs), mission_type)
    while True:
        msg = client.recv(["MISSION_REQUEST_INT", "MISSION_ACK"], 3)
        assert msg is not None, "the vehicle stopped answering the upload"
        assert msg.mission_type == mission_type
        if msg.get_type() == "MISSION_ACK":
            return msg.type
        with client.lock:
            client.conn.mav.send(msgs[msg.seq])


def read_plan(client, mission_type: int, seq: int):
    """The vehicle's count of items in its plan of ``mission_type``, and its item ``seq`` (MISSION_ITEM_INT)."""
    with client.lock:
        client.conn.mav.mission_request_list_send(1, 1, mission_type)
    count = client.recv("MISSION_COUNT", 3, lambda m: m.mission_type == mission_type).count
    with client.lock:
        client.conn.mav.mission_request_int_send(1, 1, seq, mission_type)
    return count, client.recv("MISSION_ITEM_INT", 3)


def px4_mode_name(hb) -> str:
    return mavutil.interpret_px4_mode(hb.base_mode, hb.custom_mode)


def wait_until(predicate, timeout: float, period: float = 0.02) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(period)
    return False


def wait_sim(server, seconds: float, timeout: float = 60.0) -> None:
    """Wait until ``seconds`` of the vehicle's simulated time have passed: a test's "some time later" in the
    vehicle's own clock, which a loaded machine slows but never skips."""
    until = server.sim.time_s + seconds
    assert wait_until(lambda: server.sim.time_s >= until, timeout, 0.005), \
        f"simulated time stuck at {server.sim.time_s:.3f} s, short of {until:.3f} s"


def wait_streamed(client, count: int, timeout: float = 20.0) -> None:
    """Wait until the client's stream thread has sent ``count`` more setpoints or stick messages."""
    target = client.streamed + count
    assert wait_until(lambda: client.streamed >= target, timeout, 0.005), "the stream stopped"


def distance(a, b) -> float:
    return math.dist(a, b)

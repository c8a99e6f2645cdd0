"""The vehicle in lockstep: held until released, then exactly as far as released, API messages first."""

from __future__ import annotations

import dataclasses
import socket
import time

from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.lockstep import COUNT_MODULUS, ack_message, behind, release_from
from sitl_vehicle.server import ServerConfig, VehicleServer
from sitl_vehicle.sim import VehicleConfig


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class SideChannel:
    """The companion's end, written here from the protocol's definition (sitl_vehicle.lockstep docstring)."""

    def __init__(self) -> None:
        self.truth = mavutil.mavlink_connection("udpin:127.0.0.1:0", dialect="common")
        self.truth_port = self.truth.port.getsockname()[1]
        self.api_port = _free_port()
        self.api = mavutil.mavlink_connection(f"udpin:127.0.0.1:{self.api_port}", source_system=1,
                                              source_component=191, dialect="common")
        self.sequence = 0
        self.poses: list[float] = []

    def word(self, wanted, timeout=5.0):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            msg = self.truth.recv_match(blocking=True, timeout=0.1)
            if msg is None:
                continue
            if msg.get_type() == "ODOMETRY":
                self.poses.append(msg.time_usec * 1e-6)
            elif msg.get_type() == "DEBUG_VECT" and wanted(msg):
                return msg
        raise AssertionError("no lockstep word from the vehicle")

    def release(self, until_s, api_sent=0):
        self.sequence += 1
        seq = self.sequence
        self.truth.mav.debug_vect_send(b"LOCKSTEP", int(round(until_s * 1e6)), float(api_sent), float(seq), 0.0)
        return self.word(lambda m: int(m.y) == seq)

    def close(self):
        self.truth.close()
        self.api.close()


def _held_vehicle(channel: SideChannel) -> VehicleServer:
    config = ServerConfig(vehicle=dataclasses.replace(VehicleConfig(), noise=None),
                          gcs_local=("127.0.0.1", 0), gcs_remote=None, api_local=("127.0.0.1", 0),
                          api_remote=("127.0.0.1", channel.api_port), truth_remote=("127.0.0.1", channel.truth_port),
                          lockstep=True)
    return VehicleServer(config).start()


def test_a_held_vehicle_beacons_and_runs_exactly_as_far_as_each_release():
    channel = SideChannel()
    server = _held_vehicle(channel)
    try:
        beacon = channel.word(lambda m: int(m.y) == 0)
        assert beacon.time_usec == 0
        time.sleep(0.3)                                 # wall time passes: simulation time does not
        assert server.sim.time_s == 0.0 and channel.poses == []
        ack = channel.release(0.5)
        assert ack.time_usec == 500_000 and abs(server.sim.time_s - 0.5) < 1e-9
        assert channel.poses and max(channel.poses) <= 0.5 + 1e-9 and len(channel.poses) >= 45   # truth at 100 Hz
        ack = channel.release(0.75)
        assert ack.time_usec == 750_000
        assert server.verdict()["clock"] == "lockstep"
        # streams follow simulation time: 0.75 s of it (and far more wall time) holds one 1 Hz heartbeat, at t=0
        beats = []
        while (msg := channel.api.recv_match(type="HEARTBEAT", blocking=False)) is not None:
            beats.append(msg)
        assert len(beats) == 1
    finally:
        server.stop()
        channel.close()


def test_api_messages_sent_before_a_release_take_effect_before_the_vehicle_steps():
    channel = SideChannel()
    server = _held_vehicle(channel)
    try:
        channel.word(lambda m: int(m.y) == 0)
        channel.release(0.1)
        kinds = []
        while (msg := channel.api.recv_match(blocking=False)) is not None:
            kinds.append(msg.get_type())
        assert "HEARTBEAT" in kinds
        sent = 0
        channel.api.mav.command_long_send(1, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
        sent += 1
        assert not server.sim.armed                     # held: nothing happens until the next release
        ack = channel.release(0.2, api_sent=sent)
        assert server.sim.armed and server.commander.armed
        # the vehicle's count of what it sent on the API link matches what arrived here
        received = len(kinds)
        while channel.api.recv_match(blocking=False) is not None:
            received += 1
        assert received > len(kinds) and received == int(ack.x)
    finally:
        server.stop()
        channel.close()


def test_release_words_are_parsed_strictly():
    good = ack_message(1.25, 7, 3)
    assert release_from(good).until_s == 1.25 and release_from(good).api_messages == 7
    assert release_from(mavlink.MAVLink_debug_vect_message(b"OTHER", 1, 0.0, 1.0, 0.0)) is None
    assert release_from(mavlink.MAVLink_debug_vect_message(b"LOCKSTEP", 1, float("nan"), 1.0, 0.0)) is None
    assert release_from(mavlink.MAVLink_debug_vect_message(b"LOCKSTEP", 1, -1.0, 1.0, 0.0)) is None
    assert release_from(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3)) is None
    assert behind(COUNT_MODULUS - 1, 2) and not behind(2, COUNT_MODULUS - 1) and not behind(5, 5)

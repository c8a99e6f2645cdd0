"""Fuzzing the vehicle's MAVLink edge with hypothesis: no input makes a handler raise or breaks an invariant.

Every message type the vehicle handles (each ``_on_<type>`` of ``MavlinkVehicleInterface``) is built with
random field values (NaN, inf, huge and negative numbers, out-of-range enums, any bytes in strings), packed,
parsed back through the link's own parser and handled without the interface's safety net, so an exception
fails the test.  Frames with valid framing and CRC but random payload bytes go the same way.  Random
sequences of commands, mode changes, parameter sets and mission transfers run against a stepping vehicle.
With a signing key, no unsigned message outside PX4's allowlist changes anything.

Budgets: ``fuzz_settings`` (a few seconds per test in ``make test``; ``FLOWGAP_FUZZ=deep`` runs 50 times as many
examples, see docs/testing.md).
"""

from __future__ import annotations

import dataclasses
import math
import os
import struct

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as mavlink
from pymavlink.generator.mavcrc import x25crc

from sitl_vehicle import signing
from sitl_vehicle.mavlink_io import MavlinkVehicleInterface
from sitl_vehicle.modes import FlightMode
from sitl_vehicle.server import ServerConfig, VehicleServer
from sitl_vehicle.signing import SigningKey
from sitl_vehicle.sim import VehicleConfig

DEEP = os.environ.get("FLOWGAP_FUZZ") == "deep"
KEY = bytes(range(32))


def fuzz_settings(examples: int):
    return settings(max_examples=examples * (50 if DEEP else 1), deadline=None, derandomize=not DEEP,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                           HealthCheck.function_scoped_fixture])


HANDLED = sorted({name[4:].upper() for name in dir(MavlinkVehicleInterface) if name.startswith("_on_")})
MESSAGE_CLASSES = {cls.msgname: cls for cls in mavlink.mavlink_map.values()}
assert set(HANDLED) <= set(MESSAGE_CLASSES), set(HANDLED) - set(MESSAGE_CLASSES)

INT_RANGES = {"int8_t": (-128, 127), "uint8_t": (0, 255), "int16_t": (-(1 << 15), (1 << 15) - 1),
              "uint16_t": (0, (1 << 16) - 1), "int32_t": (-(1 << 31), (1 << 31) - 1), "uint32_t": (0, (1 << 32) - 1),
              "int64_t": (-(1 << 63), (1 << 63) - 1), "uint64_t": (0, (1 << 64) - 1)}
COMMANDS = [mavlink.MAV_CMD_COMPONENT_ARM_DISARM, mavlink.MAV_CMD_NAV_TAKEOFF, mavlink.MAV_CMD_NAV_LAND,
            mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_CMD_MISSION_START,
            mavlink.MAV_CMD_DO_SET_MISSION_CURRENT, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
            mavlink.MAV_CMD_REQUEST_MESSAGE, mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
            mavlink.MAV_CMD_DO_REPOSITION, mavlink.MAV_CMD_DO_CHANGE_SPEED, mavlink.MAV_CMD_DO_SET_HOME,
            mavlink.MAV_CMD_DO_LAND_START, mavlink.MAV_CMD_DO_FLIGHTTERMINATION, mavlink.MAV_CMD_DO_ORBIT]
NASTY_FLOATS = st.sampled_from([math.nan, math.inf, -math.inf, 0.0, -0.0, 1e38, -1e38, 21196.0, 1.0, 0.5, 1e-45])


def floats(width: int):
    return st.one_of(NASTY_FLOATS, st.floats(width=width))


def field_values(name: str, ftype: str, length: int):
    if ftype == "char":
        return st.binary(max_size=max(length, 1))
    if ftype in ("float", "double"):
        base = floats(32 if ftype == "float" else 64)
    elif name == "command":
        base = st.one_of(st.sampled_from(COMMANDS), st.integers(*INT_RANGES[ftype]))
    elif name in ("target_system", "target_component"):
        base = st.sampled_from([0, 1, 2, 255])
    elif name in ("custom_mode", "base_mode"):
        base = st.one_of(st.sampled_from([0, 1, 65536 * 6, 65536 * 4 + 16777216 * 2, 0x81]),
                         st.integers(*INT_RANGES[ftype]))
    else:
        lo, hi = INT_RANGES[ftype]
        base = st.one_of(st.sampled_from([lo, hi, 0, 1]), st.integers(lo, hi))
    return st.lists(base, min_size=length, max_size=length) if length else base


@st.composite
def messages(draw, types=tuple(HANDLED)):
    cls = MESSAGE_CLASSES[draw(st.sampled_from(types))]
    values = []
    for name in cls.fieldnames:
        i = cls.ordered_fieldnames.index(name) if name in cls.ordered_fieldnames else cls.fieldnames.index(name)
        ftype = cls.fieldtypes[cls.fieldnames.index(name)]
        length = cls.array_lengths[i] if i < len(cls.array_lengths) else 0
        values.append(draw(field_values(name, ftype, length)))
    return cls(*values)


def new_vehicle(key_file=None) -> VehicleServer:
    config = ServerConfig(vehicle=dataclasses.replace(VehicleConfig(), noise=None), gcs_local=("127.0.0.1", 0),
                          gcs_remote=None, api_local=("127.0.0.1", 0), api_remote=None, truth_local=("127.0.0.1", 0),
                          truth_remote=None, signing_key=key_file)
    server = VehicleServer(config)
    server._next_control = server._next_truth = 0.0
    return server


def deliver(server: VehicleServer, frame: bytes, checked: bool = False) -> None:
    """Parse ``frame`` as the API link would and handle what it holds: with ``checked`` through the signing
    check (as received), else straight into the handler with no safety net, so that an exception escapes."""
    link = server.link("api")
    for msg in link._parse_datagram(frame):
        if checked:
            server.interface.receive(msg, link)
        else:
            server.interface.handle(msg, link)


def check_invariants(server: VehicleServer) -> None:
    c = server.commander
    assert isinstance(c.mode, FlightMode)
    assert isinstance(c.armed, bool)
    for name in server.params.names():
        spec, value = server.params.spec(name), server.params[name]
        assert math.isfinite(value) and spec.minimum <= value <= spec.maximum, (name, value)
    t = server.sim.truth
    assert all(math.isfinite(v) for v in (*t.position, *t.velocity)), t


def pack(msg, system: int = 255, component: int = 190, secret: bytes | None = None) -> bytes:
    mav = mavlink.MAVLink(None, system, component)
    if secret is not None:
        mav.signing.secret_key, mav.signing.sign_outgoing = secret, True
        mav.signing.timestamp = signing.timestamp_from_unix(2e9)
    return msg.pack(mav)


@fuzz_settings(300)
@given(msg=messages())
def test_no_field_values_make_a_handler_raise(msg):
    server = new_vehicle()
    try:
        try:
            frame = pack(msg)
        except (struct.error, OverflowError):   # a value the wire format cannot hold never reaches the vehicle
            return
        deliver(server, frame)
        server.advance(0.05, 1 << 20)
        check_invariants(server)
    finally:
        server.close()


@st.composite
def raw_frames(draw):
    cls = MESSAGE_CLASSES[draw(st.sampled_from(HANDLED))]
    payload = draw(st.binary(max_size=255))
    header = struct.pack("<BBBBBBBHB", 0xFD, len(payload), 0, 0, draw(st.integers(0, 255)), 255, 190,
                         cls.id & 0xFFFF, cls.id >> 16)
    crc = x25crc(header[1:] + payload)
    crc.accumulate(bytes([cls.crc_extra]))
    return header + payload + struct.pack("<H", crc.crc)


@fuzz_settings(300)
@given(frame=raw_frames())
def test_valid_framing_with_random_payloads_never_makes_a_handler_raise(frame):
    server = new_vehicle()
    try:
        deliver(server, frame)
        check_invariants(server)
    finally:
        server.close()


ARM = mavlink.MAVLink_command_long_message(1, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
TAKEOFF = mavlink.MAVLink_command_long_message(1, 1, mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, math.nan, math.nan,
                                               math.nan, 490.0)
STEP_TYPES = ("COMMAND_LONG", "COMMAND_INT", "SET_POSITION_TARGET_LOCAL_NED", "MANUAL_CONTROL", "PARAM_SET",
              "MISSION_COUNT", "MISSION_ITEM_INT", "MISSION_ITEM", "MISSION_CLEAR_ALL", "MISSION_SET_CURRENT",
              "HEARTBEAT")


@fuzz_settings(60)
@given(steps=st.lists(st.tuples(messages(STEP_TYPES), st.floats(0.0, 0.5)), min_size=1, max_size=12))
def test_random_command_sequences_keep_the_vehicle_in_known_states(steps):
    server = new_vehicle()
    try:
        deliver(server, pack(ARM))                  # flying, so that modes, failsafes and missions all matter
        deliver(server, pack(TAKEOFF))
        server.advance(1.0, 1 << 20)
        for msg, dt in steps:
            try:
                frame = pack(msg)
            except (struct.error, OverflowError):
                continue
            deliver(server, frame)
            server.advance(server.sim.time_s + dt, 1 << 20)
            check_invariants(server)
    finally:
        server.close()


def snapshot(server: VehicleServer) -> tuple:
    c, i = server.commander, server.interface
    return (c.mode, c.armed, tuple(c.mission), c.home, tuple(server.params.as_dict().items()),
            i.setpoints_received, i.manual_rejected, i.setpoints_rejected, i.signing.active)


@pytest.fixture(scope="module")
def key_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("signing") / "key.bin"
    signing.write_key_file(path, SigningKey(KEY, 1))
    return path


UNSIGNED_TYPES = tuple(t for t in HANDLED if MESSAGE_CLASSES[t].id not in signing.UNSIGNED_ALLOWED)


@fuzz_settings(200)
@given(batch=st.lists(st.tuples(messages(UNSIGNED_TYPES), st.booleans()), min_size=1, max_size=8))
def test_with_a_key_no_unsigned_or_wrongly_signed_message_changes_anything(key_file, batch):
    server = new_vehicle(key_file)
    try:
        deliver(server, pack(ARM, secret=KEY), checked=True)        # signed: accepted, so the state is not idle
        assert server.commander.armed
        before = snapshot(server)
        for msg, wrong_key in batch:
            try:
                frame = pack(msg, secret=bytes(32 * [7]) if wrong_key else None)
            except (struct.error, OverflowError):
                continue
            deliver(server, frame, checked=True)
        assert snapshot(server) == before
        assert signing.read_key_file(key_file).secret == KEY
    finally:
        server.interface.signing.key_path = None    # the shared key file stays as the fixture wrote it
        server.close()


@pytest.mark.parametrize("command", COMMANDS)
def test_every_command_takes_every_nasty_value_in_every_parameter(command):
    """A systematic sweep beside the random search: each handled command, each of its 7 parameters set to NaN,
    ±inf, ±1e38, -0 and the force-arm magic in turn, as COMMAND_LONG and as COMMAND_INT."""
    nasty = [math.nan, math.inf, -math.inf, 1e38, -1e38, -0.0, 21196.0, -1.0, 16777216.0]
    for slot in range(7):
        for value in nasty:
            params = [0.0] * 7
            params[slot] = value
            server = new_vehicle()
            try:
                deliver(server, pack(mavlink.MAVLink_command_long_message(1, 1, command, 0, *params)))
                x, y = (int(max(min(v, 2**31 - 1), -(2**31))) if math.isfinite(v) else 0 for v in params[4:6])
                deliver(server, pack(mavlink.MAVLink_command_int_message(1, 1, 0, command, 0, 0, *params[:4],
                                                                          x, y, params[6])))
                server.advance(0.05, 1 << 20)
                check_invariants(server)
            finally:
                server.close()

"""MAVLink 2 signing as PX4 v1.18: the key file, the incoming check, SETUP_SIGNING, and the vehicle over UDP.

Expected signatures are computed here from the MAVLink spec (SHA-256 over key + frame up to the signature,
first 6 bytes), not with the code under test.
"""

from __future__ import annotations

import hashlib
import math
import os
import struct
import time

import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle import signing
from sitl_vehicle.signing import MessageVerifier, SigningKey, SigningKeyError
from support.mavclient import wait_until

KEY = bytes(range(32))
OTHER = bytes(range(100, 132))


def signed_frame(msg, secret: bytes, timestamp: int, link_id: int = 0, system: int = 255, component: int = 190):
    mav = mavlink.MAVLink(None, system, component)
    mav.signing.secret_key = secret
    mav.signing.sign_outgoing = True
    mav.signing.link_id = link_id
    mav.signing.timestamp = timestamp
    return msg.pack(mav)


def unsigned_frame(msg, system: int = 255, component: int = 190):
    return msg.pack(mavlink.MAVLink(None, system, component))


def arm_message(arm: float = 1.0):
    return mavlink.MAVLink_command_long_message(1, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, arm, 0, 0, 0, 0, 0, 0)


def spec_signature_ok(frame: bytes, secret: bytes) -> bool:
    """The MAVLink spec's check, written independently: signed flag, then sha256(key + frame[:-6])[:6]."""
    return frame[0] == 0xFD and bool(frame[2] & 0x01) and hashlib.sha256(secret + frame[:-6]).digest()[:6] == frame[-6:]


def verifier(now: int = 10**12) -> MessageVerifier:
    v = MessageVerifier()
    v.set_key(SigningKey(KEY, 5), now)
    return v


# ------------------------------------------------------------------------------------------- pure core
def test_timestamps_count_ten_microseconds_from_2015():
    assert signing.timestamp_from_unix(1_420_070_400 + 1.5) == 150_000
    assert signing.timestamp_from_unix(0) == 0


def test_key_file_round_trip_mode_and_size(tmp_path):
    path = tmp_path / "key.bin"
    signing.write_key_file(path, SigningKey(KEY, 123456789))
    assert path.stat().st_mode & 0o777 == 0o600
    assert path.read_bytes() == KEY + struct.pack("<Q", 123456789)     # PX4's layout, little-endian timestamp
    assert signing.read_key_file(path) == SigningKey(KEY, 123456789)
    os.chmod(path, 0o644)
    with pytest.raises(SigningKeyError, match=r"mode 0644.*chmod 600") as err:
        signing.read_key_file(path)
    assert "\n" not in str(err.value)
    os.chmod(path, 0o600)
    path.write_bytes(KEY)
    with pytest.raises(SigningKeyError, match="is 32 bytes; a PX4 key file is 40"):
        signing.read_key_file(path)
    with pytest.raises(SigningKeyError, match="does not exist"):
        signing.read_key_file(tmp_path / "missing.bin")


def test_an_all_zero_key_file_means_signing_off(tmp_path):
    path = tmp_path / "key.bin"
    signing.write_key_file(path, signing.DISABLED)
    v = MessageVerifier()
    v.set_key(signing.read_key_file(path), 1000)
    assert not v.active
    assert v.check(unsigned_frame(arm_message()), 76, 255, 190) == signing.UNSIGNED


def test_a_valid_signature_is_accepted_and_advances_the_clock():
    v = verifier(now=1000)
    frame = signed_frame(arm_message(), KEY, 5000)
    assert spec_signature_ok(frame, KEY)
    assert v.check(frame, 76, 255, 190) == signing.SIGNED
    assert v.timestamp == 5000


@pytest.mark.parametrize("msg, allowed", [
    (arm_message(), False),
    (mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3), True),
    (mavlink.MAVLink_radio_status_message(1, 2, 3, 4, 5, 6, 7), True),
    (mavlink.MAVLink_param_set_message(1, 1, b"MIS_TAKEOFF_ALT", 9.0, 9), False),
])
def test_unsigned_messages_are_dropped_but_the_allowlist(msg, allowed):
    v = verifier()
    outcome = v.check(unsigned_frame(msg), msg.id, 255, 190)
    assert outcome == (signing.UNSIGNED if allowed else signing.REJECTED_UNSIGNED)
    bad = v.check(signed_frame(msg, OTHER, 10**12 + 1), msg.id, 255, 190)     # signed with another key
    assert bad == (signing.UNSIGNED if allowed else signing.REJECTED_BAD_SIGNATURE)


def test_a_replayed_or_older_timestamp_on_a_known_stream_is_rejected():
    v = verifier(now=1000)
    first = signed_frame(arm_message(), KEY, 2000)
    assert v.check(first, 76, 255, 190) == signing.SIGNED
    assert v.check(first, 76, 255, 190) == signing.REJECTED_REPLAY
    assert v.check(signed_frame(arm_message(), KEY, 1999), 76, 255, 190) == signing.REJECTED_REPLAY
    assert v.check(signed_frame(arm_message(), KEY, 2001), 76, 255, 190) == signing.SIGNED
    # another link id is another stream (MAVLink: streams are (system, component, link id))
    assert v.check(signed_frame(arm_message(), KEY, 1500, link_id=3), 76, 255, 190) == signing.SIGNED


def test_a_new_stream_may_be_at_most_a_minute_behind_the_clock():
    minute = 60 * 100_000
    v = verifier(now=10 * minute)
    assert v.check(signed_frame(arm_message(), KEY, 9 * minute - 1), 76, 255, 190) == signing.REJECTED_OLD_STREAM
    assert v.check(signed_frame(arm_message(), KEY, 9 * minute), 76, 200, 190) == signing.SIGNED


def test_a_bad_signature_does_not_touch_the_stream_it_claims():
    """The signature is checked before the timestamp (as the C library), so a forged frame with a far-future
    timestamp cannot lock the real sender's stream out."""
    v = verifier(now=1000)
    assert v.check(signed_frame(arm_message(), OTHER, 10**14), 76, 255, 190) == signing.REJECTED_BAD_SIGNATURE
    assert v.check(signed_frame(arm_message(), KEY, 2000), 76, 255, 190) == signing.SIGNED


def test_at_most_sixteen_streams_are_tracked():
    v = verifier(now=1000)
    for system in range(16):
        assert v.check(signed_frame(arm_message(), KEY, 2000, system=system + 1), 76, system + 1, 190) == signing.SIGNED
    assert v.check(signed_frame(arm_message(), KEY, 2000, system=99), 76, 99, 190) == signing.REJECTED_STREAMS_FULL


def test_a_truncated_signed_frame_is_a_bad_signature_not_an_error():
    v = verifier()
    frame = signed_frame(arm_message(), KEY, 10**12 + 5)
    assert v.check(frame[:14], 76, 255, 190) == signing.REJECTED_BAD_SIGNATURE


def test_checkpoint_writes_only_a_newer_timestamp_of_the_same_key(tmp_path):
    path = tmp_path / "key.bin"
    signing.write_key_file(path, SigningKey(KEY, 100))
    assert signing.checkpoint_key_file(path, SigningKey(KEY, 200))
    assert signing.read_key_file(path).timestamp == 200
    assert not signing.checkpoint_key_file(path, SigningKey(KEY, 150))
    assert not signing.checkpoint_key_file(path, SigningKey(OTHER, 900))     # replaced key: never restored
    assert signing.read_key_file(path) == SigningKey(KEY, 200)


# -------------------------------------------------------------------------------------- the vehicle over UDP
@pytest.fixture
def key_file(tmp_path):
    path = tmp_path / "signing.key"
    signing.write_key_file(path, SigningKey(KEY, signing.timestamp_from_unix(time.time()) - 1000))
    return path


def sign_client(client, secret: bytes = KEY) -> None:
    client.conn.setup_signing(secret, sign_outgoing=True, allow_unsigned_callback=lambda mav, msg_id: True)


def armed(client) -> bool:
    hb = client.recv("HEARTBEAT", 3.0, lambda m: m.get_srcComponent() == 1)
    assert hb is not None
    return bool(hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)


def test_with_a_key_an_unsigned_arm_is_ignored_and_a_signed_one_accepted(make_vehicle, key_file):
    server, client = make_vehicle(signing_key=key_file)
    with client.lock:
        client.conn.mav.command_long_send(1, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    assert client.statustext("Signing: rejected COMMAND_LONG (unsigned)") is not None
    assert client.recv("COMMAND_ACK", 1.0) is None                                        # dropped: no ACK
    assert not server.sim.armed
    sign_client(client)
    ack = client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert ack is not None and ack.result == mavlink.MAV_RESULT_ACCEPTED
    assert wait_until(lambda: server.sim.armed, 3.0)
    counts = server.interface.signing.summary()
    assert counts["active"] and counts["rejected_unsigned"] >= 1 and counts["signed"] >= 1


def test_the_vehicles_messages_verify_with_the_key(make_vehicle, key_file):
    _, client = make_vehicle(signing_key=key_file)
    kinds = set()
    deadline = time.monotonic() + 3.0
    while time.monotonic() < deadline and len(kinds) < 4:
        msg = client.recv(["HEARTBEAT", "ATTITUDE", "LOCAL_POSITION_NED", "SYS_STATUS"], 1.0)
        assert msg is not None
        frame = bytes(msg.get_msgbuf())
        assert spec_signature_ok(frame, KEY), msg.get_type()
        assert not spec_signature_ok(frame, OTHER)
        kinds.add(msg.get_type())
    assert len(kinds) == 4


def test_an_unsigned_setup_signing_cannot_replace_the_key(make_vehicle, key_file):
    server, client = make_vehicle(signing_key=key_file)
    with client.lock:
        client.conn.mav.setup_signing_send(1, 1, list(OTHER), 0)
    assert wait_until(lambda: server.interface.signing.summary()["rejected_unsigned"] >= 1, 3.0)
    assert signing.read_key_file(key_file).secret == KEY
    sign_client(client)                                      # the old key still commands the vehicle
    ack = client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert ack is not None and ack.result == mavlink.MAV_RESULT_ACCEPTED


def test_a_replayed_signed_command_is_rejected(make_vehicle, key_file):
    server, client = make_vehicle(signing_key=key_file)
    sign_client(client)
    with client.lock:
        recorded = arm_message(1.0).pack(client.conn.mav)       # signed with the client's clock, as sent
        client.conn.write(recorded)
    assert wait_until(lambda: server.sim.armed, 3.0)
    ack = client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0)
    assert ack is not None and ack.result == mavlink.MAV_RESULT_ACCEPTED
    assert wait_until(lambda: not server.sim.armed, 3.0)
    before = server.interface.signing.summary()["rejected_replay"]
    with client.lock:
        client.conn.write(recorded)                              # the same bytes again, an attacker's replay
    assert wait_until(lambda: server.interface.signing.summary()["rejected_replay"] > before, 3.0)
    assert not server.sim.armed


def test_a_signed_setup_signing_rotates_the_key_only_while_disarmed(make_vehicle, key_file):
    server, client = make_vehicle(signing_key=key_file)
    sign_client(client)
    assert client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == mavlink.MAV_RESULT_ACCEPTED
    with client.lock:
        client.conn.mav.setup_signing_send(1, 1, list(OTHER), 0)
    assert client.statustext("refused while armed") is not None
    assert signing.read_key_file(key_file).secret == KEY
    assert client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0).result == mavlink.MAV_RESULT_ACCEPTED
    with client.lock:
        client.conn.mav.setup_signing_send(1, 1, list(OTHER), 0)
    assert wait_until(lambda: signing.read_key_file(key_file).secret == OTHER, 3.0)
    stored = signing.read_key_file(key_file)
    assert stored.timestamp >= signing.timestamp_from_unix(time.time()) - 100_000 * 60   # never behind the clock
    # the old key no longer commands the vehicle; the new one does
    assert client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1, timeout=1.0) is None
    sign_client(client, OTHER)
    assert client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == mavlink.MAV_RESULT_ACCEPTED


def test_without_a_key_an_unsigned_setup_signing_turns_signing_on(make_vehicle):
    server, client = make_vehicle()
    assert not server.interface.signing.active
    with client.lock:
        client.conn.mav.setup_signing_send(1, 1, list(KEY), signing.timestamp_from_unix(time.time()))
    assert client.statustext("Signing: enabled") is not None
    assert server.interface.signing.active
    assert client.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1, timeout=1.0) is None


def test_rejections_are_reported_at_most_every_few_seconds(make_vehicle, key_file):
    server, client = make_vehicle(signing_key=key_file)
    for _ in range(20):
        with client.lock:
            client.conn.mav.command_long_send(1, 1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    assert wait_until(lambda: server.interface.signing.summary()["rejected_unsigned"] >= 20, 3.0)
    reports = 0
    deadline = time.monotonic() + 1.5
    while time.monotonic() < deadline:
        msg = client.recv("STATUSTEXT", 0.3)
        if msg is not None and "Signing: rejected" in msg.text:
            reports += 1
    assert reports == 1


def test_the_key_files_timestamp_is_written_back_at_shutdown(make_vehicle, key_file):
    before = signing.read_key_file(key_file).timestamp
    server, client = make_vehicle(signing_key=key_file)
    wait_until(lambda: False, 0.5)
    server.stop()
    after = signing.read_key_file(key_file)
    assert after.secret == KEY and after.timestamp > before
    assert math.isfinite(after.timestamp)


def test_the_vehicle_cli_refuses_a_key_file_readable_by_others(tmp_path, capsys):
    from sitl_vehicle.__main__ import main

    path = tmp_path / "key.bin"
    signing.write_key_file(path, SigningKey(KEY, 1))
    os.chmod(path, 0o640)
    assert main(["--signing-key", str(path), "--duration", "0.1", "--api-local", "127.0.0.1:0",
                 "--gcs-local", "127.0.0.1:0"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "chmod 600" in err
    fresh = tmp_path / "new.key"
    assert main(["--new-signing-key", str(fresh)]) == 0
    assert fresh.stat().st_mode & 0o777 == 0o600 and len(fresh.read_bytes()) == 40
    assert main(["--new-signing-key", str(fresh)]) == 2                         # never overwrites a key

"""``flowgap-tlog --signing-key``: every packet of a log classed good, replayed, bad or unsigned."""

from __future__ import annotations

import json

from pymavlink.dialects.v20 import common as mavlink

from companion.link.tlog import TlogWriter
from sitl_vehicle.signing import SigningKey, write_key_file
from tools.tlog import main

KEY = bytes(range(32))


def _mav(system, component, secret=None, timestamp=1000, link_id=0):
    mav = mavlink.MAVLink(None, system, component)
    if secret is not None:
        mav.signing.secret_key, mav.signing.sign_outgoing = secret, True
        mav.signing.timestamp, mav.signing.link_id = timestamp, link_id
    return mav


def test_signatures_are_counted_per_class_and_source(tmp_path, capsys):
    log = tmp_path / "link.tlog"
    writer = TlogWriter(log)
    vehicle = _mav(1, 1, KEY, timestamp=5000)
    companion = _mav(255, 190, KEY, timestamp=7000, link_id=2)
    stranger = _mav(42, 190, bytes(32 * [9]))
    gcs = _mav(254, 190)
    t = 1_700_000_000.0
    hb = mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4, 0, 0, 3, 3)
    arm = mavlink.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
    for k in range(5):
        writer.write(hb.pack(vehicle), t + k)                       # 5 good from 1/1
    recorded = arm.pack(companion)
    writer.write(recorded, t + 5)                                   # 1 good from 255/190
    writer.write(recorded, t + 6)                                   # the same bytes again: replayed
    writer.write(arm.pack(stranger), t + 7)                         # another key: bad
    writer.write(arm.pack(gcs), t + 8)                              # unsigned
    writer.write(hb.pack(gcs), t + 9)                               # unsigned
    writer.close()
    key = tmp_path / "key.bin"
    write_key_file(key, SigningKey(KEY, 1))
    assert main([str(log), "--signing-key", str(key), "--json", "-q"]) == 0
    sig = json.loads(capsys.readouterr().out)["signatures"]
    assert (sig["good"], sig["replayed"], sig["bad"], sig["unsigned"]) == (6, 1, 1, 2)
    assert sig["by_source"]["1/1"]["good"] == 5 and sig["by_source"]["255/190"] == {
        "good": 1, "replayed": 1, "bad": 0, "unsigned": 0}
    assert sig["by_source"]["254/190"]["unsigned"] == 2
    assert main([str(log), "--signing-key", str(key), "-q"]) == 0
    assert "signatures: 6 good, 1 replayed, 1 bad, 2 unsigned (unsigned from 254/190)" in capsys.readouterr().out


def test_a_bad_key_file_is_one_line(tmp_path, capsys):
    log = tmp_path / "x.tlog"
    log.write_bytes(b"")
    key = tmp_path / "key.bin"
    key.write_bytes(b"x" * 40)
    key.chmod(0o644)
    assert main([str(log), "--signing-key", str(key)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "chmod 600" in err[0]

"""``flowgap-companion``'s command line: bad input is one line and exit status 2, before anything flies."""

from __future__ import annotations

import pytest

from companion.__main__ import main
from companion.clock import LockstepClock
from companion.link import make_link


@pytest.mark.parametrize("argv, needle", [
    (["--lockstep", "--link", "mavsdk"], "--lockstep needs --link pymavlink"),
    (["--latency", "-0.1"], "--latency must be a number of seconds >= 0"),
    (["--latency", "nan"], "--latency must be a number of seconds >= 0"),
    (["--connect", "bogus://x"], "scheme must be udpin, udpout, tcp or serial"),
    (["--flow", "raft:nope=1"], "unknown RAFT option"),
])
def test_bad_options_are_one_line_errors(argv, needle, capsys, tmp_path):
    assert main([*argv, "--run-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("flowgap-companion: error:") and needle in err[0], err


def test_a_lockstep_companion_without_a_lockstep_vehicle_says_so(capsys, tmp_path, monkeypatch):
    from companion import lockstep

    monkeypatch.setattr(lockstep, "START_TIMEOUT_S", 0.3)
    assert main(["--lockstep", "--truth", "udpin://127.0.0.1:0", "--run-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no lockstep word from the vehicle" in err[0] and "--lockstep" in err[0]


def test_the_mavsdk_link_refuses_a_lockstep_clock():
    class Held:
        def start(self):
            return 0.0, 0

    with pytest.raises(ValueError, match="cannot run in lockstep"):
        make_link("udpin://:0", "mavsdk", clock=LockstepClock(Held()))


GOOD_KEY = bytes(range(32)) + (5).to_bytes(8, "little")


def _key_file(path, mode=0o600, data=GOOD_KEY):
    path.write_bytes(data)
    path.chmod(mode)
    return str(path)


@pytest.mark.parametrize("mode, data, needle", [
    (0o644, None, "readable by others: chmod 600"),
    (0o600, b"short", "is 5 bytes; a PX4 key file is 40"),
    (0o600, bytes(40), "is blank"),
])
def test_a_bad_signing_key_file_is_one_line_before_anything_flies(mode, data, needle, capsys, tmp_path):
    key = _key_file(tmp_path / "key.bin", mode, *(() if data is None else (data,)))
    assert main(["--signing-key", key, "--run-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0], err
    assert main(["--signing-key", str(tmp_path / "missing.bin"), "--run-dir", str(tmp_path)]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_the_mavsdk_link_says_it_cannot_sign(capsys, tmp_path):
    key = _key_file(tmp_path / "key.bin")
    assert main(["--signing-key", key, "--link", "mavsdk", "--run-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot sign MAVLink" in err[0] and "--link pymavlink" in err[0], err
    with pytest.raises(ValueError, match="cannot sign"):
        make_link("udpin://:0", "mavsdk", signing_key=tmp_path / "key.bin")

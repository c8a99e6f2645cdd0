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

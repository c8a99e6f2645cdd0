"""A lockstep flight through the link-fault relay, two processes as ``flowgap-sitl --lockstep --link-loss 0.3
--link-delay 150`` flies it: the same seed gives the same flight, faults and all."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.support.tlog import tlog_messages
from tools.launch import launch
from tools.link_faults import COMPANION_TO_VEHICLE, VEHICLE_TO_COMPANION, LinkFaults


def _fly(run_dir: Path) -> dict:
    # dis:fine, not the default RAFT: what is under test is the relay's faults on the lockstep clock, and the
    # flight is flown twice (the default flow's lockstep repeat is test_lockstep's)
    return launch("window1_brick", run_dir, start=(0.0, 0.1, 0.0), instance=8, flow="dis:fine", images=False,
                  log_sink=None, lockstep=True, seed=3, timeout_s=120,
                  link_faults=LinkFaults(loss=0.3, delay_ms=150, jitter_ms=20, duplicate=0.05, reorder=0.05))


@pytest.mark.slow
def test_the_same_lossy_lockstep_flight_twice_is_identical(tmp_path):
    first, second = _fly(tmp_path / "first"), _fly(tmp_path / "second")
    faults = first["link_faults"]
    assert faults["seed"] == 3 and faults["clock"] == "lockstep" and "error" not in faults
    for direction in (VEHICLE_TO_COMPANION, COMPANION_TO_VEHICLE):
        stats = faults[direction]
        assert stats["dropped"] > 0 and stats["mean_added_delay_ms"] >= 150
    for verdict in (first, second):
        for key in ("wall_time_s", "run_dir", "storyboard"):
            verdict.pop(key, None)
    assert first == second
    # what the companion received and sent, message by message, field by field (the tlog's own timestamps are
    # wall time)
    tlogs = [tlog_messages(tmp_path / d / "companion" / "link.tlog") for d in ("first", "second")]
    assert len(tlogs[0]) > 100 and tlogs[0] == tlogs[1]

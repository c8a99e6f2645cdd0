"""Benchmark group ``tlog``: end-to-end analysis speed of flowgap-tlog (``python -m tools.bench tlog``).

``tlog.msgs_per_s``: messages per second through ``analyse_tlog`` + ``write_outputs(plots=False)``
(report.md and metrics.json; everything but plotting), median of several runs, on a synthetic ~200k-message
flowgap-like tlog generated with pymavlink in a temporary directory. Also reported: the same on the
third-party ArduSub log in ``tests/data``, and pymavlink's plain ``recv_match`` loop on
the synthetic log as the baseline.
"""

from __future__ import annotations

import statistics
import struct
import tempfile
import time
from pathlib import Path

import numpy as np

REPEATS = 5
N_TARGET = 200_000
TESTDATA = Path(__file__).resolve().parents[2] / "tests" / "data" / "ardusub-qgc-small.tlog"


def make_synthetic_tlog(path: Path, n_target: int = N_TARGET, seed: int = 0) -> int:
    """Write a flowgap-like tlog of about ``n_target`` messages; returns the number written.

    Streams (Hz): ATTITUDE, ATTITUDE_QUATERNION, LOCAL_POSITION_NED, HIGHRES_IMU, ATT_POS_MOCAP (truth,
    own component) 50; SET_POSITION_TARGET_LOCAL_NED (companion) and POSITION_TARGET_LOCAL_NED 20;
    HEARTBEAT (vehicle, companion), SYS_STATUS 1; a STATUSTEXT every 10 s; PX4 modes change over time.
    """
    from pymavlink.dialects.v20 import common as m

    rng = np.random.default_rng(seed)
    veh = m.MAVLink(None, srcSystem=1, srcComponent=1)
    comp = m.MAVLink(None, srcSystem=1, srcComponent=191)
    tru = m.MAVLink(None, srcSystem=1, srcComponent=197)
    per_s = 5 * 50 + 2 * 20 + 3 + 0.1
    duration = n_target / per_s
    t0 = 1_750_000_000_000_000
    out = bytearray()
    count = 0
    n_steps = int(duration * 100)  # a 100 Hz base clock
    p = np.zeros(3)
    for i in range(n_steps):
        t = i * 0.01
        us = t0 + int(t * 1e6)
        msgs = []
        if i % 100 == 0:
            mode = (6 << 16) if 0.2 * duration < t < 0.9 * duration else (3 << 16)
            msgs += [(veh, m.MAVLink_heartbeat_message(2, 12, 129, mode, 4, 3)),
                     (comp, m.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3)),
                     (veh, m.MAVLink_sys_status_message(0, 0, 0, 500, 12000, 100, 80, 0, 0, 0, 0, 0, 0))]
        if i % 1000 == 0:
            msgs.append((veh, m.MAVLink_statustext_message(6, b"benchmark status %d" % i)))
        if i % 2 == 0:
            p = p + rng.normal(0, 0.01, 3)
            x, y, z = (float(c) for c in p)
            msgs += [(veh, m.MAVLink_attitude_message(int(t * 1000), 0.01, 0.02, 0.3, 0, 0, 0)),
                     (veh, m.MAVLink_attitude_quaternion_message(int(t * 1000), 1, 0, 0, 0, 0, 0, 0)),
                     (veh, m.MAVLink_local_position_ned_message(int(t * 1000), x, y, z, 0.1, 0, 0)),
                     (veh, m.MAVLink_highres_imu_message(int(t * 1e6), 0, 0, -9.8, 0, 0, 0, 0.2, 0, 0.4,
                                                         1013, 0, 0, 20, 0xFFFF)),
                     (tru, m.MAVLink_att_pos_mocap_message(int(t * 1e6), [1, 0, 0, 0], x + 0.01, y, z))]
        if i % 5 == 0:
            x, y, z = (float(c) for c in p)
            msgs += [(comp, m.MAVLink_set_position_target_local_ned_message(
                         int(t * 1000), 1, 1, 1, 0x0FF8, x + 0.1, y, z, 0, 0, 0, 0, 0, 0, 0, 0)),
                     (veh, m.MAVLink_position_target_local_ned_message(
                         int(t * 1000), 1, 0x0FF8, x + 0.1, y, z, 0, 0, 0, 0, 0, 0, 0, 0))]
        for k, (mav, msg) in enumerate(msgs):
            out += struct.pack(">Q", us + 17 * k) + msg.pack(mav)
            mav.seq = (mav.seq + 1) % 256
        count += len(msgs)
    path.write_bytes(bytes(out))
    return count


def _end_to_end(path: Path, out_dir: Path) -> tuple[float, int]:
    from tools.tlog import analyse_tlog, write_outputs

    t = time.perf_counter()
    rep = analyse_tlog(path)
    write_outputs(rep, out_dir, plots=False)
    return time.perf_counter() - t, rep.metrics.get("framing", {}).get("packets", 0)


def _median_rate(path: Path, out_dir: Path, repeats: int = REPEATS) -> float:
    _end_to_end(path, out_dir)  # warm-up: imports, dialect tables
    rates = []
    for _ in range(repeats):
        dt, n = _end_to_end(path, out_dir)
        rates.append(n / dt)
    return statistics.median(rates)


def _pymavlink_baseline(path: Path) -> float:
    from pymavlink import mavutil

    t = time.perf_counter()
    conn = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    n = 0
    while conn.recv_match() is not None:
        n += 1
    return n / (time.perf_counter() - t)


def run() -> dict:
    import logging

    logging.getLogger("tools.tlog").setLevel(logging.ERROR)  # notes are not what we time
    with tempfile.TemporaryDirectory(prefix="flowgap-bench-tlog-") as tmp:
        tmp_path = Path(tmp)
        path = tmp_path / "synthetic.tlog"
        n = make_synthetic_tlog(path)
        out = {"tlog.msgs_per_s": {"value": _median_rate(path, tmp_path / "out"), "unit": "msgs/s",
                                   "messages": n, "repeats": REPEATS},
               "tlog.pymavlink_recv_match_msgs_per_s": {"value": _pymavlink_baseline(path), "unit": "msgs/s"}}
        if TESTDATA.exists():
            out["tlog.ardusub_msgs_per_s"] = {"value": _median_rate(TESTDATA, tmp_path / "out2"), "unit": "msgs/s"}
    return out


if __name__ == "__main__":
    for key, entry in run().items():
        print(f"{key:40s} {entry['value']:12.0f} {entry['unit']}")

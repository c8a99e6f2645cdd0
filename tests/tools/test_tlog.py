"""Acceptance tests of flowgap-tlog (tools.tlog) on tlogs written here with pymavlink and on a real log."""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
from pymavlink import mavutil
from pymavlink.dialects.v10 import common as mav1
from pymavlink.dialects.v20 import common as mav2

from companion.edges import DEFAULT_EDGES
from tools.tlog import analyse_tlog, main, write_outputs
from tools.tlog.framing import crc_x25, decode_columns, load_dialect, scan_tlog

TESTDATA = Path(__file__).resolve().parents[2] / "tests" / "data"
ARDUSUB = TESTDATA / "ardusub-qgc-small.tlog"
T0_US = 1_750_000_000_000_000  # an arbitrary UNIX time in µs

PX4_POSCTL = 3 << 16
PX4_TAKEOFF = (4 << 16) | (2 << 24)
PX4_OFFBOARD = 6 << 16
PX4_LAND = (4 << 16) | (6 << 24)
POS_ONLY = 0x0FF8        # velocity, acceleration, yaw, yaw rate ignored
VEL_ONLY = 0x0FC7        # x, y, z ignored


@dataclass
class Flight:
    """What the synthetic flight wrote, kept for independent checks."""

    records: list[tuple[int, bytes, str]] = field(default_factory=list)  # (µs, packet, type)
    setpoints: list[tuple[int, int, tuple[float, float, float]]] = field(default_factory=list)
    positions: list[tuple[int, tuple[float, float, float]]] = field(default_factory=list)
    truth: list[tuple[int, tuple[float, float, float]]] = field(default_factory=list)
    heartbeats: list[tuple[int, int, bool]] = field(default_factory=list)  # (µs, custom_mode, armed)
    dropped: int = 0

    def tlog(self) -> bytes:
        return b"".join(struct.pack(">Q", t) + pkt for t, pkt, _ in sorted(self.records, key=lambda r: r[0]))

    def counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for _, _, name in self.records:
            out[name] = out.get(name, 0) + 1
        return out


def px4_mode_at(t: float) -> tuple[int, bool]:
    if t < 2.0:
        return PX4_POSCTL, False
    if t < 5.0:
        return PX4_TAKEOFF, True
    if t < 14.0:
        return PX4_OFFBOARD, True
    return PX4_LAND, t < 17.0


def synthetic_flight(seed: int = 0, with_truth: bool = True, with_positions: bool = True) -> Flight:
    """18 s PX4-style flight: heartbeats 1 Hz, setpoints 20 Hz (4–14 s, a 0.35 s gap, a velocity-only
    second), LOCAL_POSITION_NED 50 Hz following with lag and noise, signed ATT_POS_MOCAP truth from its own
    component, MAVLink 1 GCS heartbeats, STATUSTEXT, and a few vehicle packets dropped (sequence gaps)."""
    rng = np.random.default_rng(seed)
    fl = Flight()
    veh = mav2.MAVLink(None, srcSystem=1, srcComponent=1)
    comp = mav2.MAVLink(None, srcSystem=1, srcComponent=191)
    tru = mav2.MAVLink(None, srcSystem=1, srcComponent=197)
    tru.signing.secret_key = bytes(range(32))
    tru.signing.sign_outgoing = True
    tru.signing.timestamp = 1
    gcs = mav1.MAVLink(None, srcSystem=255, srcComponent=190)

    events: list[tuple[int, int, object, object, bool]] = []

    def put(mav, t_s: float, msg, keep: bool = True) -> None:
        events.append((T0_US + round(t_s * 1e6), len(events), mav, msg, keep))

    for k in range(18):
        t = k + 0.5 if k else 0.0
        mode, armed = px4_mode_at(t)
        base = mav2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (mav2.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
        put(veh, t, mav2.MAVLink_heartbeat_message(mav2.MAV_TYPE_QUADROTOR, mav2.MAV_AUTOPILOT_PX4, base, mode,
                                                    mav2.MAV_STATE_ACTIVE, 3))
        fl.heartbeats.append((T0_US + round(t * 1e6), mode, armed))
        put(comp, t + 0.0002, mav2.MAVLink_heartbeat_message(mav2.MAV_TYPE_ONBOARD_CONTROLLER,
                                                              mav2.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3))
        put(gcs, t + 0.0003, mav1.MAVLink_heartbeat_message(mav1.MAV_TYPE_GCS, mav1.MAV_AUTOPILOT_INVALID,
                                                             0, 0, 0, 3))
    put(veh, 0.1, mav2.MAVLink_statustext_message(mav2.MAV_SEVERITY_INFO, b"synthetic PX4 ready"))
    put(veh, 17.2, mav2.MAVLink_statustext_message(mav2.MAV_SEVERITY_NOTICE, b"landed, disarming"))
    long_text = b"x" * 50 + b"tail of a long text"  # MAVLink 2 chunked STATUSTEXT
    put(veh, 17.3, mav2.MAVLink_statustext_message(mav2.MAV_SEVERITY_INFO, long_text[:50], 7, 0))
    put(veh, 17.3001, mav2.MAVLink_statustext_message(mav2.MAV_SEVERITY_INFO, long_text[50:], 7, 1))
    # setpoints: a slow path forward and up, 20 Hz from 4.0 s to 13.95 s
    target = lambda t: (0.3 * (t - 4.0), 0.1 * np.sin(t), -1.5 - 0.05 * (t - 4.0))  # noqa: E731
    for i in range(200):
        t = 4.0 + 0.05 * i + 0.0011
        if 11.0 < t < 11.3:
            continue  # a 0.35 s hole in the stream
        mask = VEL_ONLY if 9.0 <= t < 10.0 else POS_ONLY
        x, y, z = target(t)
        put(comp, t, mav2.MAVLink_set_position_target_local_ned_message(
            int(t * 1000), 1, 1, mav2.MAV_FRAME_LOCAL_NED, mask, x, y, z, 0.3, 0, 0, 0, 0, 0, 0, 0))
        fl.setpoints.append((T0_US + round(t * 1e6), mask, (float(np.float32(x)), float(np.float32(y)),
                                                            float(np.float32(z)))))
    # position: first-order lag towards the setpoint + noise, 50 Hz for the whole flight
    p = np.array([0.0, 0.0, 0.0])
    sp_now = p.copy()
    sp_iter = iter(fl.setpoints)
    nxt = next(sp_iter)
    for i in range(900):
        t = 0.02 * i + 0.0007
        while nxt is not None and nxt[0] <= T0_US + round(t * 1e6):
            if nxt[1] == POS_ONLY:
                sp_now = np.array(nxt[2])
            nxt = next(sp_iter, None)
        p = p + 0.15 * (sp_now - p) + rng.normal(0, 0.01, 3)
        v = 0.15 * (sp_now - p) / 0.02
        keep = i not in (300, 301, 302, 500, 777)
        if with_positions:
            put(veh, t, mav2.MAVLink_local_position_ned_message(int(t * 1000), *p, *v), keep)
            if keep:
                fl.positions.append((T0_US + round(t * 1e6), tuple(float(np.float32(c)) for c in p)))
        if with_truth and i % 2 == 0:
            q = p + rng.normal(0, 0.02, 3)
            put(tru, t + 0.0003, mav2.MAVLink_att_pos_mocap_message(int(t * 1e6), [1, 0, 0, 0], *q))
            fl.truth.append((T0_US + round((t + 0.0003) * 1e6), tuple(float(np.float32(c)) for c in q)))
    for t_us, _, mav, msg, keep in sorted(events, key=lambda e: e[:2]):
        pkt = bytes(msg.pack(mav))  # like MAVLink.send: pack with the current seq, then advance it
        mav.seq = (mav.seq + 1) % 256
        if keep:
            fl.records.append((t_us, pkt, msg.get_type()))
        else:
            fl.dropped += 1
    return fl


def expected_tracking(fl: Flight, samples: list[tuple[int, tuple[float, float, float]]]) -> list[float]:
    """Independent reference: plain loops, latest position-only setpoint at or before each sample."""
    sps = [(t, xyz) for t, mask, xyz in fl.setpoints if mask == POS_ONLY]
    errs = []
    for t, xyz in samples:
        latest = None
        for ts, sxyz in sps:
            if ts <= t:
                latest = sxyz
        if latest is not None:
            errs.append(sum((a - b) ** 2 for a, b in zip(xyz, latest, strict=True)) ** 0.5)
    return errs


@pytest.fixture(scope="module")
def flight() -> Flight:
    return synthetic_flight()


@pytest.fixture(scope="module")
def flight_path(tmp_path_factory, flight) -> Path:
    path = tmp_path_factory.mktemp("tlog") / "flight.tlog"
    path.write_bytes(flight.tlog())
    return path


def test_synthetic_flight_counts_and_summary(flight, flight_path):
    rep = analyse_tlog(flight_path)
    m = rep.metrics
    assert rep.usable and rep.notes == []
    by_type = {k: v["count"] for k, v in m["messages"]["by_type"].items()}
    assert by_type == flight.counts()
    # pymavlink's own reader sees the same messages
    conn = mavutil.mavlink_connection(str(flight_path), dialect="ardupilotmega")
    seen: dict[str, int] = {}
    while (msg := conn.recv_match()) is not None:
        seen[msg.get_type()] = seen.get(msg.get_type(), 0) + 1
    assert seen == by_type
    assert m["duration_s"] == pytest.approx((max(r[0] for r in flight.records) - T0_US) / 1e6)
    assert m["vehicle"]["autopilot"] == "PX4" and m["vehicle"]["type"] == "quadrotor"
    assert set(m["components"]) == {"1:1", "1:191", "1:197", "255:190"}
    assert m["framing"]["mavlink1"] == 18 and m["framing"]["signed"] == len(flight.truth)
    assert m["components"]["1:1"]["lost"] == flight.dropped == 5
    assert m["components"]["1:191"]["lost"] == 0 and m["components"]["1:197"]["lost"] == 0
    assert m["messages"]["by_type"]["HEARTBEAT"]["sources"] == {"1:1": 18, "1:191": 18, "255:190": 18}
    assert [s["text"] for s in m["statustext"]] == ["synthetic PX4 ready", "landed, disarming",
                                                   "x" * 50 + "tail of a long text"]


def test_synthetic_flight_modes_and_arming(flight, flight_path):
    m = analyse_tlog(flight_path).metrics
    modes = [(round(e["t_s"], 4), e["mode"]) for e in m["modes"]["timeline"]]
    assert modes == [(0.0, "POSCTL"), (2.5, "TAKEOFF"), (5.5, "OFFBOARD"), (14.5, "LAND")]
    assert m["modes"]["mode_changes"] == 3
    assert [(e["event"], round(e["t_s"], 4)) for e in m["arm_events"]] == [("arm", 2.5), ("disarm", 17.5)]
    assert m["initially_armed"] is False
    assert m["offboard"]["offboard_time_s"] == pytest.approx(14.5 - 5.5)


def test_synthetic_flight_setpoints_and_tracking(flight, flight_path):
    off = analyse_tlog(flight_path).metrics["offboard"]
    sp = off["setpoints"]
    t_sp = [t for t, _, _ in flight.setpoints]
    assert sp["count"] == len(flight.setpoints) == 194
    assert sp["rate_hz"] == pytest.approx((len(t_sp) - 1) / ((t_sp[-1] - t_sp[0]) / 1e6))
    assert sp["longest_gap_s"] == pytest.approx(0.35, abs=1e-6)
    assert sp["gaps_over_px4_timeout"] == 0
    assert sp["position_controlled"] == sum(1 for _, mask, _ in flight.setpoints if mask == POS_ONLY)
    errs = expected_tracking(flight, flight.positions)
    te = off["tracking_error"]
    assert te["n_samples"] == len(errs)
    assert te["mean_m"] == pytest.approx(np.mean(errs), rel=1e-5)
    assert te["max_m"] == pytest.approx(max(errs), rel=1e-5)
    assert te["rms_m"] == pytest.approx(float(np.sqrt(np.mean(np.square(errs)))), rel=1e-5)
    in_off = [(t, p) for t, p in flight.positions if 5.5 <= (t - T0_US) / 1e6 < 14.5]
    assert off["tracking_error_offboard"]["mean_m"] == pytest.approx(np.mean(expected_tracking(flight, in_off)),
                                                                     rel=1e-5)
    truth = off["truth"]
    assert truth["source"] == "ATT_POS_MOCAP from 1:197" and truth["samples"] == len(flight.truth)
    terr = expected_tracking(flight, flight.truth)
    assert truth["tracking_error"]["mean_m"] == pytest.approx(np.mean(terr), rel=1e-5)
    assert 0.01 < truth["estimate_error"]["mean_m"] < 0.08  # truth = estimate + N(0, 0.02) per axis


def test_log_written_by_pymavlink_setup_logfile(tmp_path):
    """A tlog written by pymavlink's own logger (mavfile.setup_logfile) on a TCP loopback link."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    rx = mavutil.mavlink_connection(f"tcpin:127.0.0.1:{port}", source_system=255, dialect="common")
    tx = mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", source_system=1, source_component=1,
                                    dialect="common")
    path = tmp_path / "loop.tlog"
    rx.setup_logfile(str(path))
    sent = 0
    try:
        for i in range(300):
            if i % 50 == 0:
                tx.mav.heartbeat_send(mav2.MAV_TYPE_QUADROTOR, mav2.MAV_AUTOPILOT_PX4, 129 if i else 1,
                                      PX4_OFFBOARD if i else PX4_POSCTL, 4)
                sent += 1
            tx.mav.set_position_target_local_ned_send(i, 1, 1, 1, POS_ONLY, 0.01 * i, 0, -1.5, *[0] * 8)
            tx.mav.local_position_ned_send(i, 0.01 * i - 0.02, 0, -1.5, 0, 0, 0)
            sent += 2
        got = 0
        while got < sent and rx.recv_match(blocking=True, timeout=5) is not None:
            got += 1
    finally:
        rx.logfile.close()
        tx.close()
        rx.close()
    assert got == sent
    m = analyse_tlog(path).metrics
    assert m["messages"]["total"] == sent and m["offboard"]["setpoints"]["count"] == 300
    assert [e["mode"] for e in m["modes"]["timeline"]] == ["POSCTL", "OFFBOARD"]
    assert m["arm_events"][0]["event"] == "arm"
    te = m["offboard"]["tracking_error"]  # each sample logged right after its own setpoint
    assert te["n_samples"] == 300 and te["max_m"] == pytest.approx(0.02, abs=1e-5)


def test_flowgap_truth_odometry_on_its_own_channel(tmp_path):
    """flowgap's vehicle sends truth as ODOMETRY (LOCAL_NED, estimator MOCAP) with the autopilot's own ids
    on a separate link: it is found as truth, and its separate sequence counter is not packet loss."""
    main_ch = mav2.MAVLink(None, srcSystem=1, srcComponent=1)
    truth_ch = mav2.MAVLink(None, srcSystem=1, srcComponent=1)
    comp = mav2.MAVLink(None, srcSystem=1, srcComponent=191)
    recs = []
    nan21 = [float("nan")] + [0.0] * 20

    def put(mav, t_s, msg):
        recs.append(struct.pack(">Q", T0_US + round(t_s * 1e6)) + bytes(msg.pack(mav)))
        mav.seq = (mav.seq + 1) % 256

    for i in range(1000):  # 10 s at 100 Hz
        t = i * 0.01
        x = 0.1 * t
        if i % 100 == 0:
            put(main_ch, t, mav2.MAVLink_heartbeat_message(2, 12, 129, PX4_OFFBOARD, 4, 3))
        if i % 5 == 0:
            put(comp, t + 0.0001, mav2.MAVLink_set_position_target_local_ned_message(
                int(t * 1000), 1, 1, 1, POS_ONLY, x + 0.05, 0, -1.5, *[0] * 8))
        if i % 2 == 0:
            put(main_ch, t + 0.0002, mav2.MAVLink_local_position_ned_message(int(t * 1000), x + 0.01, 0, -1.5,
                                                                            0.1, 0, 0))
            # the autopilot's own odometry (an estimate, not truth)
            put(main_ch, t + 0.0003, mav2.MAVLink_odometry_message(int(t * 1e6), 1, 1, x + 5, 0, -1.5,
                                                                  [1, 0, 0, 0], 0, 0, 0, 0, 0, 0, nan21, nan21,
                                                                  0, mav2.MAV_ESTIMATOR_TYPE_NAIVE, 50))
        put(truth_ch, t + 0.0004, mav2.MAVLink_odometry_message(int(t * 1e6), 1, 1, x, 0, -1.5, [1, 0, 0, 0],
                                                               0.1, 0, 0, 0, 0, 0, nan21, nan21, 0,
                                                               mav2.MAV_ESTIMATOR_TYPE_MOCAP, 100))
    path = tmp_path / "flowgap_like.tlog"
    path.write_bytes(b"".join(recs))
    rep = analyse_tlog(path)
    m = rep.metrics
    assert m["components"]["1:1"]["lost"] == 0 and m["components"]["1:1"]["sequence_counters"] == 2
    assert any("interleaved sequence counters" in n for n in rep.notes)
    truth = m["offboard"]["truth"]
    assert truth["source"] == "ODOMETRY from 1:1" and truth["samples"] == 1000
    assert truth["estimate_error"]["max_m"] == pytest.approx(0.01, abs=1e-4)
    assert truth["tracking_error"]["mean_m"] == pytest.approx(0.05, abs=0.01)


def test_split_sequence_loss():
    from tools.tlog.analysis import split_sequence_loss

    a = list(range(250, 256)) + list(range(0, 40))
    b = list(range(100, 146))
    inter = [x for pair in zip(a, b, strict=True) for x in pair]
    assert split_sequence_loss(inter) == (0, 2)
    inter.pop(10)  # lose one packet of counter a
    assert split_sequence_loss(inter) == (1, 2)
    assert split_sequence_loss([0, 100, 200, 50, 150], max_counters=2) is None


def test_ardupilot_copter_mavlink1_guided(tmp_path):
    """An ArduCopter log in MAVLink 1: mode names from pymavlink's ArduPilot table, GUIDED counts as offboard."""
    veh = mav1.MAVLink(None, srcSystem=7, srcComponent=1)
    out = bytearray()
    modes = [0, 0, 4, 4, 4, 4, 9, 9]  # STABILIZE, GUIDED, LAND
    for k, mode in enumerate(modes):
        base = mav1.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (mav1.MAV_MODE_FLAG_SAFETY_ARMED if 0 < k < 7 else 0)
        msg = mav1.MAVLink_heartbeat_message(mav1.MAV_TYPE_QUADROTOR, mav1.MAV_AUTOPILOT_ARDUPILOTMEGA, base,
                                             mode, 4, 3)
        out += struct.pack(">Q", T0_US + k * 1_000_000) + msg.pack(veh)
        veh.seq += 1
    path = tmp_path / "copter.tlog"
    path.write_bytes(bytes(out))
    m = analyse_tlog(path).metrics
    assert m["vehicle"]["autopilot"] == "ArduPilot" and m["vehicle"]["type"] == "quadrotor"
    assert m["framing"]["mavlink1"] == len(modes) and m["framing"]["mavlink2"] == 0
    assert [(e["mode"], e["t_s"]) for e in m["modes"]["timeline"]] == [("STABILIZE", 0.0), ("GUIDED", 2.0),
                                                                       ("LAND", 6.0)]
    assert [(e["event"], e["t_s"]) for e in m["arm_events"]] == [("arm", 1.0), ("disarm", 7.0)]
    assert m["offboard"]["offboard_time_s"] == pytest.approx(4.0)
    assert m["offboard"]["setpoints"]["count"] == 0


def test_latest_before_ties_follow_file_order():
    from tools.tlog.truth import latest_before

    t_sp, i_sp = np.array([10, 20, 20, 30]), np.array([0, 2, 5, 7])
    t_pos, i_pos = np.array([5, 20, 20, 25, 40]), np.array([1, 3, 6, 4, 9])
    assert latest_before(t_pos, t_sp, i_pos, i_sp).tolist() == [-1, 1, 2, 2, 3]
    assert latest_before(t_pos, t_sp).tolist() == [-1, 2, 2, 2, 3]


def test_truth_option_none_and_absent(flight_path, tmp_path):
    assert analyse_tlog(flight_path, truth="none").metrics["offboard"]["truth"]["source"].startswith("disabled")
    no_truth = tmp_path / "nt.tlog"
    no_truth.write_bytes(synthetic_flight(with_truth=False).tlog())
    assert analyse_tlog(no_truth).metrics["offboard"]["truth"]["source"] == "none found"


def test_framing_crc_and_decoding_match_pymavlink():
    """The vectorised CRC and numpy payload decoding agree with pymavlink's own on real packets."""
    if not ARDUSUB.exists():
        pytest.skip(f"third-party test log not found at {ARDUSUB}")
    mav_mod = load_dialect()
    raw = ARDUSUB.read_bytes()
    f = scan_tlog(raw, mav_mod)
    mav = mav_mod.MAVLink(None)
    rng = np.random.default_rng(1)
    for i in rng.choice(len(f), 300, replace=False).tolist() + np.flatnonzero(~f.crc_ok).tolist():
        pkt = f.packet_bytes(i)
        try:
            mav.decode(bytearray(pkt))
            ok = True
        except Exception:  # noqa: BLE001
            ok = False
        assert ok == bool(f.crc_ok[i]), i
        extra = mav_mod.mavlink_map[int(f.msgid[i])].crc_extra
        body = pkt[1:10 + pkt[1]]
        assert (crc_x25(bytes(body) + bytes([extra])) == (pkt[10 + pkt[1]] | pkt[11 + pkt[1]] << 8)) == ok
    idx = np.flatnonzero((f.msgid == 32) & f.good)[:50]
    rows = decode_columns(f, mav_mod, 32, idx)
    for i, row in zip(idx.tolist(), rows, strict=True):
        ref = mav.decode(f.packet_bytes(i))
        assert row["time_boot_ms"] == ref.time_boot_ms and row["x"] == pytest.approx(ref.x, rel=1e-7)


def test_garbage_truncation_and_unknown_ids(flight, tmp_path):
    recs = sorted(flight.records, key=lambda r: r[0])
    rng = np.random.default_rng(7)
    out = bytearray()
    garbage_at = set(rng.choice(len(recs) - 1, 12, replace=False).tolist()) | {0}  # also right after the 1st
    injected = 0
    for k, (t, pkt, _) in enumerate(recs):
        out += struct.pack(">Q", t) + pkt
        if k in garbage_at:
            g = rng.integers(0, 256, int(rng.integers(1, 60)), dtype=np.uint8).tobytes()
            if k % 3 == 0:
                g = b"\xfd" + g  # a fake start-of-packet byte
            out += g
            injected += len(g)
    # a well-framed packet with a message id no dialect knows
    unknown = bytes([0xFD, 3, 0, 0, 0, 1, 1, 0xDE, 0xBC, 0x0A, 1, 2, 3, 0x12, 0x34])
    out += struct.pack(">Q", recs[-1][0] + 10) + unknown
    last = struct.pack(">Q", recs[-1][0] + 20) + recs[0][1]  # a HEARTBEAT, cut in half
    out += last[: len(last) // 2 + 3]
    path = tmp_path / "damaged.tlog"
    path.write_bytes(bytes(out))
    rep = analyse_tlog(path)
    assert rep.usable
    by_type = {k: v["count"] for k, v in rep.metrics["messages"]["by_type"].items()}
    assert by_type == flight.counts()
    fr = rep.metrics["framing"]
    assert fr["garbage_bytes"] == injected and fr["garbage_runs"] == len(garbage_at)
    assert fr["unknown_ids"] == {str(0x0ABCDE): 1}
    assert fr["truncated_tail_bytes"] == len(last) // 2 + 3
    text = " | ".join(rep.notes)
    assert "non-MAVLink" in text and "truncated" in text and "unknown" in text
    assert rep.metrics["offboard"]["setpoints"]["count"] == len(flight.setpoints)


def test_no_position_messages(tmp_path):
    path = tmp_path / "nopos.tlog"
    path.write_bytes(synthetic_flight(with_truth=False, with_positions=False).tlog())
    rep = analyse_tlog(path)
    assert rep.usable and rep.metrics["offboard"]["tracking_error"] is None
    assert any("no LOCAL_POSITION_NED" in n for n in rep.notes)
    assert rep.metrics["offboard"]["setpoints"]["count"] == 194


def test_an_unforeseen_failure_in_one_stage_keeps_the_rest(flight_path, tmp_path, monkeypatch):
    import tools.tlog.analysis as analysis
    from tools.tlog import summary_text

    def boom(*args, **kwargs):
        raise RuntimeError("unforeseen")

    monkeypatch.setattr(analysis, "_events", boom)
    rep = analyse_tlog(flight_path)
    assert rep.usable and any("events analysis failed" in n and "unforeseen" in n for n in rep.notes)
    assert rep.metrics["messages"]["total"] > 0 and rep.metrics["modes"]["timeline"] == []
    assert rep.metrics["offboard"]["setpoints"]["count"] == 194 and len(rep.notes) == 1
    write_outputs(rep, tmp_path, plots=False)
    assert "unforeseen" in (tmp_path / "report.md").read_text() and summary_text(rep)


def test_empty_and_not_a_tlog(tmp_path, capsys):
    empty = tmp_path / "empty.tlog"
    empty.write_bytes(b"")
    rep = analyse_tlog(empty)
    assert not rep.usable and any("empty" in n for n in rep.notes)
    text = tmp_path / "notes.txt"
    text.write_bytes(b"this is not a telemetry log\n" * 400 + bytes(range(256)) * 20)
    rep = analyse_tlog(text)
    assert not rep.usable and any("not a tlog" in n for n in rep.notes)
    assert main([str(empty), "--out", str(tmp_path / "o"), "--no-plots"]) == 1
    metrics = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert metrics["usable"] is False and metrics["notes"]
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "empty" in err[0]


def test_cli_missing_file_and_replay(tmp_path, capsys):
    assert main([str(tmp_path / "nope.tlog")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no such file" in err[0]
    assert main(["replay", str(tmp_path)]) == 2  # a directory that is not a companion run
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "summary.json is missing" in err[0]


def test_cli_outputs(flight_path, tmp_path, capsys):
    out = tmp_path / "report"
    assert main([str(flight_path), "--out", str(out), "--csv", "--scene", "no_such_scene_xyz", "-q"]) == 0
    stdout = capsys.readouterr().out
    assert "PX4 quadrotor" in stdout and "setpoints: 194" in stdout
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["offboard"]["setpoints"]["count"] == 194
    assert any("--scene no_such_scene_xyz" in n for n in metrics["notes"])
    md = (out / "report.md").read_text()
    for png in ("trajectory.png", "altitude_speed.png", "tracking_error.png", "modes.png"):
        assert (out / png).stat().st_size > 1000 and f"]({png})" in md
    csv_lines = (out / "csv" / "SET_POSITION_TARGET_LOCAL_NED.csv").read_text().splitlines()
    assert len(csv_lines) == 195 and csv_lines[0].startswith("time_unix_s,t_s,sysid,compid,time_boot_ms")
    assert (out / "csv" / "STATUSTEXT.csv").read_text().count("synthetic PX4 ready") == 1


def test_scene_drawing_with_a_spec(flight_path, tmp_path):
    from types import SimpleNamespace

    from tools.tlog.plots import make_plots, scene_geometry, wall_crossings

    opening = SimpleNamespace(polygon=lambda: [(-0.45, -1.95), (0.45, -1.95), (0.45, -1.05), (-0.45, -1.05)])
    spec = SimpleNamespace(wall_x=3.0, wall_back_x=3.15, wall=SimpleNamespace(width=7.0, height=4.0, center_y=0.0),
                           openings=(opening,))
    geo = scene_geometry(spec)
    assert geo["wall_x"] == 3.0 and geo["openings"][0].shape == (4, 2)
    rep = analyse_tlog(flight_path)
    written = make_plots(rep, tmp_path, geo)
    assert "wall_plane" in written and (tmp_path / "trajectory.png").exists()
    # a straight pass through the opening and one beside it
    t = np.array([0.0, 1.0, 2.0, 3.0])
    through = wall_crossings(t, np.array([[2.0, 0, -1.5], [2.8, 0.1, -1.5], [3.2, 0.1, -1.5], [4, 0, -1.5]]), geo)
    assert len(through) == 1 and through[0]["through_opening"] and through[0]["t_s"] == pytest.approx(1.5)
    beside = wall_crossings(t, np.array([[2.0, 1, -1.5], [2.8, 1, -1.5], [3.2, 1, -1.5], [4, 1, -1.5]]), geo)
    assert len(beside) == 1 and not beside[0]["through_opening"]


def test_scene_from_the_scenes_package(flight_path, tmp_path):
    """--scene with the real scenes package when it is there; a one-line note when it is not."""
    from tools.tlog.plots import load_scene_geometry

    geo, note = load_scene_geometry("window1_brick")
    if geo is None:
        assert note.startswith("--scene window1_brick") and "\n" not in note
        return
    assert geo["openings"] and 0 < geo["wall_x"] < 20
    out = tmp_path / "r"
    assert main([str(flight_path), "--out", str(out), "--no-plots", "--scene", "window1_brick", "-q"]) == 0
    sc = json.loads((out / "metrics.json").read_text())["scene"]
    assert sc["name"] == "window1_brick" and "estimate_wall_crossings" in sc


def test_ardusub_third_party_log(tmp_path):
    if not ARDUSUB.exists():
        pytest.skip(f"third-party test log not found at {ARDUSUB}")
    rep = analyse_tlog(ARDUSUB)
    m = rep.metrics
    assert rep.usable
    assert m["vehicle"]["autopilot"] == "ArduPilot" and m["vehicle"]["type"] == "submarine"
    assert m["vehicle"]["sysid"] == 1 and m["vehicle"]["compid"] == 1
    assert len(m["components"]) >= 5 and m["systems"] == [1, 255]
    assert m["offboard"]["setpoints"]["count"] == 0 and m["offboard"]["tracking_error"] is None
    assert m["framing"]["crc_failures"] == 4
    assert any("failed the CRC check" in n for n in rep.notes)
    assert m["messages"]["total"] == 35912 and m["messages"]["types"] == 46
    assert m["messages"]["by_type"]["ATTITUDE"]["count"] == 5245
    assert m["modes"]["timeline"][0]["mode"] == "MANUAL"
    assert [e["event"] for e in m["arm_events"]] == ["arm", "disarm"]
    assert m["statustext"][0]["text"].startswith("ArduSub V4.1.1")
    assert m["duration_s"] == pytest.approx(263.43, abs=0.01)
    written = write_outputs(rep, tmp_path, plots=False)
    assert json.loads((tmp_path / "metrics.json").read_text())["vehicle"]["type"] == "submarine"
    assert written["plots"] == {}


def test_replay_uses_the_detector_each_frame_was_flown_with(tmp_path, monkeypatch):
    """A blind look's frames (decisions.jsonl's past_the_end) are replayed with the blind detector, the others with
    the flight's own."""
    import companion.gap as gap
    from tools.tlog.replay import replay

    used = []

    def detector(name):
        def detect(flow, textured=None):
            used.append(name)
            return gap.detect_gap_parallax(flow)
        return detect

    monkeypatch.setattr(gap, "get_detector", lambda _name: detector("plain"))
    monkeypatch.setattr(gap, "blind_detector", lambda _name: detector("blind"))
    (tmp_path / "summary.json").write_text(json.dumps({"scene": "window1_brick", "flow": "dis:fast",
                                                       "detector": "parallax"}))
    level = [1.0, 0.0, 0.0, 0.0]
    frames = [{"step": n, "time_s": float(n), "position_true": [0.2 * n, 0.0, -1.5], "attitude_true": level,
               "position_est": [0.2 * n, 0.0, -1.5], "attitude_est": [0.0, 0.0, 0.0]} for n in range(4)]
    (tmp_path / "frames.jsonl").write_text("".join(json.dumps(f) + "\n" for f in frames))
    decisions = [{"step": n, "centroid_used": None, "past_the_end": n == 3} for n in (1, 2, 3)]
    (tmp_path / "decisions.jsonl").write_text("".join(json.dumps(d) + "\n" for d in decisions))
    result = replay(tmp_path)
    assert result["steps"] == 3 and used == ["plain", "plain", "blind"]


def test_replay_pairs_no_frame_with_a_looks_first_frame(tmp_path, monkeypatch):
    """A frame without a decision line is a look's first frame (a search's, or the servo's again after the thickness
    look): the pair ending on it is not replayed, the next pair starts from it."""
    import companion.perception as perception
    from tools.tlog.replay import replay

    pairs = []
    real = perception.perceive

    def perceive(prev, rgb, *args, **kwargs):
        pairs.append((float(prev.mean()), float(rgb.mean())))
        return real(prev, rgb, *args, **kwargs)

    monkeypatch.setattr(perception, "perceive", perceive)
    (tmp_path / "summary.json").write_text(json.dumps({"scene": "window1_brick", "flow": "dis:fast",
                                                       "detector": "parallax"}))
    level = [1.0, 0.0, 0.0, 0.0]
    frames = [{"step": n, "time_s": float(n), "position_true": [0.2 * n, 0.1 * (n == 3), -1.5],
               "attitude_true": level, "position_est": [0.2 * n, 0.0, -1.5], "attitude_est": [0.0, 0.0, 0.0]}
              for n in range(5)]
    (tmp_path / "frames.jsonl").write_text("".join(json.dumps(f) + "\n" for f in frames))
    decisions = [{"step": n, "centroid_used": None} for n in (1, 2, 4)]
    (tmp_path / "decisions.jsonl").write_text("".join(json.dumps(d) + "\n" for d in decisions))
    result = replay(tmp_path)
    assert result["steps"] == 3 and [r["step"] for r in result["rows"]] == [1, 2, 4]
    assert len(pairs) == 3 and pairs[1][1] != pairs[2][0]      # step 3's frame opens the last pair, not step 2's


def test_replay_reads_the_edges_as_flown_unless_told_otherwise(tmp_path, monkeypatch):
    """``--edges``: the flight's edge reading by default (the detector's masks for a run from before the option),
    the one asked for otherwise; the result and its summary say which."""
    import companion.perception as perception
    from tools.tlog.replay import describe, replay

    given = []
    real = perception.perceive

    def perceive(*args, edges=None, **kwargs):
        given.append(edges)
        return real(*args, edges=edges, **kwargs)

    monkeypatch.setattr(perception, "perceive", perceive)
    summary = {"scene": "window1_brick", "flow": "dis:fast", "detector": "parallax"}
    level = [1.0, 0.0, 0.0, 0.0]
    frames = [{"step": n, "time_s": float(n), "position_true": [1.0 + 0.2 * n, 0.0, -1.5], "attitude_true": level,
               "position_est": [1.0 + 0.2 * n, 0.0, -1.5], "attitude_est": [0.0, 0.0, 0.0]} for n in range(2)]
    (tmp_path / "frames.jsonl").write_text("".join(json.dumps(f) + "\n" for f in frames))
    (tmp_path / "decisions.jsonl").write_text(json.dumps({"step": 1, "centroid_used": None}) + "\n")
    (tmp_path / "summary.json").write_text(json.dumps(summary))
    old = replay(tmp_path)
    (tmp_path / "summary.json").write_text(json.dumps({**summary, "edges": "photo"}))
    flown = replay(tmp_path)
    asked = replay(tmp_path, edges="flow")
    assert given == [None, DEFAULT_EDGES, None]
    assert old["flown"]["edges"] == "flow" and flown["replay"]["edges"] == "photo"
    assert asked["flown"]["edges"] == "photo" and asked["replay"]["edges"] == "flow"
    assert "(edges photo), replayed with dis:fast + parallax (edges flow)" in describe(asked)
    assert flown["rows"][0]["replay_clear_radius_px"] > 10          # the suite's opening, seen from 2 m

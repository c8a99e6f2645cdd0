"""The companion's pymavlink link against the SITL vehicle: commands, offboard streaming, link loss."""

from __future__ import annotations

import logging
import math
import time

import pytest

from companion.link import LinkError, LinkLost, make_link, parse_endpoint
from tools.tlog import analyse_tlog


@pytest.mark.parametrize("url, mavutil_str", [
    ("udpin://:14540", "udpin:0.0.0.0:14540"),
    ("udpout://10.0.0.2:14550", "udpout:10.0.0.2:14550"),
    ("tcp://127.0.0.1:5760", "tcp:127.0.0.1:5760"),
    ("serial:///dev/ttyUSB0:921600", "/dev/ttyUSB0"),
])
def test_endpoint_urls(url, mavutil_str):
    assert parse_endpoint(url).mavutil == mavutil_str


@pytest.mark.parametrize("url", ["14540", "udp://:14540", "udpin://:", "serial:///dev/ttyUSB0"])
def test_bad_endpoint_urls_name_the_fix(url):
    with pytest.raises(ValueError, match="e.g."):
        parse_endpoint(url)


@pytest.mark.parametrize("text", ["short", "y" * 50, "x" * 120 + " end", "z" * 100])
def test_statustext_chunks_reassemble_as_the_vehicle_sends_them(text):
    from companion.link.base import StatusTextAssembler
    from sitl_vehicle.mavlink_io import statustext_messages

    def wire(msg):  # the text as a receiver decodes it: bytes up to the first NUL
        raw = msg.text if isinstance(msg.text, bytes) else msg.text.encode()
        return raw.split(b"\0", 1)[0].decode()

    texts = StatusTextAssembler()
    other = statustext_messages(6, "w" * 70, 8)             # another long text interleaved with this one
    mine = statustext_messages(6, text, 7)
    out = [texts.add(m.id, m.chunk_seq, wire(m)) for m in [other[0], *mine, other[1]]]
    assert [t for t in out if t is not None] == [text, "w" * 70]
    assert out[-1] == "w" * 70 and out[len(mine)] == text and all(t is None for t in out[1:len(mine)])


def test_statustext_assembler_restarts_an_id_and_bounds_what_it_keeps():
    from companion.link.base import StatusTextAssembler

    texts = StatusTextAssembler(max_pending=2)
    assert texts.add(5, 0, "a" * 50) is None
    assert texts.add(5, 0, "b" * 50) is None                # chunk 0 again: the earlier text was cut off
    assert texts.add(5, 1, "end") == "b" * 50 + "end"
    for text_id in (1, 2, 3):
        texts.add(text_id, 0, "c" * 50)                      # never finished
    assert texts.add(1, 1, "tail") == "tail"                # id 1 was dropped as the oldest
    assert texts.add(3, 1, "tail") == "c" * 50 + "tail"


def test_fly_with_the_link_and_keep_streaming_while_busy(vehicle_for_link, tmp_path):
    server, port, _ = vehicle_for_link()
    link = make_link(f"udpin://127.0.0.1:{port}", tlog_path=tmp_path / "link.tlog")
    try:
        link.connect(timeout_s=10)
        assert link.telemetry.autopilot == "px4"
        link.wait_for(lambda t: t.home is not None and t.position is not None, 5, "home and position")
        link.arm()
        link.takeoff(1.2)
        link.wait_for(lambda t: abs(t.position[2] + 1.2) < 0.05, 15, "takeoff altitude")
        link.start_offboard((0.0, 0.0, -1.2), 0.0)
        link.wait_for(lambda t: t.mode == "OFFBOARD", 3, "offboard mode")
        link.set_position_target((0.6, 0.3, -1.2), 0.0)
        # Perception hogging the interpreter for a while must not starve the setpoint stream.
        start = time.monotonic()
        busy = 0
        while time.monotonic() - start < 1.5:
            busy += sum(i * i for i in range(2000))
        sent = [t for t in link.setpoint_times if t >= start]
        gaps = [b - a for a, b in zip(sent, sent[1:], strict=False)]
        # starved, the 1.5 s spell would be one gap; PX4 needs 2 Hz at least.  Four 20 Hz periods leave room for
        # a busy 2-core machine's scheduling (0.106 s was seen once beside nothing else, 2026-12-06)
        assert len(sent) >= 15 and max(gaps) < 0.2, f"setpoint stream stalled: max gap {max(gaps):.3f} s"
        assert link.wait_position((0.6, 0.3, -1.2), 0.05, 10)
        with pytest.raises(LinkError, match="refused"):
            link.command(4242)  # unsupported: the error names the result
        link.land()
        link.wait_for(lambda t: not t.armed, 30, "landing and disarm")
    finally:
        link.close()
    # The link's .tlog of this real loopback flight, read back by flowgap-tlog's analyser.
    report = analyse_tlog(tmp_path / "link.tlog")
    m = report.metrics
    sent = len(link.setpoint_times)
    assert sent > 40 and m["offboard"]["setpoints"]["count"] == sent
    assert 15.0 <= m["offboard"]["setpoints"]["rate_hz"] <= 25.0
    modes = [entry["mode"] for entry in m["modes"]["timeline"]]
    assert modes[:4] == ["LOITER", "TAKEOFF", "LOITER", "OFFBOARD"] and modes[-1] == "LAND"
    assert [e["event"] for e in m["arm_events"]] == ["arm", "disarm"]


def test_vehicle_disappearing_is_a_clear_link_loss(vehicle_for_link):
    server, port, _ = vehicle_for_link()
    link = make_link(f"udpin://127.0.0.1:{port}")
    try:
        link.connect(timeout_s=10)
        server.stop()
        with pytest.raises(LinkLost, match="link lost"):
            link.wait_for(lambda t: False, 10, "something that never happens")
    finally:
        link.close()


def test_refusal_carries_the_autopilots_reason(vehicle_for_link):
    _, port, _ = vehicle_for_link()
    link = make_link(f"udpin://127.0.0.1:{port}")
    try:
        link.connect(timeout_s=10)
        with pytest.raises(LinkError, match="not possible: no setpoint stream"):
            link.set_mode("OFFBOARD")
        assert math.isinf(-link.telemetry.position_time) is False
    finally:
        link.close()


def test_mavsdk_backend_flies_through_the_same_interface(vehicle_for_link, capfd, caplog):
    pytest.importorskip("mavsdk")
    caplog.set_level(logging.DEBUG, logger="mavsdk")
    _, port, _ = vehicle_for_link()
    link = make_link(f"udpin://127.0.0.1:{port}", backend="mavsdk")
    try:
        link.connect(timeout_s=15)
        assert link.telemetry.autopilot == "px4"
        link.wait_for(lambda t: t.home is not None and t.position is not None and t.landed, 10,
                      "home, position and landed state")
        link.arm()
        link.takeoff(1.2)
        link.wait_for(lambda t: abs(t.position[2] + 1.2) < 0.05, 15, "takeoff altitude")
        link.start_offboard((0.0, 0.0, -1.2), 0.0)
        link.wait_for(lambda t: t.mode == "OFFBOARD", 5, "offboard mode")
        link.set_position_target((0.5, -0.3, -1.2), 0.0)
        assert link.wait_position((0.5, -0.3, -1.2), 0.05, 10)
        assert len(link.telemetry.attitude_history) > 10  # time-stamped attitude for derotation
        link.land()
        link.wait_for(lambda t: not t.armed, 30, "landing and disarm")
    finally:
        link.close()
    # MAVSDK's own log lines go to the "mavsdk" logger, not straight to the terminal
    assert any(r.name == "mavsdk" for r in caplog.records)
    assert "mavsdk_impl" not in capfd.readouterr().out

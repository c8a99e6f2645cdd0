"""The flowgap-vehicle process: --help, clean exit on signals with a verdict file, one-line errors."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import time

import pytest
from pymavlink import mavutil

from sitl_vehicle.__main__ import main as vehicle_main

VEHICLE = [sys.executable, "-m", "sitl_vehicle"]
EPHEMERAL = ["--gcs-local", "127.0.0.1:0", "--api-local", "127.0.0.1:0"]


def test_help_reads_well():
    out = subprocess.run(VEHICLE + ["--help"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0
    for fragment in ("flowgap-vehicle", "--speed", "--scene", "--result", "14540", "MIS_TAKEOFF_ALT"):
        assert fragment in out.stdout


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_process_streams_and_exits_cleanly_on_signal(tmp_path, sig):
    listener = mavutil.mavlink_connection("udpin:127.0.0.1:0", dialect="common")
    port = listener.port.getsockname()[1]
    result = tmp_path / "verdict.json"
    proc = subprocess.Popen(VEHICLE + EPHEMERAL + ["--api-remote", f"127.0.0.1:{port}", "--no-noise",
                                                   "--result", str(result)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        hb = listener.wait_heartbeat(timeout=30)
        assert hb is not None and hb.autopilot == 12  # MAV_AUTOPILOT_PX4
        # Let simulation time pass: telemetry is streaming from the running loop.
        assert listener.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=10,
                                   condition="LOCAL_POSITION_NED.time_boot_ms > 300") is not None
        proc.send_signal(sig)
        assert proc.wait(timeout=10) == 0
    finally:
        proc.kill()
        listener.close()
    stderr = proc.stderr.read()
    assert "Traceback" not in stderr
    verdict = json.loads(result.read_text())
    assert verdict["collision"] is False and verdict["crossed_wall"] is False and verdict["sim_time_s"] > 0
    assert {"min_clearance_m", "sim_time_s", "success"} <= set(verdict)


def test_port_in_use_is_a_one_line_error(capsys):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as busy:
        busy.bind(("127.0.0.1", 0))
        port = busy.getsockname()[1]
        code = vehicle_main(["--gcs-local", "127.0.0.1:0", "--api-local", f"127.0.0.1:{port}"])
    assert code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "already in use" in lines[0] and str(port) in lines[0]


@pytest.mark.parametrize("args, fragment", [
    (["--speed", "-1"], "--speed"),
    (["--param", "NOT_A_PARAM=1"], "unknown parameter"),
    (["--param", "MIS_TAKEOFF_ALT=-3"], "outside"),
    (["--start", "1,2"], "three comma-separated"),
])
def test_bad_arguments_are_one_line_errors(args, fragment, capsys):
    try:
        code = vehicle_main(EPHEMERAL + args)
    except SystemExit as exc:  # argparse's own usage errors
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err and fragment in err


def test_duration_runs_to_the_end_without_a_client(tmp_path):
    result = tmp_path / "v.json"
    t0 = time.monotonic()
    out = subprocess.run(VEHICLE + EPHEMERAL + ["--speed", "10", "--duration", "2", "--result", str(result)],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert json.loads(result.read_text())["sim_time_s"] == pytest.approx(2.0, abs=0.01)
    assert time.monotonic() - t0 < 30

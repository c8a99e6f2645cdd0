"""The Rerun recording of a flight (companion.recording): what it holds, read back with the Rerun SDK, and the
one-line error without the ``viz`` extra."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from companion.link.base import TelemetryCache
from companion.recording import RecordingError, open_recording, recorded_entities, require_rerun
from scenes.spec import SceneSpec


def test_a_recording_holds_frames_trajectories_setpoints_and_time_series(tmp_path):
    path = tmp_path / "flight.rrd"
    recording = open_recording(path, truth=lambda: (0.0, (0.1, 0.0, -1.5), (1.0, 0.0, 0.0, 0.0)))
    recording.scene(SceneSpec())
    recording.camera(np.array([[200.0, 0, 160], [0, 200.0, 120], [0, 0, 1]]), 320, 240)
    for i in range(100):                      # 2 s of 50 Hz telemetry: kept at 10 Hz
        t = 1.0 + i * 0.02
        recording.telemetry(t, position=(0.01 * i, 0.0, -1.5))
        recording.telemetry(t, attitude=(0.0, 0.01, 0.0))
    rgb = np.zeros((240, 320, 3), np.uint8)
    mask = np.zeros((240, 320), bool)
    mask[100:140, 140:180] = True
    for step in range(3):
        recording.frame(step, 1.0 + step, rgb, rgb, mask, (160.0, 120.0), (158.0, 121.0), (0.1 * step, 0, -1.5),
                        (1.0, 0.0, 0.0, 0.0), (0.01, -0.02), 2.0 - 0.2 * step, f"step {step}")
    for k in range(5):
        recording.setpoint((0.1 * k, 0.0, -1.5))
    recording.event("state: HOLD")
    recording.close()

    rows = recorded_entities(path)
    assert rows["/camera/frame"] == rows["/camera/flow"] == rows["/camera/mask"] == 3
    assert rows["/world/setpoints"] == 5
    assert 19 <= rows["/world/trajectory/estimated"] <= 21
    assert 19 <= rows["/plots/attitude/roll"] <= 21
    assert rows["/world/trajectory/true"] == rows["/world/trajectory/estimated"] + 3  # + one per frame
    assert rows["/plots/error/u"] == rows["/plots/wall_distance_m"] == 3
    for static in ("/world/scene/wall/front", "/world/scene/wall/back", "/world/scene/floor",
                   "/world/scene/background"):
        assert rows[static] == 1
    assert rows["/world/vehicle/camera"] == 2 + 3    # the mounting and the pinhole, then a frame per step


def test_without_the_viz_extra_every_rerun_option_is_one_line_naming_it(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "rerun", None)      # what `import rerun` does when it is not installed
    with pytest.raises(RecordingError, match=r"flowgap\[viz\]"):
        require_rerun()
    from companion.__main__ import main as companion
    from tools.launch import main as sitl
    from tools.tlog import main as tlog

    for run in (lambda: companion(["--rerun", "--run-dir", str(tmp_path / "c")]),
                lambda: sitl(["--rerun", "--run-dir", str(tmp_path / "s")]),
                lambda: tlog(["replay", str(tmp_path), "--rerun"])):
        assert run() == 2
        err = capsys.readouterr().err.strip()
        assert "\n" not in err and "flowgap[viz]" in err and "Traceback" not in err


def test_a_failing_telemetry_listener_never_stops_the_others():
    cache, seen = TelemetryCache(), []

    def broken(time_s, **values):
        raise RuntimeError("observer bug")

    cache.listeners += [broken, lambda time_s, **values: seen.append((time_s, values))]
    cache.notify(1.5, position=(1.0, 2.0, 3.0))
    assert seen == [(1.5, {"position": (1.0, 2.0, 3.0)})]


def _free_tcp_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_rerun_connect_streams_the_recording_live_to_a_running_viewer(tmp_path):
    """A headless viewer (``rerun --port P --save FILE``) receives what a connected recording logs."""
    import os
    import shutil
    import signal
    import socket
    import subprocess
    import time
    import warnings
    from pathlib import Path

    exe = shutil.which("rerun", path=str(Path(sys.executable).parent)) or shutil.which("rerun")
    if exe is None:
        pytest.skip("the rerun viewer binary is not installed beside the SDK")
    port, saved = _free_tcp_port(), tmp_path / "live.rrd"
    # its own process group: `rerun` is a Python wrapper around the viewer binary; Ctrl-C in a terminal reaches
    # both, and so does a SIGINT to the group
    viewer = subprocess.Popen([exe, "--port", str(port), "--save", str(saved)], stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 20
        while True:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=0.5).close()
                break
            except OSError:
                assert time.monotonic() < deadline, "the viewer never listened"
                time.sleep(0.1)
        recording = open_recording(connect=f"rerun+http://127.0.0.1:{port}/proxy")
        for step in range(3):
            recording.frame(step, float(step), np.zeros((24, 32, 3), np.uint8), None, None)
        recording.setpoint((1.0, 2.0, -1.5))
        recording.close()
        time.sleep(1.0)
    finally:
        os.killpg(viewer.pid, signal.SIGINT)           # the wrapper and the binary: the binary saves and exits
        try:
            viewer.wait(timeout=20)
        finally:
            if viewer.poll() is None:
                os.killpg(viewer.pid, signal.SIGKILL)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")      # a streamed .rrd has no footer: read by a whole-file scan
        rows = recorded_entities(saved)
    assert rows["/camera/frame"] == 3 and rows["/world/setpoints"] == 1

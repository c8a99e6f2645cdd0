"""Frame sources. ``FrameSource`` is what a real camera driver implements; ``SplatCamera`` is the simulated
one: it renders the scene's Gaussian splats at the vehicle's true pose, read from the vehicle's
simulation-only ground-truth stream (ODOMETRY), exactly as a real camera sees the true world while the
controller only knows the noisy estimate."""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from pymavlink import mavutil

from companion.link.base import parse_endpoint

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Frame:
    rgb: np.ndarray  # H×W×3 uint8
    position: tuple[float, float, float]  # NED m, body origin, at capture (truth in simulation)
    attitude: tuple[float, float, float, float]  # (w, x, y, z) body → NED
    time_s: float  # source time stamp (simulation seconds for the splat camera)
    capture_ms: float


class FrameSource(Protocol):
    width: int
    height: int
    K: np.ndarray  # 3×3 intrinsics (pixel centres at +0.5), for derotating flow

    def capture(self) -> Frame: ...

    def close(self) -> None: ...


class CameraError(RuntimeError):
    """No frame could be produced (for the splat camera: no pose from the truth stream)."""


class PoseSource(Protocol):
    """Where the simulated camera learns the vehicle's true pose: ``latest() -> (time s, position, (w,x,y,z))``."""

    def latest(self, timeout_s: float = 5.0) -> tuple[float, tuple, tuple]: ...

    def close(self) -> None: ...


class TruthPoseListener:
    """Keeps the latest true pose from the vehicle's ODOMETRY truth stream (simulation only), in a thread
    of its own (real time; in lockstep the clock reads the stream: :class:`companion.lockstep.LockstepChannel`)."""

    def __init__(self, url: str):
        endpoint = parse_endpoint(url)
        self._conn = mavutil.mavlink_connection(endpoint.mavutil, dialect="common")
        self._latest: tuple | None = None
        self._lockstep_seen = False
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="truth-rx", daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        while not self._stop.is_set():
            try:
                msg = self._conn.recv_match(type="ODOMETRY", blocking=True, timeout=0.1)
            except (OSError, ValueError):
                if self._stop.is_set():
                    return
                continue
            if msg is not None:
                with self._lock:
                    self._latest = (msg.time_usec * 1e-6, (msg.x, msg.y, msg.z), tuple(msg.q))
            elif not self._lockstep_seen:
                from companion.lockstep import is_lockstep

                word = self._conn.messages.get("DEBUG_VECT")
                self._lockstep_seen = word is not None and is_lockstep(word)

    def latest(self, timeout_s: float = 5.0) -> tuple[float, tuple, tuple]:
        deadline = time.monotonic() + timeout_s
        while True:
            with self._lock:
                if self._latest is not None:
                    return self._latest
            if time.monotonic() > deadline:
                if self._lockstep_seen:
                    raise CameraError("the vehicle runs in lockstep and waits for this companion: start it with "
                                      "--lockstep too")
                raise CameraError(f"no ground-truth pose received within {timeout_s:.0f} s: is the vehicle's "
                                  f"--truth-remote pointed at this companion's --truth address?")
            time.sleep(0.01)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2)
        self._conn.close()


class SplatCamera:
    """Renders ``scene`` at the true pose: the simulated forward camera (optical axis = body x).

    ``scene``: a suite name, spec ``.json``, capture scene ``.json`` (its ``.ply`` placed in NED) or ``.ply``.
    ``spec`` is the procedural scene's spec (None for a capture or a bare ``.ply``: no walls to draw), ``capture_spec``
    a capture's :class:`scenes.capture.CaptureSpec` (else None).
    ``truth``: the ground-truth stream's URL (listened to in a thread) or a :class:`PoseSource`.  ``delay_s``:
    each frame reaches the caller this long after its exposure, on ``clock`` (the companion's; a real camera's
    frames arrive late too), stamped with the exposure's time."""

    def __init__(self, scene: str, truth: str | PoseSource, backend: str = "cpu", camera=None, clock=None,
                 delay_s: float = 0.0):
        from scenes import PinholeCamera, load_scene
        from scenes.capture import CaptureSpec

        spec, self.cloud = load_scene(scene)
        self.capture_spec = spec if isinstance(spec, CaptureSpec) else None
        self.spec = None if self.capture_spec is not None else spec
        self.camera = camera or PinholeCamera()
        self.width, self.height = self.camera.width, self.camera.height
        self.K = self.camera.K
        self.backend = backend
        # Render once now: the first call compiles the renderer (seconds on a cold cache), which must not
        # happen in flight between a frame and the attitude samples it is matched with.
        from scenes import Pose, render_splats

        render_splats(self.cloud, self.camera, Pose((0.0, 0.0, -1.5), (1.0, 0.0, 0.0, 0.0)), backend=backend)
        self.poses = TruthPoseListener(truth) if isinstance(truth, str) else truth
        self.delay_s = float(delay_s)
        if self.delay_s > 0 and clock is None:
            raise ValueError("a camera delay needs the companion's clock to wait on")
        self.clock = clock

    def capture(self) -> Frame:
        from scenes import Pose, render_splats

        t0 = time.perf_counter()
        exposed = self.clock.now() if self.delay_s > 0 else 0.0
        stamp, position, attitude = self.poses.latest()
        result = render_splats(self.cloud, self.camera, Pose(position, attitude), backend=self.backend)
        capture_ms = (time.perf_counter() - t0) * 1000
        if self.delay_s > 0:
            self.clock.sleep_until(exposed + self.delay_s)
        return Frame(result.rgb, position, attitude, stamp, capture_ms)

    def close(self) -> None:
        self.poses.close()

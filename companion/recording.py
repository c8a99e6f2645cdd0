"""A flight as a Rerun recording (``flight.rrd``, or streamed live to a viewer): ``flowgap-companion --rerun``.

What it holds, on two timelines (``sim_time``: the vehicle's time in seconds, the autopilot's ``time_boot_ms``;
``step``: the servo step):

- ``camera/frame``, ``camera/flow``, ``camera/mask`` (with ``camera/mask/targets``: the raw centroid, the used
  target and the image centre), one of each per servo step;
- ``world/scene/...``: the wall's outline with its openings (front and back face), the background and the
  floor, and ``world/scene/splats``, a subsample of the scene's Gaussians in their colours;
- ``world/vehicle`` (the true pose) with ``world/vehicle/camera``, a pinhole frustum that shows each frame;
- ``world/trajectory/estimated`` (LOCAL_POSITION_NED), ``world/trajectory/true`` (the simulator's truth) and
  ``world/setpoints`` (every SET_POSITION_TARGET_LOCAL_NED sent), as growing line strips and points;
- ``plots/attitude/{roll,pitch,yaw}`` (rad), ``plots/error/{u,v}`` (the normalised image error) and
  ``plots/wall_distance_m`` as time series; ``log``: states, choices and refusals as text.

The world is NED (``ViewCoordinates.RIGHT_HAND_Z_DOWN``), the camera OpenCV's (x right, y down, z forward)
mounted looking along the body's x axis.  The Rerun SDK is the optional extra ``viz``; without it
:func:`open_recording` raises :class:`RecordingError` with the install line.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)

APPLICATION_ID = "flowgap"
SPLAT_POINTS = 20_000       # the scene's Gaussians shown as points (a subsample: the viewer stays fluid)
TRAJECTORY_PERIOD_S = 0.1   # the trajectories and attitude are logged at most this often (10 Hz)
SH_C0 = 0.28209479177387814  # 3DGS's degree-0 spherical-harmonic constant: rgb = 0.5 + C0 · f_dc

# The camera's axes in the body frame (columns: camera x = body y, camera y = body z, camera z = body x), as a
# quaternion (x, y, z, w) for Rerun: the rotation about (1, 1, 1)/√3 by 120°.
CAMERA_IN_BODY_XYZW = (0.5, 0.5, 0.5, 0.5)


class RecordingError(RuntimeError):
    """A recording cannot be made; the message says why and what to do."""


def require_rerun():
    """The ``rerun`` module, or :class:`RecordingError` naming the extra to install."""
    try:
        import rerun as rr
    except ImportError:
        raise RecordingError("the Rerun SDK is not installed: pip install 'flowgap[viz]' (or "
                             "pip install rerun-sdk), or fly without --rerun") from None
    return rr


def open_recording(path: Path | None = None, connect: str | None = None,
                   truth: Callable[[], tuple[float, Sequence[float], Sequence[float]]] | None = None
                   ) -> FlightRecording:
    """A recording written to ``path`` or, with ``connect`` (a viewer's address such as
    ``rerun+http://127.0.0.1:9876/proxy``), streamed to a running viewer.  ``truth`` returns the simulator's
    latest true pose (time, position, (w, x, y, z)) for the true trajectory and the vehicle's pose."""
    rr = require_rerun()
    rec = rr.RecordingStream(APPLICATION_ID)
    try:
        if connect:
            rec.connect_grpc(connect)
        else:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
            rec.save(str(path))
    except Exception as exc:  # noqa: BLE001 — the SDK's own errors: one line naming the target
        raise RecordingError(f"cannot open the Rerun recording at {connect or path}: {exc}") from None
    return FlightRecording(rr, rec, truth)


class FlightRecording:
    """Logs a flight as it happens (see the module docstring).  Thread-safe: telemetry arrives on the link's
    receive thread, frames and setpoints on the mission's."""

    def __init__(self, rr, rec, truth=None):
        self.rr, self.rec, self.truth = rr, rec, truth
        self._lock = threading.Lock()
        self._time = 0.0               # the vehicle's latest time stamp seen (s)
        self._last_position = self._last_attitude = -np.inf   # when each was last kept (s)
        self.estimated: list[tuple[float, float, float]] = []
        self.true: list[tuple[float, float, float]] = []
        self.setpoints: list[tuple[float, float, float]] = []
        self.frames = 0
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_DOWN, static=True)

    # ---------------------------------------------------------------------------------- static
    def scene(self, spec, cloud=None) -> None:
        """The scene's geometry from its spec (wall outline with openings, background, floor) and, given the
        cloud, a subsample of its splats."""
        rr = self.rr
        with self._lock:
            if spec is not None:
                for name, x in (("front", spec.wall_x), ("back", spec.wall_back_x)):
                    strips = [_rect_at(x, spec.wall.center_y - spec.wall.width / 2,
                                       spec.wall.center_y + spec.wall.width / 2, -spec.wall.height, 0.0)]
                    strips += [[(x, y, z) for y, z in (*o.polygon(), o.polygon()[0])] for o in spec.openings]
                    self.rec.log(f"world/scene/wall/{name}", rr.LineStrips3D(strips, colors=[(200, 120, 80)]),
                                 static=True)
                y_lo, y_hi, z_lo, z_hi = spec.background_rect
                self.rec.log("world/scene/background",
                             rr.LineStrips3D([_rect_at(spec.background_x, y_lo, y_hi, z_lo, z_hi)],
                                             colors=[(120, 120, 200)]), static=True)
                if spec.floor.enabled:
                    x0, x1 = spec.floor.x_min, spec.background_x
                    y0, y1 = y_lo, y_hi
                    self.rec.log("world/scene/floor", rr.Boxes3D(centers=[((x0 + x1) / 2, (y0 + y1) / 2, 0.0)],
                                                                 half_sizes=[((x1 - x0) / 2, (y1 - y0) / 2, 0.0)],
                                                                 colors=[(110, 100, 90)]), static=True)
            if cloud is not None and len(cloud.means):
                pick = np.random.default_rng(0).choice(len(cloud.means), min(SPLAT_POINTS, len(cloud.means)),
                                                       replace=False)
                rgb = np.clip(0.5 + SH_C0 * cloud.sh[pick, 0, :], 0.0, 1.0)
                self.rec.log("world/scene/splats", rr.Points3D(cloud.means[pick], colors=(rgb * 255).astype(np.uint8),
                                                               radii=0.01), static=True)

    def camera(self, K: np.ndarray, width: int, height: int) -> None:
        """The camera's intrinsics and mounting: a frustum under the vehicle's pose."""
        rr = self.rr
        with self._lock:
            self.rec.log("world/vehicle/camera", rr.Transform3D(quaternion=rr.Quaternion(xyzw=CAMERA_IN_BODY_XYZW)),
                         static=True)
            self.rec.log("world/vehicle/camera", rr.Pinhole(image_from_camera=np.asarray(K, float),
                                                            width=width, height=height, image_plane_distance=0.4),
                         static=True)

    # ------------------------------------------------------------------------------- over time
    def _at(self, time_s: float, step: int | None = None) -> None:
        self.rec.reset_time()
        self.rec.set_time("sim_time", duration=float(time_s))
        if step is not None:
            self.rec.set_time("step", sequence=int(step))

    def telemetry(self, time_s: float, position=None, attitude=None) -> None:
        """One telemetry sample from the autopilot (``time_s`` its time stamp): the estimated position (NED)
        and/or the attitude (roll, pitch, yaw), each kept at most every ``TRAJECTORY_PERIOD_S``; the true pose
        is sampled with the position."""
        rr = self.rr
        with self._lock:
            self._time = max(self._time, float(time_s))
            if position is not None and time_s - self._last_position >= TRAJECTORY_PERIOD_S:
                self._last_position = time_s
                self._at(time_s)
                self.estimated.append(tuple(map(float, position)))
                self.rec.log("world/trajectory/estimated", rr.LineStrips3D([self.estimated], colors=[(80, 160, 255)]))
                self._log_truth()
            if attitude is not None and time_s - self._last_attitude >= TRAJECTORY_PERIOD_S:
                self._last_attitude = time_s
                self._at(time_s)
                for name, value in zip(("roll", "pitch", "yaw"), attitude, strict=True):
                    self.rec.log(f"plots/attitude/{name}", rr.Scalars(float(value)))

    def _log_truth(self) -> None:
        if self.truth is None:
            return
        try:
            _, position, attitude = self.truth()
        except Exception:  # noqa: BLE001 — no truth yet (or the stream ended): nothing to draw
            return
        self._pose(position, attitude)

    def _pose(self, position, attitude) -> None:
        rr = self.rr
        w, x, y, z = (float(a) for a in attitude)
        self.true.append(tuple(map(float, position)))
        self.rec.log("world/vehicle", rr.Transform3D(translation=self.true[-1], quaternion=rr.Quaternion(
            xyzw=(x, y, z, w))))
        self.rec.log("world/trajectory/true", rr.LineStrips3D([self.true], colors=[(80, 220, 120)]))

    def setpoint(self, position, time_s: float | None = None) -> None:
        """A position setpoint sent (NED), at ``time_s`` or the latest telemetry time."""
        rr = self.rr
        with self._lock:
            self._at(self._time if time_s is None else time_s)
            self.setpoints.append(tuple(map(float, position)))
            self.rec.log("world/setpoints", rr.Points3D(self.setpoints, colors=[(255, 200, 40)], radii=0.015))

    def frame(self, step: int, time_s: float, rgb: np.ndarray, flow_rgb: np.ndarray | None, mask: np.ndarray | None,
              raw=None, used=None, position_true=None, attitude_true=None, error=None, wall_distance_m=None,
              text: str | None = None) -> None:
        """One servo step's frame, its flow colour and gap mask with the targets, the camera's true pose (the
        frustum shows the frame there), the image error and the measured wall distance."""
        rr = self.rr
        with self._lock:
            self._time = max(self._time, float(time_s))
            self._at(time_s, step)
            if position_true is not None and attitude_true is not None:
                self._pose(position_true, attitude_true)
            self.rec.log("camera/frame", rr.Image(rgb))
            self.rec.log("world/vehicle/camera", rr.Image(rgb))
            if flow_rgb is not None:
                self.rec.log("camera/flow", rr.Image(flow_rgb))
            if mask is not None:
                self.rec.log("camera/mask", rr.SegmentationImage(np.asarray(mask, np.uint8)))
            h, w = rgb.shape[:2]
            points, colours, labels = [((w - 1) / 2, (h - 1) / 2)], [(255, 255, 255)], ["image centre"]
            for p, colour, label in ((raw, (255, 60, 60), "raw centroid"), (used, (60, 255, 60), "used target")):
                if p is not None:
                    points.append(tuple(map(float, p)))
                    colours.append(colour)
                    labels.append(label)
            self.rec.log("camera/mask/targets", rr.Points2D(points, colors=colours, labels=labels, radii=3))
            if error is not None:
                self.rec.log("plots/error/u", rr.Scalars(float(error[0])))
                self.rec.log("plots/error/v", rr.Scalars(float(error[1])))
            if wall_distance_m is not None:
                self.rec.log("plots/wall_distance_m", rr.Scalars(float(wall_distance_m)))
            if text:
                self.rec.log("log", rr.TextLog(text))
            self.frames += 1

    def event(self, text: str, level: str = "INFO", time_s: float | None = None) -> None:
        """A state change, a choice or a refusal, as a line of text on the timeline."""
        with self._lock:
            self._at(self._time if time_s is None else time_s)
            self.rec.log("log", self.rr.TextLog(text, level=level))

    def close(self) -> None:
        with self._lock:
            self.rec.flush()
            self.rec.disconnect()


def _rect_at(x: float, y_lo: float, y_hi: float, z_lo: float, z_hi: float) -> list[tuple[float, float, float]]:
    return [(x, y_lo, z_lo), (x, y_hi, z_lo), (x, y_hi, z_hi), (x, y_lo, z_hi), (x, y_lo, z_lo)]


def recorded_entities(path: Path) -> dict[str, int]:
    """Rows per entity path in a ``.rrd`` (static rows included): what a recording holds, for tests and
    summaries."""
    rr = require_rerun()
    counts: dict[str, int] = {}
    for chunk in rr.chunk.RrdReader(str(path)).stream().to_chunks():
        counts[chunk.entity_path] = counts.get(chunk.entity_path, 0) + chunk.num_rows
    return counts

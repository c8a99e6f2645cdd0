"""One perception step, shared by the mission and by offline replay: flow between two frames, derotated with
the autopilot's attitude change, the gap detector, and the centroid mapped into a level virtual camera."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from companion.edges import EdgeConfig, refine_detection
from companion.gap import _no_gap, textured_pixels
from companion.motion import body_to_world_from_euler, level_pixel, rotational_flow


@dataclass(frozen=True)
class Perception:
    flow: np.ndarray  # H×W×2, derotated when asked
    detection: object  # companion.gap.GapDetection
    level_centroid: tuple[float, float] | None  # the detection's centroid as a level camera would see it
    flow_ms: float
    detect_ms: float
    textured: np.ndarray  # H×W bool: the first frame's pixels whose flow says something of their depth


def derotated_flow(prev_rgb: np.ndarray, rgb: np.ndarray, prev_attitude, attitude, K: np.ndarray, flow_backend,
                   derotate_flow: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """(flow less the camera's rotation between the frames, that rotation's flow) from ``prev_rgb`` to ``rgb``, given
    the (roll, pitch, yaw) estimates at the two frames."""
    flow = flow_backend.estimate(prev_rgb, rgb)
    h, w = flow.shape[:2]
    rotational = (rotational_flow(K, body_to_world_from_euler(*prev_attitude), body_to_world_from_euler(*attitude),
                                  h, w) if derotate_flow else np.zeros((h, w, 2), np.float32))
    return flow - rotational, rotational


def perceive(prev_rgb: np.ndarray, rgb: np.ndarray, prev_attitude, attitude, K: np.ndarray, flow_backend,
             detector, derotate_flow: bool = True, baseline_m: float | None = None,
             min_baseline_m: float = 0.0, edges: EdgeConfig | None = None) -> Perception:
    """``prev_attitude``/``attitude``: (roll, pitch, yaw) estimates at the two frames' time stamps.
    ``baseline_m``: how far the camera moved between them; under ``min_baseline_m`` the pair has no parallax to
    show and is not looked at (the flow is still returned): the flow of a camera that did not move is noise, and
    the detector finds "openings" in it.  ``detector(flow, textured=...)`` is given the first frame's textured
    pixels too (:func:`companion.gap.textured_pixels`).  ``edges``: read each opening's edge again from the two frames
    (:mod:`companion.edges`); None leaves the detector's masks as they are."""
    t0 = time.perf_counter()
    flow, rotational = derotated_flow(prev_rgb, rgb, prev_attitude, attitude, K, flow_backend, derotate_flow)
    flow_ms = (time.perf_counter() - t0) * 1000
    t0 = time.perf_counter()
    textured = textured_pixels(prev_rgb)
    if baseline_m is not None and baseline_m < min_baseline_m:
        detection = _no_gap(flow.shape[:2], f"the camera moved {baseline_m:.3f} m between the frames, under the "
                            f"{min_baseline_m:.3f} m a parallax needs: not looked at", "baseline")
    else:
        detection = detector(flow, textured=textured)
        if edges is not None:
            detection = refine_detection(detection, prev_rgb, rgb, flow, rotational, K, edges)
    detect_ms = (time.perf_counter() - t0) * 1000
    # The servo reads image position as position error: measure it in a level camera (see level_pixel).
    level = (level_pixel(detection.centroid, K, attitude[0], attitude[1])
             if detection.centroid is not None else None)
    return Perception(flow, detection, level, flow_ms, detect_ms, textured)

"""Pictures of a placed capture, to finish its JSON by: a top view (north up, the floor grid, the NED axes, start
and gate) and four level views from the start, plus the gate outline drawn into any render."""

from __future__ import annotations

import math

import cv2
import numpy as np

from scenes.camera import PinholeCamera, Pose, euler_to_quat, matrix_to_quat
from scenes.capture import Gate, opaque_bulk
from scenes.render import render_splats
from scenes.splats import GaussianCloud

GATE_COLOUR = (255, 60, 200)
START_COLOUR = (60, 230, 255)


def _project(camera: PinholeCamera, pose: Pose, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    uv, z = camera.project(np.asarray(points, np.float64), pose)
    return uv, z > camera.near


def _polyline(img: np.ndarray, camera: PinholeCamera, pose: Pose, points: np.ndarray, colour, closed: bool,
              thickness: int = 2, samples: int = 24) -> None:
    """Draw the 3-D polyline ``points`` (NED), cut where it passes behind the camera."""
    pts = np.asarray(points, np.float64)
    if closed:
        pts = np.vstack([pts, pts[:1]])
    dense = np.vstack([a + (b - a) * t for a, b in zip(pts[:-1], pts[1:], strict=True)
                       for t in np.linspace(0.0, 1.0, samples, endpoint=False)] + [pts[-1:]])
    uv, front = _project(camera, pose, dense)
    for i in range(len(dense) - 1):
        if front[i] and front[i + 1]:
            p0 = tuple(int(round(v * 16)) for v in uv[i])
            p1 = tuple(int(round(v * 16)) for v in uv[i + 1])
            cv2.line(img, p0, p1, colour, thickness, cv2.LINE_AA, shift=4)


def draw_gate(img: np.ndarray, camera: PinholeCamera, pose: Pose, gate: Gate) -> np.ndarray:
    """``img`` (RGB, the render at ``pose``) with the gate's rectangle outlined."""
    _polyline(img, camera, pose, gate.corners(), GATE_COLOUR, closed=True)
    return img


def draw_start(img: np.ndarray, camera: PinholeCamera, pose: Pose, start, yaw_deg: float, length: float) -> None:
    s = np.asarray(start, np.float64)
    yaw = math.radians(yaw_deg)
    tip = s + length * np.array([math.cos(yaw), math.sin(yaw), 0.0])
    uv, front = _project(camera, pose, np.vstack([s, tip]))
    if front.all():
        a, b = (tuple(int(round(v)) for v in p) for p in uv)
        cv2.circle(img, a, 5, START_COLOUR, 2, cv2.LINE_AA)
        cv2.arrowedLine(img, a, b, START_COLOUR, 2, cv2.LINE_AA, tipLength=0.25)


def label(img: np.ndarray, text: str) -> None:
    """White text on a dark band at the top left of ``img``."""
    (w, h), _ = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, 0.45, 1)
    img[: h + 10, : w + 10] //= 3
    cv2.putText(img, text, (5, h + 4), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA)


def _nice_step(span: float) -> float:
    raw = span / 8.0
    p = 10.0 ** math.floor(math.log10(raw))
    return next(p * k for k in (1, 2, 5, 10) if p * k >= raw)


def top_view(cloud: GaussianCloud, camera: PinholeCamera, start=None, yaw_deg: float = 0.0,
             gate: Gate | None = None) -> np.ndarray:
    """RGB from above the bulk of the splats looking down, north up, east right; the top fifth of the scene (the
    ceiling) is cut away by the near plane. Floor grid lines every nice step (the step is printed), the NED x
    (red) and y (green) axes from the origin, the start (cyan arrow: its heading) and the gate (magenta)."""
    lo, hi = opaque_bulk(cloud.means, cloud.opacity_logits)
    lo, hi = np.maximum(lo, np.percentile(cloud.means, 3, 0)), np.minimum(hi, np.percentile(cloud.means, 97, 0))
    centre = (lo + hi) / 2
    half_v = math.tan(camera.vfov_rad / 2)
    half_h = half_v * camera.width / camera.height
    above = 1.1 * max((hi[0] - lo[0]) / 2 / half_v, (hi[1] - lo[1]) / 2 / half_h, 0.5)
    room = max(float(hi[2] - lo[2]), 0.1)
    eye = np.array([centre[0], centre[1], lo[2] - above])
    cam = PinholeCamera(camera.width, camera.height, camera.vfov_rad, near=above + 0.2 * room,
                        far=above + room + 1.0)
    look_down = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])   # columns: body x, y, z in NED
    pose = Pose(tuple(eye), tuple(matrix_to_quat(look_down)))
    img = render_splats(cloud, cam, pose).rgb.copy()
    step = _nice_step(float(max(hi[0] - lo[0], hi[1] - lo[1])))
    for v in np.arange(math.floor(lo[0] / step) * step, hi[0] + step, step):
        _polyline(img, cam, pose, [(v, lo[1], 0.0), (v, hi[1], 0.0)], (90, 90, 90), False, 1, 2)
    for v in np.arange(math.floor(lo[1] / step) * step, hi[1] + step, step):
        _polyline(img, cam, pose, [(lo[0], v, 0.0), (hi[0], v, 0.0)], (90, 90, 90), False, 1, 2)
    _polyline(img, cam, pose, [(0.0, 0.0, 0.0), (step, 0.0, 0.0)], (255, 40, 40), False, 2, 2)
    _polyline(img, cam, pose, [(0.0, 0.0, 0.0), (0.0, step, 0.0)], (40, 220, 40), False, 2, 2)
    if gate is not None:
        draw_gate(img, cam, pose, gate)
    if start is not None:
        draw_start(img, cam, pose, start, yaw_deg, step)
    label(img, f"top (N up, E right), grid {step:g} m")
    return img


def level_views(cloud: GaussianCloud, camera: PinholeCamera, eye, gate: Gate | None = None) -> list[np.ndarray]:
    """Four level views from ``eye`` (NED) facing north, east, south and west, the gate outlined."""
    out = []
    for name, yaw in (("north", 0.0), ("east", 90.0), ("south", 180.0), ("west", -90.0)):
        pose = Pose(tuple(float(v) for v in eye), euler_to_quat(0.0, 0.0, math.radians(yaw)))
        img = render_splats(cloud, camera, pose).rgb.copy()
        if gate is not None:
            draw_gate(img, camera, pose, gate)
        label(img, f"from the start facing {name} ({yaw:g} deg)")
        out.append(img)
    return out


def placement_sheet(cloud: GaussianCloud, camera: PinholeCamera, start, yaw_deg: float, altitude_m: float,
                    gate: Gate | None) -> np.ndarray:
    """Top view and the four level views from the start at ``altitude_m``, in one RGB image (3 x 2 tiles)."""
    tiles = [top_view(cloud, camera, start, yaw_deg, gate)]
    tiles += level_views(cloud, camera, np.asarray(start, np.float64) - (0.0, 0.0, altitude_m), gate)
    legend = np.full_like(tiles[0], 24)
    for i, line in enumerate(("NED world: x north (red), y east (green),", "z down; floor at z = 0.",
                              "cyan: start and heading", "magenta: gate")):
        cv2.putText(legend, line, (8, 30 + 22 * i), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (230, 230, 230), 1,
                    cv2.LINE_AA)
    tiles.append(legend)
    return np.concatenate([np.concatenate(tiles[:3], 1), np.concatenate(tiles[3:], 1)], 0)

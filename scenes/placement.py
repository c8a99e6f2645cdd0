"""Placing a capture in the NED world (pure): the floor plane by RANSAC over opaque splat centres, the rotation that
turns its up direction to NED up, the scale from two points, and a draft capture JSON for the user to finish.

The proposal: RANSAC finds the largest planes of the opaque (>= 0.5) splat centres, one after the other (each
plane's points removed before the next), within the bulk of the capture (floaters cut away by percentiles).
A room's floor, walls and ceiling are all planes with nearly everything on one side; of those ("boundary
planes") the floor is taken to be the widest (the area its points span, whatever the splat density): a room's
floor is larger than any one wall, and captured better than its ceiling. Its normal, turned toward the scene,
is up. North is the
capture axis most level under that up (its projection on the floor), east completes NED. The floor goes to z = 0
and the bulk's median to x = y = 0. Every choice is printed, and ``--up`` overrides the floor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from scenes.camera import matrix_to_quat
from scenes.capture import CAPTURE_KIND, Placement, opaque_bulk
from scenes.splats import GaussianCloud

BULK_PERCENTILES = (2.0, 98.0)
MAX_POINTS = 60_000
ONE_SIDED = 0.85           # a boundary plane has at least this share of the other points on one side


@dataclass(frozen=True)
class Plane:
    """n . p = offset, with n (unit) pointing to the side most of the other points lie on."""

    normal: tuple[float, float, float]
    offset: float
    inliers: int            # points within the RANSAC threshold
    one_sided: float        # share of the other points on the normal's side
    area: float             # the area its points span (2-98 % extents along its two in-plane axes), units^2

    @property
    def boundary(self) -> bool:
        return self.one_sided >= ONE_SIDED


def bulk_points(cloud: GaussianCloud, rng: np.random.Generator, max_points: int = MAX_POINTS) -> np.ndarray:
    """Up to ``max_points`` opaque splat centres (float64) inside the capture's bulk (floaters cut away)."""
    pts = cloud.means[cloud.opacity_logits >= 0.0].astype(np.float64)
    if len(pts) < 3:
        pts = cloud.means.astype(np.float64)
    lo, hi = np.percentile(pts, BULK_PERCENTILES, axis=0)
    pad = 0.1 * (hi - lo)
    pts = pts[np.all((pts >= lo - pad) & (pts <= hi + pad), 1)]
    if len(pts) > max_points:
        pts = pts[rng.choice(len(pts), max_points, replace=False)]
    return pts


def ransac_plane(points: np.ndarray, rng: np.random.Generator, threshold: float, iterations: int = 300
                 ) -> tuple[np.ndarray, float, np.ndarray]:
    """(unit normal, offset, inlier mask) of the plane through most of ``points`` (N, 3): ``iterations`` planes
    through 3 random points, the best refined by least squares over its inliers."""
    n = len(points)
    sample = points[rng.choice(n, min(n, 8000), replace=False)]
    tri = points[rng.integers(0, n, (iterations, 3))]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norms = np.linalg.norm(normals, axis=1)
    good = norms > 1e-12
    normals = normals[good] / norms[good, None]
    offsets = np.einsum("ij,ij->i", normals, tri[good, 0])
    counts = (np.abs(sample @ normals.T - offsets) < threshold).sum(0)
    best = int(np.argmax(counts))
    normal, offset = normals[best], offsets[best]
    for _ in range(2):   # refine: the best-fitting plane of the inliers
        inliers = np.abs(points @ normal - offset) < threshold
        if inliers.sum() < 3:
            break
        centre = points[inliers].mean(0)
        normal = np.linalg.svd(points[inliers] - centre, full_matrices=False)[2][-1]
        offset = float(normal @ centre)
    return normal, float(offset), np.abs(points @ normal - offset) < threshold


def plane_candidates(points: np.ndarray, rng: np.random.Generator, count: int = 5,
                     threshold: float | None = None) -> list[Plane]:
    """The ``count`` largest planes, found one after the other; ``threshold`` defaults to 1 % of the bulk's size."""
    if threshold is None:
        threshold = 0.01 * float(np.linalg.norm(np.ptp(points, 0)))
    rest = points
    out = []
    for _ in range(count):
        if len(rest) < 50:
            break
        normal, offset, inliers = ransac_plane(rest, rng, threshold)
        side = points @ normal - offset
        off_plane = side[np.abs(side) >= threshold]
        above = float((off_plane > 0).mean()) if len(off_plane) else 0.5
        if above < 0.5:
            normal, offset, above = -normal, -offset, 1.0 - above
        out.append(Plane(tuple(float(v) for v in normal), float(offset), int(inliers.sum()), above,
                         _span_area(rest[inliers], normal)))
        rest = rest[~inliers]
    return out


def _span_area(points: np.ndarray, normal: np.ndarray) -> float:
    """Area spanned by ``points`` of a plane: the product of their 2-98 % extents along its principal axes."""
    if len(points) < 3:
        return 0.0
    flat = points - points.mean(0)
    flat -= np.outer(flat @ normal, normal)
    axes = np.linalg.svd(flat[:: max(1, len(flat) // 5000)], full_matrices=False)[2][:2]
    lo, hi = np.percentile(flat @ axes.T, BULK_PERCENTILES, axis=0)
    return float(np.prod(hi - lo))


def choose_floor(candidates: list[Plane]) -> Plane:
    """The floor among ``candidates`` (rule in the module docstring); the largest plane if none is a boundary."""
    if not candidates:
        raise ValueError("no plane found among the splats; pass the up direction with --up")
    bounded = [p for p in candidates if p.boundary and p.inliers >= 0.2 * candidates[0].inliers]
    if not bounded:
        return max(candidates, key=lambda p: p.inliers)
    return max(bounded, key=lambda p: p.area)


def rotation_to_ned(up) -> np.ndarray:
    """3x3 R (capture -> NED) turning ``up`` (capture frame) to NED up (0, 0, -1); north is the capture axis most
    level under ``up``, projected on the floor."""
    up = np.asarray(up, np.float64)
    up = up / np.linalg.norm(up)
    axes = np.eye(3)
    level = axes[int(np.argmin(np.abs(axes @ up)))]
    north = level - (level @ up) * up
    north /= np.linalg.norm(north)
    down = -up
    east = np.cross(down, north)
    return np.stack([north, east, down])


def propose_placement(points: np.ndarray, up, floor_offset: float, scale: float = 1.0) -> Placement:
    """The placement: capture ``up`` to NED up, the floor (``up . p = floor_offset``) to z = 0, the bulk's median to
    x = y = 0, ``scale`` metres per capture unit."""
    r = rotation_to_ned(up)
    up = np.asarray(up, np.float64) / np.linalg.norm(up)
    q = matrix_to_quat(r)
    median = np.median(points, 0)
    t = -scale * (r @ median)
    t[2] = scale * floor_offset          # z_ned = -scale * (up . p) + t_z is 0 on the floor
    return Placement(float(scale), tuple(float(v) for v in q), tuple(float(v) for v in t))


def scale_from_points(a, b, metres: float) -> float:
    """Metres per capture unit, when the capture-frame points ``a`` and ``b`` are ``metres`` apart."""
    units = float(np.linalg.norm(np.asarray(a, np.float64) - np.asarray(b, np.float64)))
    if units == 0.0 or not metres > 0:
        raise ValueError("the two points must differ and METRES must be positive")
    return metres / units


def parse_up(text: str) -> np.ndarray:
    """``+y``, ``-z``, ... or ``X,Y,Z`` (capture frame) -> a unit vector."""
    t = text.strip().lower()
    named = {"x": 0, "y": 1, "z": 2}
    if len(t) == 2 and t[0] in "+-" and t[1] in named:
        v = np.zeros(3)
        v[named[t[1]]] = 1.0 if t[0] == "+" else -1.0
        return v
    try:
        v = np.array([float(s) for s in t.split(",")])
    except ValueError:
        v = np.zeros(0)
    if v.shape != (3,) or not np.all(np.isfinite(v)) or np.linalg.norm(v) == 0:
        raise ValueError(f"--up {text!r} must be an axis such as -y or +z, or three numbers X,Y,Z")
    return v / np.linalg.norm(v)


def parse_scale_from(text: str) -> tuple[np.ndarray, np.ndarray, float]:
    """``X1:Y1:Z1,X2:Y2:Z2,METRES`` (or seven comma-separated numbers) -> (a, b, metres)."""
    parts = text.replace(":", ",").split(",")
    try:
        values = [float(v) for v in parts]
    except ValueError:
        values = []
    if len(values) != 7 or not all(math.isfinite(v) for v in values) or values[6] <= 0:
        raise ValueError(f"--scale-from {text!r} must be X1:Y1:Z1,X2:Y2:Z2,METRES: two points of the .ply's own "
                         f"frame and their distance in metres, e.g. 0:0:0,1.2:0:0,3.5")
    return np.array(values[:3]), np.array(values[3:6]), values[6]


def draft_capture(ply_ref: str, placement: Placement, cloud_ned: GaussianCloud) -> dict:
    """A capture JSON to finish: the placement, and a start and a gate inside the placed splats to move to the real
    start and opening (the start a quarter of the way along x, the gate three quarters, 1 x 1 m, facing it)."""
    lo, hi = opaque_bulk(cloud_ned.means, cloud_ned.opacity_logits)
    lo = np.maximum(lo, np.percentile(cloud_ned.means, 5, axis=0))
    hi = np.minimum(hi, np.percentile(cloud_ned.means, 95, axis=0))
    y = float(round((lo[1] + hi[1]) / 2, 2))
    x0, x1 = float(lo[0] + 0.25 * (hi[0] - lo[0])), float(lo[0] + 0.75 * (hi[0] - lo[0]))
    height = min(1.5, max(0.3, 0.5 * float(-lo[2])))
    return {"kind": CAPTURE_KIND, "ply": ply_ref, "to_ned": placement.to_dict(),
            "gate": {"center_ned": [round(x1, 2), y, round(-height, 2)], "normal_ned": [1.0, 0.0, 0.0],
                     "size_m": [1.0, 1.0]},
            "start_ned": [round(x0, 2), y, 0.0], "start_yaw_deg": 0.0,
            "comment": "draft from flowgap-scenes place: check the floor (z = 0) and the scale in the views, then set "
                       "gate (centre, facing normal, [width, height] in m) and start_ned / start_yaw_deg"}

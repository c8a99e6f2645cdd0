"""Capture scenes: a third-party 3DGS ``.ply`` placed in the NED world by a small JSON file.

    {"kind": "capture", "ply": "room.ply",
     "to_ned": {"scale": 2.7, "rotation_wxyz": [w, x, y, z], "translation_m": [x, y, z]},
     "gate": {"center_ned": [x, y, z], "normal_ned": [x, y, z], "size_m": [width, height]},
     "start_ned": [x, y, 0], "start_yaw_deg": 35.0}

Optional keys: ``name`` (default: the JSON's stem), ``altitude_m`` (the height the companion flies at;
default the gate centre's height), ``collision`` (:class:`FieldSettings`; the rule is in :mod:`scenes.occupancy`),
``comment``.

* p_ned = scale * R(q) * p_ply + t, the one edge where a capture's frame (y-up or z-up, any unit) meets NED.
  Each Gaussian's rotation becomes q * q_i, its log-scales gain ln(scale), and its SH colour of degree 1-3
  turns with R (:mod:`scenes.shrotate`), so that view-dependent colour stays right.
* The ``ply`` path is relative to the JSON file.
* The floor must land on z = 0, the vehicle's ground: ``start_ned`` is on it, where the vehicle starts.
* The gate is the rectangle to fly through, centred on ``center_ned``, in the plane normal to ``normal_ned``
  (either sign: the side the start is on is the approach side), its width level and its height across.

Everything here is pure but :func:`load_capture` and :func:`capture_cloud`, which read the files.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from scenes.camera import quat_to_matrix
from scenes.shrotate import rotate_sh
from scenes.spec import SpecError
from scenes.splats import GaussianCloud, read_ply

CAPTURE_KIND = "capture"
UNIT_QUATERNION_TOLERANCE = 1e-3
START_GROUND_TOLERANCE_M = 0.1
INSIDE_PERCENTILES = (1.0, 99.0)      # the bulk of the opaque splats, without their floaters
INSIDE_MARGIN = (0.5, 0.1)            # ... widened by max(0.5 m, 10 % of its size) on every side
_KEYS = {"kind", "ply", "to_ned", "gate", "start_ned", "start_yaw_deg", "name", "altitude_m", "collision", "comment"}


class CaptureError(SpecError):
    """A capture scene file is malformed; the message is one line naming the file, the problem and the fix."""


@dataclass(frozen=True)
class Placement:
    """p_ned = scale * R(q) * p_ply + t."""

    scale: float = 1.0
    rotation_wxyz: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    translation_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def rotation(self) -> np.ndarray:
        return quat_to_matrix(self.rotation_wxyz)

    def apply(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) capture-frame points -> NED (float64)."""
        return self.scale * (np.asarray(points, np.float64) @ self.rotation.T) + np.asarray(self.translation_m)

    def inverse(self) -> Placement:
        """The placement that undoes this one (p_ply = (1/s) R^T (p_ned - t))."""
        w, x, y, z = (float(v) for v in self.rotation_wxyz)
        n = math.sqrt(w * w + x * x + y * y + z * z)
        q_inv = (w / n, -x / n, -y / n, -z / n)
        t = -(quat_to_matrix(q_inv) @ np.asarray(self.translation_m, np.float64)) / self.scale
        return Placement(1.0 / self.scale, q_inv, tuple(float(v) for v in t))

    def to_dict(self) -> dict:
        return {"scale": self.scale, "rotation_wxyz": list(self.rotation_wxyz),
                "translation_m": list(self.translation_m)}


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a * b of (w, x, y, z) quaternions (broadcasting); its matrix is R(a) R(b)."""
    aw, ax, ay, az = (a[..., i] for i in range(4))
    bw, bx, by, bz = (b[..., i] for i in range(4))
    return np.stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw], -1)


def place_cloud(cloud: GaussianCloud, placement: Placement, inplace: bool = False) -> GaussianCloud:
    """``cloud`` moved by ``placement``: positions, rotations, log-scales and SH colour (degree 1-3) transformed
    together. ``inplace`` reuses the cloud's arrays (a large capture's colours are not copied)."""
    q = np.asarray(placement.rotation_wxyz, np.float64)
    q = q / np.linalg.norm(q)
    r = quat_to_matrix(q)
    means = placement.apply(cloud.means).astype(np.float32)
    quats = quat_multiply(q, cloud.quats.astype(np.float64)).astype(np.float32)
    log_scales = cloud.log_scales + np.float32(math.log(placement.scale))
    if inplace:
        cloud.means[:] = means
        cloud.quats[:] = quats
        cloud.log_scales[:] = log_scales
        rotate_sh(cloud.sh, r, out=cloud.sh)
        for attr in ("_cpu_prepared", "_torch_tensors"):   # renderers' caches, keyed on the arrays' identity
            cloud.__dict__.pop(attr, None)
        return cloud
    return GaussianCloud(means, log_scales, quats, cloud.opacity_logits.copy(), rotate_sh(cloud.sh, r),
                         cloud.labels.copy())


@dataclass(frozen=True)
class Gate:
    """The rectangle to fly through (NED). ``approach_side``: a point on the side the vehicle comes from."""

    center_ned: tuple[float, float, float]
    normal_ned: tuple[float, float, float]     # unit; either sign
    size_m: tuple[float, float]                # (width along the level axis, height across it)
    approach_side: tuple[float, float, float] = (0.0, 0.0, 0.0)
    _frame: tuple = field(default=(), init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        nx, ny, nz = self.normal_ned
        cx, cy, cz = self.center_ned
        sx, sy, sz = self.approach_side
        if (sx - cx) * nx + (sy - cy) * ny + (sz - cz) * nz > 0.0:
            nx, ny, nz = -nx, -ny, -nz          # the flight normal: from the approach side to the far side
        h = math.hypot(nx, ny)
        wx, wy, wz = -ny / h, nx / h, 0.0       # level axis: down x normal
        hx, hy, hz = ny * wz - nz * wy, nz * wx - nx * wz, nx * wy - ny * wx
        object.__setattr__(self, "_frame", ((nx, ny, nz), (wx, wy, wz), (hx, hy, hz)))

    @property
    def flight_normal(self) -> tuple[float, float, float]:
        return self._frame[0]

    @property
    def axes(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """(level width axis, height axis), unit NED vectors in the gate's plane."""
        return self._frame[1], self._frame[2]

    def signed_distance(self, p) -> float:
        """Distance of ``p`` from the gate's plane: negative on the approach side (plain floats: every physics step)."""
        (nx, ny, nz), c = self._frame[0], self.center_ned
        return (p[0] - c[0]) * nx + (p[1] - c[1]) * ny + (p[2] - c[2]) * nz

    def crossing_point(self, p0, s0: float, p1, s1: float) -> tuple[float, float, float]:
        """Where the segment p0 -> p1 (signed distances s0, s1 of opposite signs) meets the plane."""
        f = s0 / (s0 - s1) if s0 != s1 else 0.0
        return (p0[0] + f * (p1[0] - p0[0]), p0[1] + f * (p1[1] - p0[1]), p0[2] + f * (p1[2] - p0[2]))

    def contains(self, p) -> bool:
        """Whether ``p`` (in the plane, or near it) lies within the rectangle."""
        (wx, wy, wz), (hx, hy, hz) = self._frame[1], self._frame[2]
        c = self.center_ned
        dx, dy, dz = p[0] - c[0], p[1] - c[1], p[2] - c[2]
        return (abs(dx * wx + dy * wy + dz * wz) <= 0.5 * self.size_m[0]
                and abs(dx * hx + dy * hy + dz * hz) <= 0.5 * self.size_m[1])

    def corners(self) -> np.ndarray:
        """(4, 3) NED corners, in order around the rectangle."""
        w, h = (np.asarray(a) for a in self.axes)
        c = np.asarray(self.center_ned, np.float64)
        hw, hh = 0.5 * self.size_m[0], 0.5 * self.size_m[1]
        return np.array([c - hw * w - hh * h, c + hw * w - hh * h, c + hw * w + hh * h, c - hw * w + hh * h])

    def describe(self) -> dict:
        return {"center_ned": [round(v, 4) for v in self.center_ned],
                "normal_ned": [round(v, 4) for v in self.flight_normal], "size_m": list(self.size_m)}


@dataclass(frozen=True)
class FieldSettings:
    """The ``collision`` block of a capture file (all optional): the rule they tune is in :mod:`scenes.occupancy`."""

    voxel_m: float = 0.05          # edge of a voxel [m]
    solid_alpha: float = 0.5       # a Gaussian is solid where it alone is at least this opaque
    roi_margin_m: float = 2.0      # region of interest: the start-and-gate box widened by this [m]
    floor_band_m: float = 0.15     # solid voxels this close above the floor (z = 0) are left to the ground [m]

    @classmethod
    def from_dict(cls, d: dict) -> FieldSettings:
        names = [f.name for f in fields(cls)]
        for key, value in d.items():
            if key not in names:
                raise ValueError(f"unknown key {key!r} in 'collision'; its keys are {', '.join(names)}")
            if not (isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)):
                raise ValueError(f"collision.{key} must be a finite number, got {json.dumps(value)}")
        s = cls(**{k: float(v) for k, v in d.items()})
        if not 0.005 <= s.voxel_m <= 1.0:
            raise ValueError(f"collision.voxel_m {s.voxel_m:g} must be within 0.005..1 m; 0.05 is the default")
        if not 0.0 < s.solid_alpha < 1.0:
            raise ValueError(f"collision.solid_alpha {s.solid_alpha:g} must be within 0..1 (exclusive); 0.5 is the "
                             f"default")
        if s.roi_margin_m < 0 or s.floor_band_m < 0:
            raise ValueError("collision.roi_margin_m and collision.floor_band_m must not be negative")
        return s


@dataclass(frozen=True)
class CaptureSpec:
    """A parsed, checked capture scene file (see the module docstring)."""

    name: str
    path: Path                                  # the JSON file
    ply: Path                                   # resolved
    to_ned: Placement
    gate: Gate
    start_ned: tuple[float, float, float]
    start_yaw_deg: float
    altitude_m: float
    collision: FieldSettings = field(default_factory=FieldSettings)
    comment: str = ""
    source: dict = field(default_factory=dict, compare=False, repr=False)   # the JSON as read

    kind = CAPTURE_KIND


# ------------------------------------------------------------------------------------------- parsing
def _numbers(where: str, value, n: int, fix: str) -> tuple[float, ...]:
    ok = isinstance(value, list | tuple) and len(value) == n and all(
        isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in value)
    if not ok:
        raise CaptureError(f"{where} must be {n} finite numbers, got {json.dumps(value)}; {fix}")
    return tuple(float(v) for v in value)


def _number(where: str, value, fix: str) -> float:
    if not (isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)):
        raise CaptureError(f"{where} must be a finite number, got {json.dumps(value)}; {fix}")
    return float(value)


def _block(data: dict, key: str, src: str, keys: tuple[str, ...], example: str) -> dict:
    if key not in data:
        raise CaptureError(f"{src}: missing key {key!r}; add \"{key}\": {example}")
    block = data[key]
    if not isinstance(block, dict):
        raise CaptureError(f"{src}: {key!r} must be an object such as {example}")
    for k in keys:
        if k not in block:
            raise CaptureError(f"{src}: {key!r} lacks {k!r}; add it, e.g. \"{key}\": {example}")
    unknown = sorted(set(block) - set(keys))
    if unknown:
        raise CaptureError(f"{src}: unknown key {unknown[0]!r} in {key!r}; its keys are {', '.join(keys)}")
    return block


def parse_capture(data, path: str | Path) -> CaptureSpec:
    """A :class:`CaptureSpec` from the JSON object ``data`` of the file ``path`` (for the relative ``ply`` and
    the messages). Raises :class:`CaptureError` with one line naming the problem and the fix."""
    path = Path(path)
    src = str(path)
    if not isinstance(data, dict) or data.get("kind") != CAPTURE_KIND:
        raise CaptureError(f"{src}: not a capture scene (no \"kind\": \"capture\"); add it")
    unknown = sorted(set(data) - _KEYS)
    if unknown:
        raise CaptureError(f"{src}: unknown key {unknown[0]!r}; the keys are {', '.join(sorted(_KEYS))}")
    for key, example in (("ply", '"room.ply"'), ("start_ned", "[0, 0, 0]"), ("start_yaw_deg", "0.0")):
        if key not in data:
            raise CaptureError(f"{src}: missing key {key!r}; add \"{key}\": {example}")
    if not isinstance(data["ply"], str) or not data["ply"]:
        raise CaptureError(f"{src}: 'ply' must be the path of the .ply, relative to this file")
    ply = (path.parent / data["ply"]).resolve() if not Path(data["ply"]).is_absolute() else Path(data["ply"])
    if not ply.is_file():
        raise CaptureError(f"{src}: its 'ply' {data['ply']!r} is not a file (looked for {ply}); fix the path, "
                           f"which is relative to the JSON file")
    t = _block(data, "to_ned", src, ("scale", "rotation_wxyz", "translation_m"),
               '{"scale": 1.0, "rotation_wxyz": [1, 0, 0, 0], "translation_m": [0, 0, 0]}')
    scale = _number(f"{src}: to_ned.scale", t["scale"], "give the capture's metres per unit")
    if scale <= 0:
        raise CaptureError(f"{src}: to_ned.scale must be positive, got {scale:g}; give the capture's metres per unit")
    q = _numbers(f"{src}: to_ned.rotation_wxyz", t["rotation_wxyz"], 4, "give a unit quaternion (w, x, y, z)")
    norm = math.sqrt(sum(v * v for v in q))
    if abs(norm - 1.0) > UNIT_QUATERNION_TOLERANCE:
        raise CaptureError(f"{src}: to_ned.rotation_wxyz {list(q)} has norm {norm:.4f}, not 1; divide it by its "
                           f"norm (a rotation is a unit quaternion (w, x, y, z))")
    placement = Placement(scale, tuple(v / norm for v in q),
                          _numbers(f"{src}: to_ned.translation_m", t["translation_m"], 3, "give metres in NED"))
    g = _block(data, "gate", src, ("center_ned", "normal_ned", "size_m"),
               '{"center_ned": [3, 0, -1.5], "normal_ned": [1, 0, 0], "size_m": [1.0, 1.0]}')
    center = _numbers(f"{src}: gate.center_ned", g["center_ned"], 3, "give the gate's centre in NED metres")
    normal = _numbers(f"{src}: gate.normal_ned", g["normal_ned"], 3, "give the direction the gate faces in NED")
    size = _numbers(f"{src}: gate.size_m", g["size_m"], 2, "give [width, height] in metres")
    if min(size) <= 0:
        raise CaptureError(f"{src}: gate.size_m {list(size)} must be positive; give [width, height] in metres")
    n = math.sqrt(sum(v * v for v in normal))
    if n == 0 or math.hypot(normal[0], normal[1]) < 0.1 * n:
        raise CaptureError(f"{src}: gate.normal_ned {list(normal)} is zero or nearly vertical; a gate faces "
                           f"sideways: give a mostly horizontal normal such as [1, 0, 0]")
    if center[2] >= 0:
        raise CaptureError(f"{src}: gate.center_ned z = {center[2]:g} is not above the floor (z = 0, NED z is "
                           f"down); give a negative z, e.g. -1.5 for 1.5 m up")
    start = _numbers(f"{src}: start_ned", data["start_ned"], 3, "give where the vehicle starts, in NED metres")
    if abs(start[2]) > START_GROUND_TOLERANCE_M:
        raise CaptureError(f"{src}: start_ned z = {start[2]:g} m, but the vehicle starts on the ground, z = 0; set "
                           f"it to 0 (and let to_ned put the capture's floor at z = 0)")
    yaw = _number(f"{src}: start_yaw_deg", data["start_yaw_deg"], "give the start heading in degrees from north")
    normal = tuple(v / n for v in normal)
    side = (start[0] - center[0]) * normal[0] + (start[1] - center[1]) * normal[1] + (start[2] - center[2]) * normal[2]
    if abs(side) < 1e-6:
        raise CaptureError(f"{src}: start_ned lies in the gate's plane; start on one side of the gate")
    bearing = math.degrees(math.atan2(center[1] - start[1], center[0] - start[0]))
    off = (bearing - yaw + 180.0) % 360.0 - 180.0
    if abs(off) >= 90.0:
        raise CaptureError(f"{src}: start_yaw_deg {yaw:g} faces away from the gate (bearing {bearing:.0f} deg from "
                           f"the start); set start_yaw_deg near {bearing:.0f}")
    altitude = -center[2]
    if "altitude_m" in data:
        altitude = _number(f"{src}: altitude_m", data["altitude_m"], "give the flight height above the floor")
        if altitude <= 0:
            raise CaptureError(f"{src}: altitude_m must be positive, got {altitude:g}; give metres above the floor")
    collision = data.get("collision", {})
    if not isinstance(collision, dict):
        raise CaptureError(f"{src}: 'collision' must be an object such as {{\"voxel_m\": 0.05}}")
    try:
        settings = FieldSettings.from_dict(collision)
    except ValueError as exc:
        raise CaptureError(f"{src}: {exc}") from None
    name = data.get("name", path.stem.removesuffix(".capture"))
    if not isinstance(name, str) or not name:
        raise CaptureError(f"{src}: 'name' must be a non-empty string")
    return CaptureSpec(name=name, path=path.resolve(), ply=ply, to_ned=placement,
                       gate=Gate(center, normal, size, start), start_ned=start, start_yaw_deg=yaw,
                       altitude_m=altitude, collision=settings, comment=str(data.get("comment", "")),
                       source=data)


def read_json_object(path: str | Path) -> dict | None:
    """The JSON object in ``path``, or None when the file is not JSON (callers decide what that means)."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    return data if isinstance(data, dict) else None


def is_capture_file(path: str | Path) -> bool:
    p = Path(path)
    if p.suffix != ".json" or not p.is_file():
        return False
    data = read_json_object(p)
    return data is not None and data.get("kind") == CAPTURE_KIND


def load_capture(path: str | Path) -> CaptureSpec:
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise CaptureError(f"{path}: cannot read ({exc.strerror}); check the path") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise CaptureError(f"{path}: not valid JSON ({exc}); fix the file") from None
    return parse_capture(data, path)


# -------------------------------------------------------------------------------------- the splats
def opaque_bulk(means: np.ndarray, opacity_logits: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) NED box of the bulk of the opaque (>= 0.5) splats: percentiles, widened, so floaters do not count."""
    pts = means[opacity_logits >= 0.0]
    if len(pts) == 0:
        pts = means
    lo, hi = np.percentile(pts, INSIDE_PERCENTILES, axis=0)
    pad = np.maximum(INSIDE_MARGIN[0], INSIDE_MARGIN[1] * (hi - lo))
    return lo - pad, hi + pad


def check_inside_splats(spec: CaptureSpec, cloud: GaussianCloud) -> None:
    """Refuse a gate or a start outside the bulk of the placed splats (a wrong to_ned, most often)."""
    lo, hi = opaque_bulk(cloud.means, cloud.opacity_logits)
    box = ", ".join(f"{a} {lo[i]:.1f}..{hi[i]:.1f}" for i, a in enumerate("xyz"))
    for what, p in (("gate center_ned", spec.gate.center_ned), ("start_ned", spec.start_ned)):
        if np.any(np.asarray(p) < lo) or np.any(np.asarray(p) > hi):
            raise CaptureError(f"{spec.path}: {what} {list(p)} lies outside the splats (their bulk spans {box} m "
                               f"in NED); fix to_ned or the {what.split()[0]} (look with 'flowgap-scenes render "
                               f"{spec.path.name}')")


def capture_cloud(spec: CaptureSpec) -> GaussianCloud:
    """The capture's Gaussians in NED (read from the ``.ply``, placed, checked against the gate and start)."""
    cloud = place_cloud(read_ply(spec.ply), spec.to_ned, inplace=True)
    check_inside_splats(spec, cloud)
    return cloud

"""Scene spec -> Gaussian splats (pure), plus the on-disk cache and ``load_scene``.

Every surface is sampled on a regular grid with flat, disc-like Gaussians (in-plane sigma =
``density.sigma_factor * spacing``, 1 mm thick) so that neighbouring discs overlap and nothing behind a
surface leaks through. Surfaces and labels:

* wall front face (x = wall.distance), minus the openings -> ``LABEL_WALL``
* opening reveals (the slab's inner sides, across the thickness) -> ``LABEL_WALL``
* optional frame band around each opening, standing proud of the wall -> ``LABEL_FRAME``
* background plane behind the wall -> ``LABEL_BACKGROUND``
* floor (z = 0): in front of the wall ``LABEL_FLOOR``, behind the wall's back face ``LABEL_BACKGROUND``
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
from pathlib import Path

import cv2
import numpy as np

from scenes import cache as scene_cache
from scenes import textures
from scenes.camera import matrix_to_quat
from scenes.capture import CaptureSpec, capture_cloud, is_capture_file, load_capture
from scenes.geometry import distance_to_polygon_edges, points_in_polygon
from scenes.spec import SceneSpec, SpecError
from scenes.splats import (
    LABEL_BACKGROUND,
    LABEL_FLOOR,
    LABEL_FRAME,
    LABEL_WALL,
    GaussianCloud,
    PlyError,
    read_ply,
    rgb_to_sh0,
    write_ply,
)

log = logging.getLogger(__name__)

CODE_VERSION = "1"
PROJECT_ROOT = Path(__file__).resolve().parent.parent
TEXTURE_PX_PER_M = 120.0


def default_cache_dir() -> Path:
    env = os.environ.get("FLOWGAP_SCENE_CACHE")
    return Path(env) if env else PROJECT_ROOT / "cache" / "scenes"


# ------------------------------------------------------------------------------------------- sampling
def _logit(p: float) -> float:
    return float(np.log(p / (1 - p)))


def _surface(points: np.ndarray, rgb: np.ndarray, axes: np.ndarray, sigma: float, opacity: float,
             label: int) -> GaussianCloud:
    """Flat Gaussians at ``points`` whose first two scale axes are columns 0, 1 of ``axes`` (3x3 or Nx3x3)."""
    n = len(points)
    log_scales = np.tile(np.log(np.array([sigma, sigma, 1e-3], np.float32)), (n, 1))
    if axes.ndim == 2:
        quats = np.tile(matrix_to_quat(axes).astype(np.float32), (n, 1))
    else:
        quats = np.array([matrix_to_quat(a) for a in axes], np.float32).reshape(n, 4)
    return GaussianCloud(points, log_scales, quats, np.full(n, _logit(opacity), np.float32),
                         rgb_to_sh0(rgb)[:, None, :], np.full(n, label, np.uint8))


def _grid(lo: float, hi: float, spacing: float) -> np.ndarray:
    n = max(1, int(round((hi - lo) / spacing)))
    return lo + (np.arange(n) + 0.5) * (hi - lo) / n


def _sample_texture(tex: np.ndarray, u: np.ndarray, v: np.ndarray, n_u: int, n_v: int) -> np.ndarray:
    """Area-average ``tex`` onto an n_v x n_u grid and pick the cells at integer (v, u) indices."""
    small = cv2.resize(tex, (n_u, n_v), interpolation=cv2.INTER_AREA)
    return small[v, u]


def _plane_yz(spec: SceneSpec, x: float, y_lo: float, y_hi: float, z_lo: float, z_hi: float, spacing: float,
              tex: np.ndarray, keep_fn, label: int) -> GaussianCloud:
    ys, zs = _grid(y_lo, y_hi, spacing), _grid(z_lo, z_hi, spacing)
    zz, yy = np.meshgrid(zs, ys, indexing="ij")
    keep = keep_fn(yy, zz) if keep_fn is not None else np.ones(yy.shape, bool)
    vi, ui = np.nonzero(keep)
    rgb = _sample_texture(tex, ui, vi, len(ys), len(zs))
    pts = np.stack([np.full(len(ui), x), yy[vi, ui], zz[vi, ui]], 1)
    axes = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])  # columns e_y, e_z, e_x
    d = spec.density
    return _surface(pts, rgb, axes, d.sigma_factor * spacing, d.opacity, label)


def _texture_at(tex: np.ndarray, y: np.ndarray, z: np.ndarray, y_lo: float, z_lo: float, width: float,
                height: float) -> np.ndarray:
    h, w = tex.shape[:2]
    col = np.clip(((y - y_lo) / width * w).astype(int), 0, w - 1)
    row = np.clip(((z - z_lo) / height * h).astype(int), 0, h - 1)
    return tex[row, col]


def build_scene(spec: SceneSpec) -> GaussianCloud:
    """Sample the spec's surfaces into one :class:`GaussianCloud` (deterministic, pure)."""
    spec.validate()
    wall, d = spec.wall, spec.density
    jit = np.asarray(spec.jitter.tint, np.float32) * spec.jitter.exposure
    y_lo, y_hi = wall.center_y - wall.width / 2, wall.center_y + wall.width / 2
    z_lo, z_hi = -wall.height, 0.0
    polys = [op.polygon() for op in spec.openings]
    parts: list[GaussianCloud] = []

    wall_tex = textures.make_texture(wall.texture, wall.seed, wall.width, wall.height, TEXTURE_PX_PER_M,
                                     wall.texture_scale)

    def outside_openings(yy, zz):
        keep = np.ones(yy.shape, bool)
        for p in polys:
            keep &= ~points_in_polygon(yy, zz, p)
        return keep

    parts.append(_plane_yz(spec, wall.distance, y_lo, y_hi, z_lo, z_hi, d.wall_spacing, wall_tex,
                           outside_openings, LABEL_WALL))

    # reveals: the slab's inner sides along every opening edge
    s = d.wall_spacing
    xs = _grid(spec.wall_x, spec.wall_back_x, s)
    for p in polys:
        for i in range(len(p)):
            (y0, z0), (y1, z1) = p[i], p[(i + 1) % len(p)]
            length = float(np.hypot(y1 - y0, z1 - z0))
            if length < 1e-9:
                continue
            ts = _grid(0.0, 1.0, s / length)
            ey, ez = (y1 - y0) / length, (z1 - z0) / length
            tt, xx = np.meshgrid(ts, xs, indexing="ij")
            py, pz = y0 + tt.ravel() * (y1 - y0), z0 + tt.ravel() * (z1 - z0)
            pts = np.stack([xx.ravel(), py, pz], 1)
            # polygon is CCW in (y, z): the inward normal (into the opening) is (-ez, ey)
            tangent = np.array([0.0, ey, ez])
            normal = np.array([0.0, -ez, ey])
            axes = np.stack([tangent, np.array([1.0, 0.0, 0.0]), normal], 1)
            if np.linalg.det(axes) < 0:
                axes[:, 1] *= -1
            rgb = _texture_at(wall_tex, py, pz, y_lo, z_lo, wall.width, wall.height) * 0.95
            parts.append(_surface(pts, rgb, axes, d.sigma_factor * s, d.opacity, LABEL_WALL))

    # frames
    for op, p in zip(spec.openings, polys, strict=True):
        if op.frame_width <= 0:
            continue
        fw = op.frame_width
        ys_, zs_ = [q[0] for q in p], [q[1] for q in p]
        frame_rng = np.random.default_rng(wall.seed + 7919)
        fy0, fy1, fz0, fz1 = min(ys_) - fw, max(ys_) + fw, min(zs_) - fw, max(zs_) + fw
        ftex = np.broadcast_to(np.array([0.50, 0.36, 0.24], np.float32),
                               (int((fz1 - fz0) * TEXTURE_PX_PER_M) + 8, int((fy1 - fy0) * TEXTURE_PX_PER_M) + 8,
                                3)).copy()
        ftex *= 1 + 0.1 * frame_rng.standard_normal(ftex.shape[:2] + (1,)).astype(np.float32)

        def in_band(yy, zz, p=p, fw=fw):
            return ~points_in_polygon(yy, zz, p) & (distance_to_polygon_edges(yy, zz, p) <= fw)

        parts.insert(0, _plane_yz(spec, wall.distance - op.frame_depth, fy0, fy1, fz0, fz1, s, ftex, in_band,
                                  LABEL_FRAME))

    # background
    bg = spec.background
    bg_tex = textures.make_texture(spec.background_texture, bg.seed, bg.width, bg.height, TEXTURE_PX_PER_M,
                                   bg.texture_scale)
    parts.append(_plane_yz(spec, spec.background_x, *spec.background_rect, d.background_spacing, bg_tex, None,
                           LABEL_BACKGROUND))

    # floor
    if spec.floor.enabled:
        fl = spec.floor
        x_hi = spec.background_x
        width = max(wall.width, bg.width)
        sf = d.floor_spacing
        xs_f, ys_f = _grid(fl.x_min, x_hi, sf), _grid(wall.center_y - width / 2, wall.center_y + width / 2, sf)
        rng = np.random.default_rng(fl.seed)
        g = textures._fbm(rng, len(xs_f), len(ys_f), 12.0, 4)
        rgb = np.asarray(fl.color, np.float32) * (1 + 0.25 * g[..., None]) \
            + 0.03 * rng.standard_normal((len(xs_f), len(ys_f), 1)).astype(np.float32)
        xx, yy = np.meshgrid(xs_f, ys_f, indexing="ij")
        pts = np.stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)], 1)
        # keep the floor out of the wall slab
        keep = ~((pts[:, 0] > spec.wall_x - sf) & (pts[:, 0] < spec.wall_back_x + sf))
        labels = np.where(pts[:, 0] < spec.wall_x, LABEL_FLOOR, LABEL_BACKGROUND)
        floor = _surface(pts[keep], rgb.reshape(-1, 3)[keep], np.eye(3), d.sigma_factor * sf, d.opacity,
                         LABEL_FLOOR)
        floor.labels = labels[keep].astype(np.uint8)
        parts.append(floor)

    cloud = GaussianCloud.concatenate(parts)
    cloud.sh[:, 0, :] = rgb_to_sh0(np.clip((cloud.sh[:, 0, :] * 0.28209479177387814 + 0.5) * jit, 0, 1))
    log.debug("built %s: %d Gaussians", spec.name, len(cloud))
    return cloud


# ----------------------------------------------------------------------------------------------- cache
def cache_key(spec: SceneSpec) -> str:
    h = hashlib.sha256()
    h.update(CODE_VERSION.encode())
    for mod in (textures.__file__, __file__):
        h.update(Path(mod).read_bytes())
    h.update(spec.to_json().encode())
    return h.hexdigest()[:16]


def cache_paths(spec: SceneSpec, cache_dir: Path | None = None) -> tuple[Path, Path, Path]:
    """(ply, spec json, key file) paths of ``spec`` in the cache."""
    root = Path(cache_dir) if cache_dir else default_cache_dir()
    return root / f"{spec.name}.ply", root / f"{spec.name}.json", root / f"{spec.name}.key"


def is_cached(spec: SceneSpec, cache_dir: Path | None = None) -> bool:
    ply, js, key = cache_paths(spec, cache_dir)
    return ply.exists() and js.exists() and _read_key(key) == cache_key(spec)


def _read_key(key: Path) -> str | None:
    try:                    # another process may remove it between a check and the read (scenes.cache.prune)
        return key.read_text().strip()
    except FileNotFoundError:
        return None


def build_cached(spec: SceneSpec, cache_dir: Path | None = None, force: bool = False) -> tuple[Path, bool]:
    """Build ``spec`` into the cache unless it is up to date; returns (ply path, whether it was built).

    A hit marks the scene as used; a build then removes least recently used scenes beyond the cache's limit
    (:mod:`scenes.cache`, ``$FLOWGAP_SCENE_CACHE_MB``)."""
    ply, js, key = cache_paths(spec, cache_dir)
    if not force and is_cached(spec, cache_dir):
        scene_cache.touch(key)
        return ply, False
    max_bytes = scene_cache.limit_bytes()          # a bad limit is reported before the build, not after it
    cloud = build_scene(spec)
    ply.parent.mkdir(parents=True, exist_ok=True)
    tmp = ply.with_name(ply.name + f".tmp{os.getpid()}")
    write_ply(tmp, cloud)
    os.replace(tmp.with_name(tmp.name + ".labels.npy"), ply.with_name(ply.name + ".labels.npy"))
    os.replace(tmp, ply)
    spec.save(js)
    key.write_text(cache_key(spec) + "\n")
    scene_cache.prune(ply.parent, max_bytes, keep=(spec.name,))
    return ply, True


def resolve_spec(name_or_path: str | Path | SceneSpec | CaptureSpec) -> SceneSpec | CaptureSpec:
    """A library name, a spec ``.json`` path, a ``.ply`` with a sibling spec ``.json``, or a capture scene ``.json``
    (:mod:`scenes.capture`) -> its :class:`SceneSpec` or :class:`CaptureSpec` (no splats are read)."""
    from scenes import library

    if isinstance(name_or_path, SceneSpec | CaptureSpec):
        return name_or_path
    s = str(name_or_path)
    if s in library.NAMED:
        return library.NAMED[s]()
    p = Path(s)
    if p.suffix == ".json" and p.exists():
        return load_capture(p) if is_capture_file(p) else SceneSpec.load(p)
    sibling = _procedural_sibling(p) if p.suffix == ".ply" else None
    if sibling is not None:
        return SceneSpec.load(sibling)
    raise SpecError(f"unknown scene {s!r}; use a suite name such as {library.DEFAULT_SCENE!r} "
                    f"(see 'flowgap-scenes build --help'), a path to a spec .json or a capture scene .json")


def _procedural_sibling(ply: Path) -> Path | None:
    """The spec ``.json`` beside a ``.ply`` that we built (a capture file there places the .ply elsewhere: not it)."""
    js = ply.with_suffix(".json")
    return js if js.exists() and not is_capture_file(js) else None


def load_scene(name_or_path: str | Path | SceneSpec | CaptureSpec, cache_dir: Path | None = None
               ) -> tuple[SceneSpec | CaptureSpec | None, GaussianCloud]:
    """(spec, cloud in NED) for a suite name, spec ``.json`` or ``SceneSpec`` (built and cached on demand), a
    capture scene ``.json`` or ``CaptureSpec`` (its ``.ply`` read and placed), or a ``.ply`` file as it is (spec
    from a sibling spec ``.json`` if present, else None)."""
    p = Path(str(name_or_path)) if not isinstance(name_or_path, SceneSpec | CaptureSpec) else None
    if p is not None and p.suffix == ".ply":
        if not p.exists():
            raise PlyError(f"{p}: no such file; check the path")
        sibling = _procedural_sibling(p)
        return (SceneSpec.load(sibling) if sibling is not None else None), read_ply(p)
    spec = resolve_spec(name_or_path)
    if isinstance(spec, CaptureSpec):
        return spec, capture_cloud(spec)
    ply, _ = build_cached(spec, cache_dir)
    return spec, read_ply(ply)


def spec_json(spec: SceneSpec) -> dict:
    return json.loads(spec.to_json())

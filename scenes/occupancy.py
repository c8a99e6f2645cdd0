"""Collision geometry of a capture scene: a distance field from its opaque Gaussians, cached beside the scene.

The rule (what the vehicle's body sphere is checked against every physics step):

1. **Region of interest.** Only the NED box around the start (from the ground up to the flight altitude) and the
   gate's corners, widened by ``roi_margin_m`` (2 m) on every side and cut at the floor (z <= 0), is solid-
   checked. Floaters hundreds of metres out, and anything else outside the box, are ignored; outside the box the
   clearance is that of the nearest point of the box plus the distance to it.
2. **Solid voxels.** The box is cut into cubes of ``voxel_m`` (5 cm). A Gaussian of opacity o counts where it
   alone is at least ``solid_alpha`` (0.5) opaque: its ellipsoid of k = sqrt(2 ln(o / solid_alpha)) sigmas (at
   most 3); fainter Gaussians do not count. A voxel is solid when its centre lies within such an ellipsoid
   widened by half a voxel on each axis (so that a surface thinner than a voxel still marks one).
3. **The floor** is the vehicle's ground (z = 0, handled by its dynamics): solid voxels in the lowest
   ``floor_band_m`` (0.15 m) above it are cleared, so that the floor's splats do not count twice.
4. **Distance.** clearance(p) = the Euclidean distance from p to the nearest solid voxel centre, trilinearly
   interpolated between voxel centres. Splats sample surfaces, not volumes: solid voxels are samples of a surface
   (each within about half a voxel of it), so the clearance is never negative, and a body touches when it
   comes within its radius of them.

Resolution and what it may miss: surfaces are where they are to within about half a voxel plus the Gaussians'
own extent (on a suite scene the field agrees with the exact geometry within 0.7 voxel, 99 % within half a
voxel); obstacles thinner than a voxel count as a voxel thick; obstacles made only of
faint Gaussians (each under ``solid_alpha``: thin wires, glass, semi-transparent leaves), obstacles lower than
``floor_band_m`` above the floor, and anything outside the region of interest are missed; a floater inside the
region counts as an obstacle. The field knows only the splats' centres and shapes, not what a surface looks
like from behind (a wall's back face is as thin as its front).
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import os
from dataclasses import asdict
from pathlib import Path

import numpy as np
from numba import njit, prange

from scenes.capture import CaptureError, CaptureSpec, FieldSettings, Gate
from scenes.render.common import quats_to_matrices
from scenes.splats import GaussianCloud

log = logging.getLogger(__name__)

FIELD_VERSION = "1"
MAX_VOXELS = 60_000_000
MAX_SIGMAS = 3.0
FAR_M = 1e3                                   # clearance reported where nothing solid is in the region


def region_of_interest(start_ned, altitude_m: float, gate: Gate, margin_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) NED corners of the box that is solid-checked (rule 1 of the module docstring)."""
    start = np.asarray(start_ned, np.float64)
    pts = np.vstack([start, start - (0.0, 0.0, altitude_m), gate.corners()])
    lo, hi = pts.min(0) - margin_m, pts.max(0) + margin_m
    hi[2] = min(hi[2], 0.0)
    return lo, hi


@njit(parallel=True, cache=True)
def _mark_solid(means, rot, semi, origin, voxel, occ):
    """occ[i, j, k] = 1 where the centre of voxel (i, j, k) lies within some Gaussian's ellipsoid (centre means[g],
    axes the columns of rot[g], semi-axes semi[g])."""
    nx, ny, nz = occ.shape
    for g in prange(means.shape[0]):
        m0, m1, m2 = means[g, 0], means[g, 1], means[g, 2]
        a0, a1, a2 = semi[g, 0], semi[g, 1], semi[g, 2]
        r = rot[g]
        lo = np.empty(3, np.int64)
        hi = np.empty(3, np.int64)
        n = (nx, ny, nz)
        for j in range(3):
            e = math.sqrt((r[j, 0] * a0) ** 2 + (r[j, 1] * a1) ** 2 + (r[j, 2] * a2) ** 2)
            lo[j] = max(0, int(math.ceil((means[g, j] - e - origin[j]) / voxel - 0.5)))
            hi[j] = min(n[j] - 1, int(math.floor((means[g, j] + e - origin[j]) / voxel - 0.5)))
        for i in range(lo[0], hi[0] + 1):
            dx = origin[0] + (i + 0.5) * voxel - m0
            for j in range(lo[1], hi[1] + 1):
                dy = origin[1] + (j + 0.5) * voxel - m1
                for k in range(lo[2], hi[2] + 1):
                    dz = origin[2] + (k + 0.5) * voxel - m2
                    u0 = (r[0, 0] * dx + r[1, 0] * dy + r[2, 0] * dz) / a0
                    u1 = (r[0, 1] * dx + r[1, 1] * dy + r[2, 1] * dz) / a1
                    u2 = (r[0, 2] * dx + r[1, 2] * dy + r[2, 2] * dz) / a2
                    if u0 * u0 + u1 * u1 + u2 * u2 <= 1.0:
                        occ[i, j, k] = 1


def solid_voxels(cloud: GaussianCloud, lo: np.ndarray, hi: np.ndarray, settings: FieldSettings
                 ) -> tuple[np.ndarray, int]:
    """(occupancy (nx, ny, nz) uint8 of the box [lo, hi] in voxels of ``settings.voxel_m``, Gaussians that
    counted): rules 2 and 3 of the module docstring. Pure."""
    h = settings.voxel_m
    shape = np.maximum(np.ceil((hi - lo) / h).astype(np.int64), 1)
    if int(np.prod(shape)) > MAX_VOXELS:
        raise ValueError(f"the collision region {np.round(hi - lo, 1).tolist()} m holds {int(np.prod(shape)):,} "
                         f"voxels of {h:g} m (at most {MAX_VOXELS:,}); raise collision.voxel_m or lower "
                         f"collision.roi_margin_m")
    opacity = 1.0 / (1.0 + np.exp(-cloud.opacity_logits.astype(np.float64)))
    keep = opacity > settings.solid_alpha
    reach = MAX_SIGMAS * np.exp(cloud.log_scales.max(1).astype(np.float64)) + h
    keep &= np.all(cloud.means >= lo - reach[:, None], 1) & np.all(cloud.means <= hi + reach[:, None], 1)
    idx = np.nonzero(keep)[0]
    k = np.minimum(MAX_SIGMAS, np.sqrt(2.0 * np.log(opacity[idx] / settings.solid_alpha)))
    semi = k[:, None] * np.exp(cloud.log_scales[idx].astype(np.float64)) + 0.5 * h
    rot = quats_to_matrices(np.where(np.all(cloud.quats[idx] == 0, 1)[:, None], (1.0, 0.0, 0.0, 0.0),
                                     cloud.quats[idx].astype(np.float64)))
    occ = np.zeros(tuple(int(v) for v in shape), np.uint8)
    _mark_solid(cloud.means[idx].astype(np.float64), rot, semi, lo.astype(np.float64), float(h), occ)
    z_centres = lo[2] + (np.arange(shape[2]) + 0.5) * h
    occ[:, :, z_centres > -settings.floor_band_m] = 0
    return occ, len(idx)


def clearance_grid(occ: np.ndarray, voxel_m: float) -> np.ndarray:
    """Rule 4: distance from each voxel centre to the nearest solid voxel centre (float32, 0 in solid voxels)."""
    from scipy.ndimage import distance_transform_edt

    if not occ.any():
        return np.full(occ.shape, FAR_M, np.float32)
    return distance_transform_edt(occ == 0, sampling=voxel_m).astype(np.float32)


class DistanceField:
    """Clearance (m) sampled at voxel centres ``origin + (i + 0.5) * voxel`` over the box ``origin``..``upper``;
    :meth:`clearance` on plain floats."""

    def __init__(self, grid: np.ndarray, origin, voxel_m: float) -> None:
        self.grid = np.ascontiguousarray(grid, np.float32)
        self.origin = tuple(float(v) for v in origin)
        self.voxel_m = float(voxel_m)
        self.shape = tuple(int(v) for v in self.grid.shape)
        self._flat = self.grid.reshape(-1)
        self._inv = 1.0 / self.voxel_m
        self.upper = tuple(o + n * self.voxel_m for o, n in zip(self.origin, self.shape, strict=True))

    def clearance(self, p) -> float:
        """Metres from ``p`` (NED) to the nearest solid (trilinear between voxel centres; see the module docstring)."""
        idx = []
        frac = []
        outside2 = 0.0
        for axis in range(3):
            v = float(p[axis])
            lo, hi = self.origin[axis], self.upper[axis]
            if v < lo:
                outside2 += (lo - v) ** 2
                v = lo
            elif v > hi:
                outside2 += (v - hi) ** 2
                v = hi
            n = self.shape[axis]
            f = (v - lo) * self._inv - 0.5
            if f <= 0.0:
                idx.append(0)
                frac.append(0.0)
            elif f >= n - 1:
                idx.append(n - 1 if n > 1 else 0)
                frac.append(0.0)
            else:
                i = int(f)
                idx.append(i)
                frac.append(f - i)
        (i, j, k), (fx, fy, fz) = idx, frac
        _, ny, nz = self.shape
        g = self._flat.item
        i1 = i + 1 if fx > 0.0 else i
        j1 = j + 1 if fy > 0.0 else j
        k1 = k + 1 if fz > 0.0 else k
        c00 = g((i * ny + j) * nz + k) * (1 - fz) + g((i * ny + j) * nz + k1) * fz
        c01 = g((i * ny + j1) * nz + k) * (1 - fz) + g((i * ny + j1) * nz + k1) * fz
        c10 = g((i1 * ny + j) * nz + k) * (1 - fz) + g((i1 * ny + j) * nz + k1) * fz
        c11 = g((i1 * ny + j1) * nz + k) * (1 - fz) + g((i1 * ny + j1) * nz + k1) * fz
        d = (c00 * (1 - fy) + c01 * fy) * (1 - fx) + (c10 * (1 - fy) + c11 * fy) * fx
        return d + math.sqrt(outside2) if outside2 > 0.0 else d


class CaptureCollision:
    """A capture's collision world for the vehicle: ``clearance(p)`` from the splat distance field, the ``gate``
    whose rectangle the flight must cross (``crossed_wall`` means its plane), and no ``wall_x``."""

    wall_x = None

    def __init__(self, name: str, field: DistanceField, gate: Gate, settings: FieldSettings, gaussians: int,
                 solid_voxels: int) -> None:
        self.name = name
        self.field = field
        self.gate = gate
        self.settings = settings
        self.gaussians = gaussians
        self.solid_voxels = solid_voxels
        self.clearance = field.clearance

    def describe(self) -> dict:
        lo = self.field.origin
        hi = self.field.upper
        return {"voxel_m": self.field.voxel_m, "region_lo_ned": [round(v, 3) for v in lo],
                "region_hi_ned": [round(v, 3) for v in hi], "voxels": list(self.field.shape),
                "solid_voxels": self.solid_voxels, "gaussians_counted": self.gaussians,
                **{k: v for k, v in asdict(self.settings).items() if k != "voxel_m"}}

    def __repr__(self) -> str:
        return f"CaptureCollision({self.name!r}, voxel {self.field.voxel_m:g} m, shape {self.field.shape})"


def build_capture_collision(spec: CaptureSpec, cloud: GaussianCloud) -> CaptureCollision:
    """The collision world of ``spec`` from its placed ``cloud`` (pure; see the module docstring)."""
    settings = spec.collision
    lo, hi = region_of_interest(spec.start_ned, spec.altitude_m, spec.gate, settings.roi_margin_m)
    try:
        occ, counted = solid_voxels(cloud, lo, hi, settings)
    except ValueError as exc:
        raise CaptureError(f"{spec.path}: {exc}") from None
    grid = clearance_grid(occ, settings.voxel_m)
    return CaptureCollision(spec.name, DistanceField(grid, lo, settings.voxel_m), spec.gate, settings, counted,
                            int(occ.sum()))


# ------------------------------------------------------------------------------------------------ cache
def field_key(spec: CaptureSpec) -> str:
    """Everything the field depends on: the placement, gate, start, altitude, settings, the .ply's size and time,
    and this code."""
    st = spec.ply.stat()
    h = hashlib.sha256()
    h.update(FIELD_VERSION.encode())
    h.update(Path(__file__).read_bytes())
    h.update(json.dumps({"to_ned": spec.to_ned.to_dict(), "gate": spec.gate.describe(), "start": spec.start_ned,
                         "altitude": spec.altitude_m, "collision": asdict(spec.collision),
                         "ply": [str(spec.ply), st.st_size, st.st_mtime_ns]}, sort_keys=True).encode())
    return h.hexdigest()[:16]


def cache_paths(spec: CaptureSpec) -> list[Path]:
    """Where the field is cached: beside the scene file, else (a read-only folder) in the scene cache."""
    from scenes.build import default_cache_dir

    return [spec.path.with_name(spec.path.stem + ".collision.npz"),
            default_cache_dir() / "captures" / f"{spec.name}-{hashlib.sha1(str(spec.path).encode()).hexdigest()[:8]}"
                                               f".collision.npz"]


def _read_cached(path: Path, key: str, spec: CaptureSpec) -> CaptureCollision | None:
    try:
        with np.load(path, allow_pickle=False) as z:
            if str(z["key"]) != key:
                return None
            field = DistanceField(z["grid"], z["origin"], float(z["voxel_m"]))
            counts = z["counts"]
    except (OSError, KeyError, ValueError, EOFError):
        return None
    return CaptureCollision(spec.name, field, spec.gate, spec.collision, int(counts[0]),
                            int(counts[1]))


def load_capture_collision(spec: CaptureSpec, cloud: GaussianCloud | None = None) -> CaptureCollision:
    """The capture's collision world, from the cache when it is up to date, else built (reading the .ply unless
    ``cloud``, already placed, is given) and cached."""
    key = field_key(spec)
    paths = cache_paths(spec)
    for path in paths:
        if path.exists():
            cached = _read_cached(path, key, spec)
            if cached is not None:
                log.debug("collision field of %s from %s", spec.name, path)
                return cached
    if cloud is None:
        from scenes.capture import capture_cloud

        cloud = capture_cloud(spec)
    world = build_capture_collision(spec, cloud)
    for path in paths:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_name(path.name + f".tmp{os.getpid()}.npz")
            np.savez(tmp, grid=world.field.grid, origin=np.asarray(world.field.origin), voxel_m=world.field.voxel_m,
                     counts=np.array([world.gaussians, world.solid_voxels]), key=np.array(key))
            os.replace(tmp, path)
            log.info("collision field of %s cached in %s", spec.name, path)
            break
        except OSError as exc:
            log.info("cannot cache the collision field in %s (%s)", path, exc.strerror)
    return world

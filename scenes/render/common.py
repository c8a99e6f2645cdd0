"""Shared rendering constants, the result type, and the numpy reference stages (slow oracle maths).

EWA splatting as in 3DGS / gsplat:

* project: X_c = R X_w + t; Sigma_c = R Sigma_w R^T with Sigma_w = (Rq S)(Rq S)^T; J the perspective
  Jacobian at the (clamped) mean; Sigma_2d = J Sigma_c J^T + 0.3 I (the 0.3 px^2 dilation);
  conic = Sigma_2d^-1; the pixel box is the axis-aligned 3-sigma box (|du| <= 3 sqrt(S_uu), |dv| <= 3
  sqrt(S_vv)). Pixel (row i, col j) has its centre at (u, v) = (j + 0.5, i + 0.5).
* colour: real SH of degree 0-3 evaluated at the world-frame viewing direction, + 0.5, clamped at 0.
* sort: front to back by camera depth in 2 cm bins, ties by Gaussian index (stable). Coarse bins keep the
  compositing order of a surface's coplanar splats (and so its sampling pattern) the same from view to
  view; fine depth order made the rendered texture shimmer with the view and broke flow consistency.
  Surfaces closer than 2 cm to each other rely on build order (frames are built before the wall).
* rasterise: alpha = min(0.99, opacity exp(-0.5 d^T conic d)), skipped when below 1/255 or when the
  exponent is positive; a pixel stops when the next transmittance would be <= 1e-4 (that Gaussian is
  not blended). depth = sum(w z) / sum(w) (expected depth), alpha = sum(w) with w = alpha T, label = the
  label of the Gaussian at which transmittance first drops below 0.5 (0 if it never does).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

ALPHA_MAX = 0.99
ALPHA_MIN = 1.0 / 255.0
T_MIN = 1e-4
DILATION = 0.3
SIGMA_EXTENT = 3.0
JACOBIAN_CLAMP = 1.3
DEPTH_BINS = 1 << 20
DEPTH_BIN_M = 0.02
LABEL_T = 0.5

SH_C0 = 0.28209479177387814
SH_C1 = 0.4886025119029199
SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792,
         0.5462742152960396)
SH_C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
         -0.4570457994644658, 1.445305721320277, -0.5900435899266435)


@dataclass
class RenderResult:
    """rgb (H, W, 3) uint8; depth (H, W) float32 metres along the optical axis (0 where empty);
    alpha (H, W) float32 accumulated opacity; label (H, W) uint8 surface label (``scenes.splats.LABEL_*``)."""

    rgb: np.ndarray
    depth: np.ndarray
    alpha: np.ndarray
    label: np.ndarray


def sh_basis(dirs: np.ndarray, degree: int) -> np.ndarray:
    """(N, (degree+1)^2) real SH basis at unit directions (N, 3), 3DGS sign conventions."""
    x, y, z = dirs[:, 0], dirs[:, 1], dirs[:, 2]
    out = [np.full_like(x, SH_C0)]
    if degree >= 1:
        out += [-SH_C1 * y, SH_C1 * z, -SH_C1 * x]
    if degree >= 2:
        xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
        out += [SH_C2[0] * xy, SH_C2[1] * yz, SH_C2[2] * (2 * zz - xx - yy), SH_C2[3] * xz,
                SH_C2[4] * (xx - yy)]
    if degree >= 3:
        out += [SH_C3[0] * y * (3 * xx - yy), SH_C3[1] * xy * z, SH_C3[2] * y * (4 * zz - xx - yy),
                SH_C3[3] * z * (2 * zz - 3 * xx - 3 * yy), SH_C3[4] * x * (4 * zz - xx - yy),
                SH_C3[5] * z * (xx - yy), SH_C3[6] * x * (xx - 3 * yy)]
    return np.stack(out, 1)


def quats_to_matrices(q: np.ndarray) -> np.ndarray:
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], 1)


@dataclass
class Projected:
    """Per-Gaussian screen-space quantities of the visible Gaussians (index: into the cloud)."""

    index: np.ndarray   # (M,) int
    uv: np.ndarray      # (M, 2)
    conic: np.ndarray   # (M, 3) a, b, c of the inverse 2-D covariance
    cov2d: np.ndarray   # (M, 3) a, b, c of the 2-D covariance (dilated)
    depth: np.ndarray   # (M,)
    rgb: np.ndarray     # (M, 3)
    opacity: np.ndarray  # (M,)
    box: np.ndarray     # (M, 4) int: col0, col1, row0, row1 (inclusive)


def project_reference(cloud, camera, pose) -> Projected:
    """numpy float64 projection stage (oracle for the fast backends)."""
    r, t = camera.world_to_camera(pose)
    centre = -r.T @ t
    fx, fy = camera.fx, camera.fy
    px, py = camera.principal_point
    w, h = camera.width, camera.height
    means = cloud.means.astype(np.float64)
    pc = means @ r.T + t
    z = pc[:, 2]
    ok = (z > camera.near) & (z < camera.far)
    zs = np.where(ok, z, 1.0)
    limx, limy = JACOBIAN_CLAMP * 0.5 * w / fx, JACOBIAN_CLAMP * 0.5 * h / fy
    tx = zs * np.clip(pc[:, 0] / zs, -limx, limx)
    ty = zs * np.clip(pc[:, 1] / zs, -limy, limy)
    n = len(means)
    jac = np.zeros((n, 2, 3))
    jac[:, 0, 0] = fx / zs
    jac[:, 0, 2] = -fx * tx / zs**2
    jac[:, 1, 1] = fy / zs
    jac[:, 1, 2] = -fy * ty / zs**2
    m = quats_to_matrices(cloud.quats.astype(np.float64)) * np.exp(cloud.log_scales.astype(np.float64))[:, None, :]
    a = jac @ r[None] @ m
    cov = a @ a.transpose(0, 2, 1)
    ca, cb, cc = cov[:, 0, 0] + DILATION, cov[:, 0, 1], cov[:, 1, 1] + DILATION
    det = ca * cc - cb * cb
    ok &= det > 0
    dets = np.where(ok, det, 1.0)
    u = fx * pc[:, 0] / zs + px
    v = fy * pc[:, 1] / zs + py
    ex, ey = SIGMA_EXTENT * np.sqrt(np.maximum(ca, 0)), SIGMA_EXTENT * np.sqrt(np.maximum(cc, 0))
    c0 = np.ceil(u - ex - 0.5)
    c1 = np.floor(u + ex - 0.5)
    r0 = np.ceil(v - ey - 0.5)
    r1 = np.floor(v + ey - 0.5)
    ok &= (c1 >= 0) & (c0 <= w - 1) & (r1 >= 0) & (r0 <= h - 1) & (c1 >= c0) & (r1 >= r0)
    idx = np.nonzero(ok)[0]
    dirs = means[idx] - centre
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    basis = sh_basis(dirs, cloud.sh_degree)
    rgb = np.maximum(np.einsum("nk,nkc->nc", basis, cloud.sh[idx].astype(np.float64)) + 0.5, 0.0)
    box = np.stack([np.clip(c0[idx], 0, w - 1), np.clip(c1[idx], 0, w - 1), np.clip(r0[idx], 0, h - 1),
                    np.clip(r1[idx], 0, h - 1)], 1).astype(np.int64)
    dd = dets[idx]
    return Projected(idx, np.stack([u[idx], v[idx]], 1),
                     np.stack([cc[idx] / dd, -cb[idx] / dd, ca[idx] / dd], 1),
                     np.stack([ca[idx], cb[idx], cc[idx]], 1), z[idx], rgb,
                     1.0 / (1.0 + np.exp(-cloud.opacity_logits[idx].astype(np.float64))), box)


def depth_order(depth: np.ndarray) -> np.ndarray:
    """Front-to-back order by depth in ``DEPTH_BIN_M`` bins, ties by position (stable)."""
    if len(depth) == 0:
        return np.zeros(0, np.int64)
    d = np.asarray(depth, np.float32)
    key = np.minimum(((d - d.min()) * np.float32(1.0 / DEPTH_BIN_M)).astype(np.int64), DEPTH_BINS - 1)
    return np.argsort(key, kind="stable")


def rasterise_reference(p: Projected, labels: np.ndarray, width: int, height: int,
                        background: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> RenderResult:
    """Slow front-to-back compositing, one Gaussian at a time over its box (numpy)."""
    T = np.ones((height, width))
    done = np.zeros((height, width), bool)
    rgb = np.zeros((height, width, 3))
    dep = np.zeros((height, width))
    lab = np.zeros((height, width), np.uint8)
    for g in depth_order(p.depth):
        c0, c1, r0, r1 = p.box[g]
        jj, ii = np.meshgrid(np.arange(c0, c1 + 1), np.arange(r0, r1 + 1))
        dx, dy = jj + 0.5 - p.uv[g, 0], ii + 0.5 - p.uv[g, 1]
        a, b, c = p.conic[g]
        power = -0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy
        alpha = np.minimum(ALPHA_MAX, p.opacity[g] * np.exp(power))
        tt = T[r0:r1 + 1, c0:c1 + 1]
        nt = tt * (1 - alpha)
        live = ~done[r0:r1 + 1, c0:c1 + 1] & (power <= 0) & (alpha >= ALPHA_MIN)
        stop = live & (nt <= T_MIN)
        done[r0:r1 + 1, c0:c1 + 1] |= stop
        use = live & ~stop
        wgt = np.where(use, alpha * tt, 0.0)
        rgb[r0:r1 + 1, c0:c1 + 1] += wgt[..., None] * p.rgb[g]
        dep[r0:r1 + 1, c0:c1 + 1] += wgt * p.depth[g]
        cross = use & (tt >= LABEL_T) & (nt < LABEL_T)
        lab[r0:r1 + 1, c0:c1 + 1][cross] = labels[p.index[g]]
        T[r0:r1 + 1, c0:c1 + 1] = np.where(use, nt, tt)
    return finish(rgb, dep, 1.0 - T, lab, T, background)


def finish(rgb: np.ndarray, dep: np.ndarray, alpha: np.ndarray, lab: np.ndarray, T: np.ndarray,
           background) -> RenderResult:
    img = rgb + T[..., None] * np.asarray(background, np.float64)
    rgb8 = np.clip(np.rint(img * 255.0), 0, 255).astype(np.uint8)
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = np.where(alpha > 1e-6, dep / np.maximum(alpha, 1e-12), 0.0)
    return RenderResult(rgb8, depth.astype(np.float32), alpha.astype(np.float32), lab.astype(np.uint8))


def render_reference(cloud, camera, pose, background=(0.0, 0.0, 0.0)) -> RenderResult:
    """Slow, obviously-correct renderer (test oracle); same signature as the fast backends."""
    p = project_reference(cloud, camera, pose)
    return rasterise_reference(p, cloud.labels, camera.width, camera.height, background)

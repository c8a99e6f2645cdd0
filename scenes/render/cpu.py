"""CPU backend: numba kernels, staged project -> sort/bin -> rasterise (maths in ``render.common``).

Loop order (see docs/design.md, performance notes): our scenes are dense, coplanar, small splats, so each
Gaussian is scattered front to back over the pixels of its own 3-sigma box, with per-pixel
transmittance and the early-out. The image is cut into horizontal bands; each band has the depth-sorted
list of Gaussians that touch it, and bands are interleaved over the worker threads.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import njit, prange

from scenes.render.common import (
    ALPHA_MAX,
    ALPHA_MIN,
    DEPTH_BIN_M,
    DEPTH_BINS,
    DILATION,
    JACOBIAN_CLAMP,
    LABEL_T,
    SH_C0,
    SH_C1,
    SH_C2,
    SH_C3,
    SIGMA_EXTENT,
    T_MIN,
    RenderResult,
)

BAND_ROWS = 8
# The kernels bake these constants in at compile time, and numba's on-disk cache is keyed on this file
# only: if any of them changes in render.common, this assertion fails until this line is updated too
# (which also invalidates the cache).
assert (ALPHA_MAX, ALPHA_MIN, T_MIN, DILATION, SIGMA_EXTENT, JACOBIAN_CLAMP, LABEL_T, DEPTH_BINS) == (
    0.99, 1.0 / 255.0, 1e-4, 0.3, 3.0, 1.3, 0.5, 1 << 20), "render.common constants changed: update cpu.py"
_POW2_NEG = np.array([2.0**-k for k in range(64)])


@njit(inline="always", fastmath=True, cache=True)
def exp_neg(x: float) -> float:
    """exp(x) for x <= 0, relative error < 2e-6 (degree-7 polynomial for 2^f times a table of 2^-n);
    libm's exp was about half of the rasteriser's time."""
    if x < -40.0:
        return 0.0
    y = x * 1.4426950408889634
    n = math.floor(y)
    f = y - n
    p = 1.0 + f * (0.6931471805599453 + f * (0.2402265069591007 + f * (0.05550410866482158 + f * (
        0.009618129107628477 + f * (0.0013333558146428443 + f * (1.5403530393381606e-4
                                                                 + f * 1.525273380405984e-5))))))
    return p * _POW2_NEG[int(-n)]


_C2 = np.array(SH_C2)
_C3 = np.array(SH_C3)


@njit(parallel=True, cache=True, fastmath=True)
def prepare_kernel(log_scales: np.ndarray, quats: np.ndarray, opacity_logits: np.ndarray, sh: np.ndarray,
                   cov: np.ndarray, reach: np.ndarray, opacity: np.ndarray, rgb0: np.ndarray) -> None:
    """View-independent per-Gaussian terms, computed once per cloud: world covariance (N,6) [xx xy xz yy yz
    zz], 3-sigma reach (N,), opacity (N,), and the degree-0 colour (N,3)."""
    for i in prange(log_scales.shape[0]):
        s0 = math.exp(log_scales[i, 0])
        s1 = math.exp(log_scales[i, 1])
        s2 = math.exp(log_scales[i, 2])
        reach[i] = SIGMA_EXTENT * max(s0, max(s1, s2))
        qw, qx, qy, qz = quats[i, 0], quats[i, 1], quats[i, 2], quats[i, 3]
        qn = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        if qn == 0.0:
            qn = 1.0
            qw = 1.0
        qw /= qn
        qx /= qn
        qy /= qn
        qz /= qn
        m00 = (1 - 2 * (qy * qy + qz * qz)) * s0
        m01 = 2 * (qx * qy - qw * qz) * s1
        m02 = 2 * (qx * qz + qw * qy) * s2
        m10 = 2 * (qx * qy + qw * qz) * s0
        m11 = (1 - 2 * (qx * qx + qz * qz)) * s1
        m12 = 2 * (qy * qz - qw * qx) * s2
        m20 = 2 * (qx * qz - qw * qy) * s0
        m21 = 2 * (qy * qz + qw * qx) * s1
        m22 = (1 - 2 * (qx * qx + qy * qy)) * s2
        cov[i, 0] = m00 * m00 + m01 * m01 + m02 * m02
        cov[i, 1] = m00 * m10 + m01 * m11 + m02 * m12
        cov[i, 2] = m00 * m20 + m01 * m21 + m02 * m22
        cov[i, 3] = m10 * m10 + m11 * m11 + m12 * m12
        cov[i, 4] = m10 * m20 + m11 * m21 + m12 * m22
        cov[i, 5] = m20 * m20 + m21 * m21 + m22 * m22
        opacity[i] = 1.0 / (1.0 + math.exp(-opacity_logits[i]))
        for c in range(3):
            rgb0[i, c] = max(sh[i, 0, c] * SH_C0 + 0.5, 0.0)


@njit(parallel=True, cache=True, fastmath=True)
def project_kernel(means: np.ndarray, cov3: np.ndarray, reach3: np.ndarray, opac: np.ndarray, rgb0: np.ndarray,
                   sh: np.ndarray, R: np.ndarray, t: np.ndarray, centre: np.ndarray, fx: float, fy: float,
                   cx: float, cy: float, width: int, height: int, near: float, far: float,
                   uv: np.ndarray, conic: np.ndarray, depth: np.ndarray, rgb: np.ndarray, opacity: np.ndarray,
                   box: np.ndarray, visible: np.ndarray) -> None:
    """Project N Gaussians. Inputs (N,3) means, (N,6) world covariances, (N,) reach, (N,) opacity, (N,3)
    degree-0 colour, (N,K,3) SH; outputs (N,2), (N,3), (N,), (N,3), (N,), (N,4) int32 [col0, col1, row0,
    row1], (N,) bool."""
    n = means.shape[0]
    k = sh.shape[1]
    limx = JACOBIAN_CLAMP * 0.5 * width / fx
    limy = JACOBIAN_CLAMP * 0.5 * height / fy
    # side planes of the frustum (through the camera centre), normals pointing inside
    nl = math.sqrt(fx * fx + cx * cx)
    nr = math.sqrt(fx * fx + (width - cx) ** 2)
    nt = math.sqrt(fy * fy + cy * cy)
    nb = math.sqrt(fy * fy + (height - cy) ** 2)
    for i in prange(n):
        visible[i] = False
        mx, my, mz = means[i, 0], means[i, 1], means[i, 2]
        x = R[0, 0] * mx + R[0, 1] * my + R[0, 2] * mz + t[0]
        y = R[1, 0] * mx + R[1, 1] * my + R[1, 2] * mz + t[1]
        z = R[2, 0] * mx + R[2, 1] * my + R[2, 2] * mz + t[2]
        if z <= near or z >= far:
            continue
        reach = reach3[i] + 1e-3 * z
        if (fx * x + cx * z) / nl < -reach or ((width - cx) * z - fx * x) / nr < -reach:
            continue
        if (fy * y + cy * z) / nt < -reach or ((height - cy) * z - fy * y) / nb < -reach:
            continue
        tx = z * min(limx, max(-limx, x / z))
        ty = z * min(limy, max(-limy, y / z))
        j00 = fx / z
        j02 = -fx * tx / (z * z)
        j11 = fy / z
        j12 = -fy * ty / (z * z)
        # W = J R (2x3); Sigma_2d = W Sigma W^T
        w00 = j00 * R[0, 0] + j02 * R[2, 0]
        w01 = j00 * R[0, 1] + j02 * R[2, 1]
        w02 = j00 * R[0, 2] + j02 * R[2, 2]
        w10 = j11 * R[1, 0] + j12 * R[2, 0]
        w11 = j11 * R[1, 1] + j12 * R[2, 1]
        w12 = j11 * R[1, 2] + j12 * R[2, 2]
        sxx, sxy, sxz, syy, syz, szz = cov3[i, 0], cov3[i, 1], cov3[i, 2], cov3[i, 3], cov3[i, 4], cov3[i, 5]
        a0 = w00 * sxx + w01 * sxy + w02 * sxz
        a1 = w00 * sxy + w01 * syy + w02 * syz
        a2 = w00 * sxz + w01 * syz + w02 * szz
        b0 = w10 * sxx + w11 * sxy + w12 * sxz
        b1 = w10 * sxy + w11 * syy + w12 * syz
        b2 = w10 * sxz + w11 * syz + w12 * szz
        ca = a0 * w00 + a1 * w01 + a2 * w02 + DILATION
        cb = a0 * w10 + a1 * w11 + a2 * w12
        cc = b0 * w10 + b1 * w11 + b2 * w12 + DILATION
        det = ca * cc - cb * cb
        if det <= 0.0:
            continue
        u = fx * x / z + cx
        v = fy * y / z + cy
        ex = SIGMA_EXTENT * math.sqrt(ca)
        ey = SIGMA_EXTENT * math.sqrt(cc)
        c0 = math.ceil(u - ex - 0.5)
        c1 = math.floor(u + ex - 0.5)
        rr0 = math.ceil(v - ey - 0.5)
        rr1 = math.floor(v + ey - 0.5)
        if c1 < 0 or c0 > width - 1 or rr1 < 0 or rr0 > height - 1 or c1 < c0 or rr1 < rr0:
            continue
        box[i, 0] = max(0, int(c0))
        box[i, 1] = min(width - 1, int(c1))
        box[i, 2] = max(0, int(rr0))
        box[i, 3] = min(height - 1, int(rr1))
        uv[i, 0] = u
        uv[i, 1] = v
        conic[i, 0] = cc / det
        conic[i, 1] = -cb / det
        conic[i, 2] = ca / det
        depth[i] = z
        opacity[i] = opac[i]
        visible[i] = True
        if k == 1:
            rgb[i, 0] = rgb0[i, 0]
            rgb[i, 1] = rgb0[i, 1]
            rgb[i, 2] = rgb0[i, 2]
            continue
        # colour from SH at the world-frame viewing direction
        r_ = sh[i, 0, 0] * SH_C0
        g_ = sh[i, 0, 1] * SH_C0
        b_ = sh[i, 0, 2] * SH_C0
        if k > 1:
            dx, dy, dz = mx - centre[0], my - centre[1], mz - centre[2]
            dn = math.sqrt(dx * dx + dy * dy + dz * dz)
            dx /= dn
            dy /= dn
            dz /= dn
            basis = np.empty(16)
            basis[1] = -SH_C1 * dy
            basis[2] = SH_C1 * dz
            basis[3] = -SH_C1 * dx
            if k > 4:
                xx, yy, zz = dx * dx, dy * dy, dz * dz
                basis[4] = _C2[0] * dx * dy
                basis[5] = _C2[1] * dy * dz
                basis[6] = _C2[2] * (2 * zz - xx - yy)
                basis[7] = _C2[3] * dx * dz
                basis[8] = _C2[4] * (xx - yy)
                if k > 9:
                    basis[9] = _C3[0] * dy * (3 * xx - yy)
                    basis[10] = _C3[1] * dx * dy * dz
                    basis[11] = _C3[2] * dy * (4 * zz - xx - yy)
                    basis[12] = _C3[3] * dz * (2 * zz - 3 * xx - 3 * yy)
                    basis[13] = _C3[4] * dx * (4 * zz - xx - yy)
                    basis[14] = _C3[5] * dz * (xx - yy)
                    basis[15] = _C3[6] * dx * (xx - 3 * yy)
            for j in range(1, k):
                r_ += basis[j] * sh[i, j, 0]
                g_ += basis[j] * sh[i, j, 1]
                b_ += basis[j] * sh[i, j, 2]
        rgb[i, 0] = max(r_ + 0.5, 0.0)
        rgb[i, 1] = max(g_ + 0.5, 0.0)
        rgb[i, 2] = max(b_ + 0.5, 0.0)


@njit(cache=True)
def sort_and_bin(visible: np.ndarray, depth: np.ndarray, box: np.ndarray, height: int, band_rows: int,
                 bin_m: float):
    """Per-band lists of the visible Gaussians, front to back by depth in ``bin_m`` bins, ties by index.

    One counting sort keyed by (band, depth bin) over the (Gaussian, band) pairs. Returns (band_start
    (B+1,) int64, band_list (L,) int32 of Gaussian indices)."""
    n = visible.shape[0]
    lo = np.inf
    hi = -np.inf
    for i in range(n):
        if visible[i]:
            lo = min(lo, depth[i])
            hi = max(hi, depth[i])
    nbins = min(DEPTH_BINS, int((hi - lo) / bin_m) + 1) if hi >= lo else 1
    scale = 1.0 / bin_m
    nbands = (height + band_rows - 1) // band_rows
    counts = np.zeros(nbands * nbins + 1, np.int64)
    for i in range(n):
        if visible[i]:
            kk = min(nbins - 1, max(0, int((depth[i] - lo) * scale)))
            for b in range(box[i, 2] // band_rows, box[i, 3] // band_rows + 1):
                counts[b * nbins + kk + 1] += 1
    for j in range(nbands * nbins):
        counts[j + 1] += counts[j]
    band_start = np.empty(nbands + 1, np.int64)
    for b in range(nbands + 1):
        band_start[b] = counts[b * nbins]
    band_list = np.empty(counts[nbands * nbins], np.int32)
    for i in range(n):
        if visible[i]:
            kk = min(nbins - 1, max(0, int((depth[i] - lo) * scale)))
            for b in range(box[i, 2] // band_rows, box[i, 3] // band_rows + 1):
                j = b * nbins + kk
                band_list[counts[j]] = i
                counts[j] += 1
    return band_start, band_list


@njit(parallel=True, cache=True, fastmath=True)
def rasterise_kernel(band_start: np.ndarray, band_list: np.ndarray, uv: np.ndarray, conic: np.ndarray,
                     depth: np.ndarray, rgb: np.ndarray, opacity: np.ndarray, box: np.ndarray,
                     labels: np.ndarray, width: int, height: int, band_rows: int, n_workers: int,
                     background: np.ndarray, out_rgb: np.ndarray, out_depth: np.ndarray, out_alpha: np.ndarray,
                     out_label: np.ndarray) -> None:
    """Composite front to back. Outputs (H,W,3) uint8 colour over ``background`` (3,), (H,W) f32 expected
    depth (0 where empty), (H,W) f32 alpha, (H,W) uint8 label."""
    nbands = band_start.shape[0] - 1
    for worker in prange(n_workers):
        T = np.empty((band_rows, width))
        col = np.empty((band_rows, width, 3))
        dep = np.empty((band_rows, width))
        lab = np.empty((band_rows, width), np.uint8)
        done = np.empty((band_rows, width), np.bool_)
        row_done = np.empty(band_rows, np.int64)
        for b in range(worker, nbands, n_workers):
            r0 = b * band_rows
            r1 = min(height, r0 + band_rows)  # exclusive
            nrows = r1 - r0
            T[:] = 1.0
            col[:] = 0.0
            dep[:] = 0.0
            lab[:] = 0
            done[:] = False
            row_done[:] = 0
            n_done = 0
            n_pix = nrows * width
            for q in range(band_start[b], band_start[b + 1]):
                g = band_list[q]
                gu = uv[g, 0]
                gv = uv[g, 1]
                ca = conic[g, 0]
                cb = conic[g, 1]
                cc = conic[g, 2]
                op = opacity[g]
                gz = depth[g]
                cr, cg, cbl = rgb[g, 0], rgb[g, 1], rgb[g, 2]
                gl = labels[g]
                ra = max(box[g, 2], r0)
                rb = min(box[g, 3], r1 - 1)
                for row in range(ra, rb + 1):
                    lr = row - r0
                    if row_done[lr] == width:
                        continue
                    dy = row + 0.5 - gv
                    for cj in range(box[g, 0], box[g, 1] + 1):
                        if done[lr, cj]:
                            continue
                        dx = cj + 0.5 - gu
                        power = -0.5 * (ca * dx * dx + cc * dy * dy) - cb * dx * dy
                        if power > 0.0:
                            continue
                        alpha = min(ALPHA_MAX, op * exp_neg(power))
                        if alpha < ALPHA_MIN:
                            continue
                        tt = T[lr, cj]
                        nt = tt * (1.0 - alpha)
                        if nt <= T_MIN:
                            done[lr, cj] = True
                            row_done[lr] += 1
                            n_done += 1
                            continue
                        w = alpha * tt
                        col[lr, cj, 0] += w * cr
                        col[lr, cj, 1] += w * cg
                        col[lr, cj, 2] += w * cbl
                        dep[lr, cj] += w * gz
                        if tt >= LABEL_T and nt < LABEL_T:
                            lab[lr, cj] = gl
                        T[lr, cj] = nt
                if n_done == n_pix:
                    break
            for lr in range(nrows):
                for cj in range(width):
                    tt = T[lr, cj]
                    for c in range(3):
                        v = round((col[lr, cj, c] + tt * background[c]) * 255.0)
                        out_rgb[r0 + lr, cj, c] = min(255.0, max(0.0, v))
                    a = 1.0 - tt
                    out_alpha[r0 + lr, cj] = a
                    out_depth[r0 + lr, cj] = dep[lr, cj] / a if a > 1e-6 else 0.0
                    out_label[r0 + lr, cj] = lab[lr, cj]


def prepare(cloud) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """View-independent terms of ``cloud`` (cached on the cloud; clouds are treated as immutable)."""
    key = (id(cloud.log_scales), id(cloud.quats), id(cloud.opacity_logits), id(cloud.sh), len(cloud))
    cached = getattr(cloud, "_cpu_prepared", None)
    if cached is not None and cached[0] == key:
        return cached[1]
    n = len(cloud)
    out = (np.empty((n, 6), np.float32), np.empty(n, np.float32), np.empty(n, np.float32),
           np.empty((n, 3), np.float32))
    prepare_kernel(cloud.log_scales, cloud.quats, cloud.opacity_logits, cloud.sh, *out)
    cloud._cpu_prepared = (key, out)
    return out


def project(cloud, camera, pose):
    """Stage 1: per-Gaussian screen quantities; returns (uv, conic, depth, rgb, opacity, box, visible)."""
    cov, reach, opac, rgb0 = prepare(cloud)
    r, t = camera.world_to_camera(pose)
    centre = -r.T @ t
    n = len(cloud)
    uv = np.empty((n, 2), np.float32)
    conic = np.empty((n, 3), np.float32)
    depth = np.empty(n, np.float32)
    rgb = np.empty((n, 3), np.float32)
    opacity = np.empty(n, np.float32)
    box = np.empty((n, 4), np.int32)
    visible = np.empty(n, np.bool_)
    px, py = camera.principal_point
    project_kernel(cloud.means, cov, reach, opac, rgb0, cloud.sh, r, t, centre,
                   camera.fx, camera.fy, px, py, camera.width, camera.height, camera.near, camera.far,
                   uv, conic, depth, rgb, opacity, box, visible)
    return uv, conic, depth, rgb, opacity, box, visible


def render_cpu(cloud, camera, pose, background=(0.0, 0.0, 0.0)) -> RenderResult:
    h, w = camera.height, camera.width
    uv, conic, depth, rgb, opacity, box, visible = project(cloud, camera, pose)
    band_start, band_list = sort_and_bin(visible, depth, box, h, BAND_ROWS, DEPTH_BIN_M)
    res = RenderResult(np.empty((h, w, 3), np.uint8), np.empty((h, w), np.float32), np.empty((h, w), np.float32),
                       np.empty((h, w), np.uint8))
    rasterise_kernel(band_start, band_list, uv, conic, depth, rgb, opacity, box, cloud.labels, w, h, BAND_ROWS,
                     max(1, numba.get_num_threads()) * 4, np.asarray(background, np.float64), res.rgb, res.depth,
                     res.alpha, res.label)
    return res

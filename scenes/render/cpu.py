"""CPU backend: numba kernels, staged project -> sort/bin -> rasterise (maths in ``render.common``).

Loop order (see DESIGN.md performance notes): our scenes are dense, coplanar, small splats, so each
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
    finish,
)

BAND_ROWS = 8
_C2 = np.array(SH_C2)
_C3 = np.array(SH_C3)


@njit(parallel=True, cache=True, fastmath=True)
def project_kernel(means: np.ndarray, log_scales: np.ndarray, quats: np.ndarray, opacity_logits: np.ndarray,
                   sh: np.ndarray, R: np.ndarray, t: np.ndarray, centre: np.ndarray, fx: float, fy: float,
                   cx: float, cy: float, width: int, height: int, near: float, far: float,
                   uv: np.ndarray, conic: np.ndarray, depth: np.ndarray, rgb: np.ndarray, opacity: np.ndarray,
                   box: np.ndarray, visible: np.ndarray) -> None:
    """Project N Gaussians. Inputs (N,3), (N,3), (N,4), (N,), (N,K,3); outputs (N,2), (N,3), (N,), (N,3),
    (N,), (N,4) int32 [col0, col1, row0, row1], (N,) bool."""
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
        s0 = math.exp(log_scales[i, 0])
        s1 = math.exp(log_scales[i, 1])
        s2 = math.exp(log_scales[i, 2])
        reach = SIGMA_EXTENT * max(s0, max(s1, s2)) + 1e-3 * z
        if (fx * x + cx * z) / nl < -reach or ((width - cx) * z - fx * x) / nr < -reach:
            continue
        if (fy * y + cy * z) / nt < -reach or ((height - cy) * z - fy * y) / nb < -reach:
            continue
        qw, qx, qy, qz = quats[i, 0], quats[i, 1], quats[i, 2], quats[i, 3]
        qn = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        if qn == 0.0:
            continue
        qw /= qn
        qx /= qn
        qy /= qn
        qz /= qn
        r00 = 1 - 2 * (qy * qy + qz * qz)
        r01 = 2 * (qx * qy - qw * qz)
        r02 = 2 * (qx * qz + qw * qy)
        r10 = 2 * (qx * qy + qw * qz)
        r11 = 1 - 2 * (qx * qx + qz * qz)
        r12 = 2 * (qy * qz - qw * qx)
        r20 = 2 * (qx * qz - qw * qy)
        r21 = 2 * (qy * qz + qw * qx)
        r22 = 1 - 2 * (qx * qx + qy * qy)
        # M = Rq diag(s) (world); A = J R M (2x3)
        m00, m01, m02 = r00 * s0, r01 * s1, r02 * s2
        m10, m11, m12 = r10 * s0, r11 * s1, r12 * s2
        m20, m21, m22 = r20 * s0, r21 * s1, r22 * s2
        tx = z * min(limx, max(-limx, x / z))
        ty = z * min(limy, max(-limy, y / z))
        j00 = fx / z
        j02 = -fx * tx / (z * z)
        j11 = fy / z
        j12 = -fy * ty / (z * z)
        # W = J R (2x3)
        w00 = j00 * R[0, 0] + j02 * R[2, 0]
        w01 = j00 * R[0, 1] + j02 * R[2, 1]
        w02 = j00 * R[0, 2] + j02 * R[2, 2]
        w10 = j11 * R[1, 0] + j12 * R[2, 0]
        w11 = j11 * R[1, 1] + j12 * R[2, 1]
        w12 = j11 * R[1, 2] + j12 * R[2, 2]
        a0 = w00 * m00 + w01 * m10 + w02 * m20
        a1 = w00 * m01 + w01 * m11 + w02 * m21
        a2 = w00 * m02 + w01 * m12 + w02 * m22
        b0 = w10 * m00 + w11 * m10 + w12 * m20
        b1 = w10 * m01 + w11 * m11 + w12 * m21
        b2 = w10 * m02 + w11 * m12 + w12 * m22
        ca = a0 * a0 + a1 * a1 + a2 * a2 + DILATION
        cb = a0 * b0 + a1 * b1 + a2 * b2
        cc = b0 * b0 + b1 * b1 + b2 * b2 + DILATION
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
        opacity[i] = 1.0 / (1.0 + math.exp(-opacity_logits[i]))
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
        visible[i] = True


@njit(cache=True)
def sort_and_bin(visible: np.ndarray, depth: np.ndarray, box: np.ndarray, height: int, band_rows: int,
                 bin_m: float):
    """Counting sort of the visible Gaussians by depth in ``bin_m`` bins (stable), then per-band lists.

    Returns (band_start (B+1,) int64, band_list (L,) int32 of Gaussian indices, front to back per band)."""
    n = visible.shape[0]
    m = 0
    lo = np.inf
    hi = -np.inf
    for i in range(n):
        if visible[i]:
            m += 1
            lo = min(lo, depth[i])
            hi = max(hi, depth[i])
    idx = np.empty(m, np.int32)
    keys = np.empty(m, np.int32)
    nbins = min(DEPTH_BINS, int((hi - lo) / bin_m) + 1) if m > 0 else 1
    scale = 1.0 / bin_m
    counts = np.zeros(nbins + 1, np.int64)
    j = 0
    for i in range(n):
        if visible[i]:
            kk = int((depth[i] - lo) * scale)
            kk = min(nbins - 1, max(0, kk))
            idx[j] = i
            keys[j] = kk
            counts[kk + 1] += 1
            j += 1
    for b in range(nbins):
        counts[b + 1] += counts[b]
    order = np.empty(m, np.int32)
    for j in range(m):
        kk = keys[j]
        order[counts[kk]] = idx[j]
        counts[kk] += 1
    nbands = (height + band_rows - 1) // band_rows
    band_start = np.zeros(nbands + 1, np.int64)
    for j in range(m):
        g = order[j]
        for b in range(box[g, 2] // band_rows, box[g, 3] // band_rows + 1):
            band_start[b + 1] += 1
    for b in range(nbands):
        band_start[b + 1] += band_start[b]
    fill = band_start[:-1].copy()
    band_list = np.empty(band_start[nbands], np.int32)
    for j in range(m):
        g = order[j]
        for b in range(box[g, 2] // band_rows, box[g, 3] // band_rows + 1):
            band_list[fill[b]] = g
            fill[b] += 1
    return band_start, band_list


@njit(parallel=True, cache=True, fastmath=True)
def rasterise_kernel(band_start: np.ndarray, band_list: np.ndarray, uv: np.ndarray, conic: np.ndarray,
                     depth: np.ndarray, rgb: np.ndarray, opacity: np.ndarray, box: np.ndarray,
                     labels: np.ndarray, width: int, height: int, band_rows: int, n_workers: int,
                     out_rgb: np.ndarray, out_depth: np.ndarray, out_T: np.ndarray, out_label: np.ndarray) -> None:
    """Composite front to back. Outputs (H,W,3) f64 premultiplied colour, (H,W) f64 sum(w z), (H,W) f64
    final transmittance, (H,W) uint8 label."""
    nbands = band_start.shape[0] - 1
    for worker in prange(n_workers):
        T = np.empty((band_rows, width))
        col = np.empty((band_rows, width, 3))
        dep = np.empty((band_rows, width))
        lab = np.empty((band_rows, width), np.uint8)
        done = np.empty((band_rows, width), np.bool_)
        for b in range(worker, nbands, n_workers):
            r0 = b * band_rows
            r1 = min(height, r0 + band_rows)  # exclusive
            nrows = r1 - r0
            T[:] = 1.0
            col[:] = 0.0
            dep[:] = 0.0
            lab[:] = 0
            done[:] = False
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
                    dy = row + 0.5 - gv
                    for cj in range(box[g, 0], box[g, 1] + 1):
                        if done[lr, cj]:
                            continue
                        dx = cj + 0.5 - gu
                        power = -0.5 * (ca * dx * dx + cc * dy * dy) - cb * dx * dy
                        if power > 0.0:
                            continue
                        alpha = min(ALPHA_MAX, op * math.exp(power))
                        if alpha < ALPHA_MIN:
                            continue
                        tt = T[lr, cj]
                        nt = tt * (1.0 - alpha)
                        if nt <= T_MIN:
                            done[lr, cj] = True
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
                    out_rgb[r0 + lr, cj, 0] = col[lr, cj, 0]
                    out_rgb[r0 + lr, cj, 1] = col[lr, cj, 1]
                    out_rgb[r0 + lr, cj, 2] = col[lr, cj, 2]
                    out_depth[r0 + lr, cj] = dep[lr, cj]
                    out_T[r0 + lr, cj] = T[lr, cj]
                    out_label[r0 + lr, cj] = lab[lr, cj]


def project(cloud, camera, pose):
    """Stage 1: per-Gaussian screen quantities; returns (uv, conic, depth, rgb, opacity, box, visible)."""
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
    project_kernel(cloud.means, cloud.log_scales, cloud.quats, cloud.opacity_logits, cloud.sh, r, t, centre,
                   camera.fx, camera.fy, px, py, camera.width, camera.height, camera.near, camera.far,
                   uv, conic, depth, rgb, opacity, box, visible)
    return uv, conic, depth, rgb, opacity, box, visible


def render_cpu(cloud, camera, pose, background=(0.0, 0.0, 0.0)) -> RenderResult:
    h, w = camera.height, camera.width
    uv, conic, depth, rgb, opacity, box, visible = project(cloud, camera, pose)
    band_start, band_list = sort_and_bin(visible, depth, box, h, BAND_ROWS, DEPTH_BIN_M)
    out_rgb = np.empty((h, w, 3))
    out_depth = np.empty((h, w))
    out_T = np.empty((h, w))
    out_label = np.empty((h, w), np.uint8)
    rasterise_kernel(band_start, band_list, uv, conic, depth, rgb, opacity, box, cloud.labels, w, h, BAND_ROWS,
                     max(1, numba.get_num_threads()) * 4, out_rgb, out_depth, out_T, out_label)
    return finish(out_rgb, out_depth, 1.0 - out_T, out_label, out_T, background)

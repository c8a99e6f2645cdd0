"""Torch backend (CUDA when available, CPU otherwise): same stages and maths as ``render.common``.

Rasterisation is vectorised over (Gaussian, pixel) pairs: every visible Gaussian emits the pixels of its
3-sigma box in depth order, pairs are stably sorted by pixel, and per-pixel transmittance is an exclusive
cumulative product (a float64 cumulative sum of log(1 - alpha)). Because transmittance only decreases,
"stop when the next transmittance would be <= 1e-4" is the same as keeping the pairs whose inclusive
transmittance stays above 1e-4. Rows are processed in chunks to bound memory.
"""

from __future__ import annotations

import numpy as np
import torch

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

MAX_PAIRS_PER_CHUNK = 4_000_000


def _default_device() -> torch.device:
    return torch.device("cuda" if torch.cuda.is_available() else "cpu")


def _sh_colour(sh: torch.Tensor, dirs: torch.Tensor) -> torch.Tensor:
    k = sh.shape[1]
    out = SH_C0 * sh[:, 0]
    if k > 1:
        x, y, z = dirs[:, 0:1], dirs[:, 1:2], dirs[:, 2:3]
        out = out - SH_C1 * y * sh[:, 1] + SH_C1 * z * sh[:, 2] - SH_C1 * x * sh[:, 3]
        if k > 4:
            xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
            out = (out + SH_C2[0] * xy * sh[:, 4] + SH_C2[1] * yz * sh[:, 5]
                   + SH_C2[2] * (2 * zz - xx - yy) * sh[:, 6] + SH_C2[3] * xz * sh[:, 7]
                   + SH_C2[4] * (xx - yy) * sh[:, 8])
            if k > 9:
                out = (out + SH_C3[0] * y * (3 * xx - yy) * sh[:, 9] + SH_C3[1] * xy * z * sh[:, 10]
                       + SH_C3[2] * y * (4 * zz - xx - yy) * sh[:, 11]
                       + SH_C3[3] * z * (2 * zz - 3 * xx - 3 * yy) * sh[:, 12]
                       + SH_C3[4] * x * (4 * zz - xx - yy) * sh[:, 13] + SH_C3[5] * z * (xx - yy) * sh[:, 14]
                       + SH_C3[6] * x * (xx - 3 * yy) * sh[:, 15])
    return torch.clamp(out + 0.5, min=0.0)


def project_torch(means: torch.Tensor, log_scales: torch.Tensor, quats: torch.Tensor, opacity_logits: torch.Tensor,
                  sh: torch.Tensor, R: torch.Tensor, t: torch.Tensor, centre: torch.Tensor, camera) -> dict:
    """Stage 1 on (N,3), (N,3), (N,4), (N,), (N,K,3) tensors; returns a dict of the visible Gaussians'
    (M,) index, (M,2) uv, (M,3) conic, (M,) depth, (M,3) rgb, (M,) opacity, (M,4) int box."""
    w, h = camera.width, camera.height
    fx, fy = camera.fx, camera.fy
    cx, cy = camera.principal_point
    pc = means @ R.T + t
    z = pc[:, 2]
    ok = (z > camera.near) & (z < camera.far)
    zs = torch.where(ok, z, torch.ones_like(z))
    limx, limy = JACOBIAN_CLAMP * 0.5 * w / fx, JACOBIAN_CLAMP * 0.5 * h / fy
    tx = zs * torch.clamp(pc[:, 0] / zs, -limx, limx)
    ty = zs * torch.clamp(pc[:, 1] / zs, -limy, limy)
    q = quats / torch.linalg.norm(quats, dim=1, keepdim=True)
    qw, qx, qy, qz = q.unbind(1)
    rq = torch.stack([
        torch.stack([1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qw * qz), 2 * (qx * qz + qw * qy)], -1),
        torch.stack([2 * (qx * qy + qw * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qw * qx)], -1),
        torch.stack([2 * (qx * qz - qw * qy), 2 * (qy * qz + qw * qx), 1 - 2 * (qx * qx + qy * qy)], -1)], 1)
    m = rq * torch.exp(log_scales)[:, None, :]
    n = means.shape[0]
    jac = torch.zeros((n, 2, 3), dtype=means.dtype, device=means.device)
    jac[:, 0, 0] = fx / zs
    jac[:, 0, 2] = -fx * tx / zs**2
    jac[:, 1, 1] = fy / zs
    jac[:, 1, 2] = -fy * ty / zs**2
    a = (jac @ R) @ m
    cov = a @ a.transpose(1, 2)
    ca, cb, cc = cov[:, 0, 0] + DILATION, cov[:, 0, 1], cov[:, 1, 1] + DILATION
    det = ca * cc - cb * cb
    ok = ok & (det > 0)
    u = fx * pc[:, 0] / zs + cx
    v = fy * pc[:, 1] / zs + cy
    ex = SIGMA_EXTENT * torch.sqrt(torch.clamp(ca, min=0))
    ey = SIGMA_EXTENT * torch.sqrt(torch.clamp(cc, min=0))
    c0 = torch.ceil(u - ex - 0.5)
    c1 = torch.floor(u + ex - 0.5)
    r0 = torch.ceil(v - ey - 0.5)
    r1 = torch.floor(v + ey - 0.5)
    ok = ok & (c1 >= 0) & (c0 <= w - 1) & (r1 >= 0) & (r0 <= h - 1) & (c1 >= c0) & (r1 >= r0)
    idx = torch.nonzero(ok).squeeze(1)
    dirs = means[idx] - centre
    dirs = dirs / torch.linalg.norm(dirs, dim=1, keepdim=True)
    dd = det[idx]
    box = torch.stack([torch.clamp(c0[idx], 0, w - 1), torch.clamp(c1[idx], 0, w - 1),
                       torch.clamp(r0[idx], 0, h - 1), torch.clamp(r1[idx], 0, h - 1)], 1).long()
    return {"index": idx, "uv": torch.stack([u[idx], v[idx]], 1),
            "conic": torch.stack([cc[idx] / dd, -cb[idx] / dd, ca[idx] / dd], 1), "depth": z[idx],
            "rgb": _sh_colour(sh[idx], dirs), "opacity": torch.sigmoid(opacity_logits[idx]), "box": box}


def sort_torch(depth: torch.Tensor) -> torch.Tensor:
    """Stage 2: front-to-back order by depth in ``DEPTH_BIN_M`` bins, ties by index (same key as the CPU)."""
    if depth.numel() == 0:
        return torch.zeros(0, dtype=torch.long, device=depth.device)
    key = torch.clamp(((depth - depth.min()) * (1.0 / DEPTH_BIN_M)).long(), 0, DEPTH_BINS - 1)
    return torch.sort(key, stable=True).indices


def rasterise_torch(p: dict, labels: torch.Tensor, width: int, height: int, background) -> tuple:
    """Stage 3: returns (rgb (H,W,3), sum w z (H,W), alpha (H,W), label (H,W)) tensors."""
    dev = p["uv"].device
    npix = width * height
    col = torch.zeros((npix, 3), dtype=torch.float64, device=dev)
    dep = torch.zeros(npix, dtype=torch.float64, device=dev)
    acc = torch.zeros(npix, dtype=torch.float64, device=dev)
    lab = torch.zeros(npix, dtype=torch.uint8, device=dev)
    box = p["box"]
    nx = box[:, 1] - box[:, 0] + 1
    # split into row chunks so that the number of (Gaussian, pixel) pairs stays bounded
    rows_per_chunk = height
    total = int((nx * (box[:, 3] - box[:, 2] + 1)).sum()) if box.numel() else 0
    if total > MAX_PAIRS_PER_CHUNK:
        rows_per_chunk = max(1, int(height * MAX_PAIRS_PER_CHUNK / total))
    for ra in range(0, height, rows_per_chunk):
        rb = min(height, ra + rows_per_chunk) - 1
        y0 = torch.clamp(box[:, 2], min=ra)
        y1 = torch.clamp(box[:, 3], max=rb)
        sel = torch.nonzero(y1 >= y0).squeeze(1)  # keeps depth order
        if sel.numel() == 0:
            continue
        ny = (y1 - y0 + 1)[sel]
        nxs = nx[sel]
        cnt = nxs * ny
        g = torch.repeat_interleave(sel, cnt)
        start = torch.cumsum(cnt, 0) - cnt
        k = torch.arange(int(cnt.sum()), device=dev) - torch.repeat_interleave(start, cnt)
        nxg = nx[g]
        px = box[g, 0] + k % nxg
        py = y0[g] + torch.div(k, nxg, rounding_mode="floor")
        dx = px.to(p["uv"].dtype) + 0.5 - p["uv"][g, 0]
        dy = py.to(p["uv"].dtype) + 0.5 - p["uv"][g, 1]
        con = p["conic"][g]
        power = -0.5 * (con[:, 0] * dx * dx + con[:, 2] * dy * dy) - con[:, 1] * dx * dy
        alpha = torch.clamp(p["opacity"][g] * torch.exp(power), max=ALPHA_MAX)
        live = (power <= 0) & (alpha >= ALPHA_MIN)
        alpha = torch.where(live, alpha, torch.zeros_like(alpha)).double()
        pix = py * width + px
        order = torch.sort(pix, stable=True).indices
        pix, alpha, g = pix[order], alpha[order], g[order]
        log1m = torch.log1p(-alpha)
        cum = torch.cumsum(log1m, 0)
        seg_start = torch.ones_like(pix, dtype=torch.bool)
        seg_start[1:] = pix[1:] != pix[:-1]
        first = torch.nonzero(seg_start).squeeze(1)
        seg_id = torch.cumsum(seg_start.long(), 0) - 1
        base = (cum[first] - log1m[first])[seg_id]
        incl = cum - base
        t_after = torch.exp(incl)
        t_before = torch.exp(incl - log1m)
        use = (alpha > 0) & (t_after > T_MIN)
        wgt = torch.where(use, alpha * t_before, torch.zeros_like(alpha))
        col.index_add_(0, pix, wgt[:, None] * p["rgb"][g].double())
        dep.index_add_(0, pix, wgt * p["depth"][g].double())
        acc.index_add_(0, pix, wgt)
        cross = use & (t_before >= LABEL_T) & (t_after < LABEL_T)
        lab[pix[cross]] = labels[p["index"][g[cross]]]
    bg = torch.tensor(background, dtype=torch.float64, device=dev)
    col = col + (1.0 - acc)[:, None] * bg
    return col.view(height, width, 3), dep.view(height, width), acc.view(height, width), lab.view(height, width)


def cloud_tensors(cloud, dev: torch.device) -> tuple[torch.Tensor, ...]:
    """(means, log_scales, quats, opacity_logits, sh, labels) on ``dev``, cached on the cloud per device so
    that repeated renders do not copy the cloud to the GPU every frame (clouds are treated as immutable)."""
    key = (id(cloud.means), id(cloud.log_scales), id(cloud.quats), id(cloud.opacity_logits), id(cloud.sh),
           id(cloud.labels), len(cloud), str(dev))
    cache = getattr(cloud, "_torch_tensors", None)
    if cache is not None and cache[0] == key:
        return cache[1]
    f32 = {"dtype": torch.float32, "device": dev}
    out = tuple(torch.as_tensor(a, **f32) for a in (cloud.means, cloud.log_scales, cloud.quats,
                                                      cloud.opacity_logits, cloud.sh))
    out = out + (torch.as_tensor(cloud.labels, device=dev),)
    cloud._torch_tensors = (key, out)
    return out


def render_torch(cloud, camera, pose, background=(0.0, 0.0, 0.0), device: str | None = None) -> RenderResult:
    dev = torch.device(device) if device else _default_device()
    r, t = camera.world_to_camera(pose)
    centre = -r.T @ t
    f32 = {"dtype": torch.float32, "device": dev}
    means, log_scales, quats, opacity_logits, sh, labels = cloud_tensors(cloud, dev)
    p = project_torch(means, log_scales, quats, opacity_logits, sh, torch.as_tensor(r, **f32),
                      torch.as_tensor(t, **f32), torch.as_tensor(centre, **f32), camera)
    order = sort_torch(p["depth"])
    p = {k: v[order] for k, v in p.items()}
    col, dep, acc, lab = rasterise_torch(p, labels, camera.width, camera.height, background)
    rgb8 = torch.clamp(torch.round(col * 255.0), 0, 255).to(torch.uint8)
    depth = torch.where(acc > 1e-6, dep / torch.clamp(acc, min=1e-12), torch.zeros_like(dep))
    return RenderResult(rgb8.cpu().numpy(), depth.float().cpu().numpy(), acc.float().cpu().numpy(),
                        lab.cpu().numpy().astype(np.uint8))


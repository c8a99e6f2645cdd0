"""Synthetic flow fields and image pairs for the companion tests (no renderer needed)."""

from __future__ import annotations

import cv2
import numpy as np

FOCAL_320x240 = 120.0 / np.tan(np.radians(37.5))   # flowgap default camera: 320×240, vertical FOV 75°
SMALL = (60, 80)    # (H, W) of the small frames the detector's and the servo's detail tests use: they keep them fast


def box(x0: int, y0: int, x1: int, y1: int, shape: tuple[int, int] = SMALL) -> np.ndarray:
    """Bool mask of pixels x0..x1-1, y0..y1-1."""
    m = np.zeros(shape, bool)
    m[y0:y1, x0:x1] = True
    return m


def translation_flow(h: int, w: int, t: tuple[float, float, float], polygon, *, rho_near: float = 0.5,
                     rho_far: float = 0.05, focal: float = FOCAL_320x240, scale: float = 0.3,
                     occlusion: bool = False):
    """Flow of a translating camera (camera axes) seeing a near wall with a far region behind ``polygon``.

    Returns (flow H×W×2 float32, gap mask H×W bool).  ρ = 1/Z: near wall ``rho_near``, far ``rho_far``.
    ``occlusion``: as a flow estimator sees it, the far pixels the wall covers in the second frame (p + d(p)
    outside the polygon, d = the far surface's displacement against the wall's) have no match and take the
    wall's flow; False gives every far pixel its true flow.
    """
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    xs -= (w - 1) / 2.0
    ys -= (h - 1) / 2.0
    gu = xs * t[2] - focal * t[0]
    gv = ys * t[2] - focal * t[1]
    mask = np.zeros((h, w), np.uint8)
    cv2.fillPoly(mask, [np.asarray(polygon, np.int32)], 1)
    far = mask > 0
    if occlusion:
        step = (rho_far - rho_near) * scale
        lands = cv2.remap(mask, (xs + (w - 1) / 2.0 + step * gu).astype(np.float32),
                          (ys + (h - 1) / 2.0 + step * gv).astype(np.float32), cv2.INTER_NEAREST,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        far &= lands > 0
    rho = np.where(far, rho_far, rho_near)
    flow = np.stack([gu, gv], -1) * (rho * scale)[..., None]
    return flow.astype(np.float32), mask.astype(bool)


def iou(a: np.ndarray, b: np.ndarray) -> float:
    union = np.logical_or(a, b).sum()
    return float(np.logical_and(a, b).sum() / union) if union else 1.0


def textured_pair(h: int, w: int, shift: tuple[float, float], seed: int = 0):
    """A smooth random RGB texture and the same texture moved by ``shift`` = (du, dv) pixels."""
    rng = np.random.default_rng(seed)
    pad = 20
    noise = rng.random((h + 2 * pad, w + 2 * pad, 3)).astype(np.float32)
    tex = cv2.GaussianBlur(noise, (0, 0), 2.0)
    tex = (tex - tex.min()) / (tex.max() - tex.min()) * 255.0
    moved = cv2.warpAffine(tex, np.float32([[1, 0, shift[0]], [0, 1, shift[1]]]), tex.shape[1::-1],
                           flags=cv2.INTER_LINEAR)   # moved(x + d) = tex(x)
    crop = (slice(pad, pad + h), slice(pad, pad + w))
    return tex[crop].astype(np.uint8), moved[crop].astype(np.uint8)

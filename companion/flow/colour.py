"""Middlebury / Baker et al. (2011) flow colour coding.

Hue = flow direction, saturation = magnitude normalised by the frame's largest magnitude (as the paper
does); zero flow is white, the largest flow pointing right (+u) is pure red.  The wheel has 55 colours:
RY 15, YG 6, GC 4, CB 11, BM 13, MR 6.  Flow beyond the normalising magnitude (only possible with an
explicit ``max_magnitude``) is darkened to 75 %, as in the reference code.
"""

from __future__ import annotations

import numpy as np

WHEEL_SEGMENTS = (("RY", 15), ("YG", 6), ("GC", 4), ("CB", 11), ("BM", 13), ("MR", 6))


def colour_wheel() -> np.ndarray:
    """The 55×3 RGB colour wheel (float, 0..255)."""
    ry, yg, gc, cb, bm, mr = (n for _, n in WHEEL_SEGMENTS)
    wheel = np.zeros((ry + yg + gc + cb + bm + mr, 3))
    col = 0

    def ramp(n: int) -> np.ndarray:
        return np.floor(255 * np.arange(n) / n)

    wheel[col:col + ry, 0] = 255
    wheel[col:col + ry, 1] = ramp(ry)
    col += ry
    wheel[col:col + yg, 0] = 255 - ramp(yg)
    wheel[col:col + yg, 1] = 255
    col += yg
    wheel[col:col + gc, 1] = 255
    wheel[col:col + gc, 2] = ramp(gc)
    col += gc
    wheel[col:col + cb, 1] = 255 - ramp(cb)
    wheel[col:col + cb, 2] = 255
    col += cb
    wheel[col:col + bm, 2] = 255
    wheel[col:col + bm, 0] = ramp(bm)
    col += bm
    wheel[col:col + mr, 2] = 255 - ramp(mr)
    wheel[col:col + mr, 0] = 255
    return wheel


_WHEEL = colour_wheel()


def flow_to_colour(flow: np.ndarray, *, max_magnitude: float | None = None, bgr: bool = False) -> np.ndarray:
    """Colour an H×W×2 flow field; returns H×W×3 uint8, RGB unless ``bgr``.

    ``max_magnitude``: normalising magnitude; default the largest finite magnitude in this frame.
    Non-finite flow is shown black.
    """
    flow = np.asarray(flow, dtype=np.float64)
    if flow.ndim != 3 or flow.shape[2] != 2:
        raise ValueError(f"flow must be H×W×2, got {flow.shape}")
    u, v = flow[..., 0], flow[..., 1]
    bad = ~(np.isfinite(u) & np.isfinite(v))
    u = np.where(bad, 0.0, u)
    v = np.where(bad, 0.0, v)
    rad = np.hypot(u, v)
    norm = float(rad.max()) if max_magnitude is None else float(max_magnitude)
    eps = 1e-5
    u, v, rad = u / (norm + eps), v / (norm + eps), rad / (norm + eps)

    ncols = _WHEEL.shape[0]
    angle = np.arctan2(-v, -u) / np.pi                       # -1..1, +u maps to -1 -> wheel index 0 (red)
    fk = (angle + 1) / 2 * (ncols - 1)
    k0 = np.floor(fk).astype(np.int64)
    k1 = k0 + 1
    k1[k1 == ncols] = 0
    f = (fk - k0)[..., None]
    col = (1 - f) * _WHEEL[k0] / 255.0 + f * _WHEEL[k1] / 255.0
    inside = (rad <= 1)[..., None]
    col = np.where(inside, 1 - rad[..., None] * (1 - col), col * 0.75)
    out = np.floor(255 * col).astype(np.uint8)
    out[bad] = 0
    return out[..., ::-1].copy() if bgr else out

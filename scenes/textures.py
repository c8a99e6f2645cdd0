"""Procedural surface textures, deterministic from a seed (numpy + OpenCV, no global randomness).

Every generator returns a float32 RGB image in [0, 1] of shape (H, W, 3) covering ``width_m`` x
``height_m`` metres at ``px_per_m``. Row 0 is the top edge (most negative z for a wall), column 0 the
left edge (most negative y), so a wall texture looks unmirrored from the start pose looking along +x.
"""

from __future__ import annotations

import cv2
import numpy as np

DEFAULT_PX_PER_M = 150.0


def _noise(rng: np.random.Generator, h: int, w: int, cell_px: float) -> np.ndarray:
    """Smooth value noise in roughly [-1, 1] with features about ``cell_px`` pixels wide."""
    gh, gw = max(2, int(np.ceil(h / cell_px)) + 2), max(2, int(np.ceil(w / cell_px)) + 2)
    g = rng.standard_normal((gh, gw)).astype(np.float32)
    big = cv2.resize(g, (int(gw * cell_px), int(gh * cell_px)), interpolation=cv2.INTER_CUBIC)
    return big[:h, :w]


def _fbm(rng: np.random.Generator, h: int, w: int, cell_px: float, octaves: int = 4) -> np.ndarray:
    out = np.zeros((h, w), np.float32)
    amp, total = 1.0, 0.0
    for k in range(octaves):
        out += amp * _noise(rng, h, w, max(1.0, cell_px / 2**k))
        total += amp
        amp *= 0.55
    return out / total


def brick(rng: np.random.Generator, h: int, w: int, ppm: float, scale: float = 1.0) -> np.ndarray:
    bw, bh, mortar = 0.215 * scale * ppm, 0.065 * scale * ppm, 0.010 * scale * ppm
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    row = np.floor(yy / (bh + mortar)).astype(np.int64)
    xo = xx + (row % 2) * (bw + mortar) / 2
    col = np.floor(xo / (bw + mortar)).astype(np.int64)
    fy = yy - row * (bh + mortar)
    fx = xo - col * (bw + mortar)
    is_mortar = (fy >= bh) | (fx >= bw)
    n_r, n_c = int(row.max()) + 1, int(col.max()) + 1
    base = np.array([0.55, 0.27, 0.20], np.float32)
    per = base * (1 + 0.22 * rng.standard_normal((n_r, n_c, 1)).astype(np.float32))
    per += 0.04 * rng.standard_normal((n_r, n_c, 3)).astype(np.float32)
    img = per[row, col]
    grain = _fbm(rng, h, w, 0.03 * ppm * scale, 3)[..., None]
    img = img * (1 + 0.18 * grain) + 0.04 * rng.standard_normal((h, w, 1)).astype(np.float32)
    mortar_col = np.array([0.68, 0.65, 0.60], np.float32) * (1 + 0.08 * grain)
    img = np.where(is_mortar[..., None], mortar_col, img)
    return img


def granite(rng: np.random.Generator, h: int, w: int, ppm: float, scale: float = 1.0) -> np.ndarray:
    base = np.array([0.58, 0.52, 0.50], np.float32)
    img = np.broadcast_to(base, (h, w, 3)).copy()
    img *= (1 + 0.10 * _fbm(rng, h, w, 0.4 * ppm * scale, 3))[..., None]
    # multi-scale speckle: dark (biotite), pink (feldspar), white (quartz) grains of several sizes
    for colour, frac, size in (((0.12, 0.11, 0.12), 0.22, 0.012), ((0.72, 0.50, 0.45), 0.20, 0.02),
                               ((0.88, 0.87, 0.85), 0.15, 0.008), ((0.30, 0.28, 0.30), 0.15, 0.005)):
        n = _noise(rng, h, w, max(1.5, size * ppm * scale))
        thr = np.quantile(n[:: max(1, h // 64), :: max(1, w // 64)], 1 - frac)
        m = np.clip((n - thr) * 6.0, 0, 1)[..., None]
        img = img * (1 - m) + np.asarray(colour, np.float32) * m
    img += 0.05 * rng.standard_normal((h, w, 1)).astype(np.float32)
    return img


_WORDS = ("the", "city", "council", "voted", "market", "rain", "news", "report", "said", "world", "daily",
          "today", "mayor", "bridge", "river", "trade", "sport", "team", "win", "police", "school", "price",
          "storm", "north", "plan", "vote", "fund", "health", "road", "train", "music", "art", "film")


def newspaper(rng: np.random.Generator, h: int, w: int, ppm: float, scale: float = 1.0) -> np.ndarray:
    img = np.full((h, w), 219, np.uint8)
    page_w, page_h = int(0.55 * ppm * scale), int(0.75 * ppm * scale)
    margin = max(2, int(0.025 * ppm * scale))
    line_px = max(4, int(0.022 * ppm * scale))
    for py in range(-int(rng.integers(0, page_h)), h, page_h):
        for px in range(-int(rng.integers(0, page_w)), w, page_w):
            cv2.rectangle(img, (px, py), (px + page_w - 1, py + page_h - 1), int(204 + 13 * rng.random()), -1)
            y = py + margin
            # headline
            head_h = int(line_px * rng.uniform(2.0, 3.0))
            words = " ".join(rng.choice(_WORDS, size=int(rng.integers(2, 4)))).upper()
            cv2.putText(img, words, (px + margin, y + head_h), cv2.FONT_HERSHEY_DUPLEX, head_h / 24.0, 20,
                        max(1, head_h // 8), cv2.LINE_AA)
            y += head_h + line_px
            ncol = int(rng.integers(2, 5))
            col_w = (page_w - 2 * margin) // ncol
            for c in range(ncol):
                cx, cy = px + margin + c * col_w, y
                while cy < py + page_h - margin - line_px:
                    if rng.random() < 0.08:  # photo block
                        ph = int(line_px * rng.uniform(4, 9))
                        photo = 128 + 90 * _fbm(rng, ph, col_w - 4, max(2.0, col_w / 5), 3)
                        photo = np.clip(photo, 0, 255).astype(np.uint8)
                        y0, y1 = max(cy, 0), min(cy + ph, h, py + page_h - margin)
                        x0, x1 = max(cx, 0), min(cx + col_w - 4, w)
                        if y1 > y0 and x1 > x0:
                            img[y0:y1, x0:x1] = photo[y0 - cy:y1 - cy, x0 - cx:x1 - cx]
                        cy += ph + line_px
                        continue
                    text = " ".join(rng.choice(_WORDS, size=12))
                    cv2.putText(img, text, (cx, cy + line_px - 1), cv2.FONT_HERSHEY_SIMPLEX,
                                line_px / 30.0, 38, 1, cv2.LINE_AA)
                    # clip text to the column
                    img[max(cy, 0):max(cy + line_px, 0), max(cx + col_w - 4, 0):max(min(cx + col_w, w), 0)] = 209
                    cy += line_px
    img = img.astype(np.float32) / 255.0
    yellow = np.array([0.97, 0.94, 0.86], np.float32)
    out = img[..., None] * yellow * (1 + 0.04 * _fbm(rng, h, w, 0.3 * ppm, 2))[..., None]
    return out


def stone(rng: np.random.Generator, h: int, w: int, ppm: float, scale: float = 1.0) -> np.ndarray:
    cell = 0.16 * scale * ppm
    ny, nx = int(np.ceil(h / cell)) + 1, int(np.ceil(w / cell)) + 1
    gy, gx = np.mgrid[0:ny, 0:nx].astype(np.float32)
    sy = ((gy + rng.uniform(0.1, 0.9, gy.shape)) * cell).astype(np.int64).clip(0, h - 1)
    sx = ((gx + rng.uniform(0.1, 0.9, gx.shape)) * cell).astype(np.int64).clip(0, w - 1)
    seeds = np.full((h, w), 255, np.uint8)
    seeds[sy.ravel(), sx.ravel()] = 0
    _, labels = cv2.distanceTransformWithLabels(seeds, cv2.DIST_L2, 5, labelType=cv2.DIST_LABEL_PIXEL)
    n_lab = int(labels.max()) + 1
    base = np.array([0.50, 0.47, 0.42], np.float32)
    per = base * (1 + 0.20 * rng.standard_normal((n_lab, 1)).astype(np.float32))
    per += 0.015 * rng.standard_normal((n_lab, 3)).astype(np.float32)
    img = per[labels]
    img *= (1 + 0.15 * _fbm(rng, h, w, 0.05 * ppm * scale, 3))[..., None]
    edges = np.zeros((h, w), np.uint8)
    edges[:, 1:] |= (labels[:, 1:] != labels[:, :-1]).astype(np.uint8)
    edges[1:, :] |= (labels[1:, :] != labels[:-1, :]).astype(np.uint8)
    k = max(1, int(0.006 * ppm * scale))
    edges = cv2.dilate(edges, np.ones((k, k), np.uint8))
    # cracks: short random walks
    crack = np.zeros((h, w), np.uint8)
    for _ in range(int(h * w / (cell * cell) * 0.3)):
        p = np.array([rng.uniform(0, w), rng.uniform(0, h)])
        pts = [p.copy()]
        ang = rng.uniform(0, 2 * np.pi)
        for _ in range(int(rng.integers(3, 8))):
            ang += rng.normal(0, 0.6)
            p = p + cell * 0.12 * np.array([np.cos(ang), np.sin(ang)])
            pts.append(p.copy())
        cv2.polylines(crack, [np.array(pts, np.int32)], False, 1, 1, cv2.LINE_AA)
    img = np.where(edges[..., None] > 0, np.array([0.22, 0.21, 0.20], np.float32), img)
    img = np.where(crack[..., None] > 0, img * 0.45, img)
    return img


def plaster(rng: np.random.Generator, h: int, w: int, ppm: float, scale: float = 1.0) -> np.ndarray:
    """Painted stucco: weak, low-contrast texture (a hard case for flow; training data only)."""
    base = np.array(rng.uniform(0.6, 0.85, 3), np.float32)
    img = np.broadcast_to(base, (h, w, 3)).copy()
    img *= (1 + 0.06 * _fbm(rng, h, w, 0.25 * ppm * scale, 4))[..., None]
    bumps = _noise(rng, h, w, max(1.5, 0.008 * ppm * scale))
    img *= (1 + 0.05 * np.clip(bumps, -1, 1))[..., None]
    img += 0.015 * rng.standard_normal((h, w, 1)).astype(np.float32)
    return img


def tiles(rng: np.random.Generator, h: int, w: int, ppm: float, scale: float = 1.0) -> np.ndarray:
    """Square ceramic tiles with grout: a repetitive pattern (aperture/ambiguity case; training data only)."""
    size, grout = float(rng.uniform(0.1, 0.3)) * scale * ppm, max(1.0, 0.006 * scale * ppm)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    row = np.floor(yy / (size + grout)).astype(np.int64)
    col = np.floor(xx / (size + grout)).astype(np.int64)
    is_grout = (yy - row * (size + grout) >= size) | (xx - col * (size + grout) >= size)
    base = np.array(rng.uniform(0.3, 0.9, 3), np.float32)
    per = base * (1 + 0.06 * rng.standard_normal((int(row.max()) + 1, int(col.max()) + 1, 1)).astype(np.float32))
    img = per[row, col] * (1 + 0.05 * _fbm(rng, h, w, 0.1 * ppm * scale, 2))[..., None]
    img = np.where(is_grout[..., None], np.array([0.45, 0.44, 0.42], np.float32), img)
    return img + 0.02 * rng.standard_normal((h, w, 1)).astype(np.float32)


GENERATORS = {"brick": brick, "granite": granite, "newspaper": newspaper, "stone": stone, "plaster": plaster,
              "tiles": tiles}


def make_texture(kind: str, seed: int, width_m: float, height_m: float, px_per_m: float = DEFAULT_PX_PER_M,
                 scale: float = 1.0) -> np.ndarray:
    """Texture image (H, W, 3) float32 in [0, 1] for a surface of ``width_m`` x ``height_m`` metres."""
    if kind not in GENERATORS:
        raise ValueError(f"unknown texture {kind!r}; use one of {sorted(GENERATORS)}")
    w = max(8, int(round(width_m * px_per_m)))
    h = max(8, int(round(height_m * px_per_m)))
    rng = np.random.default_rng(seed)
    img = GENERATORS[kind](rng, h, w, px_per_m, scale)
    return np.clip(img, 0.0, 1.0).astype(np.float32)

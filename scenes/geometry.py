"""Vectorised 2-D polygon helpers in the wall's (y, z) coordinates (pure numpy)."""

from __future__ import annotations

import numpy as np


def points_in_polygon(y: np.ndarray, z: np.ndarray, poly: list[tuple[float, float]]) -> np.ndarray:
    """Boolean mask of points strictly inside ``poly`` (crossing-number rule), any shape of y/z."""
    y = np.asarray(y, np.float64)
    z = np.asarray(z, np.float64)
    inside = np.zeros(np.broadcast(y, z).shape, bool)
    n = len(poly)
    for i in range(n):
        y0, z0 = poly[i]
        y1, z1 = poly[(i + 1) % n]
        if z0 == z1:
            continue
        cond = (z0 > z) != (z1 > z)
        y_cross = y0 + (z - z0) * (y1 - y0) / (z1 - z0)
        inside ^= cond & (y < y_cross)
    return inside


def distance_to_polygon_edges(y: np.ndarray, z: np.ndarray, poly: list[tuple[float, float]]) -> np.ndarray:
    """Unsigned distance from points to the polygon boundary."""
    y = np.asarray(y, np.float64)
    z = np.asarray(z, np.float64)
    best = np.full(np.broadcast(y, z).shape, np.inf)
    n = len(poly)
    for i in range(n):
        y0, z0 = poly[i]
        y1, z1 = poly[(i + 1) % n]
        dy, dz = y1 - y0, z1 - z0
        ll = dy * dy + dz * dz
        t = np.clip(((y - y0) * dy + (z - z0) * dz) / ll, 0.0, 1.0) if ll > 0 else 0.0
        d = np.hypot(y - (y0 + t * dy), z - (z0 + t * dz))
        best = np.minimum(best, d)
    return best


def signed_distance_polygon(y, z, poly) -> np.ndarray:
    """Signed distance to the polygon: negative inside."""
    d = distance_to_polygon_edges(y, z, poly)
    return np.where(points_in_polygon(y, z, poly), -d, d)

"""Collision geometry of a procedural scene for the vehicle's physics loop (plain Python floats, called at 500 Hz);
a capture scene's is the distance field of its splats (:mod:`scenes.occupancy`), which ``load_collision`` returns
for a capture ``.json``.

Solids: the wall slab ``wall_x <= x <= wall_x + thickness`` over the wall rectangle minus the openings,
each opening's frame band (standing ``frame_depth`` proud of the wall), and the background surface seen
through the openings: its rectangle at ``background_x``, solid behind (a room's far wall). The floor is NOT
included (the vehicle's dynamics handles the ground). ``clearance(p)`` is the distance from the NED point ``p`` to
the nearest solid surface, negative inside a solid. 2-D signed distances in the wall's (y, z) plane are
extruded along x; the wall's 2-D distance is ``max(d_rectangle, -d_opening)``, exact inside an opening
(distance to the inner edges) and in front of the wall.
"""

from __future__ import annotations

import math
from pathlib import Path

from scenes.spec import SceneSpec

_INF = float("inf")


class _Polygon:
    """Precomputed edges of one polygon for fast pure-Python signed distances."""

    __slots__ = ("edges", "y_lo", "y_hi", "z_lo", "z_hi")

    def __init__(self, pts: list[tuple[float, float]]) -> None:
        self.edges = []
        for i in range(len(pts)):
            y0, z0 = float(pts[i][0]), float(pts[i][1])
            y1, z1 = float(pts[(i + 1) % len(pts)][0]), float(pts[(i + 1) % len(pts)][1])
            dy, dz = y1 - y0, z1 - z0
            ll = dy * dy + dz * dz
            self.edges.append((y0, z0, y1, z1, dy, dz, 1.0 / ll if ll > 0 else 0.0))
        self.y_lo = min(p[0] for p in pts)
        self.y_hi = max(p[0] for p in pts)
        self.z_lo = min(p[1] for p in pts)
        self.z_hi = max(p[1] for p in pts)

    def bbox_distance(self, y: float, z: float) -> float:
        ddy = max(self.y_lo - y, 0.0, y - self.y_hi)
        ddz = max(self.z_lo - z, 0.0, z - self.z_hi)
        return math.sqrt(ddy * ddy + ddz * ddz)

    def signed_distance(self, y: float, z: float) -> float:
        best = _INF
        inside = False
        for y0, z0, _y1, z1, dy, dz, inv in self.edges:
            t = ((y - y0) * dy + (z - z0) * dz) * inv
            if t < 0.0:
                t = 0.0
            elif t > 1.0:
                t = 1.0
            ey = y - (y0 + t * dy)
            ez = z - (z0 + t * dz)
            d2 = ey * ey + ez * ez
            if d2 < best:
                best = d2
            if (z0 > z) != (z1 > z) and y < y0 + (z - z0) * dy / dz:
                inside = not inside
        d = math.sqrt(best)
        return -d if inside else d


def _box_distance(y: float, z: float, y_lo: float, y_hi: float, z_lo: float, z_hi: float) -> float:
    """Signed distance from (y, z) to the rectangle [y_lo, y_hi] × [z_lo, z_hi], negative inside."""
    qy = abs(y - 0.5 * (y_lo + y_hi)) - 0.5 * (y_hi - y_lo)
    qz = abs(z - 0.5 * (z_lo + z_hi)) - 0.5 * (z_hi - z_lo)
    if qy > 0.0 or qz > 0.0:
        return math.sqrt(max(qy, 0.0) ** 2 + max(qz, 0.0) ** 2)
    return qy if qy > qz else qz


def _extrude(d2: float, dx: float) -> float:
    """Signed distance of a 2-D shape (signed distance d2) extruded over an x interval (signed dx)."""
    if d2 <= 0.0 and dx <= 0.0:
        return d2 if d2 > dx else dx
    a = d2 if d2 > 0.0 else 0.0
    b = dx if dx > 0.0 else 0.0
    return math.sqrt(a * a + b * b)


class SceneCollision:
    """Scene solids for the vehicle: ``clearance((x, y, z)) -> float``, ``wall_x`` (front face x) and
    ``background_x`` (the background surface's x)."""

    def __init__(self, spec: SceneSpec) -> None:
        w = spec.wall
        self.spec = spec
        self.wall_x: float = float(spec.wall_x)
        self.wall_back_x: float = float(spec.wall_back_x)
        self._y_lo, self._y_hi = w.center_y - w.width / 2, w.center_y + w.width / 2
        self._z_lo, self._z_hi = -w.height, 0.0
        self.background_x: float = float(spec.background_x)
        self._bg = spec.background_rect
        self._openings = [_Polygon(op.polygon()) for op in spec.openings]
        self._frames = [(poly, float(op.frame_width), self.wall_x - float(op.frame_depth))
                        for poly, op in zip(self._openings, spec.openings, strict=True) if op.frame_width > 0]

    def clearance(self, p: tuple[float, float, float]) -> float:
        x, y, z = float(p[0]), float(p[1]), float(p[2])
        d_rect = _box_distance(y, z, self._y_lo, self._y_hi, self._z_lo, self._z_hi)
        d2 = d_rect
        for poly in self._openings:
            # the opening can only change max(d_rect, -s) if it is nearer than |d_rect|
            if d_rect < 0.0 and poly.bbox_distance(y, z) < -d_rect:
                s = poly.signed_distance(y, z)
                if -s > d2:
                    d2 = -s
        dx = self.wall_x - x if self.wall_x - x > x - self.wall_back_x else x - self.wall_back_x
        best = _extrude(d2, dx)
        for poly, fw, fx0 in self._frames:
            if poly.bbox_distance(y, z) > fw + best:
                continue
            s = poly.signed_distance(y, z)
            d2f = abs(s - 0.5 * fw) - 0.5 * fw
            dxf = fx0 - x if fx0 - x > x - self.wall_x else x - self.wall_x
            d = _extrude(d2f, dxf)
            if d < best:
                best = d
        d = _extrude(_box_distance(y, z, *self._bg), self.background_x - x)
        return d if d < best else best

    def __repr__(self) -> str:
        return f"SceneCollision({self.spec.name!r}, wall_x={self.wall_x})"


def load_collision(scene: str | Path | SceneSpec):
    """Collision geometry of a suite name, spec ``.json`` path, ``.ply`` with a sibling spec ``.json``
    (:class:`SceneCollision`), or capture scene ``.json`` (a :class:`scenes.occupancy.CaptureCollision`: the
    distance field of its splats, built once and cached beside the scene, and its gate)."""
    from scenes.build import resolve_spec
    from scenes.capture import CaptureSpec

    spec = resolve_spec(scene)
    if isinstance(spec, CaptureSpec):
        from scenes.occupancy import load_capture_collision

        return load_capture_collision(spec)
    return SceneCollision(spec)

"""The geometry of what the opening tracker measures: how wide a slot in a turned wall looks, the stretch that takes a
mask to the wall's own plane, and how far a point lies inside a mask.  Pure functions (:mod:`companion.opening`
uses them)."""

from __future__ import annotations

import math

import numpy as np

Point = tuple[float, float]


def seen_slot_width(half_width_m: float, distance_m: float, turn_rad: float, thickness_m: float) -> float:
    """How wide (tangent of the angle, left to right) a camera centred on it sees the way through a slot of
    ``half_width_m`` in a wall ``thickness_m`` deep whose face is ``distance_m`` ahead on the axis and turned by
    ``turn_rad``.  The far side is bounded by the back face's edge; the near side by the back face's edge while
    the turn is small, then by the front face's (the back edge, shifted across by the thickness, comes out from
    behind it)."""
    s, c = math.sin(abs(turn_rad)), math.cos(turn_rad)
    r, d, t = half_width_m, distance_m, thickness_m
    far = (r * c - t * s) / (d + r * s + t * c)
    near = min(r * c / max(d - r * s, 1e-6), (r * c + t * s) / (d - r * s + t * c))
    return near + far


def turned_wall_stretch(half_width_m: float, distance_m: float, turn_rad: float, thickness_m: float) -> float:
    """The horizontal factor that takes a mask seen through a turned wall, scaled by the back face's depth
    (:meth:`companion.opening.OpeningTracker.clear_radius_m`), to the slot's own width in the wall's plane, the
    corridor a body crossing square to the face has (:mod:`companion.push` crosses a turned wall so;
    ``scenes.groundtruth.corridor_clearance`` square to the wall), over its seen width (:func:`seen_slot_width`) at
    that depth. 1 for a wall facing the camera; 1/cos(turn) were the wall infinitely thin. The near side bounded by
    the front face, nearer than the back face the scale assumes, is what 1/cos(turn) missed: on the close views of
    56 hard-world openings whose width bounds their clear circle (seeds 60, 64-68, ground-truth masks, true distance
    and thickness), the clear size came out 3 % under the truth for turns under 5°, 13 % over it for 15-21°; with
    this factor, less the thickness's t·tan(turn) (the corridor along the heading, judged until 2026-12-05), 4 %
    under and 4 % over. Evaluated at one ``half_width_m`` (the one the fit decision turns on): between 0.2 and 0.4 m
    it changes by at most 4 % (a 10° turn 1.1 m away)."""
    seen = seen_slot_width(half_width_m, distance_m, turn_rad, thickness_m) * (distance_m + thickness_m)
    return 2.0 * half_width_m / seen


def in_wall(mask: np.ndarray, stretch: float) -> tuple[np.ndarray, float]:
    """``mask`` stretched horizontally by ``stretch`` (:func:`turned_wall_stretch`: as the wall's own plane
    shows it, where a body flying along the heading crosses it) and its clear radius in those pixels."""
    import cv2

    from companion.gap import clear_circle

    h, w = mask.shape
    wide = cv2.resize(mask.astype(np.uint8), (max(1, round(w * stretch)), h), interpolation=cv2.INTER_NEAREST)
    return wide.astype(bool), clear_circle(wide)[1]


def edge_distance_px(mask: np.ndarray, point: Point) -> float:
    """Distance (px) from ``point`` to the nearest pixel outside ``mask`` (the frame's border counts as outside);
    0 outside the mask."""
    import cv2

    u, v = int(round(point[0])), int(round(point[1]))
    h, w = mask.shape
    if not (0 <= u < w and 0 <= v < h) or not mask[v, u]:
        return 0.0
    m = np.zeros((h + 2, w + 2), np.uint8)
    m[1:-1, 1:-1] = mask.astype(bool)
    return float(cv2.distanceTransform(m, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[v + 1, u + 1])


def thickness_from_sidestep(aperture_shift_px: float, wall_shift_px: float, distance_m: float) -> float | None:
    """The wall's thickness from a step sideways square to it, ``distance_m`` from its face (measured, not flown:
    ``python -m tools.thickness_look``).  Seen from within the opening's width, what shows through it is bounded by
    its far edges, a thickness t behind the face: it shifts across the image as a thing ``distance_m`` + t away
    does (``aperture_shift_px``), the face beside it as one ``distance_m`` away (``wall_shift_px``), so
    t = d·(wall shift / aperture shift − 1).  None where the two shifts are not the same way round, or the
    aperture's is the larger (nothing behind the face)."""
    if aperture_shift_px * wall_shift_px <= 0.0 or abs(aperture_shift_px) > abs(wall_shift_px):
        return None
    return distance_m * (wall_shift_px / aperture_shift_px - 1.0)

"""The thickness look: the wall's depth read by a step sideways, square to it, when an opening's size is too near
the need to tell by the assumed depth (pure: geometry and image measurements, no clock, no I/O).

What shows through an opening is bounded by its far edges, the wall's thickness t behind its face, so the size the
companion judges an opening by is scaled by the face's distance plus t (:meth:`companion.opening.OpeningTracker
.clear_radius_m`); ``ServoConfig.wall_thickness_m`` assumes 0.15 m.  Near the need, that assumption decides: the
hard world's walls are 0.10-0.25 m deep, and its refusals of passable openings, and the one impassable opening it
judged to fit (seed 117), were openings within a couple of centimetres of the need in walls far from 0.15 m.

The look (:func:`plan_look`, flown by :mod:`companion.thickness_flight`): facing the wall squarely, on the normal
through the opening's clear centre, two columns of views ``step_m`` apart across it (A and B), each a few pairs
``forward_m`` apart towards the wall for the opening's mask.  From A to B the wall's face beside the opening shifts
as a thing ``d`` away does, the aperture (its far edges) as one ``d + t`` away: :func:`thickness_reading`, once per
pair, and :func:`combined_reading`, their median.  Measured on renders (``python -m tools.thickness_look``, RAFT,
40 scenes each of seeds 7000 and 7100): a reading's error has a robust sd of 0.015 / 0.013 m against the world's
spread of 0.043 m, with a tail (one in eight off by over 0.04 m) that the median of three trims.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from companion.opening_geometry import thickness_from_sidestep

Point3 = tuple[float, float, float]


@dataclass(frozen=True)
class ThicknessLookConfig:
    enabled: bool = True
    band_m: float = 0.02          # look when the judged clear radius is within this of the need, either way (a
                                  # 0.1 m error in the assumed depth moves a 0.25 m radius seen from 1.2 m by 0.018 m)
    distance_m: float = 1.2       # the views this far from the face along its normal ...
    step_m: float = 0.3           # ... this far apart across it (within the width of an opening near the need) ...
    forward_m: float = 0.15       # ... each with a pair this far towards the wall (its mask) ...
    readings: int = 3             # ... and as many readings, each a pair nearer (a pixel of a mask's centroid is
                                  # 0.03-0.04 m of depth: one reading in five was 0.05-0.12 m off, in flight)
    agree_m: float = 0.04         # with only two of them read, they must agree within this
    ring_px: tuple[int, int] = (5, 20)   # the face's shift is read in this ring outside view A's mask ...
    min_ring_px: int = 50                # ... of this many pixels at least
    clipped_width_change: float = 0.05   # an opening whose width changes more than this between A and B is cut off
    plausible_m: tuple[float, float] = (0.03, 0.40)   # a reading outside this is no wall's depth: kept as assumed
    max_turn_rad: float = math.radians(30.0)          # no look at a wall turned more than this (none measured so)
    yaw_tolerance_rad: float = 0.01   # each view taken once the yaw is within this of square to the wall ...
    level_rad: float = 0.015          # ... and roll and pitch within this of level ...
    level_timeout_s: float = 4.0      # ... or after this long
    arrival_m: float = 0.02           # each view taken this near its place (a pair that moved across as well as
                                      # forward, 0.045 m in 0.19 m, showed no opening whole: measured, DIS fine)


@dataclass(frozen=True)
class LookPlan:
    """Where the look's frames are taken (NED, metres), along the normal at either side of the clear centre, and the
    yaw they face (NED, rad: square to the wall).  Reading k pairs ``a[k]`` with ``a[k + 1]`` (view A's mask),
    ``b[k]`` with ``b[k + 1]`` (view B's), and ``a[k]`` with ``b[k]`` (the sidestep)."""

    yaw: float
    a: tuple[Point3, ...]
    b: tuple[Point3, ...]
    distance_m: float             # the first frames' distance from the wall's face, along its normal


def plan_look(face_centre: Point3, normal_yaw: float, config: ThicknessLookConfig = ThicknessLookConfig()
              ) -> LookPlan:
    """The look at an opening whose clear centre on the wall's face is ``face_centre`` (NED), the face's normal into
    the wall pointing along NED yaw ``normal_yaw`` (a wall turned by ψ against a heading ``yaw``, its right side
    further, faces ``yaw − ψ``)."""
    c, s = math.cos(normal_yaw), math.sin(normal_yaw)
    normal, right = np.array([c, s, 0.0]), np.array([-s, c, 0.0])
    stand = np.asarray(face_centre, float) - normal * config.distance_m
    half = config.step_m / 2.0

    def point(across: float, forward: float) -> Point3:
        return tuple(float(v) for v in stand + right * across + normal * forward)

    steps = [k * config.forward_m for k in range(config.readings + 1)]
    return LookPlan(normal_yaw, tuple(point(-half, f) for f in steps), tuple(point(half, f) for f in steps),
                    config.distance_m)


def mask_span(mask: np.ndarray | None) -> tuple[float, float] | None:
    """(centroid column, width in px) of a mask, the width that of its middle 90 % of pixels by column (a few stray
    pixels at one end widened the full span by 5-15 % and failed looks whose centroids were right to a pixel);
    None without one or where it reaches the frame's left or right edge (cut off: its centroid is not the
    opening's)."""
    if mask is None or not mask.any():
        return None
    xs = np.nonzero(mask)[1]
    if xs.min() < 2 or xs.max() > mask.shape[1] - 3:
        return None
    low, high = np.percentile(xs, (5, 95))
    return float(xs.mean()), float(high - low)


def face_shift(flow: np.ndarray, mask: np.ndarray, config: ThicknessLookConfig = ThicknessLookConfig()
               ) -> float | None:
    """The horizontal flow's median in the ring ``config.ring_px`` outside ``mask``: how far the wall's face beside the
    opening moved; None where the ring is too small."""
    import cv2

    m = mask.astype(np.uint8)
    near, far = config.ring_px
    outer = cv2.dilate(m, np.ones((2 * far + 1,) * 2, np.uint8)).astype(bool)
    inner = cv2.dilate(m, np.ones((2 * near + 1,) * 2, np.uint8)).astype(bool)
    ring = outer & ~inner
    return float(np.median(flow[..., 0][ring])) if ring.sum() >= config.min_ring_px else None


def opening_at_centre(detection) -> np.ndarray | None:
    """The mask, among a detection's openings, of the one nearest the image's centre (the look faces the clear centre
    of the opening it measures); None without one."""
    found = [c for c in (detection.candidates or (detection,)) if c.found and c.mask is not None and c.mask.any()]
    if not found:
        return None
    h, w = found[0].mask.shape
    centre = np.array([(w - 1) / 2.0, (h - 1) / 2.0])

    def off(c) -> float:
        if c.mask[int(centre[1]), int(centre[0])]:
            return 0.0
        ys, xs = np.nonzero(c.mask)
        return float(np.hypot(xs.mean() - centre[0], ys.mean() - centre[1]))

    return min(found, key=off).mask


@dataclass(frozen=True)
class ThicknessReading:
    thickness_m: float | None     # None: the look could not tell (``why``)
    why: str
    aperture_shift_px: float | None = None
    wall_shift_px: float | None = None


def thickness_reading(mask_a: np.ndarray | None, mask_b: np.ndarray | None, flow_ab: np.ndarray | None,
                      distance_m: float, config: ThicknessLookConfig = ThicknessLookConfig(),
                      rotational_ab: np.ndarray | None = None) -> ThicknessReading:
    """The wall's thickness from the opening's masks at views A and B (each in its first frame's pixels), the flow
    from A's first frame to B's (the camera's rotation taken out: ``rotational_ab``, that rotation's own flow, is
    taken out of the masks' shift too), and A's distance from the face; the reading says why where it cannot tell:
    an opening not seen or cut off by the frame, no face beside it, or a depth no wall has."""
    a, b = mask_span(mask_a), mask_span(mask_b)
    if a is None or b is None:
        which = "either view" if a is None and b is None else "view A" if a is None else "view B"
        return ThicknessReading(None, f"the opening not seen whole from {which}")
    if abs(a[1] - b[1]) > config.clipped_width_change * max(a[1], b[1]):
        return ThicknessReading(None, f"the opening {a[1]:.0f} px wide from one view, {b[1]:.0f} px from the other")
    wall = face_shift(flow_ab, mask_a, config) if flow_ab is not None else None
    if wall is None:
        return ThicknessReading(None, "too little of the wall's face beside the opening")
    aperture = b[0] - a[0]
    if rotational_ab is not None:
        ys = np.nonzero(mask_a)[0]
        aperture -= float(rotational_ab[int(round(ys.mean())), int(round(a[0])), 0])
    t = thickness_from_sidestep(aperture, wall, distance_m)
    lo, hi = config.plausible_m
    if t is None or not lo <= t <= hi:
        said = "none" if t is None else f"{t:.2f} m"
        return ThicknessReading(None, f"the aperture shifted {aperture:.1f} px, the face {wall:.1f} px: a depth of "
                                f"{said}, outside {lo:.2f}-{hi:.2f} m", aperture, wall)
    return ThicknessReading(t, f"the aperture shifted {aperture:.1f} px, the face {wall:.1f} px from "
                            f"{distance_m:.2f} m: {t:.3f} m deep", aperture, wall)


def combined_reading(readings: list[ThicknessReading], config: ThicknessLookConfig = ThicknessLookConfig()
                     ) -> ThicknessReading:
    """One depth from a look's readings: the median of three or more read, the mean of two that agree within
    ``agree_m``; none from fewer, or from two that disagree (the first reading's why, or theirs)."""
    read = sorted(r.thickness_m for r in readings if r.thickness_m is not None)
    values = ", ".join(f"{t:.3f}" for t in read)
    unread = "; ".join(r.why for r in readings if r.thickness_m is None)
    if len(read) >= 3 or (len(read) == 2 and read[1] - read[0] <= config.agree_m):
        return ThicknessReading(float(np.median(read)),
                                f"the median of {len(read)} of {len(readings)} readings, {values} m")
    if len(read) == 2:
        return ThicknessReading(None, f"two readings, {values} m, more than {config.agree_m:.2f} m apart")
    return ThicknessReading(None, f"{len(read)} of {len(readings)} readings" + (f" ({unread})" if unread else ""))

"""Gap detection: from dense flow to a gap mask and centroid.

Two detectors share one result type, :class:`GapDetection`: the paper's colour-edge pipeline
(:mod:`companion.gap_paper`) and ours, here.

:func:`detect_gap_parallax` works on the flow *vectors*, not on colour grey levels that depend on flow direction.
For a camera that translates (no rotation), the flow at a pixel is ``F = ρ·g(x, y; t)`` with ρ = |T|/Z the inverse
depth (in units of the step length) and g known from the intrinsics and the translation direction t (estimated from
the flow by least squares when not given). ρ = F·g/|g|² is computed (:mod:`companion.inverse_depth`) where |g| is
large enough (away from the focus of expansion) and away from the image border, inpainted elsewhere (with
``focus_window_px``, off as flown, read near the focus from the flow's rate of expansion over a small window
instead), and put on a log scale, where the holes in the wall are searched for (:mod:`companion.holes`): repeated
Otsu splits peel off nearer surfaces (floor, wall); the far class of the sharpest significant depth step is what
lies beyond the opening. The largest far component inside the size bounds and enclosed by a nearer surface is the
mask, with the band of it that the wall hides in the second frame filled back (the flow there follows the wall).
With ``past_the_end`` (off as flown), a sharpest step with no hole beyond it has its far parts at the image's border
set aside, as what lies past the wall's end, and the rest is split again. With ``against_wall`` (on), where no hole
is found, log ρ is split again against the wall's plane fitted to it: a turned wall's far side is as deep as the
background seen through an opening on its near side. With ``plain_aside`` (on), where still no hole is found, the
plain regions of the first frame that reach the image's border (the empty space past a wall's end) are set aside
and the search runs again; in every pair, a hole most of whose pixels are such plain space
(``plain_candidate_frac``) is dropped.

Both detectors take an H×W×2 float flow (u right, v down, pixels) and return a frozen :class:`GapDetection`.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
from dataclasses import dataclass

import cv2
import numpy as np

from companion.holes import fill_occluded, filled, hole_contours, plain_fraction, reaching_border
from companion.inverse_depth import CameraMotion, focus_inverse_depth, inverse_depth

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class GapDetection:
    """A gap detector's answer for one frame.

    ``mask``: H×W bool, True inside the gap (all False when none).  ``centroid``: (u, v) pixels or None.
    ``area``: contour area in pixels² (0 when none).  ``contour``: N×2 int32 (x, y) polygon or None.
    ``reason``: why there is no gap (None when there is one).  ``detector``: which detector answered.
    ``clear_centre``/``clear_radius_px``: the centre and radius (pixels) of the largest circle inside the mask
    (its pole of inaccessibility): the point a body must aim at to clear the nearest edge by the most, which
    for an irregular or clipped opening is not its centroid.
    """

    mask: np.ndarray
    centroid: tuple[float, float] | None
    area: float
    contour: np.ndarray | None
    reason: str | None = None
    detector: str = ""
    clear_centre: tuple[float, float] | None = None
    clear_radius_px: float = 0.0
    # every opening the detector found (this one first), for a caller that must choose among several
    candidates: tuple[GapDetection, ...] = ()

    @property
    def found(self) -> bool:
        return self.centroid is not None

    @property
    def area_fraction(self) -> float:
        return self.area / float(self.mask.size) if self.mask.size else 0.0


def _no_gap(shape: tuple[int, int], reason: str, detector: str) -> GapDetection:
    return GapDetection(np.zeros(shape, dtype=bool), None, 0.0, None, reason, detector)


def clear_circle(mask: np.ndarray) -> tuple[tuple[float, float] | None, float]:
    """Centre (u, v) and radius in pixels of the largest circle inside a binary ``mask`` (its pole of
    inaccessibility, from the Euclidean distance transform); the frame's border counts as an edge, since
    nothing is known beyond it.  (None, 0.0) for an empty mask."""
    m = np.zeros((mask.shape[0] + 2, mask.shape[1] + 2), np.uint8)
    m[1:-1, 1:-1] = mask.astype(bool)
    dist = cv2.distanceTransform(m, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[1:-1, 1:-1]
    radius = float(dist.max())
    if radius <= 0:
        return None, 0.0
    # the middle of the plateau of largest distance (a rectangle's is a segment, not a point): its point
    # nearest the plateau's mean, which for a bent plateau may lie outside it
    ys, xs = np.nonzero(dist >= radius - 0.5)
    i = int(np.argmin((xs - xs.mean()) ** 2 + (ys - ys.mean()) ** 2))
    return (float(xs[i]), float(ys[i])), radius


def _from_contour(shape: tuple[int, int], contour: np.ndarray, detector: str) -> GapDetection:
    mask = filled(shape, contour)
    m = cv2.moments(contour)
    if abs(m["m00"]) > 1e-9:
        centroid = (m["m10"] / m["m00"], m["m01"] / m["m00"])
    else:  # degenerate polygon: fall back to the filled mask's moments
        mm = cv2.moments(mask, binaryImage=True)
        centroid = (mm["m10"] / mm["m00"], mm["m01"] / mm["m00"])
    polygon = contour.reshape(-1, 2).astype(np.int32)
    centre, radius = clear_circle(mask)
    return GapDetection(mask.astype(bool), (float(centroid[0]), float(centroid[1])),
                        float(cv2.contourArea(contour)), polygon, None, detector,
                        centre if centre is not None else (float(centroid[0]), float(centroid[1])), radius)


# ----------------------------------------------------------------------------------------------------------
# Our detector: inverse depth from flow under translation
# ----------------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class ParallaxGapConfig:
    """Constants of :func:`detect_gap_parallax`."""

    vfov_deg: float = 75.0            # used when no focal length is given (flowgap default camera)
    min_g_frac: float = 0.08          # |g| below this fraction of its max is "too close to the FoE": filled
    median_ksize: int = 5             # smoothing of the 8-bit log-inverse-depth image
    robust_percentiles: tuple[float, float] = (0.5, 99.5)   # log inverse depth → 8 bit
    min_contrast: float = 1.25        # a split is real when the classes' median inverse depths differ this much
    min_separability: float = 0.6     # ... and Otsu's between/total variance ratio is at least this
    max_splits: int = 4               # nearest surfaces peeled off (floor, wall, ...) before the farthest class
    open_ksize: int = 5               # opening (remove specks) then closing of the far mask
    close_ksize: int = 7
    area_min_frac: float = 0.001
    area_max_frac: float = 0.9
    border_penalty: float = 0.5       # a component touching the image border counts this much of its area
    border_min_frac: float = 0.02     # ... and needs at least this fraction of the image (flow is poor there)
    border_px: int = 6                # flow this close to the image edge is not trusted (inpainted)
    max_border_frac: float = 0.4      # a gap is a hole in a nearer surface: at most this much of its outline
                                      # may run along the image border (rejects "the whole wall beyond the floor"
                                      # and the far band beyond a wall's top edge seen from afar)
    min_flow_px: float = 0.05         # below this median |flow| there is no parallax to read
    # The edge blend (on since 2026-12-03) raises the masks' median IoU on the suite from 0.927 to 0.935 (RAFT and
    # dis:fine alike) and moves the clear radius by 0.1 px at the median (0.9 px at the 95th percentile); flown on
    # 200 hard-world scenes it changed which flights touched, not how many (docs/evaluation.md).
    edge_blend: float | None = 0.5    # the opening's edge is put where inverse depth is this fraction of the
                                      # way from the far class's median to the near class's, in linear ρ: a
                                      # flow estimator blurs an edge into a linear blend of the two surfaces'
                                      # flow, so 0.5 (its midpoint) is the edge (Otsu's split on log ρ lies
                                      # nearer the far side: 94 % of suite masks lay inside the truth); None
                                      # keeps Otsu's split
    edge_blend_reach_px: int | None = 1  # ... moving the edge at most this many pixels from Otsu's (None:
                                      # unbounded): a blurred edge is a pixel or two wide, and beyond that the
                                      # blend level can run on along a weak step (a background close behind the
                                      # wall) and join what is not the opening (unbounded, on hard-world views
                                      # the clear radius grew up to 2.6 px and other regions were picked; within
                                      # 1 px, up to 1.5 px and the same detections; docs/perception.md)
    occlusion_fill: float | None = 0.75  # fill back the band of the opening the wall covers in the second frame
                                      # (see holes.fill_occluded): this fraction of the band's modelled width (an
                                      # estimator follows the background part way into it: on 88 sideways pairs
                                      # of flown runs, RAFT, the clearance ahead came out 0.8 px short at the
                                      # median and at most 2.0 px over with 0.75; 3.0 px short, without; with
                                      # 1.0, 2.8 px over at the 90th percentile); None: the mask as flow shows it
    every_step: bool = False          # with no hole beyond the sharpest depth step, look beyond the next
                                      # sharpest (seen from afar, the floor's step can be the sharpest)
    past_the_end: bool = False        # with no hole beyond the sharpest depth step, set aside its far parts that
                                      # reach the image's border (what lies past the wall's end or above its top:
                                      # the deepest thing in view) and look for a hole in the rest, beyond each
                                      # significant step (see holes._holes_past_the_end).  Off: it lifts RAFT's masks
                                      # (random seeds 7 and 8: 90.8 -> 94.6 % and 92.4 -> 93.4 % detected), but
                                      # flown on hard-world seeds 67, 77, 78 and 79 it lost one or two flights on
                                      # each (other flights, other near-threshold judgements; docs/perception.md).
                                      # Flown since 2026-12-06 where a look has seen nothing for three frames
                                      # (blind_detector)
    past_the_end_reach_px: int = 3    # ... set aside with this many pixels of their blurred edge
    against_wall: bool = True         # with no hole found so far, look again in the inverse depth against the
                                      # wall's plane (see holes._holes_against_wall): a turned wall's far side lies as
                                      # deep as the background seen through an opening on its near side
    against_wall_band: float = 0.15   # ... where |log ρ - log ρ_plane| is at most this, the wall's plane
    against_wall_walled: float = 0.7  # ... which this much of what is measurable must lie on, and this much of
                                      # the measurable ring around a hole
    # Where the image has texture (textured_pixels): flow elsewhere (the empty space beyond a wall's end, a plain
    # surface) is filled in from the region's edges and says nothing of its depth.
    plain_aside: bool = True            # where no hole is found, and given the first frame's textured pixels, set
                                        # aside the plain regions that reach the image's border (the empty space
                                        # past a wall's end or above its top), if as large as the smallest opening,
                                        # and look again: RAFT reads them as the deepest thing in view, every split
                                        # of log ρ peels them off, and an opening nearer than them stays in the
                                        # near class (random seeds 9 and 10: RAFT 546 and 542 -> 557 and 550 of
                                        # 576 pairs detected, DIS fine 552 and 548 -> 555 and 551;
                                        # docs/perception.md).  A plain region walled all round (sky through a
                                        # window) is kept.  Set aside in every pair, not only where none is found,
                                        # hard seed 103 flew 92 -> 89/100
    # Near the focus of expansion flow says little of depth pixel by pixel; a window of them still says it.
    focus_window_px: int | None = None  # where |g| < min_g_frac·max|g|, read ρ from the flow's rate of expansion
                                        # over this square window (inverse_depth.focus_inverse_depth), not
                                        # inpainted.  Off: it lifts the masks (9: random seeds 7-10, RAFT 2212
                                        # -> 2251 of 2304 pairs detected, DIS fine 2212 -> 2249, median IoU level),
                                        # but flown it gained nothing (hard seeds 103, 101: 92 -> 91, 94 -> 95), and
                                        # its masks inside the disc move by several pixels between near-identical
                                        # frames (a flight replayed from its logged poses, window1_brick, differed
                                        # by 10.8 px at one step); docs/perception.md
    plain_candidate_frac: float | None = 0.5  # a hole whose outline holds more than this fraction of plain pixels
                                        # that reach the border (the empty space past a wall's end) is no hole
                                        # in the wall: dropped from the candidates, in every pair
    texture_min_gradient: float = 20.0  # grey Sobel magnitude (of 255) of a textured pixel ...
    texture_reach_px: int = 4           # ... and the pixels this near one (a plain patch of a textured wall
                                        # is a few pixels across; its flow is the wall's)


def textured_pixels(rgb: np.ndarray, config: ParallaxGapConfig = ParallaxGapConfig()) -> np.ndarray:
    """H×W mask of the pixels whose flow can say something of their depth: within ``texture_reach_px`` of one
    whose grey gradient (Sobel magnitude) is at least ``texture_min_gradient``."""
    grey = cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2GRAY).astype(np.float32)
    gradient = np.hypot(cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3), cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3))
    reach = 2 * config.texture_reach_px + 1
    strong = (gradient >= config.texture_min_gradient).astype(np.uint8)
    return cv2.dilate(strong, np.ones((reach, reach), np.uint8)).astype(bool)


def inverse_depth_from_flow(flow: np.ndarray, motion: CameraMotion = CameraMotion(),
                            config: ParallaxGapConfig = ParallaxGapConfig()) -> tuple[np.ndarray, np.ndarray]:
    """Inverse depth ρ = |T|/Z per pixel and the mask of pixels where it was measurable
    (:func:`companion.inverse_depth.inverse_depth` with the config's field of view and ``min_g_frac``)."""
    rho, valid, _ = _inverse_depth(flow, motion, config)
    return rho, valid


def _inverse_depth(flow: np.ndarray, motion: CameraMotion,
                   config: ParallaxGapConfig) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """:func:`companion.inverse_depth.inverse_depth` with the config's field of view and ``min_g_frac``."""
    return inverse_depth(flow, motion, config.vfov_deg, config.min_g_frac)


def detect_gap_parallax(flow: np.ndarray, config: ParallaxGapConfig = ParallaxGapConfig(),
                        motion: CameraMotion = CameraMotion(), textured: np.ndarray | None = None) -> GapDetection:
    """Our detector: the farthest region of the inverse depth read from flow (see module docstring).
    ``textured``: the first frame's pixels whose flow says something of their depth (:func:`textured_pixels`);
    None: all (the plain regions at the border are then not set aside)."""
    det = "parallax"
    flow = np.asarray(flow, dtype=np.float32)
    h, w = flow.shape[:2]
    mag = np.hypot(flow[..., 0], flow[..., 1])
    if not np.isfinite(mag).any() or float(np.nanmedian(mag)) < config.min_flow_px:
        return _no_gap((h, w), "flow too small to measure parallax", det)
    rho, away_from_focus, g = _inverse_depth(flow, motion, config)
    valid = away_from_focus.copy()
    if config.focus_window_px:
        rho, valid = focus_inverse_depth(flow, rho, valid, g, config.focus_window_px)
    if config.border_px > 0:
        b = config.border_px
        for mask in (valid, away_from_focus):
            mask[:b], mask[-b:], mask[:, :b], mask[:, -b:] = False, False, False, False
    if away_from_focus.sum() < 0.2 * h * w:     # the window fills a disc around the focus, not most of the frame
        return _no_gap((h, w), "too few pixels away from the focus of expansion", det)
    positive = valid & (rho > 0)
    if positive.sum() < 0.5 * valid.sum():
        return _no_gap((h, w), "inverse depth mostly negative (motion not translation-like)", det)
    a_min, a_max = config.area_min_frac * h * w, config.area_max_frac * h * w
    scored, reason = hole_contours(rho, positive, motion, config, a_min, a_max)
    plain = reaching_border(~textured) if textured is not None else None
    if scored and plain is not None and config.plain_candidate_frac is not None:
        in_wall = [c for c in scored if plain_fraction(c, plain) <= config.plain_candidate_frac]
        if not in_wall:
            reason = "every hole found is mostly plain space reaching the frame's border (past a wall's end)"
        scored = in_wall
    if not scored and plain is not None and config.plain_aside:
        rest = positive & ~plain
        if plain.sum() >= a_min and rest.sum() >= a_min:    # what is left holds at least the smallest opening
            positive = rest
            scored, _ = hole_contours(rho, positive, motion, config, a_min, a_max, plain)
    if not scored:
        return _no_gap((h, w), reason, det)
    if config.occlusion_fill is not None:
        scored = [fill_occluded(c, rho, positive, g, config.occlusion_fill) for c in scored]
    found = [_from_contour((h, w), cv2.approxPolyDP(c, 0.5, True), det) for c in scored]
    return dataclasses.replace(found[0], candidates=tuple(found))


DETECTORS = ("paper", "parallax")


def blind_detector(name: str):
    """The detector a look turns to once it has seen nothing for a few frames (``MissionConfig.blind_frames``):
    detector ``name`` looking past the wall's end too (``ParallaxGapConfig.past_the_end``); None for a detector
    without that option ("paper")."""
    if name == "parallax":
        return functools.partial(detect_gap_parallax, config=ParallaxGapConfig(past_the_end=True))
    return None


def get_detector(name: str):
    """The detector function registered as ``name``: "paper" (:func:`companion.gap_paper.detect_gap`) or
    "parallax" (:func:`detect_gap_parallax`)."""
    if name == "paper":
        from companion.gap_paper import detect_gap  # it answers with this module's GapDetection

        return detect_gap
    if name == "parallax":
        return detect_gap_parallax
    raise KeyError(f"unknown gap detector {name!r}; choose from {sorted(DETECTORS)}")

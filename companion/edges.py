"""An opening's edge, read again from the two frames themselves: the photometric test of two depths.

A flow estimator matches patches, so where the wall's edge crosses a patch its flow is a blend of the two
surfaces', and the parallax detector's mask follows that blur: measured on renders of hard-world openings near
the fit threshold (RAFT, the derotation and the detector as flown), the mask's clear radius came out 1.4 px short
of the truth's at the median and 5.4 px short at the 10th percentile, where the pixels near the focus of
expansion, inpainted, smear the wall's depth into the opening (a notch).  Once the detector has said where the
opening is, what is left to decide near its edge is which of two known depths each pixel has: the far side's
(what is seen through the opening) or the wall's.  Each hypothesis predicts where the pixel is in the second
frame (the rotation's flow plus ρ·g, :mod:`companion.gap`), and the one whose prediction matches the second
frame's colour wins.  The decision is made pixel by pixel, its colour differences summed over a 3×3 window where a
flow estimator's patches are 8 px and more.

Tested are the pixels within ``band_px`` of the mask's edge, against ``levels`` inverse depths from the far
side's median (inside the mask) to the wall's (in a ring around it): a pixel is far where one of the far half's
levels predicts the second frame better than every level of the near half, and joins the opening (with ``shrink``,
a pixel where the reverse holds leaves it).  The component that holds the mask's core, its holes filled, is the
opening.  Pure functions of arrays.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import cv2
import numpy as np

from companion.gap import CameraMotion, GapDetection, ParallaxGapConfig, _from_contour, _inverse_depth
from companion.holes import within


@dataclass(frozen=True)
class EdgeConfig:
    """Constants of :func:`refine_mask` (see the module docstring for what was measured)."""

    band_px: int = 8          # pixels either side of the detector's edge that are decided again
    levels: int = 7           # inverse depths tried, from the far side's to the wall's
    window_px: int = 3        # colour differences summed over this square (1: the pixel alone; 3 holds up
                              # better under sensor noise, see the module docstring)
    ring_px: int = 6          # the wall's inverse depth: the median in a ring this wide around the mask ...
    ring_gap_px: int = 2      # ... starting this far out (the blurred edge is neither surface)
    core_px: int = 2          # the far side's: the median inside the mask eroded this far
    min_pixels: int = 20      # fewer measurable pixels inside or in the ring: the mask is left as it is
    shrink: bool = False      # also take away the band's pixels the wall's depths predict better; off, the
                              # test only adds (the detector's masks are seldom too large, and moving sideways
                              # the band it fills back, hidden in the second frame, matches neither depth)


def _surface_depths(mask: np.ndarray, rho: np.ndarray, measurable: np.ndarray,
                    config: EdgeConfig) -> tuple[float, float] | None:
    """(ρ far, ρ near): the medians inside ``mask`` and in the ring around it; None where either is short of
    pixels or the far side is not farther."""
    core = cv2.erode(mask.astype(np.uint8), np.ones((3, 3), np.uint8), iterations=config.core_px).astype(bool)
    ring = within(mask, config.ring_gap_px + config.ring_px) & ~within(mask, config.ring_gap_px)
    inside, around = core & measurable, ring & measurable
    if inside.sum() < config.min_pixels or around.sum() < config.min_pixels:
        return None
    far, near = float(np.median(rho[inside])), float(np.median(rho[around]))
    return (far, near) if near > far > 0 else None


DEFAULT_EDGES = EdgeConfig()      # as flown (flowgap-companion --edges photo)
EDGE_MODES = ("photo", "flow")    # --edges: read again from the frames, or the detector's masks as flow shows them


def edges_for(mode: str | None) -> EdgeConfig | None:
    """The edge reading ``--edges MODE`` flies with: photo reads them again (:data:`DEFAULT_EDGES`); flow, or a run
    from before the option (None), keeps the detector's masks (None)."""
    return DEFAULT_EDGES if mode == "photo" else None


def prediction_costs(first_rgb: np.ndarray, second_rgb: np.ndarray, rhos, g: tuple[np.ndarray, np.ndarray],
                     rotational: np.ndarray, window_px: int = 1,
                     box: tuple[slice, slice] | None = None) -> np.ndarray:
    """levels×H×W: how far (sum of |colour difference| over the channels, and over ``window_px``²) the second
    frame, sampled where each inverse depth in ``rhos`` puts each first-frame pixel, is from the first frame.
    ``box`` (rows, columns): only those pixels (the result is the box's size)."""
    rows, cols = box or (slice(0, first_rgb.shape[0]), slice(0, first_rgb.shape[1]))
    ys, xs = np.mgrid[rows, cols].astype(np.float32)
    base_x, base_y = xs + rotational[rows, cols, 0], ys + rotational[rows, cols, 1]
    g_x, g_y = g[0][rows, cols].astype(np.float32), g[1][rows, cols].astype(np.float32)
    first = first_rgb[rows, cols].astype(np.float32)
    costs = []
    for rho in rhos:
        warped = cv2.remap(second_rgb, base_x + np.float32(rho) * g_x, base_y + np.float32(rho) * g_y,
                           cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        diff = np.abs(first - warped.astype(np.float32)).reshape(first.shape[0], first.shape[1], -1).sum(-1)
        costs.append(cv2.boxFilter(diff, -1, (window_px, window_px)) if window_px > 1 else diff)
    return np.stack(costs)


def refine_mask(mask: np.ndarray, first_rgb: np.ndarray, second_rgb: np.ndarray, rho: np.ndarray,
                measurable: np.ndarray, g: tuple[np.ndarray, np.ndarray], rotational: np.ndarray,
                config: EdgeConfig = DEFAULT_EDGES) -> np.ndarray:
    """``mask`` with the pixels within ``band_px`` of its edge decided again by the photometric test (module
    docstring).  ``rho``, ``measurable`` and ``g``: the detector's inverse depth, where it was measured, and the
    flow of unit inverse depth (:func:`companion.gap._inverse_depth`) for the derotated flow; ``rotational``: the
    flow the camera's rotation alone causes (:func:`companion.motion.rotational_flow`).  The mask unchanged where
    the two depths cannot be read."""
    mask = np.asarray(mask, bool)
    depths = _surface_depths(mask, rho, measurable, config)
    if depths is None:
        return mask
    m8 = mask.astype(np.uint8)
    core = cv2.erode(m8, np.ones((3, 3), np.uint8), iterations=config.band_px).astype(bool)
    band = within(mask, config.band_px) & ~core
    rows, cols = np.nonzero(band)
    reach = config.window_px // 2       # the window's pixels around the band's, within the frame
    h, w = mask.shape
    box = (slice(max(0, rows.min() - reach), min(h, rows.max() + reach + 1)),
           slice(max(0, cols.min() - reach), min(w, cols.max() + reach + 1)))
    rhos = np.linspace(depths[0], depths[1], max(2, config.levels))
    costs = prediction_costs(first_rgb, second_rgb, rhos, g, rotational, config.window_px, box)
    half = len(rhos) // 2
    far_cost, near_cost = costs[:half].min(0), costs[len(rhos) - half:].min(0)
    out, tested = mask.copy(), band[box]
    out[box][tested & (far_cost < near_cost)] = True
    if config.shrink:
        out[box][tested & (near_cost < far_cost)] = False
    _, labels = cv2.connectedComponents(out.astype(np.uint8))
    held = np.unique(labels[core & out])
    held = held[held > 0]
    if held.size == 0:           # the band reaches the middle of a small mask: nothing to hold on to
        return mask
    kept = cv2.morphologyEx(np.isin(labels, held).astype(np.uint8), cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8))
    contours, _ = cv2.findContours(kept, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    filled = np.zeros_like(m8)
    cv2.drawContours(filled, contours, -1, 1, thickness=cv2.FILLED)
    return filled.astype(bool)


def refine_detection(detection: GapDetection, first_rgb: np.ndarray, second_rgb: np.ndarray, flow: np.ndarray,
                     rotational: np.ndarray, K: np.ndarray, config: EdgeConfig = DEFAULT_EDGES,
                     parallax: ParallaxGapConfig | None = None) -> GapDetection:
    """``detection`` with each opening's mask (:func:`refine_mask`) and what is derived from it (contour,
    centroid, clear circle) read again; ``flow``: the derotated flow the detector saw; ``parallax``: the
    detector's constants (default: as flown)."""
    if not detection.found:
        return detection
    h, w = flow.shape[:2]
    # the principal point in the detector's pixel grid (integer pixel centres), K's in the renderer's (+0.5)
    motion = CameraMotion(focal_px=float(K[0, 0]), principal_point=(float(K[0, 2]) - 0.5, float(K[1, 2]) - 0.5))
    rho, measurable, g = _inverse_depth(flow, motion, parallax or ParallaxGapConfig())
    refined = []
    for candidate in detection.candidates or (detection,):
        mask = refine_mask(candidate.mask, first_rgb, second_rgb, rho, measurable & (rho > 0), g, rotational, config)
        contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        if not contours:
            refined.append(candidate)
            continue
        contour = cv2.approxPolyDP(max(contours, key=cv2.contourArea), 0.5, True)
        refined.append(_from_contour((h, w), contour, candidate.detector))
    return dataclasses.replace(refined[0], candidates=tuple(refined))

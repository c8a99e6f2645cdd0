"""The paper's gap detector (docs/design.md step 3, paper II.C): colour the flow with the Middlebury wheel → BGR
image → grey → Gaussian blur 5×5 → Canny(10, 40) → morphological closing 3×3 ×3 → external contours → keep
0.001·HW ≤ area ≤ 0.9·HW → largest → centroid from moments → filled mask.

It answers with :class:`companion.gap.GapDetection`, as flowgap's own detector does
(:func:`companion.gap.detect_gap_parallax`); :func:`companion.gap.get_detector` names both.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from companion.flow.colour import flow_to_colour
from companion.gap import GapDetection, _from_contour, _no_gap


@dataclass(frozen=True)
class GapDetectorConfig:
    """Constants of the paper's detector (II.C), with its defaults."""

    blur_ksize: int = 5               # Gaussian kernel, 5×5; sigma derived by OpenCV from the size (sigma=0)
    blur_sigma: float = 0.0
    canny_low: float = 10.0           # τ_low, 8-bit units
    canny_high: float = 40.0          # τ_high
    close_ksize: int = 3              # structuring element K, 3×3 rectangle
    close_iterations: int = 3
    area_min_frac: float = 0.001      # α_min
    area_max_frac: float = 0.9        # α_max


def detect_gap_in_colour(flow_bgr: np.ndarray, config: GapDetectorConfig = GapDetectorConfig(),
                         *, detector: str = "paper") -> GapDetection:
    """Run steps 3a–3e on a flow colour image given in **BGR** channel order (H×W×3 uint8)."""
    if flow_bgr.ndim != 3 or flow_bgr.shape[2] != 3 or flow_bgr.dtype != np.uint8:
        raise ValueError(f"expected an H×W×3 uint8 BGR image, got {flow_bgr.shape} {flow_bgr.dtype}")
    h, w = flow_bgr.shape[:2]
    grey = cv2.cvtColor(flow_bgr, cv2.COLOR_BGR2GRAY)
    grey = cv2.GaussianBlur(grey, (config.blur_ksize, config.blur_ksize), config.blur_sigma)
    edges = cv2.Canny(grey, config.canny_low, config.canny_high)
    kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (config.close_ksize, config.close_ksize))
    closed = cv2.morphologyEx(edges, cv2.MORPH_CLOSE, kernel, iterations=config.close_iterations)
    contours, _ = cv2.findContours(closed, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    if not contours:
        return _no_gap((h, w), "no contours in the edge map", detector)
    a_min, a_max = config.area_min_frac * h * w, config.area_max_frac * h * w
    valid = [(cv2.contourArea(c), c) for c in contours]
    valid = [(a, c) for a, c in valid if a_min <= a <= a_max]
    if not valid:
        return _no_gap((h, w), f"no contour with {a_min:.0f} <= area <= {a_max:.0f} px² "
                               f"({len(contours)} contours)", detector)
    _, best = max(valid, key=lambda ac: ac[0])
    return _from_contour((h, w), best, detector)


def detect_gap(flow: np.ndarray, config: GapDetectorConfig = GapDetectorConfig(),
               textured: np.ndarray | None = None) -> GapDetection:
    """The paper's gap detector on an H×W×2 flow field (colours it, normalised by its largest magnitude).
    ``textured`` is taken for the detectors' common call and not read: the paper reads the flow alone."""
    return detect_gap_in_colour(flow_to_colour(flow, bgr=True), config, detector="paper")

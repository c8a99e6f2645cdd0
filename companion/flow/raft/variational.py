"""Refinement of a RAFT flow at full resolution: variational (the images' own gradients) or by DIS's patches.

RAFT-small finds every motion on a 1/8-resolution grid; the variational energy of Brox et al. (brightness
and gradient constancy, robust smoothness), minimised from RAFT's flow as its starting point, then pulls each
pixel onto the match the full-resolution images say is exact.  It is OpenCV's ``VariationalRefinement``,
the same energy DIS ends each of its scales with, run coarse to fine: at 1/2**(levels-1) of the frame
first, down to the full frame.  The energy is local (linearised around the flow it starts from), so it only
refines: the large motions and the opening's edges come from RAFT.
"""

from __future__ import annotations

import cv2
import numpy as np

from companion.flow.opencv_flow import create_dis

# OpenCV's defaults for the energy's weights (smoothness alpha, colour constancy delta, gradient constancy
# gamma); measured on held-out pairs, other weights did no better (see the model card).
ALPHA = 20.0
DELTA = 5.0
GAMMA = 10.0
SOR_ITERATIONS = 5


def _grey(img: np.ndarray) -> np.ndarray:
    img = np.asarray(img)
    if img.dtype != np.uint8:
        img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    return cv2.cvtColor(img, cv2.COLOR_RGB2GRAY) if img.ndim == 3 else img


def _refiner(iterations: int) -> cv2.VariationalRefinement:
    vr = cv2.VariationalRefinement_create()
    vr.setAlpha(ALPHA)
    vr.setDelta(DELTA)
    vr.setGamma(GAMMA)
    vr.setSorIterations(SOR_ITERATIONS)
    vr.setFixedPointIterations(int(iterations))
    return vr


def variational_refine(img1: np.ndarray, img2: np.ndarray, flow: np.ndarray, levels: int = 2,
                       iterations: int = 10) -> np.ndarray:
    """``flow`` (H×W×2 float32, from ``img1`` to ``img2``, both H×W×3 RGB) refined on ``levels`` scales, the
    coarsest at 1/2**(levels-1) of the frame, with ``iterations`` fixed-point iterations on each.  ``levels``
    0 returns the flow unchanged.  A new array; the input is not modified."""
    if levels < 0 or iterations < 1:
        raise ValueError(f"variational refinement needs levels >= 0 and iterations >= 1 (got {levels}, {iterations})")
    out = np.array(flow, dtype=np.float32, copy=True)
    if levels == 0:
        return out
    g1, g2 = _grey(img1), _grey(img2)
    h, w = g1.shape
    refiner = _refiner(iterations)
    for level in range(levels - 1, -1, -1):
        s = 2 ** level
        lw, lh = w // s, h // s
        if s == 1:
            refiner.calc(g1, g2, out)
            break
        if min(lw, lh) < 8:
            continue
        small = np.ascontiguousarray(cv2.resize(out, (lw, lh), interpolation=cv2.INTER_AREA) / np.float32(s))
        refiner.calc(cv2.resize(g1, (lw, lh), interpolation=cv2.INTER_AREA),
                     cv2.resize(g2, (lw, lh), interpolation=cv2.INTER_AREA), small)
        # only the correction is carried up, so that detail the coarse level cannot see is kept
        delta = small - cv2.resize(out, (lw, lh), interpolation=cv2.INTER_AREA) / np.float32(s)
        out += cv2.resize(delta, (w, h), interpolation=cv2.INTER_LINEAR) * np.float32(s)
    return out


def patch_refine(img1: np.ndarray, img2: np.ndarray, flow: np.ndarray, levels: int = 3) -> np.ndarray:
    """``flow`` (H×W×2 float32, from ``img1`` to ``img2``) refined by DIS's inverse search (``dis:fine``'s DIS:
    MEDIUM's 8×8 patches) on ``levels`` scales, from 1/2**(levels-1) of the frame down to the full frame, each
    ending with DIS's own variational step.

    RAFT's 1/8-resolution flow finds the large motions and which surface a pixel belongs to; DIS's 8×8 patches,
    started from it, match each pixel's neighbourhood at full resolution, which is what small far-away motions
    need (DIS alone, started from zero on the same scales, misses the large ones).  ``levels`` 0 returns the
    flow unchanged.  A new array; the input is not modified."""
    if levels < 0:
        raise ValueError(f"patch refinement needs levels >= 0 (got {levels})")
    out = np.array(flow, dtype=np.float32, copy=True)
    if levels == 0:
        return out
    dis = create_dis("fine", ((int(levels) - 1, "setCoarsestScale"),))     # dis:fine's DIS, from a nearer scale
    # a flow of the frame's size and type passed in is DIS's starting point at its coarsest scale
    return dis.calc(_grey(img1), _grey(img2), out)

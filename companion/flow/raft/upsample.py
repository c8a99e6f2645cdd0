"""Flow upsampling from 1/8 resolution to full resolution (flow values scaled by 8)."""

from __future__ import annotations

import torch
import torch.nn.functional as F


def upflow8(flow: torch.Tensor, align_corners: bool = True) -> torch.Tensor:
    """Bilinear ×8.

    ``align_corners=False`` puts each coarse value at the centre of its 8×8 block (pixel 8i + 3.5), where
    its stride-8 features are centred.  ``True`` is the RAFT authors' RAFT-small: it stretches the coarse grid
    to the frame's corner pixels, misplacing values by up to 3.5 px by an amount that depends on the frame
    size, so weights trained on one size are slightly wrong on another (the official checkpoints and
    flowgap's version-1 weights were trained that way).
    """
    n, _, h, w = flow.shape
    return 8.0 * F.interpolate(flow, size=(8 * h, 8 * w), mode="bilinear", align_corners=align_corners)


def convex_upsample(flow: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Learned convex upsampling: each full-res pixel is a softmax-weighted mix of its coarse 3×3 window.

    ``flow``: N×2×h×w, ``mask``: N×(9·8·8)×h×w logits laid out as (9, 8, 8) per coarse pixel.
    """
    n, _, h, w = flow.shape
    weights = torch.softmax(mask.view(n, 1, 9, 8, 8, h, w), dim=2)
    windows = F.unfold(8.0 * flow, kernel_size=3, padding=1).view(n, 2, 9, 1, 1, h, w)
    up = (weights * windows).sum(dim=2)                       # N×2×8×8×h×w  (sub-row, sub-col, row, col)
    return up.permute(0, 1, 4, 2, 5, 3).reshape(n, 2, 8 * h, 8 * w)

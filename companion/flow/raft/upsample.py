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


def convex_upsample(flow: torch.Tensor, mask: torch.Tensor, pad: str = "zeros", factor: int = 8) -> torch.Tensor:
    """Learned convex upsampling: each fine pixel is a softmax-weighted mix of its coarse 3×3 window.

    ``flow``: N×2×h×w, ``mask``: N×(9·f·f)×h×w logits laid out as (9, f, f) per coarse pixel (window
    position row-major, then sub-row, sub-column) for ``factor`` f.  ``pad``: what the windows see beyond
    the frame's border, "zeros" (RAFT) or "replicate" (the border cell repeated).  The flow is scaled by f.
    """
    n, _, h, w = flow.shape
    f = factor
    weights = torch.softmax(mask.view(n, 1, 9, f, f, h, w), dim=2)
    if pad == "replicate":
        windows = F.unfold(F.pad(f * flow, (1, 1, 1, 1), mode="replicate"), kernel_size=3)
    elif pad == "zeros":
        windows = F.unfold(f * flow, kernel_size=3, padding=1)
    else:
        raise ValueError(f"unknown convex-upsampling padding {pad!r}; choose 'zeros' or 'replicate'")
    windows = windows.view(n, 2, 9, 1, 1, h, w)
    up = (weights * windows).sum(dim=2)                       # N×2×f×f×h×w  (sub-row, sub-col, row, col)
    return up.permute(0, 1, 4, 2, 5, 3).reshape(n, 2, f * h, f * w)


def bilinear_mask_logits(floor: float = 0.01, factor: int = 8) -> torch.Tensor:
    """The 9·f² convex-upsampling logits (same for every coarse pixel) that reproduce bilinear ×f
    interpolation from the block centres (``upflow8(align_corners=False)`` for f = 8) away from the border.

    Sub-pixel s of a block lies (s − (f−1)/2)/f cells from its own centre; its bilinear weights fall on that
    cell and the neighbour on the same side.  Window positions without weight get ``floor`` (a softmax
    cannot express zero), so that training can still move weight onto them.
    """
    f = factor
    sub = (torch.arange(f, dtype=torch.float64) - (f - 1) / 2) / f     # offset from the own centre, cells
    # 1-D weights of window positions -1, 0, +1 for each sub-pixel: 3×f
    w1 = torch.stack([(-sub).clamp(min=0), 1 - sub.abs(), sub.clamp(min=0)])
    w2 = w1.view(3, 1, f, 1) * w1.view(1, 3, 1, f)                    # (ky, kx, sub-row, sub-col)
    return torch.log(w2.reshape(9 * f * f) + floor).float()

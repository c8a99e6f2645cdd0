"""Quarter-resolution refinement (flowgap's, for RAFT-small-refined): after RAFT's iterations on the 1/8 grid,
one correction on the 1/4 grid, where the encoders' ``layer2`` features live, then learned convex ×4 upsampling.

RAFT's 1/8 grid puts an 8×8 block under every flow value; at an opening's edge, where the flow jumps, even
the best choice among a pixel's 3×3 coarse neighbours is off by the flow's gradient over a block (measured on
the validation pairs: 0.26 px EPE for the best neighbour of the exact block means, 0.50 for their bilinear
interpolation, 98 % of it within 8 px of an edge).  Here the 1/8 estimate, convex-upsampled and pooled to the
1/4 grid, is compared with frame 2's quarter features warped by it, over a (2r+1)² window, and a small
network reads that local correlation, the flow and frame 1's quarter context to correct the flow and to
weight its ×4 convex upsampling.  It starts as the identity: no correction, bilinear ×4 upsampling.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from companion.flow.raft.upsample import bilinear_mask_logits


def warp(features: torch.Tensor, flow: torch.Tensor) -> torch.Tensor:
    """``features`` (N×C×h×w) sampled at each pixel plus its ``flow`` (N×2×h×w, pixels), bilinear, zeros
    outside."""
    n, _, h, w = flow.shape
    ys, xs = torch.meshgrid(torch.arange(h, device=flow.device, dtype=flow.dtype),
                            torch.arange(w, device=flow.device, dtype=flow.dtype), indexing="ij")
    x = (xs + flow[:, 0]) * (2.0 / max(w - 1, 1)) - 1.0
    y = (ys + flow[:, 1]) * (2.0 / max(h - 1, 1)) - 1.0
    return F.grid_sample(features, torch.stack([x, y], dim=-1).to(features.dtype), mode="bilinear",
                         padding_mode="zeros", align_corners=True)


def local_correlation(f1: torch.Tensor, f2_warped: torch.Tensor, radius: int) -> torch.Tensor:
    """N×(2r+1)²×h×w: <f1(p), f2w(p + d)> / sqrt(C) for every offset d of the window (row-major), zeros
    beyond the border.

    One shifted dot product per offset: unfolding the (2r+1)² windows first (``F.unfold``) computes the same
    sums through a copy 25 times the features' size, which cost 15–19 ms of a 320×240 pair on 2 CPU threads
    against about 1 ms here."""
    n, c, h, w = f1.shape
    k = 2 * radius + 1
    dtype = torch.promote_types(f1.dtype, f2_warped.dtype)
    a, padded = f1.to(dtype), F.pad(f2_warped.to(dtype), (radius, radius, radius, radius))
    out = [(a * padded[:, :, dy:dy + h, dx:dx + w]).sum(dim=1) for dy in range(k) for dx in range(k)]
    return torch.stack(out, dim=1) / math.sqrt(c)


class QuarterRefiner(nn.Module):
    """``(flow_quarter, f1, f2, context) -> (refined flow_quarter, ×4 convex-upsampling logits)``."""

    def __init__(self, feature_dim: int = 64, context_dim: int = 64, hidden_dim: int = 64, radius: int = 2) -> None:
        super().__init__()
        self.radius = radius
        corr = (2 * radius + 1) ** 2
        self.conv1 = nn.Conv2d(corr + 2 + context_dim, hidden_dim, 3, padding=1)
        self.conv2 = nn.Conv2d(hidden_dim, hidden_dim, 3, padding=1)
        self.flow = nn.Conv2d(hidden_dim, 2, 3, padding=1)
        self.mask = nn.Sequential(nn.Conv2d(hidden_dim, hidden_dim, 3, padding=1), nn.ReLU(inplace=True),
                                  nn.Conv2d(hidden_dim, 9 * 4 * 4, 1))
        for head in (self.flow, self.mask[-1]):      # the identity at first
            nn.init.zeros_(head.weight)
            nn.init.zeros_(head.bias)
        with torch.no_grad():
            self.mask[-1].bias.copy_(bilinear_mask_logits(factor=4))

    def forward(self, flow: torch.Tensor, f1: torch.Tensor, f2: torch.Tensor,
                context: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        corr = local_correlation(f1, warp(f2, flow), self.radius)
        x = F.relu(self.conv1(torch.cat([corr, flow.to(corr.dtype), context.to(corr.dtype)], dim=1)))
        x = F.relu(self.conv2(x))
        return flow + self.flow(x).float(), self.mask(x)

"""All-pairs correlation volume and its pyramid, looked up around the current flow estimate."""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F


def sample_pixels(img: torch.Tensor, coords: torch.Tensor) -> torch.Tensor:
    """Bilinear lookup of ``img`` (N×C×H×W) at pixel coordinates ``coords`` (N×h×w×2, (x, y)); zeros outside."""
    h, w = img.shape[-2:]
    x = coords[..., 0] * (2.0 / max(w - 1, 1)) - 1.0
    y = coords[..., 1] * (2.0 / max(h - 1, 1)) - 1.0
    return F.grid_sample(img, torch.stack([x, y], dim=-1), mode="bilinear", padding_mode="zeros",
                         align_corners=True)


class CorrBlock:
    """Correlation pyramid built once per image pair, then queried every iteration.

    ``corr[p, q] = <f1(p), f2(q)> / sqrt(D)`` for every pixel p of image 1 and q of image 2 (1/8 resolution),
    average-pooled over q into ``num_levels`` levels.  ``__call__(coords1)`` returns, for each pixel p, the
    (2r+1)² values around ``coords1[p] / 2^l`` at every level l: ``num_levels·(2r+1)²`` channels.

    Channel order within a level is ``i·(2r+1) + j`` for the offset ``(dx, dy) = (i − r, j − r)``, i.e. the
    x offset varies slowest; the official and torchvision checkpoints were trained with this order.
    """

    def __init__(self, fmap1: torch.Tensor, fmap2: torch.Tensor, num_levels: int = 4, radius: int = 4) -> None:
        if fmap1.shape != fmap2.shape:
            raise ValueError(f"feature maps differ: {tuple(fmap1.shape)} vs {tuple(fmap2.shape)}")
        self.num_levels = num_levels
        self.radius = radius
        n, d, h, w = fmap1.shape
        # Pooling the volume over q is pooling frame 2's features, the dot product being linear: each level is
        # one product with the pooled features (the same values, without pooling h·w maps of the volume)
        f1 = fmap1.reshape(n, d, h * w).transpose(1, 2) / math.sqrt(d)
        f2 = fmap2
        self.pyramid = []
        for level in range(num_levels):
            if level:
                f2 = F.avg_pool2d(f2, 2, stride=2)
            h2, w2 = f2.shape[-2:]
            self.pyramid.append(torch.matmul(f1, f2.reshape(n, d, h2 * w2)).reshape(n * h * w, 1, h2, w2))
        side = 2 * radius + 1
        d_ = torch.linspace(-radius, radius, side, device=fmap1.device, dtype=fmap1.dtype)
        dx = d_.view(side, 1).expand(side, side)          # slow index -> x offset
        dy = d_.view(1, side).expand(side, side)          # fast index -> y offset
        self._offsets = torch.stack([dx, dy], dim=-1).view(1, side, side, 2)

    @property
    def out_channels(self) -> int:
        return self.num_levels * (2 * self.radius + 1) ** 2

    def __call__(self, coords: torch.Tensor) -> torch.Tensor:
        """``coords``: N×2×h×w pixel positions in image 2 (1/8 res.) → N×(L·(2r+1)²)×h×w features."""
        n, _, h, w = coords.shape
        centres = coords.permute(0, 2, 3, 1).reshape(n * h * w, 1, 1, 2)
        out = []
        for level, corr in enumerate(self.pyramid):
            window = centres / (2 ** level) + self._offsets.to(coords.dtype)
            out.append(sample_pixels(corr, window).view(n, h, w, -1))
        return torch.cat(out, dim=-1).permute(0, 3, 1, 2).contiguous()

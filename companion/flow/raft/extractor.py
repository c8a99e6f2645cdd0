"""Feature and context encoders: images → 1/8-resolution feature maps.

Module names follow the official RAFT checkpoints (``conv1``, ``norm1``, ``layer1.0.conv1``, ...), so
their state dicts load directly (see :mod:`.weights` for the ``norm3``/``norm4`` aliases they also carry).
"""

from __future__ import annotations

import torch
from torch import nn


def make_norm(kind: str, channels: int) -> nn.Module:
    """'instance' (no affine, as RAFT), 'batch', 'group' (channels/8 groups) or 'none'."""
    if kind == "instance":
        return nn.InstanceNorm2d(channels)
    if kind == "batch":
        return nn.BatchNorm2d(channels)
    if kind == "group":
        return nn.GroupNorm(num_groups=max(1, channels // 8), num_channels=channels)
    if kind == "none":
        return nn.Identity()
    raise ValueError(f"unknown norm {kind!r}")


class ResidualBlock(nn.Module):
    """Two 3×3 conv–norm–ReLU layers plus a (strided 1×1 conv + norm) shortcut when the stride is not 1."""

    def __init__(self, in_planes: int, planes: int, norm: str, stride: int = 1) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(in_planes, planes, 3, padding=1, stride=stride)
        self.conv2 = nn.Conv2d(planes, planes, 3, padding=1)
        self.norm1 = make_norm(norm, planes)
        self.norm2 = make_norm(norm, planes)
        self.relu = nn.ReLU(inplace=True)
        self.downsample = (None if stride == 1 else
                           nn.Sequential(nn.Conv2d(in_planes, planes, 1, stride=stride), make_norm(norm, planes)))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = self.relu(self.norm1(self.conv1(x)))
        y = self.relu(self.norm2(self.conv2(y)))
        if self.downsample is not None:
            x = self.downsample(x)
        return self.relu(x + y)


class BottleneckBlock(nn.Module):
    """1×1 → 3×3 (strided) → 1×1 convolutions at a quarter of the width, with the same shortcut rule."""

    def __init__(self, in_planes: int, planes: int, norm: str, stride: int = 1) -> None:
        super().__init__()
        mid = planes // 4
        self.conv1 = nn.Conv2d(in_planes, mid, 1)
        self.conv2 = nn.Conv2d(mid, mid, 3, padding=1, stride=stride)
        self.conv3 = nn.Conv2d(mid, planes, 1)
        self.norm1 = make_norm(norm, mid)
        self.norm2 = make_norm(norm, mid)
        self.norm3 = make_norm(norm, planes)
        self.relu = nn.ReLU(inplace=True)
        self.downsample = (None if stride == 1 else
                           nn.Sequential(nn.Conv2d(in_planes, planes, 1, stride=stride), make_norm(norm, planes)))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = self.relu(self.norm1(self.conv1(x)))
        y = self.relu(self.norm2(self.conv2(y)))
        y = self.relu(self.norm3(self.conv3(y)))
        if self.downsample is not None:
            x = self.downsample(x)
        return self.relu(x + y)


class Encoder(nn.Module):
    """7×7 stride-2 stem, three stages of two blocks (strides 1, 2, 2), 1×1 projection: ×1/8 resolution.

    ``widths`` = (stem, stage1, stage2, stage3); RAFT uses (64, 64, 96, 128) with residual blocks and
    RAFT-small (32, 32, 64, 96) with bottleneck blocks.
    """

    def __init__(self, output_dim: int, norm: str, block: type[nn.Module], widths: tuple[int, int, int, int],
                 dropout: float = 0.0) -> None:
        super().__init__()
        stem, w1, w2, w3 = widths
        self.conv1 = nn.Conv2d(3, stem, 7, stride=2, padding=3)
        self.norm1 = make_norm(norm, stem)
        self.relu1 = nn.ReLU(inplace=True)
        self.layer1 = nn.Sequential(block(stem, w1, norm, 1), block(w1, w1, norm, 1))
        self.layer2 = nn.Sequential(block(w1, w2, norm, 2), block(w2, w2, norm, 1))
        self.layer3 = nn.Sequential(block(w2, w3, norm, 2), block(w3, w3, norm, 1))
        self.conv2 = nn.Conv2d(w3, output_dim, 1)
        self.dropout = nn.Dropout2d(p=dropout) if dropout > 0 else None
        for m in self.modules():
            if isinstance(m, nn.Conv2d):
                nn.init.kaiming_normal_(m.weight, mode="fan_out", nonlinearity="relu")
            elif isinstance(m, (nn.BatchNorm2d, nn.GroupNorm)):
                nn.init.ones_(m.weight)
                nn.init.zeros_(m.bias)

    def forward(self, x: torch.Tensor, with_quarter: bool = False):
        """The 1/8-resolution map; with ``with_quarter`` also the 1/4-resolution one (``layer2``'s output):
        ``(eighth, quarter)``."""
        x = self.relu1(self.norm1(self.conv1(x)))
        quarter = self.layer2(self.layer1(x))
        x = self.conv2(self.layer3(quarter))
        if self.dropout is not None and self.training:
            x = self.dropout(x)
        return (x, quarter) if with_quarter else x


def basic_encoder(output_dim: int, norm: str, dropout: float = 0.0) -> Encoder:
    """RAFT's encoder (residual blocks, widths 64/64/96/128)."""
    return Encoder(output_dim, norm, ResidualBlock, (64, 64, 96, 128), dropout)


def small_encoder(output_dim: int, norm: str, dropout: float = 0.0) -> Encoder:
    """RAFT-small's encoder (bottleneck blocks, widths 32/32/64/96)."""
    return Encoder(output_dim, norm, BottleneckBlock, (32, 32, 64, 96), dropout)

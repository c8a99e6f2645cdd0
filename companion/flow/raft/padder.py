"""Pad images to multiples of 8 (RAFT works at 1/8 resolution) and crop results back."""

from __future__ import annotations

import torch
import torch.nn.functional as F


class InputPadder:
    """Built once for an image size; ``pad(*tensors)`` and ``unpad(tensor)`` are cheap.

    ``mode="sintel"`` splits the padding evenly on both sides; ``"kitti"`` splits the width padding but pads
    the height only at the bottom (as in RAFT's KITTI evaluation).  Padding replicates the border pixels.
    """

    def __init__(self, dims: tuple[int, ...] | torch.Size, mode: str = "sintel", multiple: int = 8) -> None:
        ht, wd = int(dims[-2]), int(dims[-1])
        pad_ht = (-ht) % multiple
        pad_wd = (-wd) % multiple
        if mode == "sintel":
            self._pad = (pad_wd // 2, pad_wd - pad_wd // 2, pad_ht // 2, pad_ht - pad_ht // 2)
        elif mode == "kitti":
            self._pad = (pad_wd // 2, pad_wd - pad_wd // 2, 0, pad_ht)
        else:
            raise ValueError(f"unknown padding mode {mode!r}")
        self.size = (ht, wd)
        self.padded_size = (ht + pad_ht, wd + pad_wd)

    @property
    def padding(self) -> tuple[int, int, int, int]:
        """(left, right, top, bottom)."""
        return self._pad

    def pad(self, *tensors: torch.Tensor) -> list[torch.Tensor]:
        return [F.pad(t, self._pad, mode="replicate") for t in tensors]

    def unpad(self, x: torch.Tensor) -> torch.Tensor:
        ht, wd = x.shape[-2:]
        left, right, top, bottom = self._pad
        return x[..., top:ht - bottom, left:wd - right]

"""RAFT: encode both frames, build the correlation pyramid once, refine the flow with a recurrent update."""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import torch
import torch.nn.functional as F
from torch import nn

from companion.flow.raft.corr import CorrBlock
from companion.flow.raft.extractor import basic_encoder, small_encoder
from companion.flow.raft.refine import QuarterRefiner
from companion.flow.raft.update import UpdateBlock
from companion.flow.raft.upsample import bilinear_mask_logits, convex_upsample, upflow8

VARIANTS = ("small", "small-convex", "small-refined", "large")


@dataclass(frozen=True)
class RaftConfig:
    """Architecture hyper-parameters.  Use :meth:`small` or :meth:`large` (the paper's two models), or
    :meth:`small_convex` (the companion's: RAFT-small with RAFT's learned convex upsampling)."""

    variant: str = "small"
    hidden_dim: int = 96
    context_dim: int = 64
    corr_levels: int = 4
    corr_radius: int = 3
    dropout: float = 0.0
    # RAFT-small's bilinear ×8 upsampling: True as the RAFT authors (coarse grid stretched to the corner
    # pixels), False with each coarse value at its block's centre (see ``upflow8``).  Convex upsampling
    # ignores it.
    upsample_align_corners: bool = True
    # Convex upsampling's mask head (hidden width; 0: bilinear upsampling) and how its 3×3 windows are
    # padded at the frame's border: "zeros" as RAFT, "replicate" so that border pixels are not pulled
    # towards zero flow.
    mask_dim: int = 0
    upsample_pad: str = "zeros"
    # a last correction on the 1/4 grid with the encoders' quarter-resolution features, then ×4 convex
    # upsampling (companion.flow.raft.refine)
    quarter_refine: bool = False

    @classmethod
    def small(cls, **kw) -> RaftConfig:
        return cls("small", 96, 64, 4, 3, **kw)

    @classmethod
    def small_convex(cls, **kw) -> RaftConfig:
        """RAFT-small's encoders and update block, upsampled by a learned convex combination (as RAFT) from a
        mask head of 128 channels: one pass at the camera's resolution, no enlarged second pass."""
        kw.setdefault("upsample_align_corners", False)
        return cls("small-convex", 96, 64, 4, 3, mask_dim=128, upsample_pad="replicate", **kw)

    @classmethod
    def small_refined(cls, **kw) -> RaftConfig:
        """RAFT-small-convex with a quarter-resolution refinement (:mod:`~companion.flow.raft.refine`): the
        companion's flow, one pass at the camera's resolution."""
        kw.setdefault("upsample_align_corners", False)
        return cls("small-refined", 96, 64, 4, 3, mask_dim=128, upsample_pad="replicate", quarter_refine=True, **kw)

    @classmethod
    def large(cls, **kw) -> RaftConfig:
        return cls("large", 128, 128, 4, 4, mask_dim=256, **kw)

    @classmethod
    def for_variant(cls, variant: str, **kw) -> RaftConfig:
        if variant not in VARIANTS:
            raise ValueError(f"unknown RAFT variant {variant!r}; choose one of {', '.join(VARIANTS)}")
        return {"small": cls.small, "small-convex": cls.small_convex, "small-refined": cls.small_refined,
                "large": cls.large}[variant](**kw)


class RaftOutput(NamedTuple):
    flow_low: torch.Tensor                  # N×2×(H/8)×(W/8), the state to warm-start the next pair from
    flow_up: torch.Tensor                   # N×2×H×W, the final estimate
    predictions: list[torch.Tensor]         # per-iteration N×2×H×W estimates when requested, else []
    fmap2: torch.Tensor | None = None       # the second frame's features: the next pair's first (see forward)
    fquarter2: torch.Tensor | None = None   # and its quarter-resolution features (quarter refinement only)


def coords_grid(n: int, h: int, w: int, device=None, dtype=torch.float32) -> torch.Tensor:
    """N×2×h×w pixel coordinates, channel 0 = x, channel 1 = y."""
    ys, xs = torch.meshgrid(torch.arange(h, device=device, dtype=dtype),
                            torch.arange(w, device=device, dtype=dtype), indexing="ij")
    return torch.stack([xs, ys], dim=0).unsqueeze(0).expand(n, 2, h, w).contiguous()


class RAFT(nn.Module):
    """RAFT / RAFT-small.  ``forward(image1, image2, iters, flow_init)`` on N×3×H×W images in 0..255.

    H and W must be multiples of 8 (use :class:`InputPadder`).  ``flow_init`` (N×2×H/8×W/8) starts the
    refinement from a previous estimate (warm start) instead of zero.  ``fmap1``: the first frame's features
    when they are already known (the previous pair's ``fmap2`` in a sequence: the feature encoder normalises
    each image on its own, so they are the same features), which saves one of the two encoder passes; with
    the quarter-resolution refinement, ``fquarter1`` (the previous pair's ``fquarter2``) goes with it.
    """

    def __init__(self, config: RaftConfig | None = None) -> None:
        super().__init__()
        config = config if config is not None else RaftConfig.small()
        self.config = config
        small = config.variant != "large"
        hdim, cdim = config.hidden_dim, config.context_dim
        if small:
            self.fnet = small_encoder(128, "instance", config.dropout)
            self.cnet = small_encoder(hdim + cdim, "none", config.dropout)
        else:
            self.fnet = basic_encoder(256, "instance", config.dropout)
            self.cnet = basic_encoder(hdim + cdim, "batch", config.dropout)
        corr_channels = config.corr_levels * (2 * config.corr_radius + 1) ** 2
        self.update_block = UpdateBlock(corr_channels=corr_channels, hidden_dim=hdim, context_dim=cdim,
                                        small=small, mask_dim=config.mask_dim)
        self.refiner = QuarterRefiner(feature_dim=64, context_dim=64) if config.quarter_refine else None
        if config.variant in ("small-convex", "small-refined"):
            # Start the new mask head as bilinear interpolation from the block centres, so that RAFT-small
            # weights loaded into it flow exactly as they did; training then sharpens it at edges.
            last = self.update_block.mask[-1]
            nn.init.zeros_(last.weight)
            with torch.no_grad():
                last.bias.copy_(bilinear_mask_logits() / self.update_block.mask_scale)

    def forward(self, image1: torch.Tensor, image2: torch.Tensor, iters: int = 12,
                flow_init: torch.Tensor | None = None, all_predictions: bool = False,
                fmap1: torch.Tensor | None = None, fquarter1: torch.Tensor | None = None,
                quarter_refine: bool = True) -> RaftOutput:
        n, _, h, w = image1.shape
        if image2.shape != image1.shape:
            raise ValueError(f"images differ in shape: {tuple(image1.shape)} vs {tuple(image2.shape)}")
        if h % 8 or w % 8:
            raise ValueError(f"RAFT needs H and W divisible by 8 (got {h}×{w}); pad with InputPadder")
        cfg = self.config
        image1 = 2.0 * (image1 / 255.0) - 1.0
        image2 = 2.0 * (image2 / 255.0) - 1.0

        # 1. features of both frames (one batch), context of the first (and their quarter-resolution maps)
        quarter = self.refiner is not None and quarter_refine     # False: a model that has one skips it
        if fmap1 is not None and quarter and fquarter1 is None:
            raise ValueError("known first-frame features need their quarter-resolution features (fquarter1) too "
                             "with the quarter-resolution refinement")
        if fmap1 is not None:
            fout = self.fnet(image2, with_quarter=quarter)
            fmap2, fquarter2 = fout if quarter else (fout, None)
            fmap2 = fmap2.float()
            if fmap1.shape != fmap2.shape:
                raise ValueError(f"fmap1 must be {tuple(fmap2.shape)}, got {tuple(fmap1.shape)}")
            if quarter and fquarter1.shape != fquarter2.shape:
                raise ValueError(f"fquarter1 must be {tuple(fquarter2.shape)}, got {tuple(fquarter1.shape)}")
        else:
            fout = self.fnet(torch.cat([image1, image2], dim=0), with_quarter=quarter)
            fout, fquarter = fout if quarter else (fout, None)
            fmap1, fmap2 = fout.float().chunk(2, dim=0)
            fquarter1, fquarter2 = fquarter.chunk(2, dim=0) if quarter else (None, None)
        cout = self.cnet(image1, with_quarter=quarter)
        if quarter:
            cout, cquarter = cout
        with torch.autocast(image1.device.type, enabled=False):   # the correlation volume stays float32
            corr_fn = CorrBlock(fmap1, fmap2, num_levels=cfg.corr_levels, radius=cfg.corr_radius)
        net, inp = torch.split(cout, [cfg.hidden_dim, cfg.context_dim], dim=1)
        net, inp = torch.tanh(net), torch.relu(inp)

        # 2. flow as coordinate update: coords1 − coords0, starting from zero or the warm start
        coords0 = coords_grid(n, h // 8, w // 8, device=image1.device)
        coords1 = coords0.clone()
        if flow_init is not None:
            if flow_init.shape != coords0.shape:
                raise ValueError(f"flow_init must be {tuple(coords0.shape)}, got {tuple(flow_init.shape)}")
            coords1 = coords1 + flow_init

        # 3. iterate: look up correlation around the estimate, update the hidden state, step the flow
        predictions: list[torch.Tensor] = []
        for it in range(iters):
            coords1 = coords1.detach()
            corr = corr_fn(coords1)
            net, delta = self.update_block(net, inp, corr, coords1 - coords0)
            coords1 = coords1 + delta.float()
            if all_predictions or it == iters - 1:
                predictions.append(self._upsample(coords1 - coords0, net))

        flow_low = coords1 - coords0
        flow_up = predictions[-1] if predictions else self._upsample(flow_low, net)
        if quarter:
            flow_up = self._refine(flow_up, fquarter1, fquarter2, cquarter)
            predictions.append(flow_up)
        return RaftOutput(flow_low, flow_up, predictions if all_predictions else [], fmap2, fquarter2)

    def _refine(self, flow_up: torch.Tensor, f1: torch.Tensor, f2: torch.Tensor, context: torch.Tensor) -> torch.Tensor:
        """The quarter-resolution correction of a full-resolution flow (see :mod:`.refine`)."""
        flow_quarter = F.avg_pool2d(flow_up.detach(), 4) / 4.0          # full-res px -> quarter-grid px
        flow_quarter, mask = self.refiner(flow_quarter, f1, f2, context)
        with torch.autocast(flow_up.device.type, enabled=False):
            return convex_upsample(flow_quarter.float(), mask.float(), pad="replicate", factor=4)

    def _upsample(self, flow: torch.Tensor, net: torch.Tensor) -> torch.Tensor:
        mask = self.update_block.mask_logits(net)
        # Upsampling stays float32 under bf16 autocast: an 8-bit mantissa would cost a tenth of a pixel on a
        # 40 px flow.
        with torch.autocast(flow.device.type, enabled=False):
            if mask is None:
                return upflow8(flow.float(), align_corners=self.config.upsample_align_corners)
            return convex_upsample(flow.float(), mask.float(), pad=self.config.upsample_pad)

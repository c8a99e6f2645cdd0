"""The recurrent update operator: motion encoder → ConvGRU → flow head (and upsampling-mask head).

RAFT (full) uses the basic motion encoder, a separable ConvGRU (1×5 then 5×1) and a mask head for convex
upsampling; RAFT-small uses a smaller motion encoder and a plain 3×3 ConvGRU, and upsamples bilinearly;
flowgap's RAFT-small-convex is RAFT-small with a (narrower) mask head.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn


class FlowHead(nn.Module):
    def __init__(self, input_dim: int, hidden_dim: int) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(input_dim, hidden_dim, 3, padding=1)
        self.conv2 = nn.Conv2d(hidden_dim, 2, 3, padding=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.conv2(F.relu(self.conv1(x)))


def _gru_step(convz: nn.Conv2d, convr: nn.Conv2d, convq: nn.Conv2d, h: torch.Tensor,
              x: torch.Tensor) -> torch.Tensor:
    hx = torch.cat([h, x], dim=1)
    z = torch.sigmoid(convz(hx))
    r = torch.sigmoid(convr(hx))
    q = torch.tanh(convq(torch.cat([r * h, x], dim=1)))
    return (1 - z) * h + z * q


class ConvGRU(nn.Module):
    """GRU with 3×3 convolutions (RAFT-small)."""

    def __init__(self, hidden_dim: int, input_dim: int) -> None:
        super().__init__()
        self.convz = nn.Conv2d(hidden_dim + input_dim, hidden_dim, 3, padding=1)
        self.convr = nn.Conv2d(hidden_dim + input_dim, hidden_dim, 3, padding=1)
        self.convq = nn.Conv2d(hidden_dim + input_dim, hidden_dim, 3, padding=1)

    def forward(self, h: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
        return _gru_step(self.convz, self.convr, self.convq, h, x)


class SepConvGRU(nn.Module):
    """Two GRU steps, a horizontal (1×5) then a vertical (5×1) one (RAFT)."""

    def __init__(self, hidden_dim: int, input_dim: int) -> None:
        super().__init__()
        c = hidden_dim + input_dim
        self.convz1 = nn.Conv2d(c, hidden_dim, (1, 5), padding=(0, 2))
        self.convr1 = nn.Conv2d(c, hidden_dim, (1, 5), padding=(0, 2))
        self.convq1 = nn.Conv2d(c, hidden_dim, (1, 5), padding=(0, 2))
        self.convz2 = nn.Conv2d(c, hidden_dim, (5, 1), padding=(2, 0))
        self.convr2 = nn.Conv2d(c, hidden_dim, (5, 1), padding=(2, 0))
        self.convq2 = nn.Conv2d(c, hidden_dim, (5, 1), padding=(2, 0))

    def forward(self, h: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
        h = _gru_step(self.convz1, self.convr1, self.convq1, h, x)
        return _gru_step(self.convz2, self.convr2, self.convq2, h, x)


class MotionEncoder(nn.Module):
    """Correlation features and the current flow → motion features (``out_dim`` channels incl. the flow)."""

    def __init__(self, corr_channels: int, corr_dims: tuple[int, ...], flow_dims: tuple[int, int],
                 out_dim: int) -> None:
        super().__init__()
        self.convc1 = nn.Conv2d(corr_channels, corr_dims[0], 1)
        self.convc2 = nn.Conv2d(corr_dims[0], corr_dims[1], 3, padding=1) if len(corr_dims) > 1 else None
        self.convf1 = nn.Conv2d(2, flow_dims[0], 7, padding=3)
        self.convf2 = nn.Conv2d(flow_dims[0], flow_dims[1], 3, padding=1)
        self.conv = nn.Conv2d(corr_dims[-1] + flow_dims[1], out_dim - 2, 3, padding=1)

    def forward(self, flow: torch.Tensor, corr: torch.Tensor) -> torch.Tensor:
        c = F.relu(self.convc1(corr))
        if self.convc2 is not None:
            c = F.relu(self.convc2(c))
        f = F.relu(self.convf2(F.relu(self.convf1(flow))))
        out = F.relu(self.conv(torch.cat([c, f], dim=1)))
        return torch.cat([out, flow], dim=1)


class UpdateBlock(nn.Module):
    """One refinement step: ``(net, inp, corr, flow) -> (net, delta_flow)``; ``mask_logits(net)`` gives the
    convex-upsampling mask of a hidden state (None for bilinear upsampling, ``mask_dim`` 0)."""

    # the 0.25 scale balances the mask branch's gradients; checkpoints were trained with it
    mask_scale = 0.25

    def __init__(self, *, corr_channels: int, hidden_dim: int, context_dim: int, small: bool,
                 mask_dim: int = 0) -> None:
        super().__init__()
        if small:
            self.encoder = MotionEncoder(corr_channels, (96,), (64, 32), 82)
            self.gru = ConvGRU(hidden_dim, context_dim + 82)
            self.flow_head = FlowHead(hidden_dim, 128)
        else:
            self.encoder = MotionEncoder(corr_channels, (256, 192), (128, 64), 128)
            self.gru = SepConvGRU(hidden_dim, context_dim + 128)
            self.flow_head = FlowHead(hidden_dim, 256)
        self.mask = (nn.Sequential(nn.Conv2d(hidden_dim, mask_dim, 3, padding=1), nn.ReLU(inplace=True),
                                   nn.Conv2d(mask_dim, 8 * 8 * 9, 1)) if mask_dim else None)

    def forward(self, net: torch.Tensor, inp: torch.Tensor, corr: torch.Tensor,
                flow: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        motion = self.encoder(flow, corr)
        net = self.gru(net, torch.cat([inp, motion], dim=1))
        return net, self.flow_head(net)

    def mask_logits(self, net: torch.Tensor) -> torch.Tensor | None:
        """N×576×h×w convex-upsampling logits of a hidden state (computed only when a flow is upsampled)."""
        return self.mask_scale * self.mask(net) if self.mask is not None else None

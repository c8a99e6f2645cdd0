"""The ``raft`` flow backend: our RAFT / RAFT-small behind the :class:`FlowBackend` contract."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from companion.flow.base import FlowWeightsError, check_flow, check_pair
from companion.flow.raft.model import RAFT, RaftConfig
from companion.flow.raft.padder import InputPadder
from companion.flow.raft.weights import EXPECTED, load_raft_state_dict

log = logging.getLogger(__name__)

WEIGHTS_DIR = Path(__file__).resolve().parent.parent / "weights"
DEFAULT_WEIGHTS = WEIGHTS_DIR / "raft-small-flowgap.pth"
# The 4-level correlation pyramid halves the 1/8-resolution feature map three times, so a frame (after
# padding to multiples of 8) must be at least 8 × 8 = 64 pixels on each side.
MIN_SIDE = 64


def forward_interpolate(flow_low: torch.Tensor) -> torch.Tensor:
    """Carry a 1/8-res flow (1×2×h×w) forward to the next frame: splat each vector to where it points.

    Cells nothing lands on keep their old vector.  (Official RAFT uses scattered-data interpolation here;
    nearest splatting is enough for a warm start.)
    """
    f = flow_low[0].detach().cpu().numpy()
    _, h, w = f.shape
    ys, xs = np.mgrid[0:h, 0:w]
    x1 = np.rint(xs + f[0]).astype(np.int64)
    y1 = np.rint(ys + f[1]).astype(np.int64)
    ok = (x1 >= 0) & (x1 < w) & (y1 >= 0) & (y1 < h)
    out = f.copy()
    out[0][y1[ok], x1[ok]] = f[0][ok]
    out[1][y1[ok], x1[ok]] = f[1][ok]
    return torch.from_numpy(out).unsqueeze(0).to(flow_low.device)


class RaftBackend:
    """RAFT optical flow.

    Options: ``variant`` "small"|"large"|None (None: from the weights file), ``weights`` path (default
    ``companion/flow/weights/raft-small-flowgap.pth``), ``iters`` refinement iterations (12), ``warm_start``
    (start each pair from the previous pair's flow, carried forward), ``device`` ("cpu", "cuda", ...),
    ``num_threads`` (torch intra-op threads on CPU; None leaves the setting alone), ``random_init_seed``
    (build seeded random weights instead of loading a file: for timing and tests only).
    """

    name = "raft"

    def __init__(self, variant: str | None = None, weights: str | Path | None = None, iters: int = 12,
                 warm_start: bool = False, device: str = "cpu", num_threads: int | None = None,
                 random_init_seed: int | None = None, padding_mode: str = "sintel") -> None:
        if num_threads is not None:
            torch.set_num_threads(int(num_threads))
        if iters < 0:
            raise ValueError("iters must be >= 0")
        self.iters = int(iters)
        self.warm_start = bool(warm_start)
        self.padding_mode = padding_mode
        self._device = torch.device(device)
        if self._device.type == "cuda" and not torch.cuda.is_available():
            raise RuntimeError("RAFT backend: device 'cuda' requested but CUDA is not available")
        if random_init_seed is not None:
            self.variant = variant or "small"
            with torch.random.fork_rng(devices=[]):
                torch.manual_seed(int(random_init_seed))
                self.model = RAFT(RaftConfig.for_variant(self.variant))
            self.weights_path = None
            self.weights_layout = "random"
        else:
            path = Path(weights) if weights is not None else DEFAULT_WEIGHTS
            layout, found, state = load_raft_state_dict(path)
            if variant is not None and variant != found:
                raise FlowWeightsError(f"RAFT weights mismatch: {path} holds RAFT-{found}, RAFT-{variant} was "
                                       f"requested (expected {EXPECTED})")
            self.variant = found
            self.model = RAFT(RaftConfig.for_variant(found))
            try:
                self.model.load_state_dict(state, strict=True)
            except RuntimeError as exc:
                first = str(exc).strip().splitlines()
                detail = " ".join(s.strip() for s in first[1:3])[:200] if len(first) > 1 else first[0][:200]
                raise FlowWeightsError(f"RAFT weights mismatch: {path} does not fit RAFT-{found} ({detail}; "
                                       f"expected {EXPECTED})") from None
            self.weights_path = path
            self.weights_layout = layout
        self.model.to(self._device).eval()
        self._previous_low: torch.Tensor | None = None

    @property
    def device(self) -> str:
        return str(self._device)

    def reset(self) -> None:
        """Forget the warm-start state (start of a new sequence)."""
        self._previous_low = None

    def _to_tensor(self, img: np.ndarray) -> torch.Tensor:
        return torch.from_numpy(np.ascontiguousarray(img)).permute(2, 0, 1).float().unsqueeze(0).to(self._device)

    @torch.inference_mode()
    def estimate(self, img1: np.ndarray, img2: np.ndarray, flow_init: np.ndarray | None = None,
                 iters: int | None = None) -> np.ndarray:
        """H×W×2 float32 flow.  ``flow_init``: a full-resolution initial flow (e.g. the previous result)."""
        h, w = check_pair(img1, img2)
        padder = InputPadder((h, w), mode=self.padding_mode)
        if min(padder.padded_size) < MIN_SIDE:
            raise ValueError(f"RAFT needs frames of at least {MIN_SIDE}×{MIN_SIDE} pixels (its correlation pyramid "
                             f"has 4 levels at 1/8 resolution); got {w}×{h}: use a larger camera or the dis backend")
        t1, t2 = padder.pad(self._to_tensor(img1), self._to_tensor(img2))
        ph, pw = padder.padded_size
        init = None
        if flow_init is not None:
            fi = torch.from_numpy(check_flow(flow_init, (h, w))).permute(2, 0, 1).unsqueeze(0).to(self._device)
            (fi,) = padder.pad(fi)
            init = F.avg_pool2d(fi, 8) / 8.0                   # full-res pixels -> 1/8-res cells
        elif self.warm_start and self._previous_low is not None \
                and self._previous_low.shape[-2:] == (ph // 8, pw // 8):
            init = forward_interpolate(self._previous_low)
        out = self.model(t1, t2, iters=self.iters if iters is None else int(iters), flow_init=init)
        if self.warm_start:
            self._previous_low = out.flow_low
        flow = padder.unpad(out.flow_up)[0].permute(1, 2, 0)
        return np.ascontiguousarray(flow.float().cpu().numpy(), dtype=np.float32)

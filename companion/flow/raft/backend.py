"""The ``raft`` flow backend: our RAFT / RAFT-small behind the :class:`FlowBackend` contract."""

from __future__ import annotations

import hashlib
import logging
from contextlib import nullcontext
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from companion.flow.base import FlowWeightsError, check_flow, check_pair
from companion.flow.raft.model import RAFT, RaftConfig
from companion.flow.raft.padder import InputPadder
from companion.flow.raft.settings import (
    INPUT_SCALE_RANGE,
    PRECISIONS,
    RAFT_DEFAULTS,
    InferenceSettings,
    cpu_has_native_bf16,
    describe_settings,
    refinement_is_adaptive,
    resolve_precision,
)
from companion.flow.raft.variational import patch_refine, variational_refine
from companion.flow.raft.weights import EXPECTED, load_raft_state_dict

__all__ = ["DEFAULT_WEIGHTS", "INPUT_SCALE_RANGE", "PRECISIONS", "RAFT_DEFAULTS", "InferenceSettings", "RaftBackend",
           "cpu_has_native_bf16", "describe_settings", "estimate_flow", "refinement_is_adaptive",
           "refinement_scale", "resolve_precision"]

log = logging.getLogger(__name__)

WEIGHTS_DIR = Path(__file__).resolve().parent.parent / "weights"
DEFAULT_WEIGHTS = WEIGHTS_DIR / "raft-small-refined-flowgap.pth"
# The 4-level correlation pyramid halves the 1/8-resolution feature map three times, so a frame (after
# padding to multiples of 8) must be at least 8 × 8 = 64 pixels on each side.
MIN_SIDE = 64


def zoom_frame(img: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """H×W×3 frame resized to ``size`` (width, height) as float32 0..255, bicubic (training zooms the same way)."""
    import cv2

    out = cv2.resize(np.asarray(img, dtype=np.float32), (int(size[0]), int(size[1])), interpolation=cv2.INTER_CUBIC)
    return np.clip(out, 0.0, 255.0, out=out)


def scaled_size(h: int, w: int, scale: float) -> tuple[int, int]:
    """(height, width) of an ``h``×``w`` frame enlarged by ``scale``."""
    return max(1, round(h * scale)), max(1, round(w * scale))


def mirror_flow(flow: torch.Tensor) -> torch.Tensor:
    """Left-right mirror of an N×2×H×W flow field: columns reversed and the x component negated."""
    m = torch.flip(flow, dims=[-1])
    return torch.cat([-m[:, :1], m[:, 1:]], dim=1)


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

    Options: ``variant`` "small"|"small-convex"|"large"|None (None: from the weights file), ``weights`` path
    (default :data:`DEFAULT_WEIGHTS`), ``warm_start`` (start each pair from the previous pair's flow, carried
    forward), ``device`` ("cpu", "cuda", ...), ``num_threads`` (torch intra-op threads on CPU; None leaves the
    setting alone), ``random_init_seed`` (build seeded random weights instead of loading a file: for timing
    and tests only), and the :class:`InferenceSettings` ``iters``, ``input_scale``, ``mirror_average``,
    ``refine_scale``, ``refine_iters``, ``refine_min_scale``, ``refine_max_flow``, ``patch_levels``,
    ``variational_levels``, ``variational_iters``, ``quarter_refine`` and ``precision``: each None
    (the default) takes the weights file's own setting (the one its model card was measured with), or RAFT's
    (:data:`RAFT_DEFAULTS`) for files that carry none and for random weights.
    """

    name = "raft"

    def __init__(self, variant: str | None = None, weights: str | Path | None = None, iters: int | None = None,
                 warm_start: bool = False, device: str = "cpu", num_threads: int | None = None,
                 random_init_seed: int | None = None, padding_mode: str = "sintel",
                 input_scale: float | None = None, mirror_average: bool | None = None,
                 refine_scale: float | None = None, refine_iters: int | None = None,
                 refine_min_scale: float | None = None, refine_max_flow: float | None = None,
                 patch_levels: int | None = None, variational_levels: int | None = None,
                 variational_iters: int | None = None, quarter_refine: bool | None = None,
                 precision: str | None = None) -> None:
        if num_threads is not None:
            torch.set_num_threads(int(num_threads))
        overrides = {"iters": iters, "input_scale": input_scale, "mirror_average": mirror_average,
                     "refine_scale": refine_scale, "refine_iters": refine_iters,
                     "refine_min_scale": refine_min_scale, "refine_max_flow": refine_max_flow,
                     "patch_levels": patch_levels, "variational_levels": variational_levels,
                     "variational_iters": variational_iters, "quarter_refine": quarter_refine,
                     "precision": precision}
        RAFT_DEFAULTS.replace(**overrides)           # bad values fail before any file is read
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
            own = RAFT_DEFAULTS
        else:
            path = Path(weights) if weights is not None else DEFAULT_WEIGHTS
            loaded = load_raft_state_dict(path)
            found = loaded.variant
            if variant is not None and variant != found:
                raise FlowWeightsError(f"RAFT weights mismatch: {path} holds RAFT-{found}, RAFT-{variant} was "
                                       f"requested (expected {EXPECTED})")
            self.variant = found
            self.model = RAFT(loaded.config())
            try:
                self.model.load_state_dict(loaded.state_dict, strict=True)
            except RuntimeError as exc:
                first = str(exc).strip().splitlines()
                detail = " ".join(s.strip() for s in first[1:3])[:200] if len(first) > 1 else first[0][:200]
                raise FlowWeightsError(f"RAFT weights mismatch: {path} does not fit RAFT-{found} ({detail}; "
                                       f"expected {EXPECTED})") from None
            self.weights_path = path
            self.weights_layout = loaded.layout
            own = loaded.inference or RAFT_DEFAULTS
        self.settings = own.replace(**overrides)
        self.precision = resolve_precision(self.settings.precision, self._device)
        self.model.to(self._device).eval()
        if self._device.type == "cpu":
            # oneDNN's convolutions run channels-last without reordering each layer's input (measured: 3 % off
            # a RAFT-small-refined pair on 2 threads); the flow is the same to float rounding (< 0.001 px)
            self.model.to(memory_format=torch.channels_last)
        self._previous_low: torch.Tensor | None = None
        # (digest of the last second frame, its features, its quarter-resolution features or None): in a
        # sequence of pairs (a, b), (b, c), ... the first frame's features are the previous pair's second's,
        # computed once
        self._features: tuple[bytes, torch.Tensor, torch.Tensor | None] | None = None

    # the settings by name, as the benchmarks and tools read them
    iters = property(lambda self: self.settings.iters)
    input_scale = property(lambda self: self.settings.input_scale)
    mirror_average = property(lambda self: self.settings.mirror_average)
    refine_scale = property(lambda self: self.settings.refine_scale)
    refine_iters = property(lambda self: self.settings.refine_iters)
    refine_min_scale = property(lambda self: self.settings.refine_min_scale)
    refine_max_flow = property(lambda self: self.settings.refine_max_flow)
    patch_levels = property(lambda self: self.settings.patch_levels)
    variational_levels = property(lambda self: self.settings.variational_levels)
    quarter_refine = property(lambda self: self.settings.quarter_refine)

    @property
    def device(self) -> str:
        return str(self._device)

    def describe(self) -> str:
        """What runs, for benchmark labels and logs: 'RAFT-small-convex, 4 iterations at input scale 1 (one
        pass), bf16'."""
        return f"RAFT-{self.variant}, {describe_settings(self.settings)}, {self.precision}"

    def reset(self) -> None:
        """Forget the warm-start state and the cached features (start of a new sequence)."""
        self._previous_low = None
        self._features = None

    @property
    def reuses_features(self) -> bool:
        """Whether a pair whose first frame was the previous pair's second reuses that frame's features: one
        pass on the frames as they are (enlarged or mirrored frames, or a second pass, would need features of
        other images)."""
        s = self.settings
        return s.input_scale == 1.0 and not s.refine_scale and not s.mirror_average

    @torch.inference_mode()
    def estimate(self, img1: np.ndarray, img2: np.ndarray, flow_init: np.ndarray | None = None,
                 iters: int | None = None) -> np.ndarray:
        """H×W×2 float32 flow.  ``flow_init``: a full-resolution initial flow (e.g. the previous result)."""
        h, w = check_pair(img1, img2)
        init = None if flow_init is None else check_flow(flow_init, (h, w))
        previous = self._previous_low if self.warm_start else None
        settings = self.settings if iters is None else self.settings.replace(iters=iters)
        known = None
        if self.reuses_features:
            first = _digest(img1)
            if self._features is not None and self._features[0] == first:
                known = self._features[1:]
        cache: dict = {}
        flow, low = estimate_flow(self.model, img1, img2, settings, flow_init=init, previous_low=previous,
                                  padding_mode=self.padding_mode, device=self._device, precision=self.precision,
                                  known_features=known, features_out=cache if self.reuses_features else None)
        if self.reuses_features and "fmap2" in cache:
            self._features = (_digest(img2), cache["fmap2"], cache["fquarter2"])
        if self.warm_start:
            self._previous_low = low
        return flow


def _digest(img: np.ndarray) -> bytes:
    """A frame's fingerprint, to know it again as the next pair's first frame (about 0.1 ms at 320×240)."""
    return hashlib.blake2b(np.ascontiguousarray(img).tobytes(), digest_size=16).digest() + str(img.shape).encode()


def estimate_flow(model: RAFT, img1: np.ndarray, img2: np.ndarray, settings: InferenceSettings = RAFT_DEFAULTS,
                  flow_init: np.ndarray | None = None, previous_low: torch.Tensor | None = None,
                  padding_mode: str = "sintel", device: torch.device | str = "cpu",
                  precision: str | None = None, known_features: tuple | None = None,
                  features_out: dict | None = None) -> tuple[np.ndarray, torch.Tensor]:
    """(H×W×2 float32 flow, 1/8-resolution flow of the first pass) of ``model`` for one pair of H×W×3 frames,
    run as ``settings`` say (``precision``: the resolved "bf16" or "fp32", default resolved from them).

    With a refinement scale, the first pass's flow starts a second pass of ``refine_iters`` iterations on the
    frames enlarged by :func:`refinement_scale`, whose flow is returned (the 1/8-resolution flow returned
    stays the first pass's, on the grid that ``previous_low`` is matched against).  With ``patch_levels``,
    the flow is then refined by DIS's patch search (:func:`.variational.patch_refine`), and with
    ``variational_levels`` variationally (:func:`.variational.variational_refine`).
    ``known_features``: the first frame's (features, quarter-resolution features or None), already known (one
    pass on the frames as they are only); ``features_out``: a dict that receives the second frame's as
    ``"fmap2"`` and ``"fquarter2"``.
    """
    device = torch.device(device)
    precision = precision or resolve_precision(settings.precision, device)
    autocast = (torch.autocast(device.type, torch.bfloat16) if precision == "bf16" else nullcontext())
    with autocast:
        flow, low = _one_pass(model, img1, img2, settings.iters, settings.input_scale, flow_init, previous_low,
                              padding_mode, device, settings.mirror_average, known_features, features_out,
                              settings.quarter_refine)
        if settings.refine_scale:
            scale = refinement_scale(flow, settings.refine_scale, settings.refine_min_scale, settings.refine_max_flow)
            flow, _ = _one_pass(model, img1, img2, settings.refine_iters, scale, flow, None, padding_mode, device,
                                settings.mirror_average, quarter_refine=settings.quarter_refine)
    if settings.patch_levels:
        flow = patch_refine(img1, img2, flow, settings.patch_levels)
    if settings.variational_levels:
        flow = variational_refine(img1, img2, flow, settings.variational_levels, settings.variational_iters)
    return flow, low


def refinement_scale(flow: np.ndarray, refine_scale: float, min_scale: float, max_flow: float) -> float:
    """The refinement pass's input scale for a first-pass H×W×2 ``flow``: ``refine_scale``, lowered (not below
    ``min_scale``) so that the flow's 99th-percentile length, enlarged, stays within ``max_flow`` pixels.

    ``max_flow`` 0, or ``min_scale`` at or above ``refine_scale``, keeps ``refine_scale``."""
    if not refinement_is_adaptive(refine_scale, min_scale, max_flow):
        return float(refine_scale)
    longest = float(np.percentile(np.hypot(flow[..., 0], flow[..., 1]), 99))
    return float(np.clip(max_flow / max(longest, 1e-6), min_scale, refine_scale))
def _one_pass(model: RAFT, img1: np.ndarray, img2: np.ndarray, iters: int, input_scale: float,
              flow_init: np.ndarray | None, previous_low: torch.Tensor | None, padding_mode: str,
              device: torch.device | str, mirror_average: bool, known_features: tuple | None = None,
              features_out: dict | None = None, quarter_refine: bool = True) -> tuple[np.ndarray, torch.Tensor]:
    """One RAFT pass: (H×W×2 float32 flow, 1/8-resolution flow).

    The frames are enlarged by ``input_scale`` (when not 1) and padded to multiples of 8; the flow is
    unpadded, shrunk back and rescaled to the frames' pixels.  ``flow_init`` is a full-resolution initial
    flow; ``previous_low`` a previous 1/8-resolution result to warm-start from (carried forward), used
    only when its grid matches.  ``mirror_average`` runs the padded pair and its left-right mirror image as
    one batch and averages the two flows (the mirrored one mirrored back).  Shared by :class:`RaftBackend`
    and ``flowgap-train-raft``'s validation.
    """
    import cv2

    h, w = img1.shape[:2]
    zh, zw = (h, w) if input_scale == 1.0 else scaled_size(h, w, input_scale)
    padder = InputPadder((zh, zw), mode=padding_mode)
    if min(padder.padded_size) < MIN_SIDE:
        raise ValueError(f"RAFT needs frames of at least {MIN_SIDE}×{MIN_SIDE} pixels (its correlation pyramid "
                         f"has 4 levels at 1/8 resolution); got {w}×{h}"
                         + (f" ({zw}×{zh} at input scale {input_scale:g})" if (zh, zw) != (h, w) else "")
                         + ": use a larger camera, a larger input scale or the dis backend")
    sx, sy = zw / w, zh / h
    if (zh, zw) != (h, w):
        img1, img2 = zoom_frame(img1, (zw, zh)), zoom_frame(img2, (zw, zh))
        if flow_init is not None:
            flow_init = cv2.resize(flow_init, (zw, zh), interpolation=cv2.INTER_LINEAR) * np.float32([sx, sy])

    def tensor(a: np.ndarray) -> torch.Tensor:
        return torch.from_numpy(np.ascontiguousarray(a)).permute(2, 0, 1).float().unsqueeze(0).to(device)

    t1, t2 = padder.pad(tensor(img1), tensor(img2))
    ph, pw = padder.padded_size
    init = None
    if flow_init is not None:
        (fi,) = padder.pad(tensor(flow_init))
        init = F.avg_pool2d(fi, 8) / 8.0                   # full-res pixels -> 1/8-res cells
    elif previous_low is not None and previous_low.shape[-2:] == (ph // 8, pw // 8):
        init = forward_interpolate(previous_low)
    if mirror_average:
        t1, t2 = torch.cat([t1, torch.flip(t1, dims=[-1])]), torch.cat([t2, torch.flip(t2, dims=[-1])])
        init = None if init is None else torch.cat([init, mirror_flow(init)])
    fmap1, fquarter1 = known_features if known_features is not None else (None, None)
    out = model(t1, t2, iters=iters, flow_init=init, fmap1=fmap1, fquarter1=fquarter1, quarter_refine=quarter_refine)
    if features_out is not None:
        features_out["fmap2"], features_out["fquarter2"] = out.fmap2, out.fquarter2
    flow_up, flow_low = out.flow_up, out.flow_low
    if mirror_average:
        flow_up = 0.5 * (flow_up[:1] + mirror_flow(flow_up[1:]))
        flow_low = 0.5 * (flow_low[:1] + mirror_flow(flow_low[1:]))
    flow = np.ascontiguousarray(padder.unpad(flow_up)[0].permute(1, 2, 0).float().cpu().numpy(), dtype=np.float32)
    if (zh, zw) != (h, w):
        flow = cv2.resize(flow, (w, h), interpolation=cv2.INTER_AREA) / np.float32([sx, sy])
    return np.ascontiguousarray(flow, dtype=np.float32), flow_low

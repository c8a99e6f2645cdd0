"""RAFT weights: three on-disk layouts, one in-memory layout (ours), loaded once per process.

Layouts recognised by :func:`load_raft_state_dict`:

``official``
    The RAFT authors' checkpoints (``raft-things.pth``, ``raft-sintel.pth``, ``raft-kitti.pth``,
    ``raft-chairs.pth``, ``raft-small.pth``): a state dict saved from ``nn.DataParallel``, so every key starts
    with ``module.``.  Our module names are theirs; their residual/bottleneck blocks also register the
    shortcut norm a second time as ``norm3`` (``norm4`` in bottlenecks), an alias of ``downsample.1``.
``torchvision``
    ``torchvision.models.optical_flow.raft_large / raft_small`` state dicts (``feature_encoder.``,
    ``context_encoder.``, ``update_block.motion_encoder.``, ``mask_predictor.``, ``Conv2dNormActivation``
    sub-indices ``.0`` conv / ``.1`` norm).  Mapped key by key by :func:`torchvision_to_ours`.
``flowgap``
    ``{"format": "flowgap-raft", "version": 3, "variant": "small"|"small-convex"|"large",
    "upsample_align_corners": bool, "inference": {...}, "state_dict": {...ours...}}``, written by
    :func:`save_flowgap_weights` (the RAFT training tool's output).  ``inference`` (optional, version 3) holds
    the :class:`~companion.flow.raft.settings.InferenceSettings` the weights are meant to run with, those
    their model card was measured with.  Version 1 files have no ``upsample_align_corners``: they were
    trained with the RAFT authors' ``True``, as were the official and torchvision checkpoints.

Nothing is ever downloaded: a missing or mismatched file raises :class:`FlowWeightsError` with a one-line
message naming the path and the expected format.
"""

from __future__ import annotations

import logging
import re
import threading
from collections.abc import Mapping
from pathlib import Path
from typing import NamedTuple

import torch

from companion.flow.base import FlowWeightsError
from companion.flow.raft.settings import InferenceSettings

log = logging.getLogger(__name__)

FORMAT_NAME = "flowgap-raft"
FORMAT_VERSION = 3
READABLE_VERSIONS = (1, 2, 3)
EXPECTED = ("an official RAFT checkpoint (raft-things.pth / raft-small.pth, 'module.' keys), a torchvision "
            "raft_large/raft_small state dict, or a flowgap-raft file")


class RaftWeights(NamedTuple):
    """A loaded weights file: its layout, RAFT variant, our-layout state dict, upsampling convention and the
    inference settings it carries (None: none recorded)."""

    layout: str
    variant: str
    state_dict: dict[str, torch.Tensor]
    upsample_align_corners: bool = True
    inference: InferenceSettings | None = None

    def config(self):
        """The :class:`RaftConfig` these weights were trained with."""
        from companion.flow.raft.model import RaftConfig

        return RaftConfig.for_variant(self.variant, upsample_align_corners=self.upsample_align_corners)


_CACHE: dict[tuple, RaftWeights] = {}
_LOCK = threading.Lock()


# ---------------------------------------------------------------------------------------------------------
# Layout detection and key mapping
# ---------------------------------------------------------------------------------------------------------

def detect_layout(obj: object) -> str:
    """'flowgap', 'official', 'torchvision' or 'unknown' for a loaded checkpoint object."""
    if isinstance(obj, Mapping) and obj.get("format") == FORMAT_NAME:
        return "flowgap"
    if not isinstance(obj, Mapping) or not obj:
        return "unknown"
    keys = [k for k in obj if isinstance(k, str)]
    if len(keys) != len(obj) or not all(isinstance(v, torch.Tensor) for v in obj.values()):
        return "unknown"
    stripped = [k[len("module."):] if k.startswith("module.") else k for k in keys]
    if any(k.startswith("feature_encoder.") for k in stripped):
        return "torchvision"
    if any(k.startswith("fnet.") for k in stripped):
        return "official"
    return "unknown"


def detect_variant(state_dict: Mapping[str, torch.Tensor]) -> str | None:
    """'small' / 'small-convex' / 'large' from our-layout keys, None when neither GRU is present."""
    if "update_block.gru.convz.weight" in state_dict:
        if "refiner.conv1.weight" in state_dict:
            return "small-refined"
        return "small-convex" if "update_block.mask.0.weight" in state_dict else "small"
    if "update_block.gru.convz1.weight" in state_dict:
        return "large"
    return None


_ALIAS = re.compile(r"^(?P<block>(?:fnet|cnet)\.layer\d\.\d)\.(?P<norm>norm3|norm4)\.(?P<rest>.+)$")


def official_to_ours(state_dict: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Strip ``module.`` and fold the ``norm3``/``norm4`` aliases of ``downsample.1`` into it."""
    sd = {(k[len("module."):] if k.startswith("module.") else k): v for k, v in state_dict.items()}
    out: dict[str, torch.Tensor] = {}
    is_small = "update_block.gru.convz.weight" in sd
    for key, value in sd.items():
        m = _ALIAS.match(key)
        # In residual blocks (RAFT) norm3 is the shortcut norm; in bottleneck blocks (RAFT-small) norm3
        # belongs to conv3 and norm4 is the shortcut norm.
        if m and (m["norm"] == "norm4" or not is_small):
            target = f"{m['block']}.downsample.1.{m['rest']}"
            if target in sd:
                if not torch.equal(sd[target], value):
                    raise ValueError(f"{key} differs from its alias {target}")
                continue
            key = target
        out[key] = value
    return out


_TV_RULES: list[tuple[re.Pattern, str]] = [(re.compile(p), r) for p, r in [
    (r"^feature_encoder\.", "fnet."),
    (r"^context_encoder\.", "cnet."),
    (r"^(fnet|cnet)\.convnormrelu\.0\.", r"\1.conv1."),
    (r"^(fnet|cnet)\.convnormrelu\.1\.", r"\1.norm1."),
    (r"^(fnet|cnet)\.conv\.", r"\1.conv2."),
    (r"^(fnet|cnet)\.(layer\d\.\d)\.convnormrelu(\d)\.0\.", r"\1.\2.conv\3."),
    (r"^(fnet|cnet)\.(layer\d\.\d)\.convnormrelu(\d)\.1\.", r"\1.\2.norm\3."),
    (r"^update_block\.motion_encoder\.convcorr(\d)\.0\.", r"update_block.encoder.convc\1."),
    (r"^update_block\.motion_encoder\.convflow(\d)\.0\.", r"update_block.encoder.convf\1."),
    (r"^update_block\.motion_encoder\.conv\.0\.", "update_block.encoder.conv."),
    (r"^mask_predictor\.convrelu\.0\.", "update_block.mask.0."),
    (r"^mask_predictor\.conv\.", "update_block.mask.2."),
]]
_TV_GRU = re.compile(r"^update_block\.recurrent_block\.convgru(\d)\.conv([zrq])\.(.+)$")


def torchvision_to_ours(state_dict: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Rename torchvision RAFT keys to ours (shapes are identical)."""
    sd = {(k[len("module."):] if k.startswith("module.") else k): v for k, v in state_dict.items()}
    separable = any(k.startswith("update_block.recurrent_block.convgru2.") for k in sd)
    out: dict[str, torch.Tensor] = {}
    for key, value in sd.items():
        new = key
        for pattern, repl in _TV_RULES:
            new = pattern.sub(repl, new)
        m = _TV_GRU.match(new)
        if m:
            suffix = m[1] if separable else ""
            new = f"update_block.gru.conv{m[2]}{suffix}.{m[3]}"
        out[new] = value
    return out


def to_ours(obj: object) -> tuple[str, dict[str, torch.Tensor], bool, InferenceSettings | None]:
    """(layout, our-layout state dict, upsample_align_corners, inference settings or None) for a loaded
    checkpoint object.

    Raises ValueError if the layout is unrecognised or a flowgap file's fields are malformed.
    """
    layout = detect_layout(obj)
    if layout == "flowgap":
        version = obj.get("version")
        if version not in READABLE_VERSIONS:
            raise ValueError(f"flowgap-raft version {version!r}, expected one of {READABLE_VERSIONS}")
        align = obj.get("upsample_align_corners", True)
        if not isinstance(align, bool):
            raise ValueError(f"upsample_align_corners is {align!r}, expected true or false")
        record = obj.get("inference")
        if record is not None and not isinstance(record, Mapping):
            raise ValueError(f"inference is {type(record).__name__}, expected a mapping of settings")
        inference = InferenceSettings.from_record(dict(record)) if record is not None else None
        return layout, dict(obj["state_dict"]), align, inference
    if layout == "official":
        return layout, official_to_ours(obj), True, None
    if layout == "torchvision":
        return layout, torchvision_to_ours(obj), True, None
    raise ValueError("unrecognised checkpoint layout")


# ---------------------------------------------------------------------------------------------------------
# Files
# ---------------------------------------------------------------------------------------------------------

def load_raft_state_dict(path: str | Path) -> RaftWeights:
    """:class:`RaftWeights` (layout, variant, our-layout CPU state dict, upsampling) from ``path``.

    Cached per process by path + mtime + size.
    """
    path = Path(path).expanduser()
    if not path.is_file():
        raise FlowWeightsError(f"RAFT weights not found: {path} (expected {EXPECTED}; nothing is downloaded)")
    st = path.stat()
    key = (str(path.resolve()), st.st_mtime_ns, st.st_size)
    with _LOCK:
        if key in _CACHE:
            return _CACHE[key]
        try:
            obj = torch.load(path, map_location="cpu", weights_only=True)
        except Exception as exc:  # noqa: BLE001 - any unreadable file gets the same one-line error
            raise FlowWeightsError(f"RAFT weights unreadable: {path} ({type(exc).__name__}; expected {EXPECTED})"
                                   ) from exc
        try:
            layout, sd, align, inference = to_ours(obj)
        except ValueError as exc:
            raise FlowWeightsError(f"RAFT weights not recognised: {path} ({exc}; expected {EXPECTED})") from exc
        variant = detect_variant(sd)
        if variant is None:
            raise FlowWeightsError(f"RAFT weights not recognised: {path} (no update-block GRU; expected {EXPECTED})")
        loaded = _CACHE[key] = RaftWeights(layout, variant, sd, align, inference)
        log.info("loaded RAFT-%s weights (%s layout) from %s", variant, layout, path)
        return loaded


def clear_cache() -> None:
    with _LOCK:
        _CACHE.clear()


def flowgap_weights_record(model: torch.nn.Module, variant: str,
                           inference: InferenceSettings | None = None) -> dict:
    """``model``'s weights as a flowgap-layout object (what :func:`save_flowgap_weights` writes), with the
    inference settings they are meant to run with when given."""
    record = {"format": FORMAT_NAME, "version": FORMAT_VERSION, "variant": variant,
              "upsample_align_corners": bool(model.config.upsample_align_corners),
              "state_dict": {k: v.detach().cpu() for k, v in model.state_dict().items()}}
    if inference is not None:
        record["inference"] = inference.as_record()
    return record


def save_flowgap_weights(model: torch.nn.Module, path: str | Path, variant: str,
                         inference: InferenceSettings | None = None) -> Path:
    """Write ``model``'s weights in the flowgap layout (with ``inference`` settings when given)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save(flowgap_weights_record(model, variant, inference), path)
    return path

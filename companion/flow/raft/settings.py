"""How a RAFT model is run on a frame pair (:class:`InferenceSettings`) and in which precision."""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

log = logging.getLogger(__name__)

INPUT_SCALE_RANGE = (0.25, 4.0)  # accepted input_scale values (smaller frames, or 16× the compute)
PRECISIONS = ("auto", "bf16", "fp32")


@dataclass(frozen=True)
class InferenceSettings:
    """How a RAFT model is run on a pair (what :func:`estimate_flow` does).

    ``iters`` refinement iterations; ``input_scale``: both frames enlarged by this factor before RAFT and the
    flow shrunk back (finer flow for about ``input_scale**2`` times the compute); ``mirror_average``: the pair
    and its left-right mirror in one batch, flows averaged (about twice the compute); ``refine_scale``: after
    the first pass, a second pass of ``refine_iters`` iterations on frames enlarged by up to this factor,
    started from the first pass's flow (0: one pass), at the scale :func:`refinement_scale` picks between
    ``refine_min_scale`` and ``refine_scale`` so that the enlarged motion stays within ``refine_max_flow``
    pixels (0, or ``refine_min_scale`` ≥ ``refine_scale``: always ``refine_scale``); ``patch_levels``: then the
    flow refined by DIS's patch search (:func:`.variational.patch_refine`) on this many scales, the coarsest at
    1/2**(patch_levels-1) of the frame (0: none); ``variational_levels``: then
    the flow refined by the images' own gradients (:mod:`.variational`) on this many scales, coarse to fine,
    with ``variational_iters`` fixed-point iterations each (0: RAFT's flow as it is); ``quarter_refine``: a
    model with a quarter-resolution refinement head (RAFT-small-refined) runs it (False: skips it and its
    quarter-resolution features, as when DIS's patch search refines the flow anyway); ``precision``: "bf16"
    (the network under bf16 autocast; correlation, upsampling and the flow itself stay float32), "fp32", or
    "auto" (bf16 on a CPU with AVX512-BF16 or AMX, else fp32, see :func:`resolve_precision`).

    The defaults are RAFT's own (12 iterations, one pass on the frames as they are); a flowgap weights file
    carries the settings its model card's numbers were measured with, and the backend runs those.
    """

    iters: int = 12
    input_scale: float = 1.0
    mirror_average: bool = False
    refine_scale: float = 0.0
    refine_iters: int = 4
    refine_min_scale: float = 2.0
    refine_max_flow: float = 0.0
    patch_levels: int = 0
    variational_levels: int = 0
    variational_iters: int = 10
    quarter_refine: bool = True
    precision: str = "fp32"

    def validated(self) -> InferenceSettings:
        """These settings, or ValueError naming the bad one."""
        lo, hi = INPUT_SCALE_RANGE
        if self.iters < 0:
            raise ValueError("iters must be >= 0")
        if self.refine_iters < 1:
            raise ValueError(f"refine_iters must be >= 1 (got {self.refine_iters}); set refine_scale to 0 for "
                             "one pass")
        if not (np.isfinite(self.input_scale) and lo <= self.input_scale <= hi):
            raise ValueError(f"input_scale must be within {lo:g}..{hi:g} (got {self.input_scale})")
        if self.refine_scale != 0 and not (np.isfinite(self.refine_scale) and lo <= self.refine_scale <= hi):
            raise ValueError(f"refine_scale must be 0 (one pass) or within {lo:g}..{hi:g} (got {self.refine_scale})")
        if not (np.isfinite(self.refine_min_scale) and lo <= self.refine_min_scale <= hi):
            raise ValueError(f"refine_min_scale must be within {lo:g}..{hi:g} (got {self.refine_min_scale})")
        if not (np.isfinite(self.refine_max_flow) and self.refine_max_flow >= 0):
            raise ValueError(f"refine_max_flow must be 0 (a fixed refine_scale) or a positive number of pixels "
                             f"(got {self.refine_max_flow})")
        if not 0 <= self.patch_levels <= 4:
            raise ValueError(f"patch_levels must be 0 (off) to 4 (got {self.patch_levels})")
        if not 0 <= self.variational_levels <= 4:
            raise ValueError(f"variational_levels must be 0 (off) to 4 (got {self.variational_levels})")
        if self.variational_iters < 1:
            raise ValueError(f"variational_iters must be >= 1 (got {self.variational_iters})")
        if self.precision not in PRECISIONS:
            raise ValueError(f"precision must be one of {', '.join(PRECISIONS)} (got {self.precision!r})")
        return self

    def replace(self, **changes) -> InferenceSettings:
        """A validated copy with the changes that are not None (None: keep this setting)."""
        kept = {k: v for k, v in changes.items() if v is not None}
        for key in ("iters", "refine_iters", "patch_levels", "variational_levels", "variational_iters"):
            if key in kept:
                kept[key] = int(kept[key])
        for key in ("input_scale", "refine_scale", "refine_min_scale", "refine_max_flow"):
            if key in kept:
                kept[key] = float(kept[key])
        for key in ("mirror_average", "quarter_refine"):
            if key in kept:
                kept[key] = bool(kept[key])
        return dataclasses.replace(self, **kept).validated()

    def as_record(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_record(cls, record: dict) -> InferenceSettings:
        """Settings from a weights file's ``inference`` entry (ValueError on unknown keys or bad values)."""
        unknown = sorted(set(record) - {f.name for f in dataclasses.fields(cls)})
        if unknown:
            raise ValueError(f"unknown inference settings {unknown}")
        return cls().replace(**record)


RAFT_DEFAULTS = InferenceSettings()


_BF16_FLAGS = ("avx512_bf16", "amx_bf16")


def cpu_has_native_bf16(cpuinfo: str | None = None) -> bool:
    """Whether this CPU computes bf16 in hardware (AVX512-BF16 or AMX), read from /proc/cpuinfo's flags
    (``cpuinfo``: that file's text, for tests); False where it cannot be read (not Linux)."""
    if cpuinfo is None:
        try:
            cpuinfo = Path("/proc/cpuinfo").read_text()
        except OSError:
            return False
    flags = set()
    for line in cpuinfo.splitlines():
        if line.startswith("flags"):
            flags.update(line.partition(":")[2].split())
    return any(flag in flags for flag in _BF16_FLAGS)


_fallback_logged = False


def resolve_precision(precision: str, device: torch.device, native_bf16: bool | None = None) -> str:
    """"bf16" or "fp32" for ``precision`` on ``device``: "auto" is bf16 on a CPU that has it in hardware
    (logged once when it falls back to fp32), fp32 on other devices."""
    global _fallback_logged
    if precision != "auto":
        return precision
    if device.type != "cpu":
        return "fp32"
    if cpu_has_native_bf16() if native_bf16 is None else native_bf16:
        return "bf16"
    if not _fallback_logged:
        log.info("RAFT: this CPU has no AVX512-BF16 or AMX; running in float32")
        _fallback_logged = True
    return "fp32"


def refinement_is_adaptive(refine_scale: float | None, min_scale: float, max_flow: float) -> bool:
    """Whether a refinement pass picks its scale per frame (:func:`refinement_scale`) rather than always
    running at ``refine_scale``: it needs a ``max_flow`` and room between ``min_scale`` and ``refine_scale``."""
    return bool(refine_scale and max_flow and min_scale < refine_scale)


def describe_settings(settings: InferenceSettings) -> str:
    """'12 iterations at input scale 1, then 4 at scale 2-2.5 (lowered for motion over 64 px)', '4
    iterations at input scale 1 (one pass), variational refinement on 2 scales', with ', mirror-averaged' when
    it is."""
    text = f"{settings.iters} iterations at input scale {settings.input_scale:g}"
    if refinement_is_adaptive(settings.refine_scale, settings.refine_min_scale, settings.refine_max_flow):
        text += (f", then {settings.refine_iters} at scale {settings.refine_min_scale:g}-{settings.refine_scale:g} "
                 f"(lowered for motion over {settings.refine_max_flow:g} px)")
    elif settings.refine_scale:
        text += f", then {settings.refine_iters} at scale {settings.refine_scale:g}"
    else:
        text += " (one pass)"
    if settings.mirror_average:
        text += ", mirror-averaged"
    if not settings.quarter_refine:
        text += ", no quarter-resolution head"
    if settings.patch_levels:
        text += f", DIS patch refinement on {settings.patch_levels} scale" + ("s" if settings.patch_levels > 1 else "")
    if settings.variational_levels:
        text += f", variational refinement on {settings.variational_levels} scale" + \
            ("s" if settings.variational_levels > 1 else "")
    return text

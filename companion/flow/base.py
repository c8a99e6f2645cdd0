"""The flow-backend contract shared by every optical-flow implementation.

A backend turns two RGB frames into the dense forward flow from the first to the second:

    flow = backend.estimate(img1, img2)   # img: H×W×3 uint8 RGB  ->  flow: H×W×2 float32 (u right, v down)

``flow[y, x] = (du, dv)`` means the point seen at pixel (x, y) in ``img1`` is seen at (x + du, y + dv) in
``img2``.  Backends also expose ``name`` (registry name) and ``device`` ("cpu", "cuda:0", ...).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np


class FlowError(RuntimeError):
    """Base class for flow-backend errors."""


class FlowWeightsError(FlowError):
    """A weights file is missing or does not match what the backend expects (one-line message)."""


@runtime_checkable
class FlowBackend(Protocol):
    """Dense optical flow from image 1 to image 2."""

    name: str
    device: str

    def estimate(self, img1: np.ndarray, img2: np.ndarray) -> np.ndarray:
        """Return the H×W×2 float32 forward flow for two H×W×3 uint8 RGB images."""
        ...


def check_pair(img1: np.ndarray, img2: np.ndarray) -> tuple[int, int]:
    """Validate a frame pair (H×W×3 uint8 RGB, same shape); return (H, W)."""
    for i, img in enumerate((img1, img2), start=1):
        if not isinstance(img, np.ndarray) or img.ndim != 3 or img.shape[2] != 3:
            raise ValueError(f"img{i} must be an H×W×3 RGB array, got shape {getattr(img, 'shape', None)}")
        if img.dtype != np.uint8:
            raise ValueError(f"img{i} must be uint8, got {img.dtype}")
    if img1.shape != img2.shape:
        raise ValueError(f"images differ in shape: {img1.shape} vs {img2.shape}")
    return int(img1.shape[0]), int(img1.shape[1])


def check_flow(flow: np.ndarray, shape: tuple[int, int] | None = None) -> np.ndarray:
    """Validate (and return as contiguous float32) an H×W×2 flow field."""
    flow = np.asarray(flow)
    if flow.ndim != 3 or flow.shape[2] != 2:
        raise ValueError(f"flow must be H×W×2, got shape {flow.shape}")
    if shape is not None and flow.shape[:2] != tuple(shape):
        raise ValueError(f"flow is {flow.shape[:2]}, expected {tuple(shape)}")
    return np.ascontiguousarray(flow, dtype=np.float32)

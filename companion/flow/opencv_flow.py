"""OpenCV flow backends: DIS (Kroeger et al. 2016) with its presets, and Farneback for comparison."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from companion.flow.base import check_pair

DIS_PRESETS = {
    "ultrafast": cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST,
    "fast": cv2.DISOPTICAL_FLOW_PRESET_FAST,
    "medium": cv2.DISOPTICAL_FLOW_PRESET_MEDIUM,
    "fine": cv2.DISOPTICAL_FLOW_PRESET_MEDIUM,      # ours: MEDIUM down to full resolution (finest scale 0)
}
_PRESET_OVERRIDES = {"fine": {"finest_scale": 0}}


def create_dis(preset: str, settings: tuple[tuple[int | None, str], ...] = ()) -> cv2.DISOpticalFlow:
    """A fresh OpenCV DIS object for one of :data:`DIS_PRESETS`: OpenCV's preset, flowgap's overrides of it
    ("fine": finest scale 0), then ``settings``' (value, setter name) pairs whose value is not None."""
    dis = cv2.DISOpticalFlow_create(DIS_PRESETS[preset])
    finest = _PRESET_OVERRIDES.get(preset, {}).get("finest_scale")
    for value, setter in ((finest, "setFinestScale"), *settings):
        if value is not None:
            getattr(dis, setter)(int(value))
    dis.setUseSpatialPropagation(True)
    return dis


def _grey(img: np.ndarray) -> np.ndarray:
    # Frames are RGB (flowgap convention); say so to OpenCV rather than relying on BGR defaults.
    return cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)


class DisBackend:
    """OpenCV DIS optical flow.

    ``preset``: "ultrafast" | "fast" | "medium" (OpenCV's) | "fine" (flowgap's: MEDIUM with its finest scale
    lowered to 0, i.e. patches matched at full resolution; ~4× MEDIUM's time, best gap masks on our suite).

    ``warm_start``: use the previous call's flow as the initial
    flow of the next call (useful on a video-like sequence).  Further DIS parameters may be overridden with
    ``finest_scale``, ``patch_size``, ``patch_stride``, ``gradient_descent_iterations``,
    ``variational_refinement_iterations``.
    """

    name = "dis"
    device = "cpu"

    def __init__(self, preset: str = "medium", warm_start: bool = False, *, finest_scale: int | None = None,
                 patch_size: int | None = None, patch_stride: int | None = None,
                 gradient_descent_iterations: int | None = None,
                 variational_refinement_iterations: int | None = None) -> None:
        if preset not in DIS_PRESETS:
            raise ValueError(f"unknown DIS preset {preset!r}; choose from {sorted(DIS_PRESETS)}")
        self.preset = preset
        self.warm_start = warm_start
        self._settings = ((finest_scale, "setFinestScale"), (patch_size, "setPatchSize"),
                          (patch_stride, "setPatchStride"),
                          (gradient_descent_iterations, "setGradientDescentIterations"),
                          (variational_refinement_iterations, "setVariationalRefinementIterations"))
        self._dis = self._make_dis()
        self._initialised = False   # the last call was given an initial flow
        self._previous: np.ndarray | None = None

    def _make_dis(self):
        return create_dis(self.preset, self._settings)

    def estimate(self, img1: np.ndarray, img2: np.ndarray, flow_init: np.ndarray | None = None) -> np.ndarray:
        h, w = check_pair(img1, img2)
        init = flow_init if flow_init is not None else (self._previous if self.warm_start else None)
        if init is not None and init.shape == (h, w, 2):
            # DIS uses a same-size CV_32FC2 flow argument as its initial flow (and overwrites it).
            flow = self._dis.calc(_grey(img1), _grey(img2), np.array(init, dtype=np.float32, order="C"))
            self._initialised = True
        else:
            if self._initialised:
                # OpenCV's DIS keeps using an initial flow once given one, even when later called without
                # (measured: a 23 px shift it cannot find from zero is found on every later call), so a call
                # meant to start from zero gets a fresh one.
                self._dis, self._initialised = self._make_dis(), False
            flow = self._dis.calc(_grey(img1), _grey(img2), None)
        flow = np.ascontiguousarray(flow, dtype=np.float32)
        if self.warm_start:
            self._previous = flow.copy()
        return flow

    def reset(self) -> None:
        """Forget the warm-start flow (start of a new sequence)."""
        self._previous = None


@dataclass(frozen=True)
class FarnebackParams:
    pyr_scale: float = 0.5
    levels: int = 4
    winsize: int = 15
    iterations: int = 3
    poly_n: int = 5
    poly_sigma: float = 1.2


class FarnebackBackend:
    """OpenCV Farneback dense flow (polynomial expansion), kept for comparison."""

    name = "farneback"
    device = "cpu"

    def __init__(self, **params) -> None:
        self.params = FarnebackParams(**params)

    def estimate(self, img1: np.ndarray, img2: np.ndarray) -> np.ndarray:
        check_pair(img1, img2)
        p = self.params
        flow = cv2.calcOpticalFlowFarneback(_grey(img1), _grey(img2), None, p.pyr_scale, p.levels, p.winsize,
                                            p.iterations, p.poly_n, p.poly_sigma, 0)
        return np.ascontiguousarray(flow, dtype=np.float32)

"""Rendered optical-flow training pairs for RAFT: random scenes, quadrotor-like camera motions, exact flow.

Item ``i`` of a :class:`RenderedFlowDataset` with seed ``s`` is a pure function of ``(s, i)`` and the
dataset's settings (resolution, pairs per scene, jitter): the scene comes from
``scenes.random_scene(default_rng([s, i // pairs_per_scene, 0]), ALL_TEXTURES)`` (the suite's four texture
families plus weak "plaster" and repetitive "tiles"), the pose pair from
``scenes.groundtruth.sample_pose_pair(spec, default_rng([s, i, 1]))`` and the exposure jitter from
``default_rng([s, i, 2])``, the zoom factor (when ``zoom`` is set) from ``default_rng([s, i, 4])`` and the
crop window (when ``crop`` is set) from ``default_rng([s, i, 3])`` and, with ``crop_focus``, whether and where
it is moved onto the opening from ``default_rng([s, i, 5])``.
Consecutive items share a scene (``pairs_per_scene``), and built scenes are kept in a small per-process
(hence per-DataLoader-worker) cache, so a pair costs two renders (~35 ms at 320×240) rather than a scene
build (~0.15 s).

Training renders at the flight camera's resolution (320×240, so textures and flow magnitudes look as they do
in flight) and crops a random 160×120 window of both frames, which keeps a training step cheap on a CPU
(RAFT is trained on crops for the same reason); the validation set is full 320×240 frames.  With ``zoom``
the two frames are first enlarged by a random factor (bicubic, through the same ``zoom_frame`` that
:class:`~companion.flow.raft.backend.RaftBackend` enlarges frames with for ``input_scale``) and the flow is
scaled with them, so that the network learns to run on enlarged camera frames, where its 1/8-resolution grid
is finer relative to the camera's pixels.  About one random crop of a zoomed frame in three shows only wall,
whose flow is smooth; with ``crop_focus`` a share of the crops is moved to contain a pixel seen through the
opening, so that the network sees more of the flow discontinuity at the opening's edge, which is what the gap
detector reads.  ``distance`` widens the range of distances the first camera stands from the wall: flights
start 3 m before it (up to 4 m in random scenes), where a forward step's flow near the focus of expansion is
a pixel or two.

Each item is a dict of tensors: ``image1``/``image2`` 3×H×W float32 RGB in 0..255, ``flow`` 2×H×W float32
(forward flow 1 -> 2, pixels; 0 where not valid), ``valid`` H×W float32 (1 where the flow is exact and unoccluded).

:func:`validation_set` is the fixed held-out set (seed :data:`VALIDATION_SEED`, no jitter), disjoint from
training seeds by construction (training seeds are small integers).
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np
import torch
from torch.utils.data import Dataset

DEFAULT_WIDTH = 320                 # the companion's camera (scenes.camera.PinholeCamera)
DEFAULT_HEIGHT = 240
DEFAULT_CROP = (160, 120)           # training crop (width, height)
VALIDATION_SEED = 1_000_003
DEFAULT_VALIDATION_SIZE = 32


class RenderedFlowDataset(Dataset):
    """Deterministic rendered flow pairs (see the module docstring).

    ``length`` items (indices 0..length-1; any non-negative index is valid through :meth:`item`),
    ``width``×``height`` images (multiples of 8), ``pairs_per_scene`` consecutive items per random scene,
    ``exposure_jitter`` the maximum relative gain change per image (0 disables; the two images of a pair
    get independent gains and offsets, as an auto-exposing camera would), ``max_step`` / ``max_turn_rad``
    the per-axis translation (m) and rotation (rad) bounds between the two poses, ``scene_cache`` how many
    built scenes to keep per process, ``zoom`` an optional (low, high) range of the factor both rendered
    frames are enlarged by (uniform; the flow is scaled with them), ``crop`` an optional (width, height)
    window cut at a random place from both (zoomed) frames (items are then crop-sized), ``crop_focus`` the
    probability that the window is instead placed to contain a random pixel of the background seen through
    the opening (:func:`opening_pixels`; a frame that shows none keeps its random window), ``distance`` an
    optional (low, high) range in metres of the first pose's distance before the wall (default
    ``scenes.groundtruth.DEFAULT_PAIR_DISTANCE``, 0.6–2.6 m).
    """

    def __init__(self, seed: int = 0, length: int = 100_000, width: int = DEFAULT_WIDTH,
                 height: int = DEFAULT_HEIGHT, pairs_per_scene: int = 8, exposure_jitter: float = 0.0,
                 max_step: float = 0.15, max_turn_rad: float = 0.05, scene_cache: int = 4,
                 crop: tuple[int, int] | None = None, zoom: tuple[float, float] | None = None,
                 crop_focus: float = 0.0, distance: tuple[float, float] | None = None) -> None:
        if width <= 0 or height <= 0 or width % 8 or height % 8:
            raise ValueError(f"image size must be positive multiples of 8 (got {width}x{height})")
        if crop is not None:
            cw, ch = (int(v) for v in crop)
            if cw <= 0 or ch <= 0 or cw % 8 or ch % 8 or cw > width or ch > height:
                raise ValueError(f"crop must be positive multiples of 8 within {width}x{height} (got {cw}x{ch})")
            crop = (cw, ch)
        if zoom is not None:
            lo, hi = (float(v) for v in zoom)
            if not (1.0 <= lo <= hi and np.isfinite(hi)):
                raise ValueError(f"zoom must be a range 1 <= low <= high (got {zoom})")
            if crop is None:
                raise ValueError("zoom needs a crop (zoomed frames are larger than the camera's)")
            zoom = (lo, hi)
        if not 0.0 <= crop_focus <= 1.0:
            raise ValueError(f"crop_focus must be a probability in [0, 1] (got {crop_focus})")
        if crop_focus > 0 and crop is None:
            raise ValueError("crop_focus needs a crop (it chooses where the crop window goes)")
        if distance is not None:
            near, far = (float(v) for v in distance)
            if not (0.0 < near <= far and np.isfinite(far)):
                raise ValueError(f"distance must be a range 0 < low <= high in metres (got {distance})")
            distance = (near, far)
        if length <= 0:
            raise ValueError("length must be positive")
        if pairs_per_scene <= 0:
            raise ValueError("pairs_per_scene must be positive")
        if not 0.0 <= exposure_jitter < 1.0:
            raise ValueError("exposure_jitter must be in [0, 1)")
        self.seed = int(seed)
        self.length = int(length)
        self.width, self.height = int(width), int(height)
        self.pairs_per_scene = int(pairs_per_scene)
        self.exposure_jitter = float(exposure_jitter)
        self.max_step = float(max_step)
        self.max_turn_rad = float(max_turn_rad)
        self.scene_cache = max(1, int(scene_cache))
        self.crop = crop
        self.zoom = zoom
        self.crop_focus = float(crop_focus)
        self.distance = distance
        self._scenes: OrderedDict[int, tuple] = OrderedDict()
        self._camera = None

    def __len__(self) -> int:
        return self.length

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        if index < 0:
            index += self.length
        if not 0 <= index < self.length:
            raise IndexError(index)
        return self.item(index)

    # -----------------------------------------------------------------------------------------------------

    def camera(self):
        if self._camera is None:
            from scenes.camera import PinholeCamera

            self._camera = PinholeCamera(self.width, self.height)
        return self._camera

    def scene(self, scene_index: int):
        """(spec, cloud) of scene ``scene_index`` for this seed, built once per process (LRU cache)."""
        hit = self._scenes.get(scene_index)
        if hit is not None:
            self._scenes.move_to_end(scene_index)
            return hit
        from scenes.build import build_scene
        from scenes.library import random_scene
        from scenes.spec import ALL_TEXTURES

        spec = random_scene(np.random.default_rng([self.seed, scene_index, 0]), ALL_TEXTURES)
        entry = (spec, build_scene(spec))
        self._scenes[scene_index] = entry
        while len(self._scenes) > self.scene_cache:
            self._scenes.popitem(last=False)
        return entry

    def render_pair(self, index: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(rgb1, rgb2, flow, valid, label1) of item ``index`` as rendered: whole frames, before zoom and crop.

        ``label1`` is the first frame's surface labels (``scenes.splats.LABEL_*``)."""
        from scenes.groundtruth import DEFAULT_PAIR_DISTANCE, flow_between, sample_pose_pair
        from scenes.render import render_splats

        if index < 0:
            raise IndexError(index)
        spec, cloud = self.scene(index // self.pairs_per_scene)
        cam = self.camera()
        pose1, pose2 = sample_pose_pair(spec, np.random.default_rng([self.seed, index, 1]),
                                        max_step=self.max_step, max_turn_rad=self.max_turn_rad,
                                        distance=self.distance or DEFAULT_PAIR_DISTANCE)
        r1 = render_splats(cloud, cam, pose1)
        r2 = render_splats(cloud, cam, pose2)
        flow, valid = flow_between(cloud, cam, pose1, pose2, renders=(r1, r2))
        flow = np.where(valid[..., None], flow, 0.0).astype(np.float32)  # 0 wherever it is not exact
        img1 = r1.rgb.astype(np.float32)
        img2 = r2.rgb.astype(np.float32)
        if self.exposure_jitter > 0:
            rng = np.random.default_rng([self.seed, index, 2])
            j = self.exposure_jitter
            gains = rng.uniform(1.0 - j, 1.0 + j, 2)
            offsets = rng.uniform(-20.0 * j, 20.0 * j, 2)
            img1 = np.clip(img1 * gains[0] + offsets[0], 0.0, 255.0)
            img2 = np.clip(img2 * gains[1] + offsets[1], 0.0, 255.0)
        return img1.astype(np.float32), img2.astype(np.float32), flow, valid, r1.label

    def pair(self, index: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(rgb1 H×W×3 float32, rgb2, flow H×W×2 float32, valid H×W bool) of item ``index``, as numpy."""
        img1, img2, flow, valid, label1 = self.render_pair(index)
        # with probability crop_focus, a background pixel (exact flow) the crop window will contain
        focus = None
        if self.crop is not None and self.crop_focus > 0:
            focus_rng = np.random.default_rng([self.seed, index, 5])
            if focus_rng.random() < self.crop_focus:
                ys, xs = np.nonzero(opening_pixels(label1, valid))
                if len(xs):
                    k = int(focus_rng.integers(len(xs)))
                    focus = (xs[k], ys[k], focus_rng)
        height, width = self.height, self.width
        if self.zoom is not None:
            factor = float(np.random.default_rng([self.seed, index, 4]).uniform(*self.zoom))
            width, height = round(self.width * factor), round(self.height * factor)
            img1, img2, flow, valid = zoom_pair(img1, img2, flow, valid, (width, height))
        if self.crop is not None:
            cw, ch = self.crop
            rng = np.random.default_rng([self.seed, index, 3])
            x0 = int(rng.integers(0, width - cw + 1))
            y0 = int(rng.integers(0, height - ch + 1))
            if focus is not None:
                fx, fy, focus_rng = focus
                # the chosen pixel (in zoomed coordinates) lands at a uniformly random place in the window
                px, py = int((fx + 0.5) * width / self.width), int((fy + 0.5) * height / self.height)
                x0 = int(np.clip(px - focus_rng.integers(0, cw), 0, width - cw))
                y0 = int(np.clip(py - focus_rng.integers(0, ch), 0, height - ch))
            win = (slice(y0, y0 + ch), slice(x0, x0 + cw))
            img1, img2, flow, valid = img1[win], img2[win], flow[win], valid[win]
        return (np.ascontiguousarray(img1), np.ascontiguousarray(img2), np.ascontiguousarray(flow, np.float32),
                np.ascontiguousarray(valid, bool))

    def item(self, index: int) -> dict[str, torch.Tensor]:
        img1, img2, flow, valid = self.pair(index)
        return {
            "image1": torch.from_numpy(np.ascontiguousarray(img1.transpose(2, 0, 1))),
            "image2": torch.from_numpy(np.ascontiguousarray(img2.transpose(2, 0, 1))),
            "flow": torch.from_numpy(np.ascontiguousarray(flow.transpose(2, 0, 1))),
            "valid": torch.from_numpy(valid.astype(np.float32)),
        }


def opening_pixels(label: np.ndarray, valid: np.ndarray | None = None) -> np.ndarray:
    """H×W bool: pixels of the background beyond the wall (through the opening), from a render's labels.

    ``valid`` (optional) keeps only those with exact flow."""
    from scenes.splats import LABEL_BACKGROUND

    far = np.asarray(label) == LABEL_BACKGROUND
    return far & valid if valid is not None else far


def zoom_pair(img1: np.ndarray, img2: np.ndarray, flow: np.ndarray, valid: np.ndarray,
              size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Enlarge a flow pair to ``size`` (width, height): images bicubic, flow bilinear and scaled per axis.

    A zoomed pixel keeps its flow only where every source pixel it draws on was valid, so no vector is
    blended with an occluded or inexact one.
    """
    import cv2

    from companion.flow.raft.backend import zoom_frame

    w, h = size
    sx, sy = w / img1.shape[1], h / img1.shape[0]
    f = cv2.resize(flow, (w, h), interpolation=cv2.INTER_LINEAR) * np.array([sx, sy], np.float32)
    ok = cv2.resize(valid.astype(np.float32), (w, h), interpolation=cv2.INTER_LINEAR) >= 1.0 - 1e-6
    f = np.where(ok[..., None], f, 0.0).astype(np.float32)
    return zoom_frame(img1, size), zoom_frame(img2, size), f, ok


def validation_set(size: int = DEFAULT_VALIDATION_SIZE, width: int = DEFAULT_WIDTH,
                   height: int = DEFAULT_HEIGHT, seed: int = VALIDATION_SEED,
                   distance: tuple[float, float] | None = None) -> RenderedFlowDataset:
    """The fixed held-out validation pairs (seed :data:`VALIDATION_SEED`, no exposure jitter).

    Another ``seed`` (or ``distance`` range) gives an equally built held-out set, e.g. for choosing an
    inference setting without touching the validation pairs, or for measuring flow further from the wall.
    """
    return RenderedFlowDataset(seed=seed, length=size, width=width, height=height,
                               pairs_per_scene=4, exposure_jitter=0.0, distance=distance)


def collate(items: list[dict[str, torch.Tensor]]) -> dict[str, torch.Tensor]:
    return {k: torch.stack([it[k] for it in items]) for k in items[0]}


def batch_at(dataset: RenderedFlowDataset, start: int, size: int) -> dict[str, torch.Tensor]:
    """Items ``start .. start+size-1`` stacked (indices wrap around the dataset length)."""
    return collate([dataset.item((start + k) % dataset.length) for k in range(size)])

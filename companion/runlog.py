"""A flight's run directory: the link's tlog, per-step images, one JSON line per decision, a summary."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from companion.jsonsafe import json_safe


class RunLog:
    """Layout: ``link.tlog``, ``frames/NNN.png``, ``flow/NNN.png``, ``masks/NNN.png``, ``decisions.jsonl``,
    ``frames.jsonl`` (each frame's true and estimated pose, for replay), ``summary.json``, ``storyboard.png``.
    Step images can be switched off for evaluation runs (``images=False``); the storyboard is always written."""

    def __init__(self, run_dir: Path, images: bool = True):
        self.dir = Path(run_dir)
        self.images = images
        self.dir.mkdir(parents=True, exist_ok=True)
        for sub in ("frames", "flow", "masks"):
            (self.dir / sub).mkdir(exist_ok=True)
        self._decisions = open(self.dir / "decisions.jsonl", "w")  # noqa: SIM115 — closed in close()
        self._frames = open(self.dir / "frames.jsonl", "w")  # noqa: SIM115 — closed in close()

    @property
    def tlog_path(self) -> Path:
        return self.dir / "link.tlog"

    def save_images(self, step: int, rgb: np.ndarray | None = None, flow_bgr: np.ndarray | None = None,
                    mask: np.ndarray | None = None) -> None:
        if not self.images:
            return
        if rgb is not None:
            cv2.imwrite(str(self.dir / "frames" / f"{step:03d}.png"), rgb[:, :, ::-1])
        if flow_bgr is not None:
            cv2.imwrite(str(self.dir / "flow" / f"{step:03d}.png"), flow_bgr)
        if mask is not None:
            cv2.imwrite(str(self.dir / "masks" / f"{step:03d}.png"), mask.astype(np.uint8) * 255)

    def decision(self, record: dict) -> None:
        self._decisions.write(json.dumps(json_safe(record, 5)) + "\n")
        self._decisions.flush()

    def frame(self, record: dict) -> None:
        # Full precision: replay re-renders from these poses, and the detector can turn a one-LSB pixel
        # difference into a different centroid.
        self._frames.write(json.dumps(json_safe(record)) + "\n")
        self._frames.flush()

    def storyboard(self, image_rgb: np.ndarray) -> Path:
        """``storyboard.png`` (written whether or not step images are)."""
        from companion.storyboard import save

        path = self.dir / "storyboard.png"
        save(image_rgb, path)
        return path

    def summary(self, record: dict) -> None:
        (self.dir / "summary.json").write_text(json.dumps(json_safe(record, 5), indent=2) + "\n")

    def close(self) -> None:
        self._decisions.close()
        self._frames.close()

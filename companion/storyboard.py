"""The flight as one picture: what the companion saw and decided at every servo step (``storyboard.png``).

One row per servo step: the camera frame, the flow colour, and the gap mask over the frame with the raw
centroid (red cross), the used target (green circle) and the image centre (white cross), then a line of text
(step, image error, the step sent, the measured wall distance, the state).  The push and the outcome go at the
bottom.  A long flight wraps into columns of ``rows_per_column`` rows.  Panels keep the camera's resolution,
so a 320×240 frame stays legible.  Everything is kept in memory while the mission runs (runs with
``--no-images`` get one too); :func:`render` is pure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

TEXT_H = 20
GAP = 4
FONT = cv2.FONT_HERSHEY_SIMPLEX
BACKGROUND = (24, 24, 24)
# zlib level 3: OpenCV 5's default PNG settings wrote a hard-world storyboard (2700 × 1952 px) in 5.5 MB; level 3
# writes it in 2.65 MB for 0.1 s more (level 9: 2.52 MB, 3 s).  A 100-flight sweep kept 0.5-1.4 GB of them.
PNG_PARAMS = [cv2.IMWRITE_PNG_COMPRESSION, 3]


@dataclass
class StoryRow:
    step: int
    frame: np.ndarray           # H×W×3 RGB
    flow_rgb: np.ndarray        # H×W×3 RGB flow colour
    mask: np.ndarray            # H×W bool
    raw: tuple[float, float] | None
    used: tuple[float, float] | None
    text: str


@dataclass
class Storyboard:
    rows_per_column: int = 10
    rows: list[StoryRow] = field(default_factory=list)

    def add(self, row: StoryRow) -> None:
        self.rows.append(row)

    def render(self, footer: list[str]) -> np.ndarray:
        """The storyboard as an RGB image (see the module docstring); ``footer``: lines for the bottom."""
        return render(self.rows, footer, self.rows_per_column)


def _mask_panel(row: StoryRow) -> np.ndarray:
    img = row.frame.copy()
    if row.mask.any():
        tint = np.zeros_like(img)
        tint[..., 1] = 255
        img[row.mask] = (0.55 * img[row.mask] + 0.45 * tint[row.mask]).astype(np.uint8)
        contours, _ = cv2.findContours(row.mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(img, contours, -1, (0, 255, 0), 1)
    h, w = img.shape[:2]
    cx, cy = (w - 1) // 2, (h - 1) // 2
    cv2.drawMarker(img, (cx, cy), (255, 255, 255), cv2.MARKER_CROSS, 14, 1)
    if row.raw is not None:
        cv2.drawMarker(img, (int(round(row.raw[0])), int(round(row.raw[1]))), (255, 60, 60),
                       cv2.MARKER_TILTED_CROSS, 12, 2)
    if row.used is not None:
        cv2.circle(img, (int(round(row.used[0])), int(round(row.used[1]))), 6, (60, 255, 60), 2)
    return img


def _text(width: int, lines: list[str], height: int = TEXT_H) -> np.ndarray:
    strip = np.full((height * max(1, len(lines)), width, 3), BACKGROUND, np.uint8)
    for i, line in enumerate(lines):
        cv2.putText(strip, line, (4, height * i + height - 6), FONT, 0.42, (235, 235, 235), 1, cv2.LINE_AA)
    return strip


def render(rows: list[StoryRow], footer: list[str], rows_per_column: int = 10) -> np.ndarray:
    """Rows as in the module docstring, wrapped into columns, with ``footer`` lines across the bottom."""
    if rows:
        h, w = rows[0].frame.shape[:2]
    else:
        h, w = 240, 320
    row_w = 3 * w + 2 * GAP
    row_h = h + TEXT_H
    cells = []
    for row in rows:
        panels = [row.frame, row.flow_rgb, _mask_panel(row)]
        sep = np.full((h, GAP, 3), BACKGROUND, np.uint8)
        images = np.hstack([panels[0], sep, panels[1], sep, panels[2]])
        cells.append(np.vstack([images, _text(row_w, [row.text])]))
    n_cols = max(1, math.ceil(len(cells) / rows_per_column))
    n_rows = min(len(cells), rows_per_column) if cells else 0
    body = np.full((max(1, n_rows) * (row_h + GAP), n_cols * (row_w + 2 * GAP), 3), BACKGROUND, np.uint8)
    for i, cell in enumerate(cells):
        c, r = divmod(i, rows_per_column)
        y, x = r * (row_h + GAP), c * (row_w + 2 * GAP)
        body[y:y + row_h, x:x + row_w] = cell
    header = _text(body.shape[1], ["frame | flow colour | gap mask (green), raw centroid (red x), used target "
                                   "(green o), image centre (white +)"])
    return np.vstack([header, body, _text(body.shape[1], footer)])


def step_text(step: int, error, delta, wall_distance_m, state: str) -> str:
    err = "none" if error is None else f"({error[0]:+.2f}, {error[1]:+.2f})"
    d = f"({delta[0]:.2f}, {delta[1]:+.2f}, {delta[2]:+.2f}) m"
    wall = "-" if wall_distance_m is None else f"{wall_distance_m:.2f} m"
    return f"step {step}  error {err}  step sent {d}  wall {wall}  {state}"


def save(image_rgb: np.ndarray, path) -> None:
    cv2.imwrite(str(path), np.ascontiguousarray(image_rgb[:, :, ::-1]), PNG_PARAMS)


def append_footer(path, lines: list[str]) -> None:
    """Add ``lines`` under an existing storyboard PNG (the launcher's verdict, which the companion cannot know)."""
    img = cv2.imread(str(path))
    if img is None:
        return
    strip = _text(img.shape[1], lines)[:, :, ::-1]
    cv2.imwrite(str(path), np.vstack([img, strip]), PNG_PARAMS)

"""The storyboard's layout: one row per servo step at the camera's resolution, wrapping into columns."""

from __future__ import annotations

import numpy as np

from companion.storyboard import GAP, TEXT_H, StoryRow, append_footer, render, save, step_text


def _row(step: int, h: int = 240, w: int = 320) -> StoryRow:
    rng = np.random.default_rng(step)
    mask = np.zeros((h, w), bool)
    mask[80:160, 120:200] = True
    return StoryRow(step, rng.integers(0, 255, (h, w, 3), dtype=np.uint8), np.zeros((h, w, 3), np.uint8), mask,
                    (160.0, 120.0), (150.0, 118.0), step_text(step, (0.1, -0.05), (0.2, 0.03, -0.01), 1.8, "servo"))


def test_rows_are_steps_at_full_panel_size_and_long_flights_wrap_into_columns(tmp_path):
    row_h, row_w = 240 + TEXT_H + GAP, 3 * 320 + 2 * GAP
    img = render([_row(k) for k in range(1, 8)], ["DONE"], rows_per_column=10)
    assert img.shape[0] == TEXT_H + 7 * row_h + TEXT_H and img.shape[1] == row_w + 2 * GAP
    # the first row's frame is there pixel for pixel, at 320×240
    assert np.array_equal(img[TEXT_H:TEXT_H + 240, :320], _row(1).frame)
    wrapped = render([_row(k) for k in range(1, 24)], ["DONE", "vehicle: SUCCESS"], rows_per_column=10)
    assert wrapped.shape[1] == 3 * (row_w + 2 * GAP) and wrapped.shape[0] == TEXT_H + 10 * row_h + 2 * TEXT_H
    col2 = row_w + 2 * GAP
    assert np.array_equal(wrapped[TEXT_H:TEXT_H + 240, col2:col2 + 320], _row(11).frame)
    save(wrapped, tmp_path / "s.png")
    append_footer(tmp_path / "s.png", ["vehicle's verdict: SUCCESS"])
    import cv2

    assert cv2.imread(str(tmp_path / "s.png")).shape[0] == wrapped.shape[0] + TEXT_H


def test_the_mask_panel_marks_the_gap_and_an_empty_flight_still_renders():
    img = render([_row(1)], [])
    mask_panel = img[TEXT_H:TEXT_H + 240, 2 * (320 + GAP):2 * (320 + GAP) + 320]
    assert (mask_panel[120, 130].astype(int)[1] > mask_panel[120, 130].astype(int)[0])     # tinted green inside
    assert render([], ["no frames"]).shape[0] > 0
    assert step_text(3, None, (0.2, 0.0, 0.0), None, "servo") == \
        "step 3  error none  step sent (0.20, +0.00, +0.00) m  wall -  servo"


def test_the_storyboard_png_is_compressed_and_reads_back_pixel_for_pixel(tmp_path):
    """A sweep keeps one storyboard per flight: written with zlib level 3, a smooth textured board is smaller than
    OpenCV's default PNG settings make it, and PNG stays lossless."""
    import cv2

    yy, xx = np.mgrid[0:240, 0:320]
    smooth = np.stack([(xx * 0.8) % 255, (yy * 1.1) % 255, ((xx + yy) * 0.5) % 255], -1).astype(np.uint8)
    row = StoryRow(1, smooth, smooth[::-1].copy(), np.zeros((240, 320), bool), None, None, "step 1")
    img = render([row] * 6, ["DONE"])
    save(img, tmp_path / "board.png")
    cv2.imwrite(str(tmp_path / "default.png"), np.ascontiguousarray(img[:, :, ::-1]))
    assert (tmp_path / "board.png").stat().st_size < 0.8 * (tmp_path / "default.png").stat().st_size
    assert np.array_equal(cv2.imread(str(tmp_path / "board.png"))[:, :, ::-1], img)

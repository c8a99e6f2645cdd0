"""The storyboard of the run a tlog belongs to: ``flowgap-tlog RUN/companion/link.tlog --out DIR`` adds
``storyboard.png`` to DIR.

A companion run directory keeps its ``storyboard.png``; one from before storyboards (or whose PNG was lost) is
rebuilt from the step images it saved (``frames/``, ``flow/``, ``masks/``) and ``decisions.jsonl``.
"""

from __future__ import annotations

import json
import logging
import shutil
from pathlib import Path

import cv2

log = logging.getLogger(__name__)


def run_directory(tlog: Path) -> Path | None:
    """The companion run directory ``tlog`` belongs to (its ``link.tlog`` beside ``decisions.jsonl``), or None."""
    run = tlog.resolve().parent
    return run if (run / "decisions.jsonl").exists() else None


def write_run_storyboard(tlog: Path, out_dir: Path) -> Path | None:
    """``out_dir/storyboard.png`` for the run ``tlog`` belongs to; None (and a log line saying why) when the tlog
    is not a run's, or the run kept neither a storyboard nor step images."""
    run = run_directory(tlog)
    if run is None:
        return None
    out = Path(out_dir) / "storyboard.png"
    if (run / "storyboard.png").exists():
        shutil.copyfile(run / "storyboard.png", out)
        return out
    image = rebuild_storyboard(run)
    if image is None:
        log.warning("%s has no storyboard.png and no step images to build one from (flown with --no-images)", run)
        return None
    from companion.storyboard import save

    save(image, out)
    return out


def rebuild_storyboard(run: Path):
    """The storyboard (RGB image) of ``run`` from its step images and decisions; None without the images."""
    from companion.storyboard import StoryRow, render, step_text

    rows = []
    for line in (run / "decisions.jsonl").read_text().splitlines():
        try:
            d = json.loads(line)
        except json.JSONDecodeError:
            log.warning("%s: a line of decisions.jsonl is not JSON (truncated log?); stopping there", run)
            break
        step = int(d["step"])
        images = [cv2.imread(str(run / sub / f"{step:03d}.png"), flags) for sub, flags in
                  (("frames", cv2.IMREAD_COLOR), ("flow", cv2.IMREAD_COLOR), ("masks", cv2.IMREAD_GRAYSCALE))]
        if any(i is None for i in images):
            continue
        frame, flow, mask = images
        state = "push" if d.get("push") else "aligned" if d.get("aligned") else "close" if d.get("close") else "servo"
        if d.get("note"):
            state += f"; {d['note']}"
        rows.append(StoryRow(step, frame[:, :, ::-1].copy(), flow[:, :, ::-1].copy(), mask > 0,
                             _point(d.get("centroid_raw")), _point(d.get("centroid_used")),
                             step_text(step, d.get("error"), d.get("next_delta_heading") or (0.0, 0.0, 0.0),
                                       d.get("wall_distance_m"), state)))
    if not rows:
        return None
    footer = []
    if (run / "summary.json").exists():
        s = json.loads((run / "summary.json").read_text())
        footer.append(f"companion: {str(s.get('state', '?')).upper()} after {s.get('servo_steps', '?')} servo steps"
                      + (f" ({s['reason']})" if s.get("reason") else ""))
    return render(rows, footer)


def _point(p):
    return None if p is None else (float(p[0]), float(p[1]))

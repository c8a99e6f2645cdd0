"""Holes in a wall, found in the inverse depth (pure: arrays in, outlines out).

:func:`hole_contours` is the search behind :func:`companion.gap.detect_gap_parallax`: the inverse depth, on a log
scale and inpainted where it is not measurable, is split by repeated Otsu splits (:func:`far_regions`), peeling
off nearer surfaces (floor, wall); the far class of the sharpest significant depth step is what lies beyond the
opening, and its components inside the size bounds, enclosed by a nearer surface, are the holes
(:func:`_holes`), best first.  Where none is found it looks past the wall's end (``past_the_end``) and against the
wall's plane (``against_wall``).  :func:`fill_occluded` fills back the band of a hole the wall hides in the second
frame.  The constants are :class:`companion.gap.ParallaxGapConfig`'s.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import cv2
import numpy as np

from companion.inverse_depth import CameraMotion, focal_length_px, wall_plane_log

if TYPE_CHECKING:     # the detector's config; companion.gap imports this module
    from companion.gap import ParallaxGapConfig


def hole_contours(rho: np.ndarray, measurable: np.ndarray, motion: CameraMotion, config: ParallaxGapConfig,
                   a_min: float, a_max: float, plain: np.ndarray | None = None) -> tuple[list[np.ndarray], str]:
    """The outlines of the holes found in the inverse depth ``rho`` where ``measurable``, best first, and why
    there are none.  ``plain``: regions set aside (no hole in the wall reaches them)."""
    kept, beside = (None, None) if plain is None else (~plain, within(plain, 1))
    log_rho = np.log(np.where(measurable, rho, np.nan))
    img, span = _log_image(log_rho, measurable, config)
    fars, reason = far_regions(img, span / 255.0, config, region=kept)
    scored = []
    for far in (fars if config.every_step else fars[:1]):   # the sharpest step beyond which is a hole
        scored = _holes(far, config, a_min, a_max, outside=beside)
        if scored:
            break
    else:
        if fars and config.past_the_end:
            scored = _holes_past_the_end(img, fars[0], span / 255.0, config, a_min, a_max, beside)
    if not scored and config.against_wall:
        scored = _holes_against_wall(log_rho, measurable, motion, config, a_min, a_max)
    if not fars:
        return scored, reason
    return scored, f"no far region with {a_min:.0f} <= area <= {a_max:.0f} px² enclosed by a nearer surface"


def _holes(far: np.ndarray, config: ParallaxGapConfig, a_min: float, a_max: float,
           outside: np.ndarray | None = None) -> list[np.ndarray]:
    """Contours of the far mask's components that can be an opening, best first (area, border penalised).
    ``outside``: pixels of no wall (what is set aside past its end): a component that reaches them is none."""
    h, w = far.shape
    far = far.astype(np.uint8)
    far = cv2.morphologyEx(far, cv2.MORPH_OPEN, cv2.getStructuringElement(
        cv2.MORPH_ELLIPSE, (config.open_ksize, config.open_ksize)))
    far = cv2.morphologyEx(far, cv2.MORPH_CLOSE, cv2.getStructuringElement(
        cv2.MORPH_ELLIPSE, (config.close_ksize, config.close_ksize)))
    contours, _ = cv2.findContours(far, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    scored = []
    for c in contours:
        area = cv2.contourArea(c)
        if not a_min <= area <= a_max:
            continue
        pts = c.reshape(-1, 2)
        if outside is not None and outside[pts[:, 1], pts[:, 0]].any():
            continue
        on_border = (pts[:, 0] <= 0) | (pts[:, 1] <= 0) | (pts[:, 0] >= w - 1) | (pts[:, 1] >= h - 1)
        touches = bool(on_border.any())
        if touches and (area < config.border_min_frac * h * w or on_border.mean() > config.max_border_frac):
            continue
        scored.append((area * (config.border_penalty if touches else 1.0), c))
    scored.sort(key=lambda sc: -sc[0])
    return [c for _, c in scored]


def _holes_past_the_end(log_img: np.ndarray, far: np.ndarray, log_step: float, config: ParallaxGapConfig,
                        a_min: float, a_max: float, plain_beside: np.ndarray | None = None) -> list[np.ndarray]:
    """Holes found once the parts of ``far`` (the sharpest step's far class, which held none) that reach the
    image's border are set aside: seen past the wall's end (or above its top), the empty space or a distant
    background is the deepest thing in view, its step against the wall the sharpest, and the opening, nearer
    than it, falls in the near class (measured: on the frames of hard-world flights, seeds 77-79, that had the
    wall's end in view, 42-49 % found no far region enclosed by a nearer surface, against 8-12 % without).  What
    is left is split again (:func:`far_regions`) and the far class of each significant step, sharpest first, is
    looked through for holes; one that reaches what was set aside is no hole in the wall.  ``plain_beside``:
    the plain regions set aside already, and a pixel round them (:func:`detect_gap_parallax`)."""
    edge = reaching_border(far)
    if not edge.any():
        return []
    aside = within(edge, config.past_the_end_reach_px)
    if plain_beside is not None:
        aside = aside | plain_beside
    fars, _ = far_regions(log_img, log_step, config, region=~aside)
    beside = within(aside, 1)
    for far_rest in fars:
        scored = _holes(far_rest & ~aside, config, a_min, a_max, outside=beside)
        if scored:
            return scored
    return []


def _holes_against_wall(log_rho: np.ndarray, measurable: np.ndarray, motion: CameraMotion,
                        config: ParallaxGapConfig, a_min: float, a_max: float) -> list[np.ndarray]:
    """Holes found in the inverse depth against the wall's plane (ρ over the plane's ρ there), where the plain
    split found none.  A wall turned against the camera spans a range of depths: its far side can lie as far as
    what is seen through an opening on its near side, so that no one split of ρ separates them (measured:
    hard-world walls turned 16-20° with the background 0.6-1.2 m behind, seeds 99, 101-103, the opening plain to
    see in the flow and no hole found in most frames; six flights stalled in front of it).  Against the wall's
    plane the wall is flat at 0, the opening below it.  Only holes clear of the image's border count: what lies
    past the wall's end is as far below the plane, and reaches the border."""
    h, w = log_rho.shape
    plane = wall_plane_log(log_rho, measurable, focal_length_px(motion, config.vfov_deg, h), config.against_wall_band)
    if plane is None:
        return []
    on_wall = measurable & (np.abs(log_rho - plane) <= config.against_wall_band)
    if on_wall.sum() < config.against_wall_walled * measurable.sum():
        return []       # no one plane in view dominates it: no wall to measure holes against
    img, span = _log_image(log_rho - plane, measurable, config)
    fars, _ = far_regions(img, span / 255.0, config)
    border = np.ones((h, w), bool)
    border[1:-1, 1:-1] = False
    for far in fars:
        scored = [c for c in _holes(far, config, a_min, a_max, outside=border)
                  if _walled(c, on_wall, measurable, config)]
        if scored:
            return scored
    return []


def _walled(contour: np.ndarray, on_wall: np.ndarray, measurable: np.ndarray, config: ParallaxGapConfig,
            ring_px: int = 4) -> bool:
    """Whether the ring around a hole lies on the wall's plane where it is measurable (``against_wall_walled``
    of it at least, and a third of it measurable): a hole in the wall is walled all round; a blob in the flow of
    the empty space past the wall's end, or one that reaches it, is not."""
    mask = filled(on_wall.shape, contour)
    ring = within(mask, ring_px) & ~within(mask, 1)
    seen = ring & measurable
    return bool(seen.sum() >= ring.sum() / 3) and float(on_wall[seen].mean()) >= config.against_wall_walled


def fill_occluded(contour: np.ndarray, rho: np.ndarray, measurable: np.ndarray,
                   g: tuple[np.ndarray, np.ndarray], fraction: float, ring_px: int = 6) -> np.ndarray:
    """The opening's outline with the band the wall hides in the second frame filled back in.

    Forward flow lives on the first frame's pixels.  A background pixel p seen through the opening is seen again
    only if p + d(p) lies in the opening, d = (ρ_far − ρ_near)·g(p) being how far the background moves against
    the wall; the others have no match, the flow there follows the wall, and the mask is the opening cut by a
    band of width |d| on the side d points to (moving sideways, the side it moves to: measured, a 0.2 m step
    from 1.1 m cut 17 px off a 0.9 m opening, and its clear centre moved 8 px).  The mask shifted by d covers
    that band (the opening cut on the other side), so the union is the opening; moving toward it, d points
    into the opening and adds nothing.  ρ_far and ρ_near: medians inside the mask and in a ring around it."""
    h, w = rho.shape
    mask = filled((h, w), contour)
    inner = cv2.erode(mask, np.ones((5, 5), np.uint8)).astype(bool) & measurable
    ring = within(mask, ring_px) & ~within(mask, 2) & measurable
    if inner.sum() < 20 or ring.sum() < 20:
        return contour
    step = fraction * (float(np.median(rho[inner])) - float(np.median(rho[ring])))
    if step >= 0:
        return contour
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    shifted = cv2.remap(mask, xs - (step * g[0]).astype(np.float32), ys - (step * g[1]).astype(np.float32),
                        cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    contours, _ = cv2.findContours(mask | shifted, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    return max(contours, key=cv2.contourArea) if contours else contour


def far_region(log_img: np.ndarray, log_step: float, config: ParallaxGapConfig) -> tuple[np.ndarray | None, str]:
    """The far class of the sharpest significant depth step (see :func:`far_regions`), or (None, reason)."""
    fars, reason = far_regions(log_img, log_step, config)
    return (fars[0] if fars else None), reason


def far_regions(log_img: np.ndarray, log_step: float, config: ParallaxGapConfig,
                region: np.ndarray | None = None) -> tuple[list[np.ndarray], str]:
    """The far classes of an 8-bit log-inverse-depth image's significant depth steps, sharpest first.

    Otsu splits the image into near and far, then splits the far class again, and so on (``max_splits``
    times), peeling off nearer surfaces (floor, then wall).  Of the *significant* splits (median inverse
    depths differ by ``min_contrast`` and η ≥ ``min_separability``) the one with the largest contrast is the
    depth step at the opening; its far class is what lies beyond.  A floor ramp may give a weak first split
    and a sharp second one, so weak splits do not stop the descent; splits of one surface's noise are weak.
    The other significant steps follow in order of contrast: seen from afar, the floor's step can be sharper
    than the wall's, and its far class (wall and opening together) is then no hole in anything.
    ``region``: the pixels to split (default: all).
    """
    region = np.ones(log_img.shape, bool) if region is None else np.asarray(region, bool).copy()
    fars: list[tuple[float, np.ndarray]] = []
    a_min = config.area_min_frac * log_img.size
    best = (0.0, 0.0)
    for _ in range(config.max_splits):
        values = log_img[region]
        t, eta = _otsu_split(values)
        low = values <= t
        if low.all() or not low.any() or low.sum() < a_min:
            break
        far_level, near_level = float(np.median(values[low])), float(np.median(values[~low]))
        contrast = float(np.exp((near_level - far_level) * log_step))
        new_region = np.zeros_like(region)
        new_region[region] = low
        if contrast >= config.min_contrast and eta >= config.min_separability:
            far = new_region
            if config.edge_blend is not None:
                far = region & (log_img <= _blend_level(far_level, near_level, log_step, config.edge_blend))
                if config.edge_blend_reach_px is not None:
                    far &= within(new_region, config.edge_blend_reach_px)
            fars.append((contrast, far))
        elif not fars and contrast * eta > best[0] * best[1]:
            best = (contrast, eta)
        region = new_region
    if not fars:
        return [], f"no depth contrast (best split: inverse-depth ratio {best[0]:.2f}, separability {best[1]:.2f})"
    fars.sort(key=lambda cf: -cf[0])     # stable: of equally sharp steps the nearer (earlier) comes first
    return [far for _, far in fars], "no depth contrast"


def _otsu_split(values: np.ndarray) -> tuple[int, float]:
    """Otsu threshold of 8-bit ``values`` (1-D) and its separability η = σ²_between / σ²_total."""
    t, _ = cv2.threshold(values.reshape(-1, 1), 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    low = values <= t
    total = values.var()
    if total <= 0 or low.all() or not low.any():
        return int(t), 0.0
    w0 = low.mean()
    between = w0 * (1 - w0) * (values[low].mean() - values[~low].mean()) ** 2
    return int(t), float(between / total)


def _blend_level(far_level: float, near_level: float, log_step: float, blend: float) -> float:
    """The 8-bit log-ρ level where linear ρ is ``blend`` of the way from ``far_level``'s to ``near_level``'s."""
    rho_far, rho_near = np.exp(far_level * log_step), np.exp(near_level * log_step)
    return float(np.log(rho_far + blend * (rho_near - rho_far)) / log_step)


def _log_image(log_values: np.ndarray, measurable: np.ndarray, config: ParallaxGapConfig) -> tuple[np.ndarray, float]:
    """8-bit image of a log inverse depth (or of a log ratio of inverse depths) over its robust range, and that
    range; pixels not ``measurable`` (near the FoE, ρ ≤ 0) are inpainted from their neighbours."""
    lo, hi = np.nanpercentile(log_values[measurable], config.robust_percentiles)
    span = max(float(hi - lo), 1e-6)
    img = (255 * np.clip((np.nan_to_num(log_values, nan=lo) - lo) / span, 0, 1)).astype(np.uint8)
    if not measurable.all():
        img = cv2.inpaint(img, (~measurable).astype(np.uint8), 5, cv2.INPAINT_TELEA)
    if config.median_ksize > 1:
        img = cv2.medianBlur(img, config.median_ksize)
    return img, span


def within(mask: np.ndarray, reach_px: int) -> np.ndarray:
    """The pixels at most ``reach_px`` (8-connected steps) from ``mask``."""
    if reach_px <= 0:
        return mask
    grown = cv2.dilate(mask.astype(np.uint8), np.ones((3, 3), np.uint8), iterations=int(reach_px))
    return grown.astype(bool)


def reaching_border(mask: np.ndarray) -> np.ndarray:
    """The components of ``mask`` (8-connected) that reach the image's border, whole."""
    _, labels = cv2.connectedComponents(mask.astype(np.uint8), connectivity=8)
    at_border = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    return np.isin(labels, at_border[at_border > 0])


def filled(shape: tuple[int, int], contour: np.ndarray) -> np.ndarray:
    """uint8 mask (0/1) of ``contour`` filled, in a frame of ``shape``."""
    mask = np.zeros(shape, np.uint8)
    cv2.drawContours(mask, [contour], -1, 1, thickness=cv2.FILLED)
    return mask


def plain_fraction(contour: np.ndarray, plain: np.ndarray) -> float:
    """The fraction of the pixels inside ``contour`` (filled; a contour fills one pixel at least) that ``plain``
    holds."""
    return float(plain[filled(plain.shape, contour).astype(bool)].mean())

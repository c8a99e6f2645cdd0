"""Inverse depth from the flow of a translating camera (pure: arrays in, arrays out).

For a camera that translates (no rotation) the flow at a pixel is F = ρ·g(x, y; t), with ρ = |T|/Z the inverse
depth in units of the step length and g known from the intrinsics and the translation's direction t
(:func:`estimate_translation` reads t from the flow where it is not given).  :func:`inverse_depth` divides it out
away from the focus of expansion; :func:`focus_inverse_depth` reads it near the focus from the flow's rate of
expansion over a window; :func:`wall_plane_log` fits the dominant plane (the wall) to it.  The gap detector
(:mod:`companion.gap`) finds openings in what these return.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


@dataclass(frozen=True)
class CameraMotion:
    """Translation of the camera between the two frames, in camera axes (x right, y down, z forward).

    Only its direction matters.  ``focal_px`` and ``principal_point`` default to the flowgap camera model
    (the vertical FOV the caller gives, centred principal point).
    """

    translation: tuple[float, float, float] | None = None
    focal_px: float | None = None
    principal_point: tuple[float, float] | None = None


def _pixel_grid(h: int, w: int, cx: float, cy: float) -> tuple[np.ndarray, np.ndarray]:
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    return xs - cx, ys - cy


def estimate_translation(flow: np.ndarray, focal_px: float, principal_point: tuple[float, float],
                         *, iterations: int = 3, stride: int = 2) -> np.ndarray:
    """Camera translation direction (unit 3-vector, camera axes) from a translation-only flow field.

    Each pixel gives one linear constraint: the flow is parallel to g = (x'·tz − f·tx, y'·tz − f·ty), i.e.
    u·(y'·tz − f·ty) − v·(x'·tz − f·tx) = 0.  Solved as a homogeneous least-squares problem (SVD), with
    iteratively reweighted residuals; the sign is chosen so that inverse depth comes out positive.
    """
    h, w = flow.shape[:2]
    xs, ys = _pixel_grid(h, w, *principal_point)
    u = flow[::stride, ::stride, 0].ravel().astype(np.float64)
    v = flow[::stride, ::stride, 1].ravel().astype(np.float64)
    xp, yp = xs[::stride, ::stride].ravel(), ys[::stride, ::stride].ravel()
    ok = np.isfinite(u) & np.isfinite(v)
    u, v, xp, yp = u[ok], v[ok], xp[ok], yp[ok]
    f = focal_px
    a = np.stack([f * v, -f * u, u * yp - v * xp], axis=1)   # coefficients of (tx, ty, tz)
    mag = np.hypot(u, v) + 1e-6
    a = a / mag[:, None]                                      # normalise: constraint is on the direction
    weights = np.ones(len(a))
    t = np.array([0.0, 0.0, 1.0])
    for _ in range(iterations):
        _, _, vt = np.linalg.svd(a * weights[:, None], full_matrices=False)
        t = vt[-1]
        r = np.abs(a @ t)
        scale = np.median(r) + 1e-9
        weights = 1.0 / np.maximum(1.0, r / (2.0 * scale))   # Huber-like down-weighting of outliers
    g_u = xp * t[2] - f * t[0]
    g_v = yp * t[2] - f * t[1]
    if np.median(u * g_u + v * g_v) < 0:
        t = -t
    return t / np.linalg.norm(t)


def focal_length_px(motion: CameraMotion, vfov_deg: float, height: int) -> float:
    """The camera's focal length in pixels: the motion's, else from the vertical field of view and the frame's
    height."""
    return motion.focal_px or (height / 2.0) / np.tan(np.radians(vfov_deg) / 2.0)


def inverse_depth(flow: np.ndarray, motion: CameraMotion, vfov_deg: float,
                  min_g_frac: float) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """Inverse depth ρ = |T|/Z per pixel, the mask of pixels where it was measurable, and the flow field
    g = (g_u, g_v) of unit inverse depth (F = ρ·g).

    T is the camera translation between the frames (only its direction is used, so ρ is Z's inverse in units of
    the step length: Z = |T|/ρ), Z the depth along the optical axis.  Pixels too close to the focus of expansion
    (|g| < ``min_g_frac``·max|g|) or with non-finite flow are NaN / invalid.  ``vfov_deg`` gives the focal length
    where ``motion`` does not."""
    h, w = flow.shape[:2]
    f = focal_length_px(motion, vfov_deg, h)
    cx, cy = motion.principal_point or ((w - 1) / 2.0, (h - 1) / 2.0)
    if motion.translation is None:
        t = estimate_translation(flow, f, (cx, cy))
    else:
        t = np.asarray(motion.translation, dtype=np.float64)
        t = t / (np.linalg.norm(t) + 1e-12)
    xs, ys = _pixel_grid(h, w, cx, cy)
    g_u = xs * t[2] - f * t[0]
    g_v = ys * t[2] - f * t[1]
    g2 = g_u * g_u + g_v * g_v
    u = flow[..., 0].astype(np.float64)
    v = flow[..., 1].astype(np.float64)
    valid = (g2 >= (min_g_frac ** 2) * g2.max()) & np.isfinite(u) & np.isfinite(v)
    rho = np.where(valid, (u * g_u + v * g_v) / np.maximum(g2, 1e-12), np.nan)
    return rho, valid, (g_u, g_v)


def focus_inverse_depth(flow: np.ndarray, rho: np.ndarray, valid: np.ndarray, g: tuple[np.ndarray, np.ndarray],
                        window_px: int) -> tuple[np.ndarray, np.ndarray]:
    """``rho`` and ``valid`` with the pixels too near the focus of expansion (finite flow, not ``valid``) given
    the inverse depth read from the flow's rate of expansion over a ``window_px`` square around each: F = a·p + b
    fitted by least squares (p the pixel, a scalar a = ρ·t_z, b any vector), ρ = a / t_z.  One pixel's |g| there
    is too small to divide by; a window's spread of pixels is not, even at the focus itself.  The focus's own place
    drops out with b, so an error in it (the translation estimated from the flow, a rotation taken out imperfectly)
    biases nothing: ΣF·g/Σ|g|² over the window reads a wall as farther the farther the focus is from where it was
    estimated, a far "opening" at the focus."""
    h, w = flow.shape[:2]
    t_z = float(g[0][0, 1] - g[0][0, 0]) if w > 1 else 0.0     # g_u = x·t_z - f·t_x: its slope along x
    finite = np.isfinite(flow).all(axis=-1)
    near_focus = finite & ~valid
    if abs(t_z) < 1e-6 or not near_focus.any():
        return rho, valid
    weight = finite.astype(np.float64)          # a pixel without flow counts for nothing in its windows
    x, y = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    u = np.where(finite, flow[..., 0], 0.0).astype(np.float64)
    v = np.where(finite, flow[..., 1], 0.0).astype(np.float64)

    def window_sum(values: np.ndarray) -> np.ndarray:
        return cv2.boxFilter(values * weight, -1, (window_px, window_px), normalize=False,
                             borderType=cv2.BORDER_REPLICATE)

    n = np.maximum(window_sum(np.ones_like(x)), 1.0)
    sx, sy, su, sv = window_sum(x), window_sum(y), window_sum(u), window_sum(v)
    spread = window_sum(x * x) - sx * sx / n + window_sum(y * y) - sy * sy / n
    along = window_sum(u * x) - su * sx / n + window_sum(v * y) - sv * sy / n
    rho, valid = rho.copy(), valid | near_focus
    rho[near_focus] = along[near_focus] / (np.maximum(spread[near_focus], 1e-12) * t_z)
    return rho, valid


def wall_plane_log(log_rho: np.ndarray, measurable: np.ndarray, focal_px: float, band: float,
                   rounds: int = 4) -> np.ndarray | None:
    """log ρ of the dominant plane in view (the wall), per pixel: on a plane ρ is linear in the image
    coordinates, so it is fitted by least squares to the measurable pixels, first the nearer 70 % (what lies
    beyond an opening or past the wall's end is farther), then ``rounds`` times to those within ``band`` (in log
    ρ) of the last fit.  None when too little is measurable or the plane comes out behind the camera."""
    h, w = log_rho.shape
    ys, xs = np.mgrid[0:h, 0:w]
    design = np.stack([(xs - (w - 1) / 2) / focal_px, (ys - (h - 1) / 2) / focal_px, np.ones((h, w))], -1)
    rho = np.exp(np.where(measurable, log_rho, -np.inf))
    keep = measurable & (log_rho >= np.nanpercentile(log_rho[measurable], 30)) if measurable.any() else measurable
    for _ in range(rounds + 1):
        if keep.sum() < 0.1 * h * w:
            return None
        coef, *_ = np.linalg.lstsq(design[keep], rho[keep], rcond=None)
        plane = design @ coef
        if not (plane > 0).all():
            return None
        keep = measurable & (np.abs(log_rho - np.log(plane)) <= band)
    return np.log(plane)

"""Turning view-dependent colour with the scene: real spherical harmonics of degree 1-3, 3DGS conventions.

A Gaussian's colour seen along the unit direction d is ``sum_k c_k Y_k(d)`` with the real SH basis ``Y`` that
the renderer evaluates (:func:`scenes.render.common.sh_basis`: the 3DGS ordering and signs, e.g. band 1 is
``C1 * (-y, z, -x)``). When the world turns by R (p' = R p), the colour seen along d' afterwards must be the
colour seen along d = R^T d' before. Each band l spans a space that rotations map onto itself, so
``Y_l(R^T d) = D_l Y_l(d)`` for one (2l+1) x (2l+1) orthogonal matrix D_l: the Wigner D-matrix of R in this
real basis. The turned coefficients are ``c'_l = D_l^T c_l``.

D_l is solved from the basis itself at 64 fixed, well-spread directions by least squares. Because the band is
invariant the fit is exact (to rounding): no table of signs or orderings to get wrong, and it follows the
renderer's basis by construction. The DC term (band 0) never changes, nor does colour under a uniform scale.
"""

from __future__ import annotations

import numpy as np

from scenes.render.common import sh_basis


def _fibonacci_directions(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(1.0 - z * z)
    phi = np.pi * (3.0 - np.sqrt(5.0)) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)


_DIRECTIONS = _fibonacci_directions(64)


def band_rotations(rotation: np.ndarray, degree: int) -> list[np.ndarray]:
    """[D_1, ..., D_degree]: the real-SH rotation matrix of each band for the 3x3 rotation ``rotation``."""
    r = np.asarray(rotation, np.float64)
    if degree < 1:
        return []
    basis = sh_basis(_DIRECTIONS, degree)
    turned = sh_basis(_DIRECTIONS @ r, degree)        # row j: Y(R^T d_j), since (R^T d)^T = d^T R
    out = []
    for band in range(1, degree + 1):
        cols = slice(band * band, (band + 1) ** 2)
        d_transposed, *_ = np.linalg.lstsq(basis[:, cols], turned[:, cols], rcond=None)
        out.append(d_transposed.T)
    return out


def rotate_sh(sh: np.ndarray, rotation: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """SH coefficients (N, K, 3), K in 1, 4, 9, 16, of Gaussians turned by ``rotation``, as float32: into ``out``
    (which may be ``sh`` itself, to spare a copy of a large cloud's colours) or a new array."""
    sh = np.asarray(sh, np.float32)
    if out is None:
        out = sh.copy()
    elif out is not sh:
        out[:, :1] = sh[:, :1]
    degree = int(round(np.sqrt(sh.shape[1]))) - 1
    for band, d in enumerate(band_rotations(rotation, degree), start=1):
        cols = slice(band * band, (band + 1) ** 2)
        out[:, cols, :] = np.matmul(d.T.astype(np.float32), sh[:, cols, :])
    return out

"""Gaussian splat clouds and the standard 3DGS ``.ply`` format.

Storage follows the reference 3D Gaussian Splatting trainer: one ``vertex`` element, binary little-endian,
properties ``x y z nx ny nz f_dc_0..2 f_rest_0..M-1 opacity scale_0..2 rot_0..3`` (float32), where the
values are *pre-activation*: scales are log-scales (``exp``), opacity is a logit (``sigmoid``), rotations
are unnormalised quaternions (w, x, y, z) (normalise), colours are SH coefficients with the DC term in
``f_dc`` and the rest in ``f_rest`` stored channel-major (all R coefficients, then G, then B).
The SH degree (0-3) is inferred from M in (0, 9, 24, 45).

Per-Gaussian surface labels (ground truth, not part of the 3DGS layout) travel in a sidecar
``<file>.labels.npy`` so that the ``.ply`` stays loadable by unmodified viewers.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)

SH_C0 = 0.28209479177387814
REST_COUNT_TO_DEGREE = {0: 0, 9: 1, 24: 2, 45: 3}

LABEL_NONE, LABEL_WALL, LABEL_FRAME, LABEL_BACKGROUND, LABEL_FLOOR = 0, 1, 2, 3, 4
LABEL_NAMES = {LABEL_NONE: "none", LABEL_WALL: "wall", LABEL_FRAME: "frame",
               LABEL_BACKGROUND: "background (beyond the wall)", LABEL_FLOOR: "floor (in front of the wall)"}


class PlyError(ValueError):
    """A ``.ply`` file is corrupt or unsupported; ``str(exc)`` is one line naming the problem and the fix."""


def rgb_to_sh0(rgb: np.ndarray) -> np.ndarray:
    return (np.asarray(rgb, np.float32) - 0.5) / SH_C0


def sh0_to_rgb(sh0: np.ndarray) -> np.ndarray:
    return np.asarray(sh0, np.float32) * SH_C0 + 0.5


@dataclass
class GaussianCloud:
    """N Gaussians in world (NED) coordinates; arrays are float32, pre-activation as in 3DGS.

    means (N, 3); log_scales (N, 3); quats (N, 4) wxyz (not necessarily unit); opacity_logits (N,);
    sh (N, K, 3) with K = (degree + 1)**2; labels (N,) uint8 (``LABEL_*``, ground truth).
    """

    means: np.ndarray
    log_scales: np.ndarray
    quats: np.ndarray
    opacity_logits: np.ndarray
    sh: np.ndarray
    labels: np.ndarray = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        n = len(self.means)
        self.means = np.ascontiguousarray(self.means, np.float32).reshape(n, 3)
        self.log_scales = np.ascontiguousarray(self.log_scales, np.float32).reshape(n, 3)
        self.quats = np.ascontiguousarray(self.quats, np.float32).reshape(n, 4)
        self.opacity_logits = np.ascontiguousarray(self.opacity_logits, np.float32).reshape(n)
        self.sh = np.ascontiguousarray(self.sh, np.float32)
        if self.sh.ndim != 3 or self.sh.shape[0] != n or self.sh.shape[2] != 3 or \
                self.sh.shape[1] not in (1, 4, 9, 16):
            raise ValueError(f"sh must be (N, K, 3) with K in 1, 4, 9, 16; got {self.sh.shape}")
        if self.labels is None:
            self.labels = np.zeros(n, np.uint8)
        self.labels = np.ascontiguousarray(self.labels, np.uint8).reshape(n)

    def __len__(self) -> int:
        return len(self.means)

    @property
    def sh_degree(self) -> int:
        return int(round(np.sqrt(self.sh.shape[1]))) - 1

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        if len(self) == 0:
            return np.zeros(3, np.float32), np.zeros(3, np.float32)
        return self.means.min(0), self.means.max(0)

    def subset(self, index: np.ndarray) -> GaussianCloud:
        return GaussianCloud(self.means[index], self.log_scales[index], self.quats[index],
                             self.opacity_logits[index], self.sh[index], self.labels[index])

    @staticmethod
    def concatenate(clouds: list[GaussianCloud]) -> GaussianCloud:
        k = max(c.sh.shape[1] for c in clouds)
        sh = [np.concatenate([c.sh, np.zeros((len(c), k - c.sh.shape[1], 3), np.float32)], 1) for c in clouds]
        return GaussianCloud(np.concatenate([c.means for c in clouds]),
                             np.concatenate([c.log_scales for c in clouds]),
                             np.concatenate([c.quats for c in clouds]),
                             np.concatenate([c.opacity_logits for c in clouds]), np.concatenate(sh),
                             np.concatenate([c.labels for c in clouds]))


# ------------------------------------------------------------------------------------------------- PLY
_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


def _property_names(degree: int) -> list[str]:
    n_rest = 3 * ((degree + 1) ** 2 - 1)
    return (["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
            + [f"f_rest_{i}" for i in range(n_rest)]
            + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"])


def write_ply(path: str | Path, cloud: GaussianCloud, *, write_labels: bool = True) -> None:
    """Write ``cloud`` as a standard 3DGS binary little-endian ``.ply`` (plus ``.labels.npy`` sidecar)."""
    path = Path(path)
    n, k = len(cloud), cloud.sh.shape[1]
    names = _property_names(cloud.sh_degree)
    data = np.zeros((n, len(names)), np.float32)
    data[:, 0:3] = cloud.means
    data[:, 6:9] = cloud.sh[:, 0, :]
    rest = cloud.sh[:, 1:, :].transpose(0, 2, 1).reshape(n, 3 * (k - 1))  # channel-major
    data[:, 9:9 + rest.shape[1]] = rest
    o = 9 + rest.shape[1]
    data[:, o] = cloud.opacity_logits
    data[:, o + 1:o + 4] = cloud.log_scales
    data[:, o + 4:o + 8] = cloud.quats
    header = "ply\nformat binary_little_endian 1.0\n" + f"element vertex {n}\n"
    header += "".join(f"property float {p}\n" for p in names) + "end_header\n"
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(data.astype("<f4").tobytes())
    if write_labels:
        np.save(_labels_path(path), cloud.labels)


def _labels_path(path: Path) -> Path:
    return path.with_name(path.name + ".labels.npy")


def read_ply_header(path: str | Path) -> tuple[int, list[tuple[str, str]], int, list[tuple[str, int, int]]]:
    """Parse a ply header: (vertex count, [(name, dtype)], byte offset of the vertex data, other elements
    as (name, count, row bytes, before vertex))."""
    path = Path(path)
    try:
        f = open(path, "rb")
    except OSError as exc:
        raise PlyError(f"{path}: cannot open ({exc.strerror}); check the path") from None
    with f:
        first = f.readline(64)
        if first.strip() != b"ply":
            raise PlyError(f"{path}: not a PLY file (no 'ply' magic); pass a Gaussian-splat .ply")
        props: list[tuple[str, str]] = []
        n_vertex = -1
        elements: list[list] = []  # [name, count, row bytes, before vertex, has list property]
        current = None
        fmt_ok = False
        for _ in range(10000):
            raw = f.readline(4096)
            if not raw:
                raise PlyError(f"{path}: header ends before 'end_header' (truncated file); re-export it")
            try:
                line = raw.decode("ascii").strip()
            except UnicodeDecodeError:
                raise PlyError(f"{path}: header is not ASCII (corrupt file); re-export it") from None
            parts = line.split()
            if not parts or parts[0] in ("comment", "obj_info"):
                continue
            if parts[0] == "format":
                if len(parts) < 2 or parts[1] != "binary_little_endian":
                    fmt = parts[1] if len(parts) > 1 else "?"
                    raise PlyError(f"{path}: PLY format {fmt!r} is not supported; convert it to "
                                   f"binary_little_endian (as written by 3DGS/nerfstudio)")
                fmt_ok = True
            elif parts[0] == "element":
                if len(parts) != 3 or not parts[2].isdigit():
                    raise PlyError(f"{path}: malformed element line {line!r}; re-export the file")
                current = parts[1]
                if current == "vertex":
                    n_vertex = int(parts[2])
                else:
                    elements.append([current, int(parts[2]), 0, n_vertex < 0, False])
            elif parts[0] == "property":
                if current is None:
                    raise PlyError(f"{path}: property line {line!r} comes before any 'element' line (corrupt "
                                   f"header); re-export the file")
                if len(parts) >= 2 and parts[1] == "list":
                    if current == "vertex" or not elements:
                        raise PlyError(f"{path}: list property in element {current!r} is not supported; export "
                                       f"Gaussians only (no faces)")
                    elements[-1][4] = True
                    continue
                if len(parts) != 3 or parts[1] not in _PLY_TYPES:
                    raise PlyError(f"{path}: malformed property line {line!r}; re-export the file")
                if current == "vertex":
                    props.append((parts[2], "<" + _PLY_TYPES[parts[1]]))
                elif elements:
                    elements[-1][2] += int(_PLY_TYPES[parts[1]][1])
            elif parts[0] == "end_header":
                break
            else:
                raise PlyError(f"{path}: unexpected header line {line!r}; re-export the file")
        else:
            raise PlyError(f"{path}: header too long or missing 'end_header'; re-export the file")
        if not fmt_ok:
            raise PlyError(f"{path}: no 'format' line in the header; re-export the file")
        if n_vertex < 0:
            raise PlyError(f"{path}: no 'element vertex' in the header; pass a Gaussian-splat .ply")
        offset = f.tell()
        for name, count, size, before, has_list in elements:
            if before:
                if has_list:
                    raise PlyError(f"{path}: element {name!r} before the vertices has a list property; this "
                                   f"layout is not supported (re-export as a plain 3DGS .ply)")
                offset += count * size
        _check_body_size(path, n_vertex, props, offset, os.fstat(f.fileno()).st_size,
                         [(count, size, has_list) for _, count, size, before, has_list in elements if not before])
        return n_vertex, props, offset, [tuple(e[:4]) for e in elements]


def _check_body_size(path: Path, n_vertex: int, props: list[tuple[str, str]], offset: int, file_size: int,
                     after: list[tuple[int, int, bool]]) -> None:
    """Refuse a body that cannot be what the header describes, before anything is allocated: a vertex count
    too big for the file (a corrupt count would otherwise ask for terabytes), or bytes left over when every
    element has a fixed size (a count too small, or a property line lost or added, shifts every column
    and would be read as a wrong cloud without complaint). ``after``: (count, row bytes, has a list
    property) of the elements after the vertices."""
    row = sum(np.dtype(t).itemsize for _, t in props)
    need = n_vertex * row
    available = file_size - offset
    if need > available:
        raise PlyError(f"{path}: truncated: header promises {n_vertex} Gaussians ({need} bytes) but only "
                       f"{max(available, 0)} bytes follow; re-download or re-export the file")
    if any(has_list for _, _, has_list in after):
        return  # faces and the like: their size is only known by reading them
    described = need + sum(count * size for count, size, _ in after)
    if available > described:
        raise PlyError(f"{path}: {available - described} bytes more than the header describes ({n_vertex} "
                       f"Gaussians of {row} bytes): header and data disagree (corrupt or hand-edited file); "
                       f"re-export it")
    if available < described:
        log.warning("%s: the elements after the Gaussians are truncated (%d of %d bytes); the Gaussians are whole",
                    path, available - need, described - need)


def read_ply(path: str | Path) -> GaussianCloud:
    """Read a 3DGS ``.ply`` (reference trainer, nerfstudio export, or ours). Raises :class:`PlyError`."""
    path = Path(path)
    n, props, offset, _ = read_ply_header(path)
    names = [p for p, _ in props]
    if len(set(names)) != len(names):
        raise PlyError(f"{path}: duplicate vertex property names; re-export the file")
    # nerfstudio writes degree-0 splats with uchar red/green/blue instead of f_dc_*
    rgb_colours = "f_dc_0" not in names and all(c in names for c in ("red", "green", "blue"))
    required = ["x", "y", "z", "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    if not rgb_colours:
        required[3:3] = ["f_dc_0", "f_dc_1", "f_dc_2"]
    missing = [r for r in required if r not in names]
    if missing:
        raise PlyError(f"{path}: vertex lacks Gaussian properties {missing[:4]}; this is not a 3DGS splat "
                       f"file (export one with 3DGS or 'ns-export gaussian-splat')")
    n_rest = sum(1 for p in names if p.startswith("f_rest_"))
    if n_rest not in REST_COUNT_TO_DEGREE:
        raise PlyError(f"{path}: {n_rest} f_rest properties is not SH degree 0-3 (need 0, 9, 24 or 45); "
                       f"re-export with a supported SH degree")
    rest_names = [f"f_rest_{i}" for i in range(n_rest)]
    if any(r not in names for r in rest_names):
        raise PlyError(f"{path}: f_rest properties are not numbered 0..{n_rest - 1}; re-export the file")
    dtype = np.dtype(props)
    need = n * dtype.itemsize
    with open(path, "rb") as f:  # read_ply_header has checked that the file holds `need` bytes here
        f.seek(offset)
        buf = f.read(need)
    if len(buf) < need:  # the file shrank since its header was read
        raise PlyError(f"{path}: truncated: header promises {n} Gaussians ({need} bytes) but only {len(buf)} "
                       f"bytes follow; re-download or re-export the file")
    v = np.frombuffer(buf, dtype=dtype, count=n)

    def cols(keys: list[str]) -> np.ndarray:
        if not keys:
            return np.zeros((n, 0), np.float32)
        return np.stack([v[k].astype(np.float32) for k in keys], axis=1)

    k = n_rest // 3 + 1
    sh = np.zeros((n, k, 3), np.float32)
    if rgb_colours:
        scale = 255.0 if np.issubdtype(v["red"].dtype, np.integer) else 1.0
        sh[:, 0, :] = rgb_to_sh0(cols(["red", "green", "blue"]) / scale)
    else:
        sh[:, 0, :] = cols(["f_dc_0", "f_dc_1", "f_dc_2"])
    if n_rest:
        sh[:, 1:, :] = cols(rest_names).reshape(n, 3, k - 1).transpose(0, 2, 1)
    labels = None
    if "label" in names:
        labels = v["label"].astype(np.uint8)
    elif _labels_path(path).exists():
        labels = _read_label_sidecar(_labels_path(path), n)
    cloud = GaussianCloud(cols(["x", "y", "z"]), cols(["scale_0", "scale_1", "scale_2"]),
                          cols(["rot_0", "rot_1", "rot_2", "rot_3"]), v["opacity"].astype(np.float32), sh, labels)
    _check_finite(path, cloud)
    return cloud


def _check_finite(path: Path, cloud: GaussianCloud) -> None:
    """Refuse NaN or inf anywhere a Gaussian is drawn from: one such value makes the renderer's sums NaN
    (a black or garbage frame), far from the file that caused it."""
    arrays = {"positions": cloud.means, "scales": cloud.log_scales, "rotations": cloud.quats,
              "opacities": cloud.opacity_logits, "colours": cloud.sh}
    bad_by_name = {name: ~np.isfinite(a).all(axis=tuple(range(1, a.ndim))) for name, a in arrays.items()}
    bad = np.zeros(len(cloud), bool)
    for rows in bad_by_name.values():
        bad |= rows
    if bad.any():
        names = ", ".join(name for name, rows in bad_by_name.items() if rows.any())
        raise PlyError(f"{path}: non-finite values (NaN or inf) in the {names} of {int(bad.sum())} Gaussian(s), "
                       f"the first at index {int(np.argmax(bad))} (corrupt file); re-export it")


def _read_label_sidecar(path: Path, n: int) -> np.ndarray | None:
    """The ``.labels.npy`` sidecar's labels, None (with a warning) when it is unreadable or of another cloud:
    labels are ground truth for evaluation, the splats render without them."""
    try:
        labels = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError) as exc:
        log.warning("%s: ignoring unreadable label sidecar (%s)", path, exc)
        return None
    if labels.shape != (n,):
        log.warning("%s: ignoring label sidecar of shape %s (expected (%d,))", path, labels.shape, n)
        return None
    return labels.astype(np.uint8)

"""Synthetic captures for tests and benchmarks: a procedural scene written as a third-party 3DGS export would be.

:func:`write_reexpressed_capture` turns a suite (or random) scene into what a capture looks like from outside:
the NED world turned by a yaw, view-dependent colour (SH degree 3), floaters far out, written in the Inria
layout (no label sidecar) in another frame and scale, plus the capture ``.json`` whose ``to_ned`` is that
frame's exact inverse, its gate on the opening and its start where the procedural scene starts. Loading the
JSON gives back the turned scene, which the procedural one predicts exactly: renders (poses turned the same
way) and collision geometry can be compared with the originals.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from scenes.build import build_scene
from scenes.capture import Placement, place_cloud
from scenes.spec import SceneSpec
from scenes.splats import GaussianCloud, write_ply


@dataclass(frozen=True)
class Reexpressed:
    """What :func:`write_reexpressed_capture` wrote: the capture ``json`` and ``ply``, the ``turn`` taking the
    procedural scene's NED world to the capture's NED world, and the placement of the ``.ply`` (``to_ned``)."""

    json: Path
    ply: Path
    turn: Placement
    to_ned: Placement
    gaussians: int
    floaters: int
    procedural: GaussianCloud | None = None     # the scene before the turn, with its view dependence, no floaters


def random_rotation(rng: np.random.Generator) -> tuple[float, float, float, float]:
    q = rng.standard_normal(4)
    q /= np.linalg.norm(q)
    return tuple(float(v) for v in (q if q[0] >= 0 else -q))


def yaw_turn(yaw_deg: float, shift_m=(0.0, 0.0)) -> Placement:
    """Turn the NED world about the vertical by ``yaw_deg`` and shift it horizontally (the floor stays at z = 0)."""
    half = math.radians(yaw_deg) / 2
    return Placement(1.0, (math.cos(half), 0.0, 0.0, math.sin(half)), (float(shift_m[0]), float(shift_m[1]), 0.0))


def add_view_dependence(cloud: GaussianCloud, rng: np.random.Generator, strength: float = 0.08) -> GaussianCloud:
    """``cloud`` with random SH degree-3 terms (colour changing with the view, as in trained captures)."""
    rest = (strength * rng.standard_normal((len(cloud), 15, 3))).astype(np.float32)
    sh = np.concatenate([cloud.sh[:, :1, :], rest], 1)
    return GaussianCloud(cloud.means, cloud.log_scales, cloud.quats, cloud.opacity_logits, sh, cloud.labels)


def floaters(rng: np.random.Generator, n: int, centre, near_m: float, far_m: float) -> GaussianCloud:
    """``n`` stray Gaussians (the debris of real captures) ``near_m``..``far_m`` from ``centre`` in every direction:
    log-uniform distances and sizes (5 cm - 2 m), random opacity (many opaque), strong view dependence."""
    d = rng.standard_normal((n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = np.exp(rng.uniform(math.log(near_m), math.log(far_m), n))
    means = np.asarray(centre, np.float64) + d * r[:, None]
    log_scales = rng.uniform(math.log(0.05), math.log(2.0), (n, 3))
    quats = rng.standard_normal((n, 4))
    sh = 0.3 * rng.standard_normal((n, 16, 3))
    return GaussianCloud(means, log_scales, quats, rng.uniform(-3.0, 5.0, n), sh)


def _opening_gate(spec: SceneSpec, turn: Placement) -> dict:
    """The gate on the first opening's bounding rectangle, in the wall's front face, turned with the world."""
    poly = np.asarray(spec.openings[0].polygon())
    (y0, z0), (y1, z1) = poly.min(0), poly.max(0)
    centre = turn.apply(np.array([[spec.wall_x, (y0 + y1) / 2, (z0 + z1) / 2]]))[0]
    normal = turn.rotation @ np.array([-1.0, 0.0, 0.0])          # facing the start
    return {"center_ned": [round(float(v), 6) for v in centre], "normal_ned": [round(float(v), 6) for v in normal],
            "size_m": [round(float(y1 - y0), 6), round(float(z1 - z0), 6)]}


def write_reexpressed_capture(spec: SceneSpec, out_dir: str | Path, rng: np.random.Generator, *,
                              yaw_deg: float | None = None, scale: float | None = None, floater_count: int = 2000,
                              floater_far_m: float = 200.0, gaussians: int | None = None,
                              view_dependence: float = 0.08, name: str | None = None,
                              keep_procedural: bool = False) -> Reexpressed:
    """Write ``spec`` as a capture (see the module docstring) into ``out_dir``; every draw from ``rng``.

    ``yaw_deg`` (default: drawn within +-180) turns the NED world; ``scale`` (default: drawn log-uniformly in
    0.2-5) is the capture's metres per unit; ``gaussians`` (default: the spec's own density) rescales the splat
    spacing to reach about that many; ``floater_far_m``: floaters out to this distance, from 10 m;
    ``keep_procedural``: return the scene before the turn (with the same view dependence) to compare with."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    name = name or f"{spec.name}_capture"
    if gaussians is not None:
        k = math.sqrt(len(build_scene(spec)) / gaussians)
        d = spec.density
        spec = replace(spec, density=replace(d, wall_spacing=d.wall_spacing * k,
                                             background_spacing=d.background_spacing * k,
                                             floor_spacing=d.floor_spacing * k))
    yaw = float(rng.uniform(-180.0, 180.0)) if yaw_deg is None else float(yaw_deg)
    turn = yaw_turn(yaw, rng.uniform(-20.0, 20.0, 2))
    procedural = build_scene(spec)
    if view_dependence > 0:
        procedural = add_view_dependence(procedural, rng, view_dependence)
    cloud = place_cloud(procedural, turn)
    centre = turn.apply(np.array([[spec.wall_x, 0.0, -1.5]]))[0]
    stray = floaters(rng, floater_count, centre, 10.0, floater_far_m)
    cloud = GaussianCloud.concatenate([cloud, stray])
    s = float(np.exp(rng.uniform(math.log(0.2), math.log(5.0)))) if scale is None else float(scale)
    to_ned = Placement(s, random_rotation(rng), tuple(float(v) for v in rng.uniform(-50.0, 50.0, 3)))
    ply = out_dir / f"{name}.ply"
    write_ply(ply, place_cloud(cloud, to_ned.inverse()), write_labels=False)
    start = turn.apply(np.zeros((1, 3)))[0]
    doc = {"kind": "capture", "name": name, "ply": ply.name, "to_ned": to_ned.to_dict(),
           "gate": _opening_gate(spec, turn), "start_ned": [round(float(v), 6) for v in start],
           "start_yaw_deg": round(yaw + spec.start_yaw_deg, 6),
           "comment": f"{spec.name} re-expressed: NED world turned by {yaw:.1f} deg, .ply in another frame"}
    path = out_dir / f"{name}.json"
    path.write_text(json.dumps(doc, indent=2) + "\n")
    return Reexpressed(path, ply, turn, to_ned, len(cloud), floater_count, procedural if keep_procedural else None)

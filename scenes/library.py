"""The named scene suite (``window1``..``window4`` x four textures) and random scenes for training.

Openings are sized for a ~0.35 m quadrotor with margin (0.8-1.0 m across) and centred near z = -1.5.
The background surface uses the wall's texture family with its texture scale multiplied by
``background_x / wall_x``, so that from the start pose its features have the same apparent size as the
wall's: appearance cannot tell them apart, only parallax can.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from scenes.spec import (
    TEXTURES,
    BackgroundSpec,
    JitterSpec,
    OpeningSpec,
    SceneSpec,
    WallSpec,
)

DEFAULT_SCENE = "window1_brick"

OPENINGS: dict[str, OpeningSpec] = {
    # centred rectangle
    "window1": OpeningSpec("rect", center=(0.0, -1.5), size=(0.9, 0.9)),
    # off-centre rectangle (right and a little high)
    "window2": OpeningSpec("rect", center=(0.85, -1.65), size=(1.0, 0.8)),
    # ellipse, left of centre
    "window3": OpeningSpec("ellipse", center=(-0.55, -1.45), size=(1.0, 0.9)),
    # irregular polygon (about 1.0 m x 0.95 m, inscribed circle radius > 0.35 m)
    "window4": OpeningSpec("polygon", vertices=(
        (-0.20, -1.93), (0.30, -2.00), (0.72, -1.78), (0.80, -1.30), (0.52, -1.04), (-0.02, -1.06),
        (-0.22, -1.42))),
}

_TEXTURE_SEEDS = {"brick": 11, "granite": 23, "newspaper": 37, "stone": 41}
_WINDOW_SEEDS = {"window1": 0, "window2": 100, "window3": 200, "window4": 300}


def suite_spec(window: str, texture: str) -> SceneSpec:
    if window not in OPENINGS or texture not in TEXTURES:
        raise KeyError(f"{window}_{texture}")
    seed = _TEXTURE_SEEDS[texture] + _WINDOW_SEEDS[window]
    wall = WallSpec(distance=3.0, width=7.0, height=4.0, thickness=0.15, texture=texture, seed=seed)
    bg_gap = 2.0
    bg = BackgroundSpec(gap=bg_gap, width=7.0, height=4.5, seed=seed + 1,
                        texture_scale=(wall.distance + wall.thickness + bg_gap) / wall.distance)
    return SceneSpec(name=f"{window}_{texture}", wall=wall, openings=(OPENINGS[window],), background=bg)


SUITE: list[str] = [f"{w}_{t}" for w in OPENINGS for t in TEXTURES]

def _named(name: str) -> Callable[[], SceneSpec]:
    window, texture = name.split("_")
    return lambda: suite_spec(window, texture)


NAMED: dict[str, Callable[[], SceneSpec]] = {name: _named(name) for name in SUITE}


def random_opening(rng: np.random.Generator) -> OpeningSpec:
    kind = rng.choice(["rect", "rect_off", "ellipse", "polygon"])
    w, h = float(rng.uniform(0.8, 1.1)), float(rng.uniform(0.75, 1.0))
    cy, cz = float(rng.uniform(-1.2, 1.2)), float(rng.uniform(-1.75, -1.3))
    if kind == "rect":
        cy = float(rng.uniform(-0.3, 0.3))
    frame = float(rng.uniform(0.03, 0.08)) if rng.random() < 0.3 else 0.0
    if kind in ("rect", "rect_off"):
        return OpeningSpec("rect", center=(cy, cz), size=(w, h), frame_width=frame)
    if kind == "ellipse":
        return OpeningSpec("ellipse", center=(cy, cz), size=(w, h), frame_width=frame)
    n = int(rng.integers(5, 9))
    ang = np.linspace(0, 2 * np.pi, n, endpoint=False) + rng.uniform(-0.25, 0.25, n)
    rad = rng.uniform(0.85, 1.0, n)
    verts = tuple((cy + w / 2 * r * np.cos(a), cz + h / 2 * r * np.sin(a)) for a, r in zip(ang, rad, strict=True))
    return OpeningSpec("polygon", vertices=tuple((float(a), float(b)) for a, b in verts), frame_width=frame)


def random_scene(rng: np.random.Generator, textures: Sequence[str] = TEXTURES) -> SceneSpec:
    """A random wall-with-opening scene for training and Monte-Carlo flights (all draws from ``rng``).

    ``textures``: the families to draw from (the suite's four by default; RAFT training adds
    ``scenes.spec.EXTRA_TEXTURES``).
    """
    texture = str(rng.choice(list(textures)))
    seed = int(rng.integers(0, 2**31 - 1))
    distance = float(rng.uniform(2.5, 4.0))
    wall = WallSpec(distance=distance, width=float(rng.uniform(6.5, 8.0)), height=4.0,
                    thickness=float(rng.uniform(0.1, 0.25)), center_y=float(rng.uniform(-0.5, 0.5)),
                    texture=texture, seed=seed, texture_scale=float(rng.uniform(0.8, 1.25)))
    gap = float(rng.uniform(1.0, 4.0))
    matched = rng.random() < 0.7
    bg_scale = wall.texture_scale * ((distance + wall.thickness + gap) / distance if matched
                                     else float(rng.uniform(0.8, 2.0)))
    bg = BackgroundSpec(gap=gap, width=wall.width + 1.0, height=4.5, seed=seed + 1, texture_scale=bg_scale)
    jitter = JitterSpec(exposure=float(rng.uniform(0.8, 1.2)),
                        tint=tuple(float(v) for v in rng.uniform(0.92, 1.08, 3)))
    return SceneSpec(name=f"random_{seed:010d}", wall=wall, openings=(random_opening(rng),), background=bg,
                     jitter=jitter)

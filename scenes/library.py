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


WORLDS = ("standard", "hard")


def _random_wall(rng: np.random.Generator, textures: Sequence[str]) -> tuple[WallSpec, int]:
    """The wall both worlds draw (its texture, the scene's seed, distance, size, thickness, place, scale), in the
    order the standard world always drew them."""
    texture = str(rng.choice(list(textures)))
    seed = int(rng.integers(0, 2**31 - 1))
    distance = float(rng.uniform(2.5, 4.0))
    wall = WallSpec(distance=distance, width=float(rng.uniform(6.5, 8.0)), height=4.0,
                    thickness=float(rng.uniform(0.1, 0.25)), center_y=float(rng.uniform(-0.5, 0.5)),
                    texture=texture, seed=seed, texture_scale=float(rng.uniform(0.8, 1.25)))
    return wall, seed


def random_scene(rng: np.random.Generator, textures: Sequence[str] = TEXTURES, world: str = "standard") -> SceneSpec:
    """A random wall-with-opening scene for training and Monte-Carlo flights (all draws from ``rng``).

    ``textures``: the families to draw from (the suite's four by default; RAFT training adds
    ``scenes.spec.EXTRA_TEXTURES``).  ``world``: "standard" (one opening 0.75–1.1 m, the wall facing the start;
    the same draws for a seed as ever) or "hard" (:func:`hard_scene`).
    """
    if world == "hard":
        return hard_scene(rng, textures)
    if world != "standard":
        raise ValueError(f"unknown world {world!r}; choose one of {WORLDS}")
    wall, seed = _random_wall(rng, textures)
    gap = float(rng.uniform(1.0, 4.0))
    matched = rng.random() < 0.7
    bg_scale = wall.texture_scale * ((wall.distance + wall.thickness + gap) / wall.distance if matched
                                     else float(rng.uniform(0.8, 2.0)))
    bg = BackgroundSpec(gap=gap, width=wall.width + 1.0, height=4.5, seed=seed + 1, texture_scale=bg_scale)
    jitter = JitterSpec(exposure=float(rng.uniform(0.8, 1.2)),
                        tint=tuple(float(v) for v in rng.uniform(0.92, 1.08, 3)))
    return SceneSpec(name=f"random_{seed:010d}", wall=wall, openings=(random_opening(rng),), background=bg,
                     jitter=jitter)


HARD_OPENING_SIZE = (0.3, 1.3)      # m, each side of a hard-world opening (some too small to pass)
HARD_BACKGROUND_GAP = (0.6, 4.0)    # m behind the wall
HARD_TURN_DEG = 20.0                # the wall turned up to this much against the start heading
HARD_OPENINGS = (1, 3)
HARD_SPACING_M = 0.4                # of wall between two openings' bounding boxes, at least


def hard_scene(rng: np.random.Generator, textures: Sequence[str] = TEXTURES) -> SceneSpec:
    """A hard-world scene: 1–3 openings 0.3–1.3 m wide or high (some impassable), the wall turned up to ±20°
    against the start heading (``start_yaw_deg``), the background 0.6–4 m behind it.  All draws from ``rng``."""
    wall, seed = _random_wall(rng, textures)
    wanted = int(rng.integers(HARD_OPENINGS[0], HARD_OPENINGS[1] + 1))
    openings: list[OpeningSpec] = []
    boxes: list[tuple[float, float, float, float]] = []
    for _ in range(40 * wanted):                    # rejection sampling, bounded
        if len(openings) == wanted:
            break
        op = _hard_opening(rng)
        ys, zs = zip(*op.polygon(), strict=True)
        box = (min(ys), max(ys), min(zs), max(zs))
        inside = (box[0] >= wall.center_y - wall.width / 2 + 0.3 and box[1] <= wall.center_y + wall.width / 2 - 0.3
                  and box[2] >= -wall.height + 0.3 and box[3] <= -0.3)
        apart = all(box[1] + HARD_SPACING_M <= b[0] or b[1] + HARD_SPACING_M <= box[0]
                    or box[3] + HARD_SPACING_M <= b[2] or b[3] + HARD_SPACING_M <= box[2] for b in boxes)
        if inside and apart:
            openings.append(op)
            boxes.append(box)
    gap = float(rng.uniform(*HARD_BACKGROUND_GAP))
    bg_scale = wall.texture_scale * (wall.distance + wall.thickness + gap) / wall.distance
    bg = BackgroundSpec(gap=gap, width=wall.width + 1.0, height=4.5, seed=seed + 1, texture_scale=bg_scale)
    jitter = JitterSpec(exposure=float(rng.uniform(0.8, 1.2)),
                        tint=tuple(float(v) for v in rng.uniform(0.92, 1.08, 3)))
    yaw = float(rng.uniform(-HARD_TURN_DEG, HARD_TURN_DEG))
    return SceneSpec(name=f"hard_{seed:010d}", wall=wall, openings=tuple(openings), background=bg, jitter=jitter,
                     start_yaw_deg=yaw)


def _hard_opening(rng: np.random.Generator) -> OpeningSpec:
    kind = str(rng.choice(["rect", "ellipse", "polygon"]))
    w, h = (float(v) for v in rng.uniform(*HARD_OPENING_SIZE, 2))
    cy, cz = float(rng.uniform(-1.6, 1.6)), float(rng.uniform(-2.0, -1.0))
    frame = float(rng.uniform(0.03, 0.08)) if rng.random() < 0.3 else 0.0
    if kind in ("rect", "ellipse"):
        return OpeningSpec(kind, center=(cy, cz), size=(w, h), frame_width=frame)
    n = int(rng.integers(5, 9))
    ang = np.linspace(0, 2 * np.pi, n, endpoint=False) + rng.uniform(-0.25, 0.25, n)
    rad = rng.uniform(0.85, 1.0, n)
    verts = tuple((cy + w / 2 * r * np.cos(a), cz + h / 2 * r * np.sin(a)) for a, r in zip(ang, rad, strict=True))
    return OpeningSpec("polygon", vertices=tuple((float(a), float(b)) for a, b in verts), frame_width=frame)

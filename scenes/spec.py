"""Scene specification: a versioned, JSON-serialisable description of one wall-with-opening scene.

World frame is NED (x forward/north, y right/east, z down), metres and radians. The vehicle starts near
the origin at z = -1.5 looking along +x. The wall is the slab ``wall.distance <= x <= wall.distance +
wall.thickness``, spanning ``|y - wall.center_y| <= wall.width / 2`` and ``-wall.height <= z <= 0`` (it
stands on the floor, z = 0). Openings are shapes in the wall's (y, z) coordinates. A background surface
(same texture family, different seed) stands behind the wall at ``x = wall back face + background.gap``.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

SPEC_VERSION = 1
TEXTURES = ("brick", "granite", "newspaper", "stone")          # the four families of the suite
EXTRA_TEXTURES = ("plaster", "tiles")                          # weak and repetitive texture, for training data
ALL_TEXTURES = TEXTURES + EXTRA_TEXTURES
SHAPES = ("rect", "ellipse", "polygon")
ELLIPSE_SEGMENTS = 64


class SpecError(ValueError):
    """A scene spec is malformed; the message is one line naming the problem and the fix."""


@dataclass(frozen=True)
class WallSpec:
    distance: float = 3.0          # x of the front face [m]
    width: float = 7.0             # extent along y [m]
    height: float = 4.0            # extent up from the floor [m]
    thickness: float = 0.15        # slab depth along x [m]
    center_y: float = 0.0
    texture: str = "brick"
    seed: int = 0
    texture_scale: float = 1.0     # >1 makes texture features larger


@dataclass(frozen=True)
class OpeningSpec:
    shape: str = "rect"                       # rect | ellipse | polygon
    center: tuple[float, float] = (0.0, -1.5)  # (y, z) of the centre (rect, ellipse)
    size: tuple[float, float] = (0.9, 0.9)     # (width along y, height along z) (rect, ellipse)
    vertices: tuple[tuple[float, float], ...] = ()  # (y, z) vertices (polygon)
    frame_width: float = 0.0                  # thin frame band around the opening on the wall face [m]
    frame_depth: float = 0.03                 # how far the frame stands proud of the wall [m]

    def polygon(self) -> list[tuple[float, float]]:
        """Outline as (y, z) vertices, counter-clockwise in the (y, z) plane."""
        if self.shape == "rect":
            (cy, cz), (w, h) = self.center, self.size
            pts = [(cy - w / 2, cz - h / 2), (cy + w / 2, cz - h / 2), (cy + w / 2, cz + h / 2),
                   (cy - w / 2, cz + h / 2)]
        elif self.shape == "ellipse":
            (cy, cz), (w, h) = self.center, self.size
            pts = [(cy + w / 2 * math.cos(a), cz + h / 2 * math.sin(a))
                   for a in (2 * math.pi * k / ELLIPSE_SEGMENTS for k in range(ELLIPSE_SEGMENTS))]
        elif self.shape == "polygon":
            pts = [(float(y), float(z)) for y, z in self.vertices]
        else:
            raise SpecError(f"unknown opening shape {self.shape!r}; use one of {SHAPES}")
        area2 = sum(pts[i][0] * pts[(i + 1) % len(pts)][1] - pts[(i + 1) % len(pts)][0] * pts[i][1]
                    for i in range(len(pts)))
        return pts if area2 > 0 else pts[::-1]


@dataclass(frozen=True)
class BackgroundSpec:
    gap: float = 2.0               # distance behind the wall's back face [m]
    width: float = 8.0
    height: float = 5.0
    texture: str = ""              # "" = same family as the wall
    seed: int = 1
    texture_scale: float = 1.0


@dataclass(frozen=True)
class FloorSpec:
    enabled: bool = True
    x_min: float = -1.0
    seed: int = 2
    color: tuple[float, float, float] = (0.42, 0.40, 0.37)


@dataclass(frozen=True)
class JitterSpec:
    exposure: float = 1.0                          # multiplies all colours
    tint: tuple[float, float, float] = (1.0, 1.0, 1.0)


@dataclass(frozen=True)
class SplatDensity:
    wall_spacing: float = 0.013        # grid spacing of wall Gaussians [m]
    background_spacing: float = 0.025
    floor_spacing: float = 0.03
    sigma_factor: float = 0.7          # in-plane sigma = factor * spacing
    opacity: float = 0.95


@dataclass(frozen=True)
class SceneSpec:
    name: str = "custom"
    wall: WallSpec = field(default_factory=WallSpec)
    openings: tuple[OpeningSpec, ...] = (OpeningSpec(),)
    background: BackgroundSpec = field(default_factory=BackgroundSpec)
    floor: FloorSpec = field(default_factory=FloorSpec)
    jitter: JitterSpec = field(default_factory=JitterSpec)
    density: SplatDensity = field(default_factory=SplatDensity)
    # the heading the vehicle starts on, degrees clockwise from north (+x): a wall turned against it by this
    # much (the hard world's turned walls); 0 faces the wall squarely
    start_yaw_deg: float = 0.0
    version: int = SPEC_VERSION

    # --- derived geometry -------------------------------------------------------------------------
    @property
    def start_ned(self) -> tuple[float, float, float]:
        """Where the vehicle starts, on the ground (a capture scene says; procedural scenes start at the origin)."""
        return (0.0, 0.0, 0.0)

    @property
    def wall_x(self) -> float:
        return self.wall.distance

    @property
    def wall_back_x(self) -> float:
        return self.wall.distance + self.wall.thickness

    @property
    def background_x(self) -> float:
        return self.wall_back_x + self.background.gap

    @property
    def background_rect(self) -> tuple[float, float, float, float]:
        """(y_lo, y_hi, z_lo, z_hi) of the background surface: centred on the wall, standing on the floor."""
        half = self.background.width / 2
        return self.wall.center_y - half, self.wall.center_y + half, -self.background.height, 0.0

    @property
    def background_texture(self) -> str:
        return self.background.texture or self.wall.texture

    def validate(self) -> SceneSpec:
        if self.version != SPEC_VERSION:
            raise SpecError(f"scene spec version {self.version} is not supported; re-save it as version "
                            f"{SPEC_VERSION}")
        for tex in (self.wall.texture, self.background_texture):
            if tex not in ALL_TEXTURES:
                raise SpecError(f"unknown texture {tex!r}; use one of {ALL_TEXTURES}")
        if self.wall.thickness <= 0 or self.wall.width <= 0 or self.wall.height <= 0:
            raise SpecError("wall width, height and thickness must be positive; fix the 'wall' block")
        if not (math.isfinite(self.start_yaw_deg) and abs(self.start_yaw_deg) < 90):
            raise SpecError(f"start_yaw_deg {self.start_yaw_deg} must be within ±90° (the wall must face the start); "
                            "fix 'start_yaw_deg'")
        y_lo, y_hi = self.wall.center_y - self.wall.width / 2, self.wall.center_y + self.wall.width / 2
        for i, op in enumerate(self.openings):
            poly = op.polygon()
            if len(poly) < 3:
                raise SpecError(f"opening {i} has fewer than 3 vertices; fix 'openings'")
            if op.frame_width < 0 or op.frame_depth < 0:
                raise SpecError(f"opening {i} has a negative frame width or depth; fix 'openings'")
            ys, zs = [p[0] for p in poly], [p[1] for p in poly]
            if min(ys) < y_lo or max(ys) > y_hi or min(zs) < -self.wall.height or max(zs) > 0:
                raise SpecError(f"opening {i} extends beyond the wall (y {min(ys):.2f}..{max(ys):.2f}, z "
                                f"{min(zs):.2f}..{max(zs):.2f}); move or shrink it")
        return self

    # --- JSON -------------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def to_json(self, indent: int | None = 2) -> str:
        return json.dumps(self.to_dict(), indent=indent, sort_keys=True)

    @classmethod
    def from_dict(cls, d: dict) -> SceneSpec:
        try:
            d = dict(d)
            openings = tuple(
                OpeningSpec(**{**o, "center": tuple(o.get("center", (0.0, -1.5))),
                               "size": tuple(o.get("size", (0.9, 0.9))),
                               "vertices": tuple(tuple(v) for v in o.get("vertices", ()))})
                for o in d.pop("openings", [dataclasses.asdict(OpeningSpec())]))
            floor = dict(d.pop("floor", {}))
            if "color" in floor:
                floor["color"] = tuple(floor["color"])
            jitter = dict(d.pop("jitter", {}))
            if "tint" in jitter:
                jitter["tint"] = tuple(jitter["tint"])
            spec = cls(wall=WallSpec(**d.pop("wall", {})), openings=openings,
                       background=BackgroundSpec(**d.pop("background", {})), floor=FloorSpec(**floor),
                       jitter=JitterSpec(**jitter), density=SplatDensity(**d.pop("density", {})), **d)
        except TypeError as exc:
            raise SpecError(f"scene spec has an unknown or misspelt field ({exc}); compare with "
                            f"SceneSpec().to_json()") from None
        return spec.validate()

    @classmethod
    def from_json(cls, text: str) -> SceneSpec:
        try:
            d = json.loads(text)
        except json.JSONDecodeError as exc:
            raise SpecError(f"scene spec is not valid JSON ({exc}); fix the file") from None
        if not isinstance(d, dict):
            raise SpecError("scene spec JSON must be an object; fix the file")
        return cls.from_dict(d)

    @classmethod
    def load(cls, path: str | Path) -> SceneSpec:
        p = Path(path)
        try:
            text = p.read_text()
        except OSError as exc:
            raise SpecError(f"cannot read scene spec {p} ({exc.strerror}); check the path") from None
        return cls.from_json(text)

    def save(self, path: str | Path) -> None:
        Path(path).write_text(self.to_json() + "\n")

import dataclasses

import numpy as np
import pytest

from scenes.build import resolve_spec
from scenes.collision import SceneCollision
from scenes.library import DEFAULT_SCENE, SUITE, random_scene, suite_spec
from scenes.spec import SceneSpec, SpecError


def test_suite_names():
    assert len(SUITE) == 16 and len(set(SUITE)) == 16
    assert DEFAULT_SCENE in SUITE
    assert {n.split("_")[1] for n in SUITE} == {"brick", "granite", "newspaper", "stone"}


def test_json_round_trip(tmp_path):
    for name in ("window1_brick", "window4_stone"):
        spec = resolve_spec(name)
        again = SceneSpec.from_json(spec.to_json())
        assert again == spec
        spec.save(tmp_path / "s.json")
        assert resolve_spec(str(tmp_path / "s.json")) == spec


def test_bad_specs_raise_one_line_errors():
    with pytest.raises(SpecError, match="unknown or misspelt"):
        SceneSpec.from_json('{"wal": {}}')
    with pytest.raises(SpecError, match="not valid JSON"):
        SceneSpec.from_json("{")
    with pytest.raises(SpecError, match="unknown texture"):
        SceneSpec.from_json('{"wall": {"texture": "marble"}}')
    with pytest.raises(SpecError, match="unknown scene"):
        resolve_spec("window9_brick")
    with pytest.raises(SpecError, match="beyond the wall"):
        SceneSpec.from_json('{"openings": [{"shape": "rect", "center": [0, -3.9], "size": [1, 1]}]}')


def best_clearance_in_opening(spec, n: int) -> float:
    """Largest collision clearance over an n×n grid spanning the opening's bounding box, mid-wall."""
    col = SceneCollision(spec)
    poly = np.array(spec.openings[0].polygon())
    ys, zs = np.meshgrid(np.linspace(poly[:, 0].min(), poly[:, 0].max(), n),
                         np.linspace(poly[:, 1].min(), poly[:, 1].max(), n))
    x_mid = spec.wall_x + spec.wall.thickness / 2
    return max(col.clearance((x_mid, y, z)) for y, z in zip(ys.ravel(), zs.ravel(), strict=True))


@pytest.mark.parametrize("name", SUITE)
def test_suite_openings_fit_the_vehicle(name):
    """Every suite opening has a point 0.3 m or more from its edges, near z = -1.5 (0.35 m drone + margin)."""
    spec = resolve_spec(name)
    poly = np.array(spec.openings[0].polygon())
    assert best_clearance_in_opening(spec, 40) > 0.3
    assert -1.8 < poly[:, 1].mean() < -1.2


def test_random_scene_is_deterministic():
    a = random_scene(np.random.default_rng(5))
    b = random_scene(np.random.default_rng(5))
    c = random_scene(np.random.default_rng(6))
    assert a == b and a != c
    assert SceneSpec.from_json(a.to_json()) == a


def test_random_scene_texture_families():
    """The suite's four families by default; training scenes also draw the extra ones, which specs accept."""
    from scenes.spec import ALL_TEXTURES, EXTRA_TEXTURES, TEXTURES

    default = {random_scene(np.random.default_rng(s)).wall.texture for s in range(60)}
    assert default == set(TEXTURES)
    specs = [random_scene(np.random.default_rng(s), ALL_TEXTURES) for s in range(60)]
    assert {s.wall.texture for s in specs} == set(ALL_TEXTURES)
    extra = next(s for s in specs if s.wall.texture in EXTRA_TEXTURES)
    assert SceneSpec.from_json(extra.to_json()).validate() == extra
    with pytest.raises(SpecError, match="unknown texture 'marble'"):
        dataclasses.replace(extra, wall=dataclasses.replace(extra.wall, texture="marble")).validate()


def test_background_scale_matches_apparent_size():
    spec = suite_spec("window1", "stone")
    assert spec.background_texture == "stone"
    assert spec.background.texture_scale == pytest.approx(spec.background_x / spec.wall_x)
    assert dataclasses.replace(spec, version=99) != spec
    with pytest.raises(SpecError, match="version"):
        dataclasses.replace(spec, version=99).validate()


def test_random_openings_fit_the_vehicle():
    rng = np.random.default_rng(11)
    for _ in range(20):
        assert best_clearance_in_opening(random_scene(rng), 25) > 0.25

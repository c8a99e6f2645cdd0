import dataclasses

import pytest

from scenes.collision import load_collision
from scenes.library import suite_spec
from scenes.spec import OpeningSpec


def test_window1_clearances():
    c = load_collision("window1_brick")  # 0.9 x 0.9 opening centred at (0, -1.5); slab 3.0..3.15
    assert c.wall_x == 3.0
    assert c.clearance((0.0, 0.0, -1.5)) == pytest.approx(((3.0) ** 2 + 0.45**2) ** 0.5, rel=1e-9)
    assert c.clearance((2.0, 1.5, -1.5)) == pytest.approx(1.0)           # in front of solid wall
    assert c.clearance((3.07, 0.0, -1.5)) == pytest.approx(0.45)         # centre of the opening
    assert c.clearance((3.07, 0.3, -1.4)) == pytest.approx(0.15)         # inside, near the right edge
    assert c.clearance((3.05, 1.5, -1.5)) == pytest.approx(-0.05)        # inside the slab
    assert c.clearance((3.1, 0.6, -1.5)) == pytest.approx(-0.05)         # slab beside the opening
    assert c.clearance((4.15, 1.5, -1.5)) == pytest.approx(1.0)          # behind the wall
    assert c.background_x == 5.15                                         # background 2 m behind the back face
    assert c.clearance((4.65, 0.0, -1.5)) == pytest.approx(0.5)          # through the opening, before it
    assert c.clearance((5.25, 0.0, -1.5)) == pytest.approx(-0.1)         # behind the background surface
    assert c.clearance((5.25, 3.5 + 0.3, -1.5)) == pytest.approx(0.3)    # beside its edge (7 m wide)
    assert c.clearance((2.0, 1.5, -0.01)) == pytest.approx(1.0)          # the floor is not a solid here


def test_polygon_and_ellipse():
    c = load_collision("window3_stone")  # ellipse 1.0 x 0.9 centred at (-0.55, -1.45)
    assert c.clearance((3.07, -0.55, -1.45)) == pytest.approx(0.45, abs=2e-3)
    assert c.clearance((3.07, -0.55 + 0.45, -1.45)) == pytest.approx(0.05, abs=2e-3)
    p = load_collision("window4_granite")
    assert p.clearance((3.07, 0.3, -1.5)) > 0.3
    assert p.clearance((3.07, 1.2, -1.5)) < 0


def test_frame_is_solid():
    spec = suite_spec("window1", "brick")
    spec = dataclasses.replace(spec, openings=(OpeningSpec("rect", (0.0, -1.5), (0.9, 0.9), frame_width=0.05,
                                                           frame_depth=0.04),))
    from scenes.collision import SceneCollision

    c = SceneCollision(spec)
    assert c.clearance((2.98, 0.475, -1.5)) < 0            # inside the frame band, proud of the wall
    assert c.clearance((2.9, 0.475, -1.5)) == pytest.approx(0.06)
    assert c.clearance((2.98, 0.2, -1.5)) == pytest.approx(0.25)

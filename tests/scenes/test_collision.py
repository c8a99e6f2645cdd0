import dataclasses
import math

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


# --- the 2-D signed-distance pieces, hand-worked -------------------------------------------------------------

def test_box_distance_outside_along_an_edge_at_a_corner_and_inside():
    from scenes.collision import _box_distance

    box = (1.0, 3.0, -2.0, 0.0)                                  # y in [1, 3], z in [-2, 0]
    assert _box_distance(3.5, -1.0, *box) == pytest.approx(0.5)           # right of it
    assert _box_distance(2.0, 0.25, *box) == pytest.approx(0.25)          # below it (z down)
    assert _box_distance(-2.0, -6.0, *box) == pytest.approx(5.0)          # 3-4-5 from the corner (1, -2)
    assert _box_distance(4.0, 1.0, *box) == pytest.approx(math.sqrt(2))   # from the corner (3, 0)
    assert _box_distance(1.25, -1.0, *box) == pytest.approx(-0.25)        # inside: minus the nearest edge
    assert _box_distance(2.0, -0.1, *box) == pytest.approx(-0.1)
    assert _box_distance(2.0, -1.0, *box) == pytest.approx(-1.0)          # centre: 1 from every edge


def test_extrude_combines_the_section_and_the_depth():
    from scenes.collision import _extrude

    assert _extrude(-0.3, -0.1) == pytest.approx(-0.1)      # inside both: the nearer face
    assert _extrude(-0.1, -0.3) == pytest.approx(-0.1)
    assert _extrude(0.3, -0.5) == pytest.approx(0.3)        # beside the slab, within its depth
    assert _extrude(-0.5, 0.4) == pytest.approx(0.4)        # in front of the section
    assert _extrude(0.3, 0.4) == pytest.approx(0.5)         # off an edge of the slab: 3-4-5
    assert _extrude(0.0, 0.0) == 0.0


def test_polygon_signed_distance_and_bounding_box():
    from scenes.collision import _Polygon

    tri = _Polygon([(0.0, 0.0), (4.0, 0.0), (0.0, 3.0)])         # right triangle, hypotenuse 5
    assert (tri.y_lo, tri.y_hi, tri.z_lo, tri.z_hi) == (0.0, 4.0, 0.0, 3.0)
    assert tri.signed_distance(2.0, -1.0) == pytest.approx(1.0)           # below the y edge
    assert tri.signed_distance(-2.0, 1.0) == pytest.approx(2.0)           # left of the z edge
    assert tri.signed_distance(7.0, -4.0) == pytest.approx(5.0)           # from the vertex (4, 0)
    assert tri.signed_distance(4.0, 3.0) == pytest.approx(12 / 5)          # from the hypotenuse 3y + 4z = 12
    assert tri.signed_distance(1.0, 1.0) == pytest.approx(-1.0)           # inside: nearest legs at 1
    assert tri.signed_distance(0.5, 2.0) == pytest.approx(-(12 - 1.5 - 8) / 5)   # nearer the hypotenuse
    assert tri.bbox_distance(2.0, 1.0) == 0.0
    assert tri.bbox_distance(7.0, 7.0) == pytest.approx(5.0)
    assert tri.bbox_distance(-1.0, -2.0) == pytest.approx(math.sqrt(5))
    assert tri.bbox_distance(2.0, -0.5) == pytest.approx(0.5) and tri.bbox_distance(-0.5, 2.0) == pytest.approx(0.5)
    # a repeated vertex (a zero-length edge) changes nothing
    sq = _Polygon([(0.0, 0.0), (2.0, 0.0), (2.0, 0.0), (2.0, 2.0), (0.0, 2.0)])
    assert sq.signed_distance(1.0, 0.5) == pytest.approx(-0.5) and sq.signed_distance(3.0, 1.0) == pytest.approx(1.0)


def test_more_hand_worked_2d_cases():
    from scenes.collision import _box_distance, _Polygon

    # a box away from z = 0 (the wall's own rectangle always ends at z = 0)
    assert _box_distance(0.0, -4.0, -1.0, 1.0, -3.0, -1.5) == pytest.approx(1.0)
    assert _box_distance(0.0, -2.0, -1.0, 1.0, -3.0, -1.5) == pytest.approx(-0.5)
    tri = _Polygon([(1.0, -2.0), (5.0, -2.0), (1.0, 1.0)])       # the right triangle moved to (1, −2)
    assert (tri.y_lo, tri.y_hi, tri.z_lo, tri.z_hi) == (1.0, 5.0, -2.0, 1.0)
    # outside, beside the hypotenuse (3y + 4z = 7 here): 0.2 from it, not inside
    assert tri.signed_distance(4.0, -1.0) == pytest.approx((3 * 4.0 + 4 * -1.0 - 7) / 5)
    assert tri.signed_distance(2.0, -1.0) == pytest.approx(-1.0)


def _two_windows():
    from scenes.collision import SceneCollision

    spec = suite_spec("window1", "brick")               # wall 7 x 4 m, front face x = 3, 0.15 thick
    ops = (OpeningSpec("rect", (-1.0, -1.5), (0.6, 0.6), frame_width=0.05, frame_depth=0.04),
           OpeningSpec("rect", (1.0, -1.5), (0.6, 0.6), frame_width=0.05, frame_depth=0.04))
    return SceneCollision(dataclasses.replace(spec, openings=ops))


def test_with_two_openings_each_is_judged_on_its_own():
    c = _two_windows()
    assert "window1" in repr(c)
    # in the slab 2 cm right of the first opening (right edge y = −0.7), the second 1.25 m away
    assert c.clearance((3.075, -0.68, -1.5)) == pytest.approx(-0.02)
    # in front of the second opening's frame (outer edge y = 1.35): 2 cm in front of its front face at x = 2.96
    assert c.clearance((2.94, 1.33, -1.5)) == pytest.approx(0.02)
    # the wall's own edges: beside its right end (y = 3.5) and below its bottom (z = −4... floor side z = 0)
    assert c.clearance((3.075, 3.8, -1.5)) == pytest.approx(0.3)
    assert c.clearance((3.075, -3.9, -1.5)) == pytest.approx(0.4)
    assert c.clearance((3.075, 0.0, -4.25)) == pytest.approx(0.25)
    assert c.clearance((3.075, 0.0, 0.2)) == pytest.approx(0.2)

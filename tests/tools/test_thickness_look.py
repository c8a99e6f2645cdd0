"""tools.thickness_look and companion.opening_geometry.thickness_from_sidestep: the wall's thickness from a step
sideways square to it, the opening (bounded by its far edges) shifting as a thing t further away than the face
(the flown look's own reading: tests/companion/test_thickness.py)."""

from __future__ import annotations

import json

import pytest

from companion.opening_geometry import thickness_from_sidestep
from tools import thickness_look

FOCAL = 156.387


@pytest.mark.parametrize("distance, thickness, step", [(1.2, 0.15, 0.3), (1.0, 0.10, 0.2), (1.6, 0.25, -0.3)])
def test_the_thickness_follows_from_the_two_shifts_a_pinhole_gives(distance, thickness, step):
    wall = -FOCAL * step / distance                   # a step right: what is ahead moves left
    aperture = -FOCAL * step / (distance + thickness)
    assert thickness_from_sidestep(aperture, wall, distance) == pytest.approx(thickness)


def test_shifts_no_depth_explains_give_no_thickness():
    assert thickness_from_sidestep(3.0, -30.0, 1.2) is None          # opposite ways
    assert thickness_from_sidestep(-31.0, -30.0, 1.2) is None        # the opening nearer than the face
    assert thickness_from_sidestep(0.0, -30.0, 1.2) is None
    assert thickness_from_sidestep(-30.0, -30.0, 1.2) == 0.0


def test_a_run_reads_the_thickness_with_the_rendered_truth(tmp_path):
    """One scene end to end: with the rendered truth's masks the geometry reads the wall's thickness to about a
    centimetre (2026-12-07, RAFT: 0.011 m spread over 38 scenes of seed 7000)."""
    assert thickness_look.main(["--scenes", "1", "--seed", "7000", "-o", str(tmp_path)]) == 0
    out = json.loads((tmp_path / "thickness_look.json").read_text())
    assert (tmp_path / "thickness_look.md").is_file() and out["summary"]["scenes"] == 1
    row = out["rows"][0]
    assert row["truth_thickness_m"] == pytest.approx(row["thickness_m"], abs=0.02)


def test_bad_arguments_are_refused_in_one_line(capsys):
    assert thickness_look.main(["--step", "0.6"]) == 2
    assert "--step" in capsys.readouterr().err
    assert thickness_look.main(["--flow", "nosuchflow"]) == 2
    assert capsys.readouterr().err.startswith("thickness_look: ")

"""Random worlds: the standard world's draws as they always were, the hard world's ranges, and ground-truth
passability of an opening for a body flying along a heading."""

from __future__ import annotations

import hashlib
import json
import math

import numpy as np
import pytest

from scenes.groundtruth import corridor_clearance, passable_openings
from scenes.library import HARD_OPENING_SIZE, random_scene, suite_spec
from scenes.spec import OpeningSpec, SceneSpec

# sha256 (first 16 hex) of random_scene(default_rng([7, 0xF1, k])).to_dict(), sorted JSON, written by the
# generator before the hard world existed (commit 411c6e5): the standard world must draw exactly these
STANDARD_DIGESTS = ["7db62158f960155c", "a165ba6a269f43fa", "86e333878aec0c68", "7429c488faf89ec8",
                    "c371d7075541a3f4", "e6eabdd471497734"]


def test_the_standard_world_draws_what_it_always_drew():
    for k, digest in enumerate(STANDARD_DIGESTS):
        d = random_scene(np.random.default_rng([7, 0xF1, k])).to_dict()
        assert d.pop("start_yaw_deg") == 0.0                      # the one new field, at its neutral value
        assert hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:16] == digest
        assert random_scene(np.random.default_rng([7, 0xF1, k]), world="standard").to_dict() == \
            random_scene(np.random.default_rng([7, 0xF1, k])).to_dict()


def test_hard_world_scenes_span_the_stated_ranges_and_are_seeded():
    specs = [random_scene(np.random.default_rng([3, k]), world="hard") for k in range(60)]
    assert random_scene(np.random.default_rng([3, 5]), world="hard") == specs[5]
    counts = {len(s.openings) for s in specs}
    assert counts == {1, 2, 3}
    yaws = [s.start_yaw_deg for s in specs]
    assert max(abs(y) for y in yaws) <= 20.0 and min(yaws) < -10 and max(yaws) > 10
    gaps = [s.background.gap for s in specs]
    assert 0.6 <= min(gaps) and max(gaps) <= 4.0 and min(gaps) < 1.0
    lo, hi = HARD_OPENING_SIZE
    for s in specs:
        s.validate()
        boxes = []
        for op in s.openings:
            ys, zs = zip(*op.polygon(), strict=True)
            assert lo * 0.84 <= max(ys) - min(ys) <= hi and lo * 0.84 <= max(zs) - min(zs) <= hi
            assert max(zs) <= -0.3                                # off the floor
            boxes.append((min(ys), max(ys), min(zs), max(zs)))
        for i, a in enumerate(boxes):                             # never overlapping: wall between them
            for b in boxes[i + 1:]:
                assert a[1] + 0.39 <= b[0] or b[1] + 0.39 <= a[0] or a[3] + 0.39 <= b[2] or b[3] + 0.39 <= a[2]
    passable = [any(passable_openings(s, 0.19, 0.05)) for s in specs]
    assert 0.1 < 1 - np.mean(passable) < 0.6                      # some scenes have no opening to pass
    with pytest.raises(ValueError, match="unknown world"):
        random_scene(np.random.default_rng(0), world="moon")


def test_corridor_clearance_is_the_inscribed_circle_narrowed_by_the_slant_through_the_wall():
    square = suite_spec("window1", "brick")                      # 0.9 m square, wall 0.15 m
    assert corridor_clearance(square, 0) == pytest.approx(0.45, abs=0.0015)
    for deg in (10.0, 20.0):
        slant = 0.15 * math.tan(math.radians(deg))               # the far edge seen shifted by t·tan(ψ)
        assert corridor_clearance(square, 0, math.radians(deg)) == pytest.approx(0.45 - slant / 2, abs=0.0015)
    assert corridor_clearance(square, 0, math.radians(20)) == corridor_clearance(square, 0, math.radians(-20))
    slot = SceneSpec(openings=(OpeningSpec("rect", center=(0.0, -1.5), size=(0.45, 1.2)),))
    assert corridor_clearance(slot, 0) == pytest.approx(0.225, abs=0.0015)
    assert passable_openings(slot, 0.19, 0.05) == [False] and passable_openings(square, 0.19, 0.05) == [True]
    turned = SceneSpec(openings=(OpeningSpec("rect", center=(0.0, -1.5), size=(0.52, 0.52)),), start_yaw_deg=20.0)
    assert passable_openings(turned, 0.19, 0.05, heading_rad=None) == [False]   # not along the start heading (0.233)
    assert passable_openings(turned, 0.19, 0.05) == [True]       # square to the wall, the default: 0.26


def test_a_scene_with_a_start_heading_round_trips_and_a_sideways_one_is_refused():
    spec = SceneSpec(start_yaw_deg=-12.5)
    assert SceneSpec.from_json(spec.to_json()).start_yaw_deg == -12.5
    from scenes.spec import SpecError

    with pytest.raises(SpecError, match="start_yaw_deg"):
        SceneSpec.from_json(SceneSpec(start_yaw_deg=95.0).to_json())

"""The flight evaluation's start draws and its summary arithmetic."""

from __future__ import annotations

import numpy as np

from tools.eval_flights import draw_starts, markdown, summarise


def test_starts_are_within_the_specified_ranges_and_seeded():
    starts = draw_starts(np.random.default_rng(4), 200, wall_x=3.0, altitude=1.5)
    assert starts == draw_starts(np.random.default_rng(4), 200, wall_x=3.0, altitude=1.5)
    xs = [s[0][0] for s in starts]
    ys = [s[0][1] for s in starts]
    alts = [a for _, a in starts]
    assert min(xs) >= -1.0 and max(xs) <= 1.0  # 2–4 m before a wall at x = 3
    assert max(abs(y) for y in ys) <= 0.5 and all(1.0 <= a <= 2.0 for a in alts)
    assert all(s[0][2] == 0.0 for s in starts)  # on the ground


def test_summary_counts_and_never_counts_a_touch_as_success():
    rows = [
        {"scene": "a", "success": True, "collision": False, "servo_steps": 10, "sim_time_s": 20, "wall_time_s": 9},
        {"scene": "a", "success": False, "collision": True, "servo_steps": 7, "sim_time_s": 15, "wall_time_s": 8},
        {"scene": "b", "success": False, "collision": False, "servo_steps": None, "sim_time_s": None,
         "wall_time_s": 3},
    ]
    s = summarise(rows)
    assert (s["flights"], s["success"], s["collisions"], s["touching_counted_as_success"]) == (3, 1, 1, 0)
    assert abs(s["success_rate"] - 1 / 3) < 1e-3
    table = markdown(rows, s)
    assert "| a | 2 | yes | 1 | 0 | 1 |" in table and "**1 (33 %, 95 % CI 6–79 %)**" in table


def test_random_scene_files_are_seeded_valid_specs(tmp_path):
    from scenes.build import resolve_spec
    from scenes.spec import TEXTURES
    from tools.eval_flights import random_scene_files

    paths = random_scene_files(5, 3, tmp_path / "a")
    again = random_scene_files(5, 3, tmp_path / "b")
    other = random_scene_files(5, 4, tmp_path / "c")
    assert [p.rsplit("/", 1)[1] for p in paths] == [p.rsplit("/", 1)[1] for p in again]
    assert {p.rsplit("/", 1)[1] for p in paths}.isdisjoint(p.rsplit("/", 1)[1] for p in other)
    specs = [resolve_spec(p) for p in paths]
    assert len({s.name for s in specs}) == 5 and all(s.wall.texture in TEXTURES for s in specs)


def test_bad_arguments_are_one_line_errors(tmp_path, capsys):
    from tools.eval_flights import main

    assert main(["--random", "-1", "--out", str(tmp_path)]) == 2
    assert main(["no_such_scene", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(line.startswith("flowgap-eval-flights: error:") for line in err)


def test_two_sweeps_on_one_machine_never_share_an_instance():
    import socket

    from tools.eval_flights import InstancePool

    first, second = InstancePool(), InstancePool()       # as two flowgap-eval-flights processes would hold them
    a = [first.acquire() for _ in range(2)]
    busy = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    busy.bind(("0.0.0.0", 14540 + max(a) + 1))             # a port of the next instance taken by something else
    try:
        b = [second.acquire() for _ in range(2)]
        assert not set(a) & set(b) and max(a) + 1 not in b
    finally:
        busy.close()
    first.release(a[0])
    assert second.acquire() == a[0]                        # released, it is free again

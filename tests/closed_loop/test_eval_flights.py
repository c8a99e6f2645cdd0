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
    # --scenes, as flowgap-eval-masks takes them, names scenes too
    assert main(["--scenes", "no_such_scene", "--out", str(tmp_path)]) == 2
    assert "no_such_scene" in capsys.readouterr().err


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


def test_the_summary_says_where_the_flights_flew_and_how_many_were_reused(tmp_path):
    from tools.eval_flights import summary_line

    rows = [{"scene": "a", "success": True, "collision": False, "servo_steps": 10, "sim_time_s": 20,
             "wall_time_s": 9, "node": n} for n in ("n1", "n2", "n1")]
    s = summarise(rows)
    s.update(executor="ray", flown=2, reused=1, nodes=["n1", "n2"])
    assert "Executor ray, rows from 2 node(s); 2 flights flown in this run, 1 reused" in markdown(rows, s)
    line = summary_line(s, tmp_path)
    assert line.startswith("success 3/3 (95 % CI 44–100 %)") and "2 flown on ray, 1 reused" in line


def test_a_capture_is_flown_from_its_own_start_and_judged_by_its_gate():
    import math
    from pathlib import Path

    from scenes.capture import CaptureSpec, Gate, Placement
    from tools.eval_flights import draw_flight, judge

    capture = CaptureSpec(name="room", path=Path("room.capture.json"), ply=Path("room.ply"), to_ned=Placement(),
                          gate=Gate((7.0, -2.0, -1.3), (1.0, 0.0, 0.0), (0.8, 0.8), (4.0, -2.0, -1.3)),
                          start_ned=(4.0, -2.0, 0.0), start_yaw_deg=90.0, altitude_m=1.3)
    flights = [draw_flight(capture, 3, i, "standard") for i in range(20)]
    assert flights[0] == draw_flight(capture, 3, 0, "standard")                 # (seed, scene, start) only
    for f in flights:
        x, y, z = f["start"]
        # facing east (90 deg): "across the heading" is north-south, so only x moves, by at most 0.5 m
        assert abs(y + 2.0) < 1e-9 and abs(x - 4.0) <= 0.5 and z == 0.0
        assert abs(f["altitude"] - 1.3) <= 0.1 + 1e-9 and f["wind"] is None
    assert len({f["start"] for f in flights}) > 10 and math.isfinite(flights[0]["seed"])
    beside = {"crossed_wall": True, "collision": False, "gate": {"crossed": False}}
    through = {"crossed_wall": True, "collision": False, "gate": {"crossed": True}}
    assert not judge(beside, True)["success"] and judge(through, True)["success"]


def test_a_sweep_without_the_thickness_look_resumes_only_such_a_sweep():
    """``--no-thickness-look`` is part of what a resumed flight must share; a sweep flown with the look (whose saved
    settings predate the option) resumes as it did."""
    from tools.eval_flights import _parser, sweep_settings

    with_look = sweep_settings(_parser().parse_args(["--world", "hard"]), None)
    without = sweep_settings(_parser().parse_args(["--world", "hard", "--no-thickness-look"]), None)
    assert "thickness_look" not in with_look and without == {**with_look, "thickness_look": False}

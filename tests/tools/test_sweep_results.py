"""A sweep's result files and resumption, with an executor that flies nothing; and the one-line errors of
``--ray``/``--resume``. (The same on real flights and a local Ray: test_ray_sweeps.py.)"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import pytest

from tools.sweep_results import (
    ResumeError,
    SweepInterrupted,
    load_results,
    record_run,
    recorded_runs,
    run_sweep,
)

SETTINGS = {"world": "standard", "seed": 0, "flow": "dis:fine", "link_faults": None}


@dataclass(frozen=True)
class Job:
    key: str


class FakeFlights:
    """Flies every job at once; raises KeyboardInterrupt (a Ctrl-C) after ``stop_after`` of them."""

    def __init__(self, stop_after: int | None = None, interrupted: frozenset = frozenset()) -> None:
        self.stop_after, self.interrupted, self.flown = stop_after, interrupted, []

    def run(self, jobs):
        for job in jobs:
            if self.stop_after is not None and len(self.flown) == self.stop_after:
                raise KeyboardInterrupt
            self.flown.append(job.key)
            yield job, ({"error": "interrupted (Ctrl-C): both processes were stopped"} if job.key in self.interrupted
                        else {"success": True})


def make_row(job, verdict) -> dict:
    return {"key": job.key, **verdict}


JOBS = [Job(f"scene-{i}") for i in range(5)]


def test_a_stopped_sweep_resumed_flies_only_what_is_missing(tmp_path):
    first = FakeFlights(stop_after=2)
    with pytest.raises(SweepInterrupted) as stop:
        run_sweep(JOBS, first, make_row, tmp_path, SETTINGS, progress=False)
    assert (stop.value.saved, stop.value.missing) == (2, 3) and "--resume" in str(stop.value)
    assert sorted(p.name for p in (tmp_path / "results").glob("*")) == ["scene-0.json", "scene-1.json"]
    second = FakeFlights()
    outcome = run_sweep(JOBS, second, make_row, tmp_path, SETTINGS, resume=True, progress=False)
    assert second.flown == ["scene-2", "scene-3", "scene-4"]
    assert (outcome.reused, outcome.flown) == (2, 3)
    assert [r["key"] for r in outcome.rows] == [j.key for j in JOBS]            # in the jobs' order
    again = FakeFlights()
    assert run_sweep(JOBS, again, make_row, tmp_path, SETTINGS, resume=True, progress=False).reused == 5
    assert again.flown == []


def test_each_run_of_a_sweep_is_recorded_and_a_new_sweep_starts_the_record_again(tmp_path, caplog):
    record_run(tmp_path, 12.34, 2, "interrupted")
    record_run(tmp_path, 30.0, 3, "complete")
    assert recorded_runs(tmp_path) == [{"wall_s": 12.3, "flown": 2, "ended": "interrupted"},
                                       {"wall_s": 30.0, "flown": 3, "ended": "complete"}]
    with (tmp_path / "sweep_runs.jsonl").open("a") as f:
        f.write("{not json\n")
    assert len(recorded_runs(tmp_path)) == 2 and "line 3 is not a run record" in caplog.text
    run_sweep(JOBS, FakeFlights(), make_row, tmp_path, SETTINGS, progress=False)     # not resumed: a new sweep
    assert recorded_runs(tmp_path) == [] and recorded_runs(tmp_path / "nowhere") == []


def test_without_resume_an_earlier_sweeps_results_are_cleared_and_flown_again(tmp_path):
    run_sweep(JOBS[:3], FakeFlights(), make_row, tmp_path, SETTINGS, progress=False)
    flights = FakeFlights()
    outcome = run_sweep(JOBS[1:2], flights, make_row, tmp_path, SETTINGS, progress=False)
    assert flights.flown == ["scene-1"] and outcome.reused == 0
    assert [p.name for p in (tmp_path / "results").glob("*.json")] == ["scene-1.json"]


def test_a_flight_stopped_by_a_ctrl_c_is_no_result(tmp_path):
    outcome = run_sweep(JOBS[:3], FakeFlights(interrupted=frozenset({"scene-1"})), make_row, tmp_path, SETTINGS,
                        progress=False)
    assert [r["key"] for r in outcome.rows] == ["scene-0", "scene-2"] and outcome.missing == ["scene-1"]
    assert not (tmp_path / "results" / "scene-1.json").exists()
    flights = FakeFlights()
    run_sweep(JOBS[:3], flights, make_row, tmp_path, SETTINGS, resume=True, progress=False)
    assert flights.flown == ["scene-1"]


def test_a_result_flown_with_other_settings_is_not_merged(tmp_path):
    run_sweep(JOBS[:2], FakeFlights(), make_row, tmp_path, SETTINGS, progress=False)
    with pytest.raises(ResumeError, match=r"scene-0\.json was flown with flow 'dis:fine', this sweep has 'raft'"):
        load_results(tmp_path, [j.key for j in JOBS], {**SETTINGS, "flow": "raft"})
    (tmp_path / "results" / "scene-1.json").write_text("{cut short")               # unreadable: missing
    assert set(load_results(tmp_path, [j.key for j in JOBS], SETTINGS)) == {"scene-0"}


def _without_ray(monkeypatch) -> None:
    """As if Ray were not installed."""
    import importlib.util

    real_find_spec = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "ray" else real_find_spec(name, *a))


def test_the_eval_flights_arguments_for_ray_and_resume_are_one_line_errors(tmp_path, capsys, monkeypatch):
    from tools.eval_flights import main

    assert main(["window1_brick", "--cpus-per-flight", "0", "--out", str(tmp_path)]) == 2
    assert main(["--ray", "window1_brick", "--out", str(tmp_path)]) == 2
    _without_ray(monkeypatch)
    assert main(["window1_brick", "--ray", "local", "--out", str(tmp_path)]) == 2
    monkeypatch.undo()
    saved = tmp_path / "results" / "window1_brick-0.json"
    saved.parent.mkdir(parents=True)
    saved.write_text(json.dumps({"sweep": {"flow": "raft"}, "row": {}}))
    assert main(["window1_brick", "--starts", "1", "--resume", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 4 and all(line.startswith("flowgap-eval-flights: error:") for line in err)
    assert "--cpus-per-flight" in err[0] and "a scene name goes before --ray" in err[1]
    assert "pip install -e '.[ray]'" in err[2]
    assert "was flown with" in err[3] and "--resume" in err[3]


def test_eval_masks_says_how_to_install_ray(tmp_path, capsys, monkeypatch):
    from tools.eval_masks import main

    _without_ray(monkeypatch)
    assert main(["--quick", "--scenes", "window1_brick", "--ray", "--out", str(tmp_path), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["flowgap-eval-masks: error: --ray needs Ray, which is not installed: pip install -e '.[ray]'"]


def test_a_ray_task_run_directory_comes_back_where_the_local_pool_writes_it(tmp_path):
    from tools.sweep_executors import pack_dir, relocate, unpack_dir

    worker = tmp_path / "worker" / "scene-0"
    (worker / "companion").mkdir(parents=True)
    (worker / "companion" / "summary.json").write_text("{}")
    here = tmp_path / "out" / "scene-0"
    unpack_dir(pack_dir(worker), here)
    assert (here / "companion" / "summary.json").read_text() == "{}"
    moved = relocate({"run_dir": str(worker), "storyboard": str(worker / "companion" / "storyboard.png"),
                      "scene": "scene"}, here)
    assert moved == {"run_dir": str(here), "storyboard": str(here / "companion" / "storyboard.png"), "scene": "scene"}


def test_scene_files_travel_by_value_and_suite_scenes_by_name(tmp_path):
    from tools.ray_sweep import materialise_scene, scene_payload

    spec = tmp_path / "driver" / "random_1.json"
    spec.parent.mkdir()
    spec.write_text('{"name": "random_1"}')
    assert scene_payload("window1_brick") == {}
    payload = scene_payload(str(spec))
    assert payload == {"random_1.json": b'{"name": "random_1"}'}
    assert materialise_scene("window1_brick", {}, tmp_path / "w") == "window1_brick"
    written = Path(materialise_scene(str(spec), payload, tmp_path / "worker"))
    assert written.parent == tmp_path / "worker" and written.read_bytes() == spec.read_bytes()


def test_a_resumed_sweep_judges_its_reused_rows_by_todays_passable_rule(tmp_path, monkeypatch):
    """A row saved by an earlier sweep keeps how it was flown, not how it was judged: a 0.50 m slot in a 0.2 m wall
    turned 16° was impassable along the start heading (0.44 m left) and is passable square to the wall, so the
    crossing its saved row records is a success now."""
    import tools.sweep_results as sweep_results
    from scenes.spec import OpeningSpec, SceneSpec, WallSpec
    from tools.eval_flights import main

    spec = SceneSpec(name="turned_slot", wall=WallSpec(thickness=0.2),
                     openings=(OpeningSpec("rect", center=(0.0, -1.5), size=(0.5, 1.0)),), start_yaw_deg=16.0)
    spec.save(tmp_path / "turned_slot.json")
    saved = {"scene": "turned_slot", "start_index": 0, "crossed_wall": True, "collision": False, "refused": False,
             "passable": False, "through": True, "success": False, "servo_steps": 12, "sim_time_s": 16.0,
             "wall_time_s": 24.0, "min_clearance_m": 0.055, "node": "vm"}

    def reused(jobs, executor, make_row, out, settings, resume=False, progress=True):
        assert resume and [job.label for job in jobs] == ["turned_slot"]
        return sweep_results.SweepOutcome([dict(saved)], 1, 0, [])

    monkeypatch.setattr(sweep_results, "run_sweep", reused)
    out = tmp_path / "out"
    assert main([str(tmp_path / "turned_slot.json"), "--starts", "1", "--resume", "--out", str(out)]) == 0
    flights = json.loads((out / "flights.json").read_text())
    assert [(r["passable"], r["success"]) for r in flights["rows"]] == [(True, True)]
    assert (flights["summary"]["passable"], flights["summary"]["success"]) == (1, 1)


def test_a_flight_flown_again_starts_from_an_empty_run_directory(tmp_path, monkeypatch):
    import tools.sweep_executors as executors
    from tools.eval_flights import InstancePool

    run_dir = tmp_path / "out" / "scene-0"
    (run_dir / "companion" / "frames").mkdir(parents=True)
    (run_dir / "companion" / "frames" / "007.png").write_bytes(b"an earlier flight's frame")
    seen = []

    def launch(scene, run_dir, *args, **kwargs):
        seen.append(sorted(p.name for p in Path(run_dir).rglob("*")))
        return {"success": True}

    monkeypatch.setattr(executors, "launch", launch)
    job = executors.FlightJob("scene", "scene", 0, {"start": (0.0, 0.0, 0.0), "seed": 1, "altitude": 1.5,
                                                    "wind": None, "camera_delay_s": 0.0})
    verdict = executors.fly(job, executors.FlightSettings(), "scene", run_dir, InstancePool())
    assert verdict["success"] and seen == [[]]

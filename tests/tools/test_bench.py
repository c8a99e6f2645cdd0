"""The benchmark runner's results file: merging re-runs, dropping keys no benchmark writes any more."""

from __future__ import annotations

import json

from tools import bench


def test_merge_keeps_other_groups_and_drops_stale_keys_of_rerun_prefixes(tmp_path):
    path = tmp_path / "results.json"
    path.write_text(json.dumps({
        "perception.old_name_ms": {"value": 1.0, "unit": "ms"},
        "perception.dis_ms": {"value": 2.0, "unit": "ms"},
        "vehicle.steps_per_s": {"value": 3.0, "unit": "steps/s"},
    }))
    merged = bench.merge_results({"perception.dis_ms": {"value": 5.0, "unit": "ms"}}, path, {"perception"})
    assert "perception.old_name_ms" not in merged                      # renamed away: dropped
    assert merged["perception.dis_ms"]["value"] == 5.0
    assert merged["vehicle.steps_per_s"]["value"] == 3.0                # a group not re-run keeps its numbers
    assert json.loads(path.read_text()) == merged
    kept = bench.merge_results({"perception.dis_ms": {"value": 6.0, "unit": "ms"}}, path)
    assert "vehicle.steps_per_s" in kept                                 # no prefix re-run: nothing dropped


def test_a_prefix_is_rerun_only_when_every_group_writing_under_it_ran():
    assert bench.key_prefix("vehicle_link") == bench.key_prefix("vehicle") == "vehicle"
    assert bench.rerun_prefixes(["perception"]) == {"perception"}
    assert bench.rerun_prefixes(["vehicle"]) == set()                   # vehicle_link writes vehicle.* too
    assert bench.rerun_prefixes(["vehicle", "vehicle_link", "tlog"]) == {"vehicle", "tlog"}
    assert bench.rerun_prefixes(bench.available_groups()) == {bench.key_prefix(g) for g in bench.available_groups()}

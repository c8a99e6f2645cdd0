"""tools.flown_masks: masks re-perceived on a flight's own frame pairs, scored against the rendered truth."""

from __future__ import annotations

import json

import pytest

from tools import flown_masks


def test_a_pair_is_sideways_when_its_motion_across_exceeds_most_of_its_motion_forward():
    assert flown_masks.is_sideways((0.0, -0.2, 0.0))
    assert flown_masks.is_sideways((0.1, 0.05, 0.02))           # 0.07 > 0.06
    assert not flown_masks.is_sideways((0.2, 0.05, 0.0))
    assert not flown_masks.is_sideways((0.1, 0.03, 0.03))        # exactly 0.6: forward


def test_summary_reports_errors_per_group_and_fill_and_skips_pairs_without_a_detection():
    def pair(sideways, radius, clearance, truth_clearance=20.0):
        return {"sideways": sideways, "fills": {
            "none": {"radius_px": radius, "truth_radius_px": 30.0, "clearance_px": clearance,
                     "truth_clearance_px": truth_clearance},
            "0.75": None}}
    rows = [pair(True, 28.0, 10.0), pair(True, 30.0, 16.0), pair(False, 29.0, 20.0, truth_clearance=0.0)]
    summary = flown_masks.summarise(rows, ["none", "0.75"])
    side = summary["sideways"]["none"]
    assert side["pairs"] == 2
    assert side["radius_err_px"]["median"] == pytest.approx(-1.0) and side["radius_err_px"]["max"] == 0.0
    assert side["clearance_err_px"]["median"] == pytest.approx(-7.0)
    # a clearance whose truth is 0 (the axis outside the opening) says nothing about the mask's edge
    assert summary["forward"]["none"]["clearance_err_px"] is None
    assert summary["all"]["none"]["pairs"] == 3
    assert summary["all"]["0.75"] == {"pairs": 0, "radius_err_px": None, "clearance_err_px": None}
    table = flown_masks.markdown(summary)
    assert "| sideways | none | 2 | -1.8 / -1.0 / -0.2 / +0.0 |" in table and "| all | 0.75 | 0 | – | – |" in table


def test_a_folder_that_is_no_flight_sweep_is_refused_in_one_line(tmp_path, capsys):
    assert flown_masks.main([str(tmp_path), "--flow", "dis:fine", "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "not a flowgap-eval-flights output" in err and "-o folder" in err


def test_a_flight_whose_frame_log_was_cut_short_is_skipped_with_a_warning_that_names_it(tmp_path, caplog):
    from scenes.library import suite_spec

    run = tmp_path / "sweep"
    (run / "scenes").mkdir(parents=True)
    suite_spec("window1", "brick").save(run / "scenes" / "window1_brick.json")
    frames = run / "window1_brick-0" / "companion"
    frames.mkdir(parents=True)
    (frames / "frames.jsonl").write_text('{"step": 0, "position_true": [1.8, 0.1, -1.5]}\n{"step": 1, "posi')
    assert flown_masks.main([str(run), "--flow", "dis:fine", "-o", str(tmp_path / "out")]) == 0
    assert "skipping window1_brick-0" in caplog.text and "frames.jsonl:2 is not valid JSON" in caplog.text
    assert json.loads((tmp_path / "out" / "flown_masks.json").read_text())["rows"] == []


def test_a_bad_fill_is_refused_by_the_parser(capsys):
    with pytest.raises(SystemExit):
        flown_masks.main(["runs", "--fill", "most"])
    assert "'most' is neither 'none' nor a fraction" in capsys.readouterr().err


@pytest.mark.slow
def test_a_sideways_step_by_an_opening_is_scored_and_the_fill_brings_its_edge_back(tmp_path):
    from scenes.library import suite_spec

    run = tmp_path / "sweep"
    (run / "scenes").mkdir(parents=True)
    suite_spec("window1", "brick").save(run / "scenes" / "window1_brick.json")   # wall 3 m north, 0.9 m opening
    frames = run / "window1_brick-0" / "companion"
    frames.mkdir(parents=True)
    level = [1.0, 0.0, 0.0, 0.0]
    lines = [{"step": s, "position_true": [1.8, y, -1.5], "attitude_true": level, "position_est": [1.8, y, -1.5],
              "attitude_est": [0.0, 0.0, 0.0]} for s, y in ((0, 0.1), (1, -0.1))]   # 0.2 m to the left, 1.2 m off
    (frames / "frames.jsonl").write_text("".join(json.dumps(r) + "\n" for r in lines))
    out = tmp_path / "out"
    assert flown_masks.main([str(run), "--flow", "dis:fine", "--pairs", "5", "--fill", "none", "0.75",
                             "-o", str(out)]) == 0
    result = json.loads((out / "flown_masks.json").read_text())
    assert len(result["rows"]) == 1 and result["rows"][0]["sideways"] and result["flow"] == "dis:fine"
    cut, filled = result["rows"][0]["fills"]["none"], result["rows"][0]["fills"]["0.75"]
    assert cut["truth_clearance_px"] > 20
    assert cut["clearance_px"] < cut["truth_clearance_px"] - 5      # the band on the side it moved to is lost
    assert abs(filled["clearance_px"] - filled["truth_clearance_px"]) < 3
    assert (out / "flown_masks.md").read_text().startswith("| pairs |")

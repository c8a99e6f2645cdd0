"""tools.fit_replay: the fit judgement replayed on a sweep's decision logs for another wall thickness."""

from __future__ import annotations

import json
import math

import pytest

from companion.opening import OpeningConfig
from companion.opening_geometry import turned_wall_stretch
from companion.servo import ServoConfig
from scenes import PinholeCamera
from tools import fit_replay

F = float(PinholeCamera().K[0, 0])
FLOWN = ServoConfig().wall_thickness_m
INSET = OpeningConfig().mask_inset_px
NEED = ServoConfig().body_radius_m + ServoConfig().clearance_margin_m
AS_FLOWN, THIN = fit_replay.tracker_for(FLOWN), fit_replay.tracker_for(0.10)


def frame(radius_m: float, depth_m: float = 1.2, judged: bool = True, count: int = 2, turn: float | None = None):
    """A decision line whose estimate is ``radius_m``, as the tracker scales it at ``depth_m`` (flown thickness)."""
    pixels = radius_m * F / (depth_m + FLOWN) - INSET
    return {"judged": judged, "judged_estimates": count, "estimate_m": radius_m, "estimate_px": pixels,
            "wall_turn_rad": turn}


def test_a_frame_rescaled_for_the_thickness_flown_is_its_own_estimate_and_thinner_is_smaller():
    for turn in (None, 0.0, math.radians(12), math.radians(-18)):
        d = frame(0.245, turn=turn)
        assert fit_replay.rescaled(d, AS_FLOWN, AS_FLOWN, F) == pytest.approx(0.245)
        assert fit_replay.rescaled(d, THIN, AS_FLOWN, F) < 0.245
    facing = frame(0.245)
    assert fit_replay.rescaled(facing, THIN, AS_FLOWN, F) == pytest.approx(0.245 * 1.30 / 1.35)
    turned = frame(0.245, turn=math.radians(15))
    ratio = turned_wall_stretch(NEED, 1.2, math.radians(15), 0.10) / turned_wall_stretch(NEED, 1.2, math.radians(15),
                                                                                        FLOWN)
    pixels = turned["estimate_px"] * ratio
    assert ratio < 1.0
    assert fit_replay.rescaled(turned, THIN, AS_FLOWN, F) == pytest.approx((pixels + INSET) * 1.30 / F)


def test_the_judgement_is_replayed_as_the_tracker_makes_it():
    just_fits = [frame(0.257, count=1), frame(0.253, count=2), frame(0.252, count=3)]
    assert not fit_replay.refused_for_size(just_fits, AS_FLOWN, AS_FLOWN, F)
    assert fit_replay.refused_for_size(just_fits, THIN, AS_FLOWN, F)
    # two estimates are no judgement; frames not judged (from the side, far) do not count
    assert not fit_replay.refused_for_size(just_fits[:2] + [frame(0.2, judged=False)], THIN, AS_FLOWN, F)
    # a count back at 1 is another opening: the small one's two estimates do not judge the wide one
    switched = [frame(0.20, count=1), frame(0.20, count=2), frame(0.30, count=1), frame(0.30, count=2),
                frame(0.30, count=3)]
    assert not fit_replay.refused_for_size(switched, AS_FLOWN, AS_FLOWN, F)
    # the upper quartile of the latest five, from the third on
    low = [frame(0.30, count=1)] + [frame(0.23, count=k) for k in (2, 3, 4, 5)]
    assert fit_replay.refused_for_size(low, AS_FLOWN, AS_FLOWN, F)            # 0.30 past a quartile
    assert not fit_replay.refused_for_size(low[:4], AS_FLOWN, AS_FLOWN, F)    # 0.30 lifts the quartile


def _sweep(tmp_path, flights: dict) -> None:
    """A folder as flowgap-eval-flights writes it: results/<key>.json and <key>/companion/decisions.jsonl."""
    (tmp_path / "results").mkdir(parents=True)
    for key, (row, decisions) in flights.items():
        run_dir = tmp_path / key
        (run_dir / "companion").mkdir(parents=True)
        (run_dir / "companion" / "decisions.jsonl").write_text("".join(json.dumps(d) + "\n" for d in decisions))
        row = {"scene": key.rsplit("-", 1)[0], "run_dir": "/elsewhere/moved", "collision": False, **row}
        (tmp_path / "results" / f"{key}.json").write_text(json.dumps({"sweep": {}, "row": row}))


def test_a_sweep_replayed_names_the_flights_a_thinner_wall_would_have_refused(tmp_path, capsys):
    tight = [frame(0.257, count=1), frame(0.253, count=2), frame(0.252, count=3)]
    roomy = [frame(0.35, count=1), frame(0.34, count=2), frame(0.36, count=3)]
    refused = [frame(0.2, count=1), frame(0.21, count=2)]          # logged before its refusing frame was
    _sweep(tmp_path / "run", {
        "passable_tight-0": ({"passable": True, "success": True, "refused": False}, tight),
        "passable_roomy-0": ({"passable": True, "success": True, "refused": False}, roomy),
        "impassable_flown-0": ({"passable": False, "success": False, "refused": False}, tight),
        "impassable_refused-0": ({"passable": False, "success": True, "refused": True,
                                  "companion_reason": "opening 0.4 × 0.4 m (0.41 m clear) is narrower than ..."},
                                 refused),
    })
    report = fit_replay.replay_run(fit_replay.flights(tmp_path / "run"), [0.10, FLOWN], F)
    assert report[f"{FLOWN:g}"] == {"passable": 2, "passable_through": 2, "impassable": 2, "impassable_flown": 1,
                                    "lost": [], "now_refused": [], "undecided": ["impassable_refused"]}
    thin = report["0.1"]
    assert thin["passable_through"] == 1 and thin["lost"] == ["passable_tight"]
    assert thin["impassable_flown"] == 0 and thin["now_refused"] == ["impassable_flown"]
    # the command: files and a table, and one line for a folder that is no sweep or a log that is not JSON
    out = tmp_path / "out"
    assert fit_replay.main([str(tmp_path / "run"), "--thickness", "0.1", "0.15", "-o", str(out)]) == 0
    assert json.loads((out / "fit_replay.json").read_text())["runs"][str(tmp_path / "run")] == report
    assert "| 0.1 | 1/2 | 0/2 | passable_tight | impassable_flown | 1 |" in (out / "fit_replay.md").read_text()
    capsys.readouterr()
    assert fit_replay.main([str(tmp_path / "out"), "-o", str(out)]) == 2
    assert "no results/*.json" in capsys.readouterr().err
    (tmp_path / "run" / "passable_tight-0" / "companion" / "decisions.jsonl").write_text("{not json\n")
    assert fit_replay.main([str(tmp_path / "run"), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "not JSON lines" in err and len(err.strip().splitlines()) == 1
    assert fit_replay.main([str(tmp_path / "run"), "--thickness", "nan"]) == 2

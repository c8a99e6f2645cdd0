"""``flowgap-scenes place``: the floor plane by RANSAC gives the up direction, two points give the scale, and the
draft capture JSON loads; ``render`` and ``info`` take capture scenes; bad capture files are one-line errors."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from scenes.__main__ import main
from scenes.capture import load_capture, place_cloud
from scenes.placement import (
    bulk_points,
    choose_floor,
    parse_scale_from,
    plane_candidates,
    propose_placement,
    rotation_to_ned,
    scale_from_points,
)
from scenes.splats import read_ply


def _true_up(reexpressed) -> np.ndarray:
    return reexpressed.to_ned.rotation.T @ np.array([0.0, 0.0, -1.0])


def test_ransac_over_opaque_centres_finds_the_floor_and_its_up(reexpressed):
    cloud = read_ply(reexpressed.ply)                    # in the capture's own frame, floaters and all
    rng = np.random.default_rng(0)
    pts = bulk_points(cloud, rng)
    floor = choose_floor(plane_candidates(pts, rng))
    up = _true_up(reexpressed)
    assert np.degrees(np.arccos(np.clip(np.dot(floor.normal, up), -1, 1))) < 2.0
    # placed with the proposal (and the true scale), the floor lands at z = 0 and up is NED up
    placement = propose_placement(pts, floor.normal, floor.offset, reexpressed.to_ned.scale)
    placed = place_cloud(cloud, placement)
    floor_z = placed.means[np.abs(placed.means[:, 2]) < 0.05, 2]
    assert len(floor_z) > 1000 and abs(float(np.median(floor_z))) < 0.01
    assert np.allclose(rotation_to_ned(up) @ up, (0.0, 0.0, -1.0))


def test_scale_from_two_points():
    a, b, metres = parse_scale_from("0:0:0,3:4:0,2.5")
    assert scale_from_points(a, b, metres) == pytest.approx(0.5)
    with pytest.raises(ValueError, match="X1:Y1:Z1,X2:Y2:Z2,METRES"):
        parse_scale_from("1,2,3")


def test_place_writes_a_draft_that_loads_and_views_to_finish_it(tmp_path, capsys, reexpressed):
    out = tmp_path / "draft.json"
    # two capture-frame points one metre apart in NED give the capture's scale
    a, b = reexpressed.to_ned.inverse().apply(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]))
    scale_from = ",".join(":".join(f"{v:.9g}" for v in p) for p in (a, b)) + ",1.0"
    assert main(["place", str(reexpressed.ply), "-o", str(out), "--scale-from", scale_from, "--width", "96",
                 "--height", "72"]) == 0
    text = capsys.readouterr().out
    assert "<- floor" in text and "draft capture scene" in text
    spec = load_capture(out)
    assert spec.to_ned.scale == pytest.approx(reexpressed.to_ned.scale, rel=1e-5)
    up_ned = spec.to_ned.rotation @ _true_up(reexpressed)
    assert np.degrees(np.arccos(np.clip(-up_ned[2], -1, 1))) < 2.0
    sheet = cv2.imread(str(out.with_suffix(".png")))
    assert sheet.shape == (2 * 72, 3 * 96, 3)
    assert main(["place", str(reexpressed.ply), "-o", str(out)]) == 2          # will not overwrite the draft
    assert "--force" in capsys.readouterr().err
    assert main(["render", str(out), "--width", "64", "--height", "48", "-o", str(tmp_path / "v.png")]) == 0
    assert "RGB | depth | gate" in capsys.readouterr().out


def test_render_and_info_take_a_capture_scene(tmp_path, capsys, reexpressed):
    png = tmp_path / "r.png"
    assert main(["render", str(reexpressed.json), "--width", "64", "--height", "48", "-o", str(png)]) == 0
    out = capsys.readouterr().out
    assert "RGB | depth | gate" in out and "pose NED" in out
    img = cv2.imread(str(png))[..., ::-1]
    gate_panel = img[:, 128:]
    assert (np.abs(gate_panel.astype(int) - (255, 60, 200)).sum(2) < 60).sum() > 20   # the gate is drawn
    assert main(["info", str(reexpressed.json)]) == 0
    out = capsys.readouterr().out
    assert "SH degree 3" in out and "gate" in out and "solid from" in out and "at the gate centre" in out


def _ahead(doc: dict, metres: float) -> list[float]:
    yaw = np.radians(doc["start_yaw_deg"])
    return [doc["start_ned"][0] + metres * np.cos(yaw), doc["start_ned"][1] + metres * np.sin(yaw), -1.5]


@pytest.mark.parametrize("change, words", [
    (lambda d: d.pop("start_ned"), "missing key 'start_ned'"),
    (lambda d: d["to_ned"].update(rotation_wxyz=[0.5, 0.5, 0.5, 0.6]), "not 1"),
    (lambda d: d.update(ply="gone.ply"), "is not a file"),
    (lambda d: d["gate"].update(center_ned=_ahead(d, 150.0)), "outside the splats"),
])
def test_bad_capture_files_are_one_line_errors_on_the_command_line(tmp_path, capsys, reexpressed, change, words):
    doc = json.loads(reexpressed.json.read_text())
    doc["ply"] = str(reexpressed.ply)
    change(doc)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(doc))
    for argv in (["render", str(path)], ["info", str(path)]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert words in err and err.count("\n") == 1 and "Traceback" not in err, err

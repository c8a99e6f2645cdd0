"""PID analysis: every default loop has >= 45 deg phase margin; the CLI writes its outputs."""

import json
from dataclasses import replace

import pytest

from sitl_vehicle.airframes import AIRFRAMES
from sitl_vehicle.control.config import ControlConfig
from tools.tune_pid import LOOPS, main, margins


@pytest.mark.parametrize("airframe", sorted(AIRFRAMES))
def test_default_gains_have_45_deg_phase_margin(airframe):
    res = margins(ControlConfig(), AIRFRAMES[airframe])
    assert set(res) == set(LOOPS)
    for name, r in res.items():
        assert r["closed_loop_stable"], name
        assert r["phase_margin_deg"] >= 45.0, (name, r)
        assert r["gain_margin_db"] >= 6.0, (name, r)


def test_aggressive_gains_are_flagged():
    bad = replace(ControlConfig(), rate_p=(400.0, 400.0, 15.0), rate_d=(0.0, 0.0, 0.0))
    res = margins(bad, AIRFRAMES["quad250"])
    assert res["rate_rp"]["phase_margin_deg"] < 45.0


def test_cli_writes_json_and_plots(tmp_path, capsys):
    assert main(["--airframe", "tello", "--out", str(tmp_path)]) == 0
    data = json.loads((tmp_path / "margins.json").read_text())
    assert data["all_ok"] and set(data["loops"]) == set(LOOPS)
    assert len(list(tmp_path.glob("step_*.png"))) == len(LOOPS)
    out = capsys.readouterr().out
    assert "rate_rp" in out and "position_xy" in out
    assert main(["--out", str(tmp_path), "--no-plots", "--min-pm", "179"]) == 1

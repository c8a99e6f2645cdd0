"""The RAFT-small weights shipped in companion/flow/weights: default, accurate, and as their model card says."""

import json

import numpy as np
import pytest
import torch

from companion.flow import make_flow_backend
from companion.flow.raft.backend import (
    DEFAULT_INPUT_SCALE,
    DEFAULT_MIRROR_AVERAGE,
    DEFAULT_REFINE_ITERS,
    DEFAULT_REFINE_MAX_FLOW,
    DEFAULT_REFINE_MIN_SCALE,
    DEFAULT_REFINE_SCALE,
    DEFAULT_WEIGHTS,
)
from tests.companion.synthetic import textured_pair
from tools import train_raft

torch.set_num_threads(2)

CARD_RESULTS = DEFAULT_WEIGHTS.with_suffix(".json")

if not DEFAULT_WEIGHTS.is_file():  # the shipped file is part of the repository; its absence is a packaging bug
    pytest.fail(f"shipped RAFT weights missing: {DEFAULT_WEIGHTS}", pytrace=False)


def test_raft_backend_loads_the_shipped_weights_by_default():
    backend = make_flow_backend("raft")
    assert backend.weights_path == DEFAULT_WEIGHTS
    assert backend.variant == "small" and backend.weights_layout == "flowgap"


def test_shipped_weights_recover_a_uniform_shift():
    img1, img2 = textured_pair(120, 160, (2.5, -1.5))
    flow = make_flow_backend("raft").estimate(img1, img2)
    inner = flow[16:-16, 16:-16].reshape(-1, 2)
    assert np.median(np.linalg.norm(inner - (2.5, -1.5), axis=1)) < 0.25


def test_model_card_epe_is_reproduced(tmp_path):
    val = json.loads(CARD_RESULTS.read_text())      # as `--eval-only` wrote it when the weights were made
    argv = ["--eval-only", str(DEFAULT_WEIGHTS), "--out", str(tmp_path), "--threads", "2",
            "--val-size", str(val["pairs"]), "--width", str(val["width"]), "--height", str(val["height"]),
            "--val-iters", str(val["iters"]), "--input-scale", str(val.get("input_scale", 1.0)),
            "--mirror-average" if val.get("mirror_average") else "--no-mirror-average",
            "--refine-scale", str(val.get("refine_scale", 0)), "--refine-iters", str(val.get("refine_iters") or 1),
            "--refine-min-scale", str(val.get("refine_min_scale") or DEFAULT_REFINE_MIN_SCALE),
            "--refine-max-flow", str(val.get("refine_max_flow", 0))]
    assert train_raft.main(argv) == 0
    result = json.loads((tmp_path / "eval.json").read_text())
    assert result["pairs"] == val["pairs"] and result["valid_pixels"] == val["valid_pixels"]
    assert result["epe"] == pytest.approx(val["epe"], rel=2e-3)
    assert result["dis_medium_epe"] == pytest.approx(val["dis_medium_epe"], rel=2e-3)
    assert result["epe"] < 1.0          # trained: random RAFT-small weights score about 14 px on these pairs
    card = (DEFAULT_WEIGHTS.parent / "MODEL_CARD.md").read_text()
    assert f"{val['epe']:.3f}" in card
    # the card's number is for the settings the backend runs the weights with by default
    assert val["input_scale"] == DEFAULT_INPUT_SCALE and f"input scale {DEFAULT_INPUT_SCALE:g}" in card
    assert val.get("mirror_average", False) == DEFAULT_MIRROR_AVERAGE
    assert (val["refine_scale"], val["refine_iters"]) == (DEFAULT_REFINE_SCALE, DEFAULT_REFINE_ITERS)
    assert (val["refine_min_scale"], val["refine_max_flow"]) == (DEFAULT_REFINE_MIN_SCALE, DEFAULT_REFINE_MAX_FLOW)
    assert (f"refined at input scale {DEFAULT_REFINE_MIN_SCALE:g}–{DEFAULT_REFINE_SCALE:g} (motion within "
            f"{DEFAULT_REFINE_MAX_FLOW:g} px, {DEFAULT_REFINE_ITERS} iterations)") in card

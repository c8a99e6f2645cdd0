"""The RAFT weights shipped in companion/flow/weights: default, accurate, and as their model card says."""

import json

import numpy as np
import pytest
import torch

from companion.flow import make_flow_backend
from companion.flow.raft.backend import DEFAULT_WEIGHTS, describe_settings
from companion.flow.raft.weights import load_raft_state_dict
from tests.companion.synthetic import textured_pair
from tools import train_raft

torch.set_num_threads(2)

CARD_RESULTS = DEFAULT_WEIGHTS.with_suffix(".json")

if not DEFAULT_WEIGHTS.is_file():  # the shipped file is part of the repository; its absence is a packaging bug
    pytest.fail(f"shipped RAFT weights missing: {DEFAULT_WEIGHTS}", pytrace=False)


def test_raft_backend_loads_the_shipped_weights_by_default():
    backend = make_flow_backend("raft")
    assert backend.weights_path == DEFAULT_WEIGHTS and backend.weights_layout == "flowgap"
    assert backend.variant == load_raft_state_dict(DEFAULT_WEIGHTS).variant
    # ... and runs them as the file says, which is what the model card measured
    assert backend.settings == load_raft_state_dict(DEFAULT_WEIGHTS).inference


def test_shipped_weights_recover_a_uniform_shift():
    img1, img2 = textured_pair(120, 160, (2.5, -1.5))
    flow = make_flow_backend("raft").estimate(img1, img2)
    inner = flow[16:-16, 16:-16].reshape(-1, 2)
    assert np.median(np.linalg.norm(inner - (2.5, -1.5), axis=1)) < 0.25


def test_model_card_epe_is_reproduced(tmp_path):
    val = json.loads(CARD_RESULTS.read_text())      # as `--eval-only` wrote it when the weights were made
    argv = ["--eval-only", str(DEFAULT_WEIGHTS), "--out", str(tmp_path), "--threads", "2",
            "--val-size", str(val["pairs"]), "--width", str(val["width"]), "--height", str(val["height"])]
    assert train_raft.main(argv) == 0               # no inference options: the file's own settings
    result = json.loads((tmp_path / "eval.json").read_text())
    assert result["pairs"] == val["pairs"] and result["valid_pixels"] == val["valid_pixels"]
    for key in ("iters", "input_scale", "mirror_average", "refine_scale", "refine_iters", "refine_min_scale",
                "refine_max_flow", "patch_levels", "variational_levels"):
        assert result[key] == val[key], key
    if result["precision"] == val.get("precision", "fp32"):   # bf16 weights on a CPU without it run fp32
        assert result["epe"] == pytest.approx(val["epe"], rel=2e-3)
    else:
        assert result["epe"] == pytest.approx(val["epe"], abs=0.02)
    assert result["dis_medium_epe"] == pytest.approx(val["dis_medium_epe"], rel=2e-3)
    assert result["epe"] < 1.0          # trained: random RAFT-small weights score about 14 px on these pairs
    card = " ".join((DEFAULT_WEIGHTS.parent / "MODEL_CARD.md").read_text().split())   # line breaks aside
    assert f"{val['epe']:.3f}" in card
    assert describe_settings(load_raft_state_dict(DEFAULT_WEIGHTS).inference) in card

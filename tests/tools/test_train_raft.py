"""RAFT training tooling: rendered data, sequence loss, training, checkpoint/resume, evaluation, CLI errors.

Tiny settings throughout (64×64 images — the smallest RAFT's 4-level correlation pyramid allows —
RAFT-small, batch 2, 2 iterations) so that the whole file runs in well under a minute on 2 CPU cores.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from tools import train_raft
from tools.raft_data import VALIDATION_SEED, RenderedFlowDataset, batch_at, validation_set

ROOT = Path(__file__).resolve().parents[2]
TINY = ["--width", "64", "--height", "64", "--crop", "none", "--batch", "2", "--iters", "2", "--val-iters", "2",
        "--quiet"]


@pytest.fixture(autouse=True)
def _threads():
    before = torch.get_num_threads()
    yield
    torch.set_num_threads(before)


def _read_log(path: Path) -> dict[int, float]:
    out = {}
    for line in path.read_text().splitlines():
        rec = json.loads(line)
        if "loss" in rec:
            out[rec["step"]] = rec["loss"]
    return out


@pytest.fixture(scope="module")
def trained_run(tmp_path_factory) -> Path:
    """One uninterrupted 4-step run with a checkpoint at step 2."""
    out = tmp_path_factory.mktemp("run_a")
    rc = train_raft.main([*TINY, "--steps", "4", "--save-every", "2", "--val-size", "0", "--seed", "3",
                          "--lr", "1e-3", "--out", str(out)])
    assert rc == 0
    return out


# ---------------------------------------------------------------------------------------------------------
# Data
# ---------------------------------------------------------------------------------------------------------

def test_dataset_is_deterministic_per_seed_and_differs_across_seeds():
    a = RenderedFlowDataset(seed=5, width=64, height=64, pairs_per_scene=2, exposure_jitter=0.1)
    b = RenderedFlowDataset(seed=5, width=64, height=64, pairs_per_scene=2, exposure_jitter=0.1)
    b.item(0)  # a different cache history must not matter
    x, y = a.item(3), b.item(3)
    for key in ("image1", "image2", "flow", "valid"):
        assert torch.equal(x[key], y[key]), key
    assert x["image1"].shape == (3, 64, 64) and x["flow"].shape == (2, 64, 64) and x["valid"].shape == (64, 64)
    assert x["image1"].dtype == torch.float32
    other = RenderedFlowDataset(seed=6, width=64, height=64, pairs_per_scene=2, exposure_jitter=0.1).item(3)
    assert not torch.equal(other["image1"], x["image1"])
    assert not torch.equal(other["flow"], x["flow"])
    assert not torch.equal(a.item(2)["flow"], x["flow"])  # items of one scene differ too
    val = validation_set(2, 64, 64)
    assert val.seed == VALIDATION_SEED and val.exposure_jitter == 0.0
    assert not torch.equal(val.item(0)["image1"], RenderedFlowDataset(seed=0, width=64, height=64).item(0)["image1"])


def test_dataset_flow_is_correct_where_valid():
    from scenes.groundtruth import warp_backward

    ds = RenderedFlowDataset(seed=1, width=96, height=64, pairs_per_scene=2)
    warped_err = plain_err = 0.0
    n_valid = 0
    for i in range(4):
        img1, img2, flow, valid = ds.pair(i)
        assert flow.shape == (64, 96, 2) and valid.dtype == bool
        assert valid.mean() > 0.2
        assert np.all(flow[~valid] == 0)
        warped = warp_backward(img2, flow)
        warped_err += np.abs(warped - img1)[valid].sum()
        plain_err += np.abs(img2 - img1)[valid].sum()
        n_valid += int(valid.sum())
    assert plain_err / n_valid > 2.0           # the camera really moved
    assert warped_err < 0.5 * plain_err        # and the flow explains the motion


def _window_of(full: np.ndarray, crop: np.ndarray) -> tuple[int, int]:
    ch, cw = crop.shape[:2]
    hits = [(y, x) for y in range(full.shape[0] - ch + 1) for x in range(full.shape[1] - cw + 1)
            if np.array_equal(full[y:y + ch, x:x + cw], crop)]
    assert len(hits) == 1
    return hits[0]


def test_crop_is_a_seeded_window_of_the_full_pair():
    full = RenderedFlowDataset(seed=3, width=128, height=96)
    cropped = RenderedFlowDataset(seed=3, width=128, height=96, crop=(64, 64))
    windows = set()
    for i in range(3):
        f1, f2, ff, fv = full.pair(i)
        c1, c2, cf, cv = cropped.pair(i)
        assert c1.shape == (64, 64, 3) and cf.shape == (64, 64, 2) and cv.shape == (64, 64)
        y, x = _window_of(f1, c1)
        win = (slice(y, y + 64), slice(x, x + 64))
        assert np.array_equal(f2[win], c2) and np.array_equal(ff[win], cf) and np.array_equal(fv[win], cv)
        windows.add((y, x))
        assert np.array_equal(cropped.pair(i)[0], c1)          # deterministic
    assert len(windows) > 1                                     # the window moves from item to item
    with pytest.raises(ValueError, match="crop"):
        RenderedFlowDataset(width=128, height=96, crop=(160, 64))


def test_crop_focus_moves_the_window_onto_the_opening():
    from tools.raft_data import opening_pixels

    settings = dict(seed=7, width=128, height=96, pairs_per_scene=2)
    full = RenderedFlowDataset(**settings)
    focused = RenderedFlowDataset(**settings, crop=(48, 48), crop_focus=1.0)
    plain = RenderedFlowDataset(**settings, crop=(48, 48))
    shown = {"focused": 0, "plain": 0}
    frames_with_opening = 0
    for i in range(8):
        f1, _, _, fv, label = full.render_pair(i)
        far = opening_pixels(label, fv)
        if not far.any():
            continue
        frames_with_opening += 1
        for name, ds in (("focused", focused), ("plain", plain)):
            y, x = _window_of(f1, ds.pair(i)[0])
            shown[name] += bool(far[y:y + 48, x:x + 48].any())
        assert np.array_equal(focused.pair(i)[0], RenderedFlowDataset(**settings, crop=(48, 48),
                                                                       crop_focus=1.0).pair(i)[0])
    assert frames_with_opening >= 4
    assert shown["focused"] == frames_with_opening       # every focused window shows the opening
    assert shown["plain"] < frames_with_opening          # random windows often do not
    # no focus: exactly the random windows of a dataset built without the option
    for x, y in zip(RenderedFlowDataset(**settings, crop=(48, 48), crop_focus=0.0).pair(3), plain.pair(3),
                    strict=True):
        assert np.array_equal(x, y)
    with pytest.raises(ValueError, match="crop_focus"):
        RenderedFlowDataset(**settings, crop=(48, 48), crop_focus=1.5)
    with pytest.raises(ValueError, match="crop"):
        RenderedFlowDataset(**settings, crop_focus=0.5)


def test_distance_moves_the_first_camera_further_from_the_wall():
    settings = dict(seed=7, width=64, height=64, pairs_per_scene=2)
    plain = RenderedFlowDataset(**settings)
    same = RenderedFlowDataset(**settings, distance=(0.6, 2.6))
    far = RenderedFlowDataset(**settings, distance=(3.0, 4.0))
    for x, y in zip(plain.pair(1), same.pair(1), strict=True):   # the default range, asked for or not
        assert np.array_equal(x, y)
    # further away the same motions make smaller flow: compare median flow over items
    near_mag = [np.median(np.linalg.norm(plain.pair(i)[2], axis=-1)) for i in range(6)]
    far_mag = [np.median(np.linalg.norm(far.pair(i)[2], axis=-1)) for i in range(6)]
    assert np.median(far_mag) < np.median(near_mag)
    assert validation_set(2, 64, 64, distance=(3.0, 4.0)).distance == (3.0, 4.0)
    for bad in ((0.0, 1.0), (2.0, 1.0)):
        with pytest.raises(ValueError, match="distance"):
            RenderedFlowDataset(**settings, distance=bad)


def test_zoom_enlarges_the_pair_and_scales_its_flow_like_a_larger_camera():
    """A zoomed pair's flow matches the exact flow rendered by a camera of twice the resolution."""
    from scenes.camera import PinholeCamera
    from scenes.groundtruth import flow_between, sample_pose_pair
    from scenes.render import render_splats
    from tools.raft_data import zoom_pair

    ds = RenderedFlowDataset(seed=3, width=96, height=64)
    spec, cloud = ds.scene(0)
    pose1, pose2 = sample_pose_pair(spec, np.random.default_rng(5))
    small, large = PinholeCamera(96, 64), PinholeCamera(192, 128)
    flow, valid = flow_between(cloud, small, pose1, pose2)
    big_flow, big_valid = flow_between(cloud, large, pose1, pose2)
    img = render_splats(cloud, small, pose1).rgb.astype(np.float32)
    z1, z2, zflow, zvalid = zoom_pair(img, img, np.where(valid[..., None], flow, 0).astype(np.float32), valid,
                                      (192, 128))
    assert z1.shape == (128, 192, 3) and zflow.shape == (128, 192, 2) and zvalid.shape == (128, 192)
    assert z1.dtype == np.float32 and z1.min() >= 0.0 and z1.max() <= 255.0
    assert np.all(zflow[~zvalid] == 0)
    both = zvalid & big_valid
    assert both.mean() > 0.5
    err = np.linalg.norm(zflow - big_flow, axis=-1)[both]
    assert np.median(np.linalg.norm(big_flow, axis=-1)[both]) > 1.0      # the camera really moved
    assert err.mean() < 0.1, err.mean()                                  # x2 magnitudes, same geometry


def test_zoomed_items_are_seeded_crops_of_varying_scale():
    ds = RenderedFlowDataset(seed=4, width=96, height=64, crop=(64, 64), zoom=(1.0, 2.0))
    a, b = ds.pair(1), RenderedFlowDataset(seed=4, width=96, height=64, crop=(64, 64), zoom=(1.0, 2.0)).pair(1)
    for x, y in zip(a, b, strict=True):
        assert np.array_equal(x, y)
    assert a[0].shape == (64, 64, 3) and a[2].shape == (64, 64, 2)
    plain = RenderedFlowDataset(seed=4, width=96, height=64, crop=(64, 64)).pair(1)
    assert not np.array_equal(plain[0], a[0])
    with pytest.raises(ValueError, match="zoom"):
        RenderedFlowDataset(width=96, height=64, crop=(64, 64), zoom=(0.5, 1.0))
    with pytest.raises(ValueError, match="crop"):
        RenderedFlowDataset(width=96, height=64, zoom=(1.0, 2.0))


def test_exposure_jitter_changes_brightness_not_flow():
    plain = RenderedFlowDataset(seed=2, width=64, height=64).item(1)
    jit = RenderedFlowDataset(seed=2, width=64, height=64, exposure_jitter=0.3).item(1)
    assert torch.equal(plain["flow"], jit["flow"])
    assert not torch.equal(plain["image1"], jit["image1"])
    assert float(jit["image1"].min()) >= 0.0 and float(jit["image1"].max()) <= 255.0


# ---------------------------------------------------------------------------------------------------------
# Loss and optimisation
# ---------------------------------------------------------------------------------------------------------

def test_sequence_loss_weights_iterations_and_ignores_invalid_pixels():
    gt = torch.zeros(1, 2, 8, 8)
    valid = torch.ones(1, 8, 8)
    valid[0, :, :4] = 0
    p0 = torch.ones(1, 2, 8, 8)            # off by 1 px per component on every pixel
    p1 = torch.zeros(1, 2, 8, 8)
    p1[0, :, :, :4] = 100.0                # wrong only where invalid
    loss, epe = train_raft.sequence_loss([p0, p1], gt, valid, gamma=0.8)
    assert float(loss) == pytest.approx(0.8)
    assert epe == pytest.approx(0.0)
    loss2, _ = train_raft.sequence_loss([p1, p0], gt, valid, gamma=0.8)
    assert float(loss2) == pytest.approx(1.0)


def test_motion_boundaries_mark_the_band_around_a_flow_jump():
    """A 5x5 block moving 2 px in a still 20x20 field: the jump lies between the block's pixels and their
    neighbours outside it, so the pixels within 3 px (Chebyshev) of that ring of 7x7 pixels are marked."""
    gt = torch.zeros(1, 2, 20, 20)
    gt[0, 0, 5:10, 5:10] = 2.0
    ring = np.zeros((20, 20), bool)
    ring[4:11, 4:11] = True
    ring[4:11, 4:11][1:-1, 1:-1] = False
    ring[4, 4] = ring[4, 10] = ring[10, 4] = ring[10, 10] = False      # corners touch the block only diagonally
    ring[5:10, 5:10] = True                                          # the block's own pixels at the jump ...
    ring[6:9, 6:9] = False                                           # ... but not its inside
    want = np.zeros((20, 20), bool)
    for y, x in zip(*np.nonzero(ring), strict=True):
        want[max(0, y - 3):y + 4, max(0, x - 3):x + 4] = True
    got = train_raft.motion_boundaries(gt)[0, 0].numpy() > 0.5
    assert (got == want).all()
    # a smooth ramp (0.1 px per pixel, as a wall seen at an angle) has no boundary
    ramp = torch.zeros(1, 2, 20, 20)
    ramp[0, 0] = torch.arange(20.0) * 0.1
    assert float(train_raft.motion_boundaries(ramp).sum()) == 0.0


def test_boundary_weight_counts_the_band_more_and_leaves_the_epe_alone():
    gt = torch.zeros(1, 2, 20, 20)
    gt[0, 0, 5:10, 5:10] = 2.0
    band = train_raft.motion_boundaries(gt)[0, 0] > 0.5
    n, nb = 400, int(band.sum())
    pred = gt.clone()
    pred[0, 1][band] = 1.0                     # off by 1 px (one component) in the band only
    plain, epe = train_raft.sequence_loss([pred], gt, torch.ones(1, 20, 20))
    weighted, epe_w = train_raft.sequence_loss([pred], gt, torch.ones(1, 20, 20), boundary_weight=4.0)
    assert float(plain) == pytest.approx(nb / (2 * n))
    assert float(weighted) == pytest.approx(5 * nb / (2 * (n + 4 * nb)))
    assert epe == pytest.approx(nb / n) and epe_w == pytest.approx(epe)


@pytest.mark.parametrize("variant", ["small", "small-convex"])
def test_training_steps_reduce_loss_on_a_fixed_batch(variant):
    torch.set_num_threads(2)
    batch = batch_at(RenderedFlowDataset(seed=4, width=64, height=64, pairs_per_scene=2), 0, 2)
    torch.manual_seed(0)
    model = train_raft.build_model(variant)
    model.train()
    opt = torch.optim.AdamW(model.parameters(), lr=1e-3, weight_decay=1e-4)
    losses = []
    for _ in range(12):
        opt.zero_grad()
        out = model(batch["image1"], batch["image2"], iters=2, all_predictions=True)
        loss, _ = train_raft.sequence_loss(out.predictions, batch["flow"], batch["valid"])
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        opt.step()
        losses.append(float(loss.detach()))
    assert min(losses[-3:]) < 0.7 * losses[0], losses


# ---------------------------------------------------------------------------------------------------------
# Checkpoints, resume, evaluation
# ---------------------------------------------------------------------------------------------------------

def test_run_writes_loadable_weights_and_checkpoints(trained_run):
    from companion.flow.registry import make_flow_backend

    assert (trained_run / "checkpoint-000002.pth").is_file()
    assert (trained_run / "checkpoint-000004.pth").is_file()
    losses = _read_log(trained_run / "log.jsonl")
    assert sorted(losses) == [1, 2, 3, 4] and all(math.isfinite(v) for v in losses.values())
    img = np.zeros((64, 64, 3), np.uint8)
    for name in ("raft-small-flowgap.pth", "checkpoint-000004.pth"):
        backend = make_flow_backend("raft", variant="small", weights=trained_run / name, iters=2)
        assert backend.weights_layout == "flowgap"
        assert backend.estimate(img, img).shape == (64, 64, 2)
    final = torch.load(trained_run / "raft-small-flowgap.pth", weights_only=True)["state_dict"]
    ckpt = torch.load(trained_run / "checkpoint-000004.pth", weights_only=True)
    assert ckpt["train"]["step"] == 4
    assert all(torch.equal(final[k], ckpt["state_dict"][k]) for k in final)
    # new runs upsample from the 8×8 blocks' centres, and the files say so
    assert ckpt["train"]["config"]["upsample"] == "centres" and ckpt["upsample_align_corners"] is False


def test_checkpoints_from_before_the_upsampling_choice_resume_with_corners(trained_run, tmp_path):
    old = torch.load(trained_run / "checkpoint-000002.pth", weights_only=True)
    del old["upsample_align_corners"], old["train"]["config"]["upsample"], old["train"]["config"]["crop_focus"]
    del old["train"]["config"]["distance"]
    old["version"] = 1
    torch.save(old, tmp_path / "old.pth")
    rc = train_raft.main(["--resume", str(tmp_path / "old.pth"), "--stop-at", "3", "--out", str(tmp_path / "run"),
                          "--quiet"])
    assert rc == 0
    resumed = torch.load(tmp_path / "run" / "checkpoint-000003.pth", weights_only=True)
    assert resumed["train"]["config"]["upsample"] == "corners" and resumed["upsample_align_corners"] is True
    assert resumed["train"]["config"]["crop_focus"] == 0.0   # nor did they move crops onto the opening
    assert resumed["train"]["config"]["distance"] is None    # nor stand further than 2.6 m from the wall
    rc = train_raft.main(["--eval-only", str(tmp_path / "run" / "checkpoint-000003.pth"), "--width", "64",
                          "--height", "64", "--val-size", "1", "--val-iters", "1", "--out", str(tmp_path / "ev")])
    assert rc == 0
    assert json.loads((tmp_path / "ev" / "eval.json").read_text())["upsample"] == "corners"


def test_resume_continues_identically(trained_run, tmp_path):
    rc = train_raft.main(["--resume", str(trained_run / "checkpoint-000002.pth"), "--out", str(tmp_path),
                          "--quiet"])
    assert rc == 0
    uninterrupted = _read_log(trained_run / "log.jsonl")
    resumed = _read_log(tmp_path / "log.jsonl")
    assert sorted(resumed) == [3, 4]
    assert resumed[3] == uninterrupted[3] and resumed[4] == uninterrupted[4]
    assert uninterrupted[3] != uninterrupted[1]
    a = torch.load(trained_run / "raft-small-flowgap.pth", weights_only=True)["state_dict"]
    b = torch.load(tmp_path / "raft-small-flowgap.pth", weights_only=True)["state_dict"]
    assert a.keys() == b.keys()
    assert all(torch.equal(a[k], b[k]) for k in a)
    start = torch.load(trained_run / "checkpoint-000002.pth", weights_only=True)["state_dict"]
    assert not all(torch.equal(a[k], start[k]) for k in a)   # the resumed steps did train


def test_stop_at_ends_early_on_the_same_schedule(trained_run, tmp_path):
    """--stop-at 2 writes what the full run's step-2 checkpoint holds, and --resume from it finishes the run."""
    rc = train_raft.main([*TINY, "--steps", "4", "--stop-at", "2", "--save-every", "0", "--val-size", "0",
                          "--seed", "3", "--lr", "1e-3", "--out", str(tmp_path)])
    assert rc == 0
    assert sorted(_read_log(tmp_path / "log.jsonl")) == [1, 2]
    early = torch.load(tmp_path / "checkpoint-000002.pth", weights_only=True)
    full = torch.load(trained_run / "checkpoint-000002.pth", weights_only=True)
    assert early["train"]["step"] == 2 and early["train"]["config"]["steps"] == 4
    assert all(torch.equal(early["state_dict"][k], full["state_dict"][k]) for k in full["state_dict"])
    assert train_raft.main(["--resume", str(tmp_path / "checkpoint-000002.pth"), "--stop-at", "2",
                            "--out", str(tmp_path), "--quiet"]) == 2


def test_eval_only_prints_epe_and_writes_json(trained_run, tmp_path, capsys):
    rc = train_raft.main(["--eval-only", str(trained_run / "checkpoint-000004.pth"), "--width", "64",
                          "--height", "64", "--val-size", "2", "--val-iters", "2", "--out", str(tmp_path)])
    assert rc == 0
    out = capsys.readouterr().out
    assert "EPE raft-small" in out and "dis:medium" in out
    result = json.loads((tmp_path / "eval.json").read_text())
    assert result["pairs"] == 2 and result["layout"] == "flowgap"
    assert math.isfinite(result["epe"]) and result["epe"] >= 0
    assert math.isfinite(result["dis_medium_epe"]) and result["dis_medium_epe"] >= 0
    assert f"{result['epe']:.3f}" in out and "dis:fine" in out and math.isfinite(result["dis_fine_epe"])
    # the checkpoint carries the settings its run validated with: RAFT's one pass, iterations as asked
    assert (result["iters"], result["input_scale"], result["refine_scale"], result["refine_iters"]) == (2, 1.0, 0, 0)
    assert result["precision"] == "fp32" and "(one pass)" in out
    rc = train_raft.main(["--eval-only", str(trained_run / "checkpoint-000004.pth"), "--width", "64",
                          "--height", "64", "--val-size", "2", "--refine-scale", "1.5", "--refine-iters", "2",
                          "--out", str(tmp_path / "two-pass")])
    assert rc == 0 and "then 2 at scale 1.5" in capsys.readouterr().out
    two_pass = json.loads((tmp_path / "two-pass" / "eval.json").read_text())
    assert two_pass["refine_scale"] == 1.5 and two_pass["refine_iters"] == 2 and two_pass["epe"] != result["epe"]
    assert two_pass["iters"] == 2 and two_pass["refine_max_flow"] == 0
    rc = train_raft.main(["--eval-only", str(trained_run / "checkpoint-000004.pth"), "--width", "64",
                          "--height", "64", "--val-size", "2", "--refine-scale", "2", "--refine-max-flow", "8",
                          "--refine-min-scale", "1.25", "--out", str(tmp_path / "adaptive")])
    assert rc == 0 and "at scale 1.25-2 (lowered for motion over 8 px)" in capsys.readouterr().out
    rc = train_raft.main(["--eval-only", str(trained_run / "checkpoint-000004.pth"), "--width", "64",
                          "--height", "64", "--val-size", "2", "--val-iters", "2", "--input-scale", "1.5",
                          "--out", str(tmp_path / "zoomed")])
    assert rc == 0 and "input scale 1.5" in capsys.readouterr().out
    zoomed = json.loads((tmp_path / "zoomed" / "eval.json").read_text())
    assert zoomed["input_scale"] == 1.5 and zoomed["valid_pixels"] == result["valid_pixels"]
    assert zoomed["epe"] != result["epe"] and zoomed["dis_medium_epe"] == result["dis_medium_epe"]
    rc = train_raft.main(["--eval-only", str(trained_run / "checkpoint-000004.pth"), "--width", "64",
                          "--height", "64", "--val-size", "2", "--val-iters", "2", "--val-seed", "7",
                          "--out", str(tmp_path / "other")])
    assert rc == 0 and "2 seed-7 pairs" in capsys.readouterr().out
    other = json.loads((tmp_path / "other" / "eval.json").read_text())
    assert other["seed"] == 7 and other["epe"] != result["epe"]
    assert "distance" not in result and "distance" not in other
    rc = train_raft.main(["--eval-only", str(trained_run / "checkpoint-000004.pth"), "--width", "64",
                          "--height", "64", "--val-size", "2", "--val-iters", "2", "--distance", "3", "4",
                          "--out", str(tmp_path / "far")])
    assert rc == 0 and f"2 seed-{VALIDATION_SEED} 3-4 m pairs" in capsys.readouterr().out
    far = json.loads((tmp_path / "far" / "eval.json").read_text())
    assert far["distance"] == [3.0, 4.0] and far["epe"] != result["epe"]


def test_a_convex_run_starts_from_small_weights_and_trains_under_bf16(trained_run, tmp_path, capsys):
    rc = train_raft.main([*TINY, "--variant", "small-convex", "--init", str(trained_run / "raft-small-flowgap.pth"),
                          "--steps", "2", "--val-size", "1", "--precision", "bf16", "--seed", "5",
                          "--out", str(tmp_path)])
    assert rc == 0
    err = capsys.readouterr().err
    assert "starts from" in err and "new heads (update_block.mask) start as bilinear upsampling" in err
    ckpt = torch.load(tmp_path / "checkpoint-000002.pth", weights_only=True)
    assert ckpt["variant"] == "small-convex" and ckpt["train"]["config"]["precision"] == "bf16"
    start = torch.load(trained_run / "raft-small-flowgap.pth", weights_only=True)["state_dict"]
    moved = [k for k in start if not torch.equal(start[k], ckpt["state_dict"][k])]
    assert moved and all(k in ckpt["state_dict"] for k in start)           # trained from them, not replaced
    # weights trained under bf16 are meant to run in it (where the CPU has it): the file says so
    assert ckpt["inference"]["precision"] == "auto" and ckpt["inference"]["iters"] == 2
    # ... and a refined one from those convex weights (its quarter refiner new), with faster heads
    rc = train_raft.main([*TINY, "--variant", "small-refined", "--init", str(tmp_path / "checkpoint-000002.pth"),
                          "--steps", "1", "--val-size", "0", "--head-lr-mult", "5", "--out", str(tmp_path / "ref")])
    assert rc == 0 and "new heads (refiner.conv1, refiner.conv2, refiner.flow, refiner.mask)" in capsys.readouterr().err
    refined = torch.load(tmp_path / "ref" / "checkpoint-000001.pth", weights_only=True)
    assert refined["variant"] == "small-refined" and refined["train"]["config"]["head_lr_mult"] == 5.0
    groups = refined["train"]["optimizer"]["param_groups"]
    assert len(groups) == 2 and groups[1]["lr"] == pytest.approx(5 * groups[0]["lr"])
    rc = train_raft.main([*TINY, "--variant", "large", "--init", str(trained_run / "raft-small-flowgap.pth"),
                          "--steps", "1", "--val-size", "0", "--out", str(tmp_path / "large")])
    assert rc == 2 and "use --variant small" in capsys.readouterr().err


# ---------------------------------------------------------------------------------------------------------
# Command-line errors
# ---------------------------------------------------------------------------------------------------------

def test_missing_weights_file_is_a_one_line_error_exit_2(tmp_path):
    missing = tmp_path / "nope.pth"
    proc = subprocess.run([sys.executable, "-m", "tools.train_raft", "--eval-only", str(missing)],
                          cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "nope.pth" in lines[0] and "Traceback" not in proc.stderr


@pytest.mark.parametrize("argv, needle", [
    (["--init", "missing.pth"], "missing.pth"),
    (["--resume", "missing.pth"], "missing.pth"),
    (["--width", "60"], "multiples of 8"),
    (["--width", "48", "--height", "48"], "at least 64"),
    (["--width", "128", "--height", "96"], "larger than the 128x96 frames"),
    (["--crop", "160by120"], "WIDTHxHEIGHT"),
    (["--crop", "56x56"], "at least 64x64"),
    (["--zoom", "0.5", "2"], "--zoom must be 1 <= LOW <= HIGH"),
    (["--zoom", "1", "2", "--crop", "none"], "--zoom needs a --crop"),
    (["--input-scale", "0"], "--input-scale must be within"),
    (["--refine-scale", "9"], "--refine-scale must be 0 (one pass) or within"),
    (["--refine-iters", "0"], "--refine-iters must be at least 1"),
    (["--refine-min-scale", "nan"], "--refine-min-scale must be within"),
    (["--refine-max-flow", "-3"], "--refine-max-flow must be 0"),
    (["--crop-focus", "nan"], "--crop-focus must be a probability"),
    (["--crop-focus", "0.5", "--crop", "none"], "--crop-focus needs a --crop"),
    (["--distance", "0", "3"], "--distance must be 0 < NEAR <= FAR"),
    (["--distance", "3", "2"], "--distance must be 0 < NEAR <= FAR"),
])
def test_bad_input_is_a_one_line_error(argv, needle, tmp_path, capsys):
    rc = train_raft.main([*argv, "--out", str(tmp_path), "--quiet"])
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0]


def test_unrecognised_weights_file_is_a_one_line_error(tmp_path, capsys):
    bogus = tmp_path / "bogus.pth"
    torch.save({"something": torch.zeros(2)}, bogus)
    rc = train_raft.main(["--eval-only", str(bogus), "--out", str(tmp_path)])
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bogus.pth" in err[0]


def test_export_writes_the_weights_with_the_inference_settings_given(tmp_path, capsys):
    """--export: the same tensors, with the command line's inference settings over the weights' own."""
    shipped = Path(__file__).resolve().parents[2] / "companion/flow/weights/raft-small-refined-flowgap.pth"
    assert train_raft.main(["--export", str(shipped), "--val-iters", "3", "--variational-levels", "1",
                            "--quarter-refine", "-o", str(tmp_path)]) == 0
    before, after = train_raft.read_weights(shipped), train_raft.read_weights(
        tmp_path / "raft-small-refined-flowgap.pth")
    assert after.variant == before.variant == "small-refined"
    assert after.inference.iters == 3 and after.inference.variational_levels == 1 and after.inference.quarter_refine
    assert before.inference.iters == 2 and before.inference.patch_levels == 3     # the model card's
    assert not before.inference.quarter_refine
    assert after.inference.variational_iters == before.inference.variational_iters     # kept
    assert before.state_dict.keys() == after.state_dict.keys()
    assert all(torch.equal(before.state_dict[k], after.state_dict[k]) for k in before.state_dict)
    assert train_raft.main(["--export", str(tmp_path / "missing.pth"), "-o", str(tmp_path)]) == 2
    assert "RAFT weights not found" in capsys.readouterr().err

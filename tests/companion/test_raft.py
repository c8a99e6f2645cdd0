"""Our RAFT: checkpoint layouts, padding, warm start, correlation lookup.  Tiny images, few iterations."""

import re

import numpy as np
import pytest
import torch

from companion.flow import FlowWeightsError, make_flow_backend
from companion.flow.raft import RAFT, InputPadder, RaftConfig
from companion.flow.raft.backend import RAFT_DEFAULTS, InferenceSettings
from companion.flow.raft.corr import CorrBlock
from companion.flow.raft.upsample import convex_upsample, upflow8
from companion.flow.raft.weights import clear_cache, load_raft_state_dict, save_flowgap_weights
from companion.flow.registry import parse_backend
from tests.companion.synthetic import textured_pair

torch.set_num_threads(2)

# torchvision's published parameter counts (Raft_Large_Weights / Raft_Small_Weights meta "num_params")
TORCHVISION_NUM_PARAMS = {"large": 5257536, "small": 990162}
# (key, shape) pairs as torchvision's raft_large / raft_small name them
TORCHVISION_KNOWN = {
    "large": {
        "feature_encoder.convnormrelu.0.weight": (64, 3, 7, 7),
        "context_encoder.convnormrelu.1.running_var": (64,),
        "context_encoder.layer2.0.downsample.1.weight": (96,),
        "context_encoder.conv.weight": (256, 128, 1, 1),
        "update_block.motion_encoder.convcorr1.0.weight": (256, 324, 1, 1),
        "update_block.recurrent_block.convgru1.convz.weight": (128, 384, 1, 5),
        "update_block.recurrent_block.convgru2.convq.weight": (128, 384, 5, 1),
        "update_block.flow_head.conv1.weight": (256, 128, 3, 3),
        "mask_predictor.convrelu.0.weight": (256, 128, 3, 3),
        "mask_predictor.conv.weight": (576, 256, 1, 1),
    },
    "small": {
        "feature_encoder.layer1.0.convnormrelu3.0.weight": (32, 8, 1, 1),
        "feature_encoder.layer2.0.downsample.0.weight": (64, 32, 1, 1),
        "context_encoder.conv.weight": (160, 96, 1, 1),
        "update_block.motion_encoder.convcorr1.0.weight": (96, 196, 1, 1),
        "update_block.motion_encoder.conv.0.weight": (80, 128, 3, 3),
        "update_block.recurrent_block.convgru1.convz.weight": (96, 242, 3, 3),
        "update_block.flow_head.conv1.weight": (128, 96, 3, 3),
    },
}


# --- an independent mapping, written here from torchvision's module names: ours/official -> torchvision ----

def ours_to_torchvision(sd: dict, variant: str) -> dict:
    out = {}
    for key, value in sd.items():
        parts = key.split(".")
        if parts[0] in ("fnet", "cnet"):
            enc = {"fnet": "feature_encoder", "cnet": "context_encoder"}[parts[0]]
            if parts[1] == "conv1":
                new = [enc, "convnormrelu", "0", *parts[2:]]
            elif parts[1] == "norm1":
                new = [enc, "convnormrelu", "1", *parts[2:]]
            elif parts[1] == "conv2":
                new = [enc, "conv", *parts[2:]]
            else:                                   # layerA.B.<name>.<param>
                layer, idx, name = parts[1], parts[2], parts[3]
                if name.startswith("conv"):
                    new = [enc, layer, idx, "convnormrelu" + name[4:], "0", *parts[4:]]
                elif name.startswith("norm"):
                    new = [enc, layer, idx, "convnormrelu" + name[4:], "1", *parts[4:]]
                else:                               # downsample.0 / downsample.1
                    new = [enc, *parts[1:]]
        elif parts[1] == "encoder":
            name = parts[2]
            table = {"convc1": "convcorr1.0", "convc2": "convcorr2.0", "convf1": "convflow1.0",
                     "convf2": "convflow2.0", "conv": "conv.0"}
            new = ["update_block", "motion_encoder", *table[name].split("."), *parts[3:]]
        elif parts[1] == "gru":
            name = parts[2]                         # convz / convz1 / convz2
            gru = "convgru" + (name[5:] or "1")
            new = ["update_block", "recurrent_block", gru, name[:5], *parts[3:]]
        elif parts[1] == "mask":
            new = ["mask_predictor", {"0": "convrelu.0", "2": "conv"}[parts[2]], *parts[3:]]
        else:
            new = parts                             # update_block.flow_head.*
        out[".".join(new)] = value
    return out


def ours_to_official(sd: dict, variant: str) -> dict:
    """DataParallel prefix, plus the shortcut-norm aliases the official blocks register."""
    out = {"module." + k: v for k, v in sd.items()}
    alias = "norm4" if variant == "small" else "norm3"
    for key, value in sd.items():
        m = re.match(r"^((?:fnet|cnet)\.layer\d\.\d)\.downsample\.1\.(.+)$", key)
        if m:
            out[f"module.{m[1]}.{alias}.{m[2]}"] = value
    return out


def random_model(variant: str, seed: int = 0) -> RAFT:
    torch.manual_seed(seed)
    model = RAFT(RaftConfig.for_variant(variant))
    with torch.no_grad():     # make BatchNorm statistics matter
        for m in model.modules():
            if isinstance(m, torch.nn.BatchNorm2d):
                m.running_mean.uniform_(-0.2, 0.2)
                m.running_var.uniform_(0.5, 1.5)
                m.weight.uniform_(0.5, 1.5)
                m.bias.uniform_(-0.1, 0.1)
    return model


@pytest.fixture(autouse=True)
def _fresh_cache():
    clear_cache()
    yield
    clear_cache()


@pytest.mark.parametrize("variant", ["small", "large"])
def test_official_and_torchvision_layouts_give_identical_flow(tmp_path, variant):
    model = random_model(variant)
    ours = {k: v.clone() for k, v in model.state_dict().items()}
    assert sum(p.numel() for p in model.parameters()) == TORCHVISION_NUM_PARAMS[variant]
    tv = ours_to_torchvision(ours, variant)
    for key, shape in TORCHVISION_KNOWN[variant].items():
        assert tuple(tv[key].shape) == shape, key
    official = ours_to_official(ours, variant)
    torch.save(official, tmp_path / f"raft-{variant}-official.pth")
    torch.save(tv, tmp_path / f"raft_{variant}_tv.pth")
    save_flowgap_weights(model, tmp_path / "ours.pth", variant)

    img1, img2 = textured_pair(64, 72, (1.5, -1.0))
    flows = {}
    for name in (f"raft-{variant}-official.pth", f"raft_{variant}_tv.pth", "ours.pth"):
        backend = make_flow_backend("raft", weights=tmp_path / name, iters=2)
        assert backend.variant == variant
        flows[name] = backend.estimate(img1, img2)
    ref = flows["ours.pth"]
    assert np.abs(ref).max() > 0
    for name, flow in flows.items():
        assert np.array_equal(flow, ref), name


def test_module_prefix_is_optional_and_loading_is_cached(tmp_path):
    model = random_model("small")
    sd = model.state_dict()
    torch.save(sd, tmp_path / "plain.pth")                        # no "module." prefix
    torch.save(ours_to_official(sd, "small"), tmp_path / "dp.pth")
    img1, img2 = textured_pair(64, 64, (1.0, 0.0))
    a = make_flow_backend("raft", weights=tmp_path / "plain.pth", iters=1).estimate(img1, img2)
    b = make_flow_backend("raft", weights=tmp_path / "dp.pth", iters=1).estimate(img1, img2)
    assert np.array_equal(a, b)
    from companion.flow.raft import weights as w
    assert len(w._CACHE) == 2
    make_flow_backend("raft", weights=tmp_path / "dp.pth", iters=1)
    assert len(w._CACHE) == 2


def _one_line_error(match: str, **options):
    with pytest.raises(FlowWeightsError) as info:
        make_flow_backend("raft", **options)
    msg = str(info.value)
    assert "\n" not in msg and match in msg
    return msg


def test_missing_weights_say_so(tmp_path):
    msg = _one_line_error("nope.pth", weights=tmp_path / "nope.pth")
    assert "not found" in msg and "official RAFT" in msg and "torchvision" in msg


def test_mismatched_weights_are_rejected(tmp_path):
    small = random_model("small").state_dict()
    torch.save(ours_to_torchvision(small, "small"), tmp_path / "small_tv.pth")
    msg = _one_line_error(str(tmp_path / "small_tv.pth"), weights=tmp_path / "small_tv.pth", variant="large")
    assert "mismatch" in msg
    broken = dict(small)
    broken["update_block.flow_head.conv2.weight"] = torch.zeros(2, 128, 5, 5)
    torch.save(broken, tmp_path / "bad_shape.pth")
    _one_line_error("bad_shape.pth", weights=tmp_path / "bad_shape.pth")
    del broken["update_block.flow_head.conv2.weight"]
    torch.save(broken, tmp_path / "missing_key.pth")
    _one_line_error("missing_key.pth", weights=tmp_path / "missing_key.pth")
    torch.save({"something": torch.zeros(3)}, tmp_path / "other.pth")
    _one_line_error("not recognised", weights=tmp_path / "other.pth")
    (tmp_path / "garbage.pth").write_bytes(b"not a checkpoint")
    _one_line_error("unreadable", weights=tmp_path / "garbage.pth")


@pytest.mark.parametrize("h, w", [(75, 100), (64, 64), (61, 83)])
def test_output_shape_and_padding(h, w):
    backend = make_flow_backend("raft", random_init_seed=1, iters=2)
    img1, img2 = textured_pair(h, w, (1.0, 0.5))
    flow = backend.estimate(img1, img2)
    assert flow.shape == (h, w, 2) and flow.dtype == np.float32 and np.isfinite(flow).all()
    padder = InputPadder((h, w))
    x = torch.arange(h * w, dtype=torch.float32).view(1, 1, h, w)
    (padded,) = padder.pad(x)
    assert padded.shape[-2] % 8 == 0 and padded.shape[-1] % 8 == 0
    assert padded.shape[-2] - h < 8 and padded.shape[-1] - w < 8
    assert torch.equal(padder.unpad(padded), x)
    left, right, top, bottom = padder.padding
    assert abs(left - right) <= 1 and abs(top - bottom) <= 1


@pytest.mark.parametrize("h, w", [(48, 100), (100, 56), (20, 20)])
def test_frames_too_small_for_the_pyramid_are_a_one_line_error(h, w):
    backend = make_flow_backend("raft", random_init_seed=1, iters=1, input_scale=1.0)
    img1, img2 = textured_pair(h, w, (1.0, 0.5))
    with pytest.raises(ValueError, match="at least 64×64") as info:
        backend.estimate(img1, img2)
    assert "\n" not in str(info.value) and f"{w}×{h}" in str(info.value)


def test_model_rejects_unpadded_input():
    model = RAFT(RaftConfig.small()).eval()
    with pytest.raises(ValueError, match="divisible by 8"):
        model(torch.zeros(1, 3, 60, 64), torch.zeros(1, 3, 60, 64))


def test_warm_start_changes_result_and_zero_update_returns_init():
    img1, img2 = textured_pair(64, 64, (2.0, 1.0))
    backend = make_flow_backend("raft", random_init_seed=2, iters=2)
    cold = backend.estimate(img1, img2)
    init = np.zeros((64, 64, 2), np.float32)
    assert np.allclose(backend.estimate(img1, img2, flow_init=init), cold, atol=1e-5)  # zero init == cold
    init[..., 0], init[..., 1] = 2.0, 1.0
    warm = backend.estimate(img1, img2, flow_init=init)
    assert np.abs(warm - cold).max() > 1e-3
    # With the flow head silenced, refinement adds nothing: any number of iterations returns the init.
    with torch.no_grad():
        backend.model.update_block.flow_head.conv2.weight.zero_()
        backend.model.update_block.flow_head.conv2.bias.zero_()
    for iters in (0, 1, 5):
        out = backend.estimate(img1, img2, flow_init=init, iters=iters)
        np.testing.assert_allclose(out, init, atol=1e-5)


def assert_silenced_flow_head_returns_init(backend, img1, img2, uv: tuple[float, float]) -> None:
    """With its flow head zeroed RAFT only carries its initial flow through: a uniform ``uv`` must come back."""
    with torch.no_grad():
        backend.model.update_block.flow_head.conv2.weight.zero_()
        backend.model.update_block.flow_head.conv2.bias.zero_()
    init = np.zeros((*img1.shape[:2], 2), np.float32)
    init[..., 0], init[..., 1] = uv
    np.testing.assert_allclose(backend.estimate(img1, img2, flow_init=init), init, atol=1e-4)


@pytest.mark.parametrize("scale", [1.5, 2.0, 0.75])
def test_input_scale_zooms_frames_and_returns_flow_in_frame_pixels(scale):
    img1, img2 = textured_pair(90, 100, (2.0, 1.0))
    backend = make_flow_backend("raft", random_init_seed=2, iters=2, input_scale=scale)
    flow = backend.estimate(img1, img2)
    assert flow.shape == (90, 100, 2) and flow.dtype == np.float32 and np.isfinite(flow).all()
    assert not np.allclose(flow, make_flow_backend("raft", random_init_seed=2, iters=2).estimate(img1, img2))
    # A uniform (2, -1) px init goes out to the zoomed frames as (2, -1) * scale and must come back as
    # (2, -1) frame pixels.
    assert_silenced_flow_head_returns_init(backend, img1, img2, (2.0, -1.0))


def test_mirror_average_is_the_mean_of_the_pair_and_its_mirror_image():
    img1, img2 = textured_pair(72, 88, (2.0, 1.0))
    plain = make_flow_backend("raft", random_init_seed=4, iters=2, refine_scale=0)
    averaged = make_flow_backend("raft", random_init_seed=4, iters=2, mirror_average=True, refine_scale=0)
    a = plain.estimate(img1, img2)
    m = plain.estimate(img1[:, ::-1].copy(), img2[:, ::-1].copy())[:, ::-1] * np.float32([-1, 1])
    assert not np.allclose(a, m, atol=1e-3)            # random weights: the two estimates differ
    np.testing.assert_allclose(averaged.estimate(img1, img2), 0.5 * (a + m), atol=2e-4)
    # the initial flow is mirrored there and back
    assert_silenced_flow_head_returns_init(averaged, img1, img2, (1.5, -0.5))


def test_refinement_pass_is_a_second_pass_on_enlarged_frames_started_from_the_first():
    img1, img2 = textured_pair(72, 88, (2.0, 1.0))
    refined = make_flow_backend("raft", random_init_seed=5, iters=2, input_scale=1.0, refine_scale=1.5,
                                refine_iters=3)
    first = make_flow_backend("raft", random_init_seed=5, iters=2, input_scale=1.0, refine_scale=0)
    second = make_flow_backend("raft", random_init_seed=5, iters=3, input_scale=1.5, refine_scale=0)
    coarse = first.estimate(img1, img2)
    expected = second.estimate(img1, img2, flow_init=coarse)
    np.testing.assert_array_equal(refined.estimate(img1, img2), expected)
    assert not np.allclose(expected, coarse, atol=1e-3)
    # refine_scale None is the weights' own setting: one pass for random weights, as RAFT runs
    single = make_flow_backend("raft", random_init_seed=5, iters=2, input_scale=1.0, refine_scale=None)
    np.testing.assert_array_equal(single.estimate(img1, img2), coarse)
    # a caller's initial flow starts the first pass; with the flow head silenced both passes carry it through
    assert_silenced_flow_head_returns_init(refined, img1, img2, (1.5, -0.5))


def test_the_refinement_scale_keeps_the_enlarged_motion_within_refine_max_flow():
    from companion.flow.raft.backend import refinement_scale

    def uniform(length):
        return np.full((24, 32, 2), length / np.sqrt(2.0), np.float32)

    assert refinement_scale(uniform(20.0), 2.5, 2.0, 64.0) == pytest.approx(2.5)        # 20 px × 2.5 = 50 px
    assert refinement_scale(uniform(30.0), 2.5, 2.0, 64.0) == pytest.approx(64.0 / 30.0)
    assert refinement_scale(uniform(40.0), 2.5, 2.0, 64.0) == pytest.approx(2.0)        # never below the floor
    assert refinement_scale(np.zeros((24, 32, 2), np.float32), 2.5, 2.0, 64.0) == pytest.approx(2.5)
    assert refinement_scale(uniform(40.0), 2.5, 2.0, 0.0) == 2.5                         # 0: fixed
    assert refinement_scale(uniform(40.0), 1.5, 2.0, 64.0) == 1.5                        # floor above: fixed
    # the 99th percentile, not the mean, decides: a few fast pixels (1 %) do not
    flow = uniform(10.0)
    flow[:2, :2] = 100.0
    assert refinement_scale(flow, 2.5, 2.0, 64.0) == pytest.approx(2.5)


def test_an_adaptive_refinement_runs_the_second_pass_at_the_scale_it_picks():
    from companion.flow.raft.backend import refinement_scale

    img1, img2 = textured_pair(72, 88, (2.0, 1.0))
    adaptive = make_flow_backend("raft", random_init_seed=5, iters=2, refine_scale=2.0, refine_min_scale=1.25,
                                 refine_max_flow=3.0, refine_iters=2)
    first = make_flow_backend("raft", random_init_seed=5, iters=2, refine_scale=0)
    coarse = first.estimate(img1, img2)
    scale = refinement_scale(coarse, 2.0, 1.25, 3.0)
    assert 1.25 <= scale < 2.0                                      # lowered, for this pair's motion
    second = make_flow_backend("raft", random_init_seed=5, iters=2, input_scale=scale, refine_scale=0)
    np.testing.assert_array_equal(adaptive.estimate(img1, img2), second.estimate(img1, img2, flow_init=coarse))


def test_settings_come_from_the_weights_file_and_options_override_them(tmp_path):
    # random weights and files without a record run RAFT's own settings: 12 iterations, one pass
    backend = make_flow_backend("raft", random_init_seed=1)
    assert backend.settings == RAFT_DEFAULTS and (backend.iters, backend.refine_scale) == (12, 0.0)
    own = InferenceSettings(iters=3, input_scale=1.25, refine_scale=1.5, refine_iters=2, precision="fp32")
    model = RAFT(RaftConfig.small(upsample_align_corners=False))
    save_flowgap_weights(model, tmp_path / "w.pth", "small", inference=own)
    clear_cache()
    backend = make_flow_backend("raft", weights=tmp_path / "w.pth")
    assert backend.settings == own
    backend = make_flow_backend("raft", weights=tmp_path / "w.pth", iters=5, refine_scale=0)
    assert backend.settings == InferenceSettings(iters=5, input_scale=1.25, refine_scale=0.0, refine_iters=2)
    save_flowgap_weights(model, tmp_path / "plain.pth", "small")
    assert make_flow_backend("raft", weights=tmp_path / "plain.pth").settings == RAFT_DEFAULTS


def test_a_malformed_settings_record_is_a_one_line_error(tmp_path):
    model = RAFT(RaftConfig.small())
    save_flowgap_weights(model, tmp_path / "w.pth", "small")
    obj = torch.load(tmp_path / "w.pth", weights_only=True)
    for bad, needle in (({"iters": 2, "zoom": 3}, "unknown inference settings"), ({"refine_iters": 0}, "refine_iters"),
                        ([1, 2], "expected a mapping")):
        obj["inference"] = bad
        torch.save(obj, tmp_path / "bad.pth")
        clear_cache()
        _one_line_error(needle, weights=tmp_path / "bad.pth")


@pytest.mark.parametrize("options, needle", [
    ({"refine_scale": float("nan")}, "refine_scale must be 0"), ({"refine_scale": 8.0}, "refine_scale must be 0"),
    ({"refine_scale": -1.0}, "refine_scale must be 0"), ({"refine_iters": 0}, "refine_iters must be >= 1"),
    ({"refine_min_scale": 0.0}, "refine_min_scale must be within"),
    ({"refine_max_flow": -1.0}, "refine_max_flow must be 0"), ({"refine_max_flow": float("inf")}, "refine_max_flow"),
])
def test_bad_refinement_settings_are_refused(options, needle):
    with pytest.raises(ValueError, match=needle):
        make_flow_backend("raft", random_init_seed=1, **options)


def test_frames_too_small_after_zooming_name_the_input_scale():
    backend = make_flow_backend("raft", random_init_seed=1, iters=1, input_scale=0.5)
    img1, img2 = textured_pair(100, 100, (1.0, 0.5))
    with pytest.raises(ValueError, match="50×50 at input scale 0.5") as info:
        backend.estimate(img1, img2)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("scale", [0.0, -1.0, float("nan"), 8.0])
def test_bad_input_scale_is_refused(scale):
    with pytest.raises(ValueError, match="input_scale"):
        make_flow_backend("raft", random_init_seed=1, input_scale=scale)


def test_backend_warm_start_carries_previous_flow():
    img1, img2 = textured_pair(64, 64, (2.0, 1.0))
    warm = make_flow_backend("raft", random_init_seed=3, iters=1, warm_start=True)
    cold = make_flow_backend("raft", random_init_seed=3, iters=1)
    first = warm.estimate(img1, img2)
    assert np.array_equal(first, cold.estimate(img1, img2))   # nothing to carry on the first pair
    second = warm.estimate(img1, img2)
    assert not np.allclose(second, first)
    warm.reset()
    assert np.array_equal(warm.estimate(img1, img2), first)


def test_corr_block_lookup_matches_brute_force_and_channel_order():
    torch.manual_seed(0)
    f1, f2 = torch.randn(1, 8, 6, 7), torch.randn(1, 8, 6, 7)
    r = 2
    corr = CorrBlock(f1, f2, num_levels=2, radius=r)
    coords = torch.zeros(1, 2, 6, 7)
    coords[0, 0] = torch.arange(7.0).view(1, 7)     # zero flow: coords = pixel grid
    coords[0, 1] = torch.arange(6.0).view(6, 1)
    out = corr(coords)
    assert out.shape == (1, 2 * (2 * r + 1) ** 2, 6, 7)
    y, x = 3, 3
    for i, dx in enumerate(range(-r, r + 1)):        # x offset is the slow index (official layout)
        for j, dy in enumerate(range(-r, r + 1)):
            expected = (f1[0, :, y, x] * f2[0, :, y + dy, x + dx]).sum() / np.sqrt(8)
            assert out[0, i * (2 * r + 1) + j, y, x].item() == pytest.approx(expected.item(), abs=1e-5)


def test_corr_pyramid_levels_are_the_volume_average_pooled_over_the_second_frame():
    import torch.nn.functional as F

    torch.manual_seed(2)
    n, d, h, w = 1, 16, 30, 40
    f1, f2 = torch.randn(n, d, h, w), torch.randn(n, d, h, w)
    volume = (torch.einsum("ndp,ndq->npq", f1.reshape(n, d, -1), f2.reshape(n, d, -1)) / np.sqrt(d))
    expected = volume.reshape(n * h * w, 1, h, w)
    corr = CorrBlock(f1, f2, num_levels=4, radius=3)
    for level, got in enumerate(corr.pyramid):
        if level:
            expected = F.avg_pool2d(expected, 2, stride=2)
        assert got.shape == expected.shape == (n * h * w, 1, h // 2 ** level, w // 2 ** level)
        torch.testing.assert_close(got, expected, atol=2e-5, rtol=1e-5)


def test_convex_upsampling_of_constant_flow_is_exact_inside():
    flow = torch.zeros(1, 2, 4, 5)
    flow[:, 0], flow[:, 1] = 1.25, -0.5
    up = convex_upsample(flow, torch.randn(1, 576, 4, 5))
    assert up.shape == (1, 2, 32, 40)
    inner = up[0, :, 8:24, 8:32]            # coarse cells whose 3×3 window lies inside (RAFT pads with 0)
    assert torch.allclose(inner[0], torch.full_like(inner[0], 10.0))
    assert torch.allclose(inner[1], torch.full_like(inner[1], -4.0))
    assert not torch.allclose(up[0, 0, :8], torch.full((8, 40), 10.0))


@pytest.mark.parametrize("h, w", [(15, 20), (38, 50)])
def test_bilinear_upsampling_from_block_centres_is_exact_for_linear_flow_at_any_size(h, w):
    # A linear field sampled at the 8×8 blocks' centres (8i + 3.5) must come back exactly wherever the
    # interpolation is not clamped at the border, whatever the frame size.
    a, b, c = 0.12, -0.05, 2.0
    ys, xs = np.mgrid[0:h, 0:w]
    coarse = (a * (8 * xs + 3.5) + b * (8 * ys + 3.5) + c) / 8.0
    flow = torch.from_numpy(np.stack([coarse, -coarse])).float().unsqueeze(0)
    Y, X = np.mgrid[0:8 * h, 0:8 * w]
    exact = a * X + b * Y + c
    inside = (slice(4, 8 * h - 4), slice(4, 8 * w - 4))
    centres = upflow8(flow, align_corners=False)[0].numpy()
    assert np.allclose(centres[0][inside], exact[inside], atol=1e-4)
    assert np.allclose(centres[1][inside], -exact[inside], atol=1e-4)
    corners = upflow8(flow, align_corners=True)[0].numpy()
    # The RAFT authors' convention stretches the grid to the corners: off by up to 3.5 px × the gradient.
    assert np.abs(corners[0] - exact).max() > 0.3


def test_weights_file_records_the_upsampling_convention(tmp_path):
    centres = RAFT(RaftConfig.small(upsample_align_corners=False))
    save_flowgap_weights(centres, tmp_path / "centres.pth", "small")
    loaded = load_raft_state_dict(tmp_path / "centres.pth")
    assert loaded.layout == "flowgap" and loaded.variant == "small"
    assert loaded.upsample_align_corners is False and loaded.config().upsample_align_corners is False
    # A version-1 file (before the convention was recorded) was trained with the RAFT authors' corners.
    obj = torch.load(tmp_path / "centres.pth", weights_only=True)
    v1 = {k: v for k, v in obj.items() if k != "upsample_align_corners"} | {"version": 1}
    torch.save(v1, tmp_path / "v1.pth")
    assert load_raft_state_dict(tmp_path / "v1.pth").upsample_align_corners is True
    # The backend builds its model with the file's convention, so the two files give different flow.
    img1, img2 = textured_pair(64, 72, (1.5, -1.0))
    a = make_flow_backend("raft", weights=tmp_path / "centres.pth", iters=2)
    b = make_flow_backend("raft", weights=tmp_path / "v1.pth", iters=2)
    assert a.model.config.upsample_align_corners is False and b.model.config.upsample_align_corners is True
    assert not np.array_equal(a.estimate(img1, img2), b.estimate(img1, img2))
    torch.save(obj | {"upsample_align_corners": "yes"}, tmp_path / "bad.pth")
    torch.save(obj | {"version": 4}, tmp_path / "v4.pth")
    for name, needle in (("bad.pth", "upsample_align_corners"), ("v4.pth", "version 4")):
        with pytest.raises(FlowWeightsError, match=needle):
            make_flow_backend("raft", weights=tmp_path / name)


def test_converter_writes_flowgap_layout(tmp_path, capsys):
    from companion.flow.raft.convert import main

    model = random_model("small", seed=5)
    torch.save(ours_to_torchvision(model.state_dict(), "small"), tmp_path / "tv.pth")
    assert main([str(tmp_path / "tv.pth"), str(tmp_path / "out.pth")]) == 0
    assert "torchvision layout, RAFT-small" in capsys.readouterr().out
    obj = torch.load(tmp_path / "out.pth", weights_only=True)
    assert obj["format"] == "flowgap-raft" and obj["variant"] == "small"
    assert obj["upsample_align_corners"] is True      # as the RAFT authors trained it
    img1, img2 = textured_pair(64, 64, (1.0, 0.0))
    a = make_flow_backend("raft", weights=tmp_path / "tv.pth", iters=1).estimate(img1, img2)
    b = make_flow_backend("raft", weights=tmp_path / "out.pth", iters=1).estimate(img1, img2)
    assert np.array_equal(a, b)
    assert main([str(tmp_path / "absent.pth"), str(tmp_path / "x.pth")]) == 1


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
def test_cuda_matches_cpu():
    torch.backends.cuda.matmul.allow_tf32 = False       # compare like with like
    torch.backends.cudnn.allow_tf32 = False
    img1, img2 = textured_pair(64, 64, (1.0, 0.5))
    cpu = make_flow_backend("raft", random_init_seed=4, iters=3).estimate(img1, img2)
    gpu = make_flow_backend("raft", random_init_seed=4, iters=3, device="cuda")
    assert gpu.device.startswith("cuda")
    np.testing.assert_allclose(gpu.estimate(img1, img2), cpu, atol=2e-2, rtol=1e-3)


def contraction_weights(backend, alpha: float = 0.5, target=(1.5, -0.75), eps: float = 1e-2) -> None:
    """Hand-set RAFT-small update weights so that each iteration does flow += alpha·(target − flow).

    The motion features end with the raw flow; the GRU's update gate is forced open (z = 1) and its candidate
    carries tanh(eps·flow) in hidden channels 0–1; the flow head splits them into ± ReLU parts and maps them
    back to −alpha·flow, plus alpha·target as bias.  A contraction: any start converges to the target.
    """
    ub = backend.model.update_block
    hidden, flow_ch = 96, 96 + 64 + 80                      # h, then x = [context 64, motion 80 + flow 2]
    with torch.no_grad():
        for conv in (ub.gru.convz, ub.gru.convr, ub.gru.convq, ub.flow_head.conv1, ub.flow_head.conv2):
            conv.weight.zero_()
            conv.bias.zero_()
        ub.gru.convz.bias.fill_(30.0)
        ub.gru.convq.weight[0, flow_ch, 1, 1] = eps
        ub.gru.convq.weight[1, flow_ch + 1, 1, 1] = eps
        for k in range(2):
            ub.flow_head.conv1.weight[2 * k, k, 1, 1] = 1.0
            ub.flow_head.conv1.weight[2 * k + 1, k, 1, 1] = -1.0
            ub.flow_head.conv2.weight[k, 2 * k, 1, 1] = -alpha / eps
            ub.flow_head.conv2.weight[k, 2 * k + 1, 1, 1] = alpha / eps
            ub.flow_head.conv2.bias[k] = alpha * target[k] / 8.0     # the loop works in 1/8-res pixels
    assert hidden == ub.gru.convz.out_channels


def test_warm_start_converges_to_cold_result_with_enough_iterations():
    img1, img2 = textured_pair(64, 64, (1.0, 0.5))
    # the hand-set update works in the frames' pixels: one pass on the frames as they are
    backend = make_flow_backend("raft", random_init_seed=6, input_scale=1.0, refine_scale=0)
    contraction_weights(backend)
    init = np.zeros((64, 64, 2), np.float32)
    init[..., 0], init[..., 1] = -3.0, 2.0
    few_cold = backend.estimate(img1, img2, iters=2)
    few_warm = backend.estimate(img1, img2, iters=2, flow_init=init)
    assert np.abs(few_warm - few_cold).max() > 0.5          # the start matters after a few iterations (0.75)
    cold = backend.estimate(img1, img2, iters=30)
    warm = backend.estimate(img1, img2, iters=30, flow_init=init)
    np.testing.assert_allclose(warm, cold, atol=1e-3)       # ... and not after enough of them
    np.testing.assert_allclose(cold[..., 0], 1.5, atol=2e-3)
    np.testing.assert_allclose(cold[..., 1], -0.75, atol=2e-3)


# --- RAFT-small-convex: RAFT-small with a learned convex upsampling head -----------------------------------

def test_small_convex_shapes_and_its_file_is_recognised(tmp_path):
    model = RAFT(RaftConfig.small_convex()).eval()
    assert model.config.variant == "small-convex" and model.update_block.mask is not None
    small = RAFT(RaftConfig.small())
    extra = sum(p.numel() for p in model.parameters()) - sum(p.numel() for p in small.parameters())
    assert extra == (96 * 9 + 1) * 128 + (128 + 1) * 576      # the mask head: 3×3 96→128, 1×1 128→576
    img = torch.rand(2, 3, 64, 96) * 255
    with torch.inference_mode():
        out = model(img, img.flip(-1), iters=3, all_predictions=True)
    assert out.flow_up.shape == (2, 2, 64, 96) and out.flow_low.shape == (2, 2, 8, 12) and len(out.predictions) == 3
    save_flowgap_weights(model, tmp_path / "convex.pth", "small-convex")
    clear_cache()
    assert load_raft_state_dict(tmp_path / "convex.pth").variant == "small-convex"
    backend = make_flow_backend("raft", weights=tmp_path / "convex.pth", iters=2)
    assert backend.variant == "small-convex" and backend.estimate(*textured_pair(64, 64, (1, 1))).shape == (64, 64, 2)


def test_a_new_convex_head_upsamples_like_the_bilinear_model_it_grows_from():
    small = random_model("small", seed=3)
    convex = RAFT(RaftConfig.small_convex()).eval()
    missing = convex.load_state_dict(small.state_dict(), strict=False).missing_keys
    assert sorted(missing) == sorted(k for k in convex.state_dict() if k.startswith("update_block.mask."))
    small.config = RaftConfig.small(upsample_align_corners=False)      # the centres convention, as convex's
    img1, img2 = (torch.from_numpy(a).permute(2, 0, 1)[None].float() for a in textured_pair(64, 80, (2.0, -1.0)))
    with torch.inference_mode():
        a, b = small(img1, img2, iters=2).flow_up, convex(img1, img2, iters=2).flow_up
    # the same coarse flow; the head's bilinear start leaks 1 % weight onto each of the other window cells
    assert (a - b).abs().mean() < 0.02 * a.abs().mean() + 1e-3


def test_bilinear_mask_logits_reproduce_bilinear_upsampling_of_a_linear_field():
    from companion.flow.raft.upsample import bilinear_mask_logits

    h, w = 6, 7
    ys, xs = torch.meshgrid(torch.arange(h, dtype=torch.float32), torch.arange(w, dtype=torch.float32), indexing="ij")
    flow = torch.stack([0.3 * xs - 0.1 * ys + 1.0, 0.2 * ys + 0.05 * xs]).unsqueeze(0)
    logits = bilinear_mask_logits(floor=1e-9).view(1, 576, 1, 1).expand(1, 576, h, w)
    up = convex_upsample(flow, logits, pad="replicate")
    ref = upflow8(flow, align_corners=False)
    assert torch.allclose(up[..., 4:-4, 4:-4], ref[..., 4:-4, 4:-4], atol=1e-4)


def test_replicate_padding_keeps_a_constant_flow_exact_up_to_the_border():
    flow = torch.full((1, 2, 4, 5), 1.25)
    mask = torch.randn(1, 576, 4, 5)
    assert torch.allclose(convex_upsample(flow, mask, pad="replicate"), torch.full((1, 2, 32, 40), 10.0))
    assert not torch.allclose(convex_upsample(flow, mask, pad="zeros"), torch.full((1, 2, 32, 40), 10.0))
    with pytest.raises(ValueError, match="unknown convex-upsampling padding"):
        convex_upsample(flow, mask, pad="reflect")


# --- precision ------------------------------------------------------------------------------------------

def test_native_bf16_is_read_from_the_cpu_flags():
    from companion.flow.raft.settings import cpu_has_native_bf16

    assert cpu_has_native_bf16("processor: 0\nflags\t\t: fpu sse avx2 avx512f avx512_bf16 avx512vl\n")
    assert cpu_has_native_bf16("flags : fpu amx_bf16 amx_tile\n")
    assert not cpu_has_native_bf16("flags : fpu sse avx2 avx512f avx512bw\n")
    assert not cpu_has_native_bf16("")


def test_auto_precision_falls_back_to_fp32_with_a_log_line_where_the_cpu_has_no_bf16(caplog, monkeypatch):
    from companion.flow.raft import settings

    monkeypatch.setattr(settings, "_fallback_logged", False)
    with caplog.at_level("INFO", logger="companion.flow.raft.settings"):
        assert settings.resolve_precision("auto", torch.device("cpu"), native_bf16=False) == "fp32"
    assert "no AVX512-BF16 or AMX; running in float32" in caplog.text
    assert settings.resolve_precision("auto", torch.device("cpu"), native_bf16=True) == "bf16"
    assert settings.resolve_precision("bf16", torch.device("cpu"), native_bf16=False) == "bf16"   # as asked
    assert settings.resolve_precision("auto", torch.device("cuda"), native_bf16=True) == "fp32"
    monkeypatch.setattr(settings, "cpu_has_native_bf16", lambda: False)
    backend = make_flow_backend("raft", random_init_seed=1, precision="auto")
    assert backend.precision == "fp32" and backend.describe().endswith(", fp32")


def test_bf16_and_fp32_agree_on_a_textured_pair():
    img1, img2 = textured_pair(96, 128, (2.5, -1.5))
    flows = {p: make_flow_backend("raft", random_init_seed=7, iters=3, precision=p).estimate(img1, img2)
             for p in ("fp32", "bf16")}
    diff = np.abs(flows["bf16"] - flows["fp32"])
    scale = np.abs(flows["fp32"]).mean()
    assert diff.mean() < 0.05 * scale + 0.01 and not np.array_equal(flows["bf16"], flows["fp32"])


# --- RAFT-small-refined: a quarter-resolution correction after the iterations ------------------------------

def test_small_refined_starts_as_the_convex_model_it_grows_from_and_is_recognised(tmp_path):
    convex = RAFT(RaftConfig.small_convex()).eval()
    refined = RAFT(RaftConfig.small_refined()).eval()
    missing = refined.load_state_dict(convex.state_dict(), strict=False).missing_keys
    assert missing and all(k.startswith("refiner.") for k in missing)
    img1, img2 = (torch.from_numpy(a).permute(2, 0, 1)[None].float() for a in textured_pair(96, 128, (3.0, -1.5)))
    with torch.inference_mode():
        a = convex(img1, img2, iters=2)
        b = refined(img1, img2, iters=2, all_predictions=True)
    assert b.flow_up.shape == a.flow_up.shape and len(b.predictions) == 3      # 2 iterations + the refinement
    # no correction yet: the convex flow, pooled to the 1/4 grid and upsampled bilinearly again (the head's
    # start, which leaks 1 % weight onto each other window cell)
    import torch.nn.functional as F

    pooled = F.avg_pool2d(a.flow_up, 4)
    expected = F.interpolate(pooled, scale_factor=4, mode="bilinear", align_corners=False)
    inner = (..., slice(4, -4), slice(4, -4))
    assert (b.flow_up - expected)[inner].abs().mean() < 0.03 * pooled.abs().mean() + 1e-3
    save_flowgap_weights(refined, tmp_path / "r.pth", "small-refined")
    clear_cache()
    assert load_raft_state_dict(tmp_path / "r.pth").variant == "small-refined"


def test_small_refined_can_skip_its_quarter_head_and_then_flows_as_its_convex_iterations_do():
    """InferenceSettings.quarter_refine False (spec ``quarter=0``): RAFT-small-refined's quarter-resolution head
    and the quarter-resolution features it reads are not computed; the flow is the iterations' convex-upsampled
    one, and a sequence still reuses each frame's features."""
    a, b = textured_pair(96, 128, (1.5, 0.5))
    c = np.roll(b, (1, 2), axis=(0, 1))
    skip = make_flow_backend("raft", random_init_seed=0, iters=2, variant="small-refined", quarter_refine=False)
    full = make_flow_backend("raft", random_init_seed=0, iters=2, variant="small-refined")
    with torch.no_grad():                # a head that corrects something, so that skipping it shows
        weight = full.model.refiner.flow.weight
        weight.copy_(0.01 * torch.randn(weight.shape, generator=torch.Generator().manual_seed(3)))

    def untouched(*_args, **_kw):
        raise AssertionError("the quarter-resolution head ran")

    skip.model.refiner.forward = untouched
    img1, img2 = (torch.from_numpy(x).permute(2, 0, 1)[None].float() for x in (a, b))
    with torch.inference_mode():
        convex = full.model(img1, img2, iters=2, quarter_refine=False)
    assert convex.fquarter2 is None
    np.testing.assert_allclose(skip.estimate(a, b), convex.flow_up[0].permute(1, 2, 0).numpy(), atol=1e-3)
    assert np.abs(full.estimate(a, b) - skip.estimate(a, b)).max() > 1e-3
    fresh = make_flow_backend("raft", random_init_seed=0, iters=2, variant="small-refined", quarter_refine=False)
    fresh.model.refiner.forward = untouched
    np.testing.assert_allclose(skip.estimate(b, c), fresh.estimate(b, c), atol=1e-3)   # b's features reused
    assert "no quarter-resolution head" in skip.describe() and "quarter" not in full.describe()
    assert parse_backend("raft:quarter=0,patch=3")[1] == {"quarter_refine": False, "patch_levels": 3}
    with pytest.raises(ValueError, match="quarter"):
        parse_backend("raft:quarter=yes")


def test_local_correlation_is_the_dot_product_over_the_window():
    from companion.flow.raft.refine import local_correlation, warp

    torch.manual_seed(1)
    f1, f2 = torch.randn(1, 4, 6, 7), torch.randn(1, 4, 6, 7)
    out = local_correlation(f1, f2, radius=1)
    y, x = 3, 2
    for i, (dy, dx) in enumerate((dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1)):
        expected = (f1[0, :, y, x] * f2[0, :, y + dy, x + dx]).sum() / 2.0
        assert out[0, i, y, x].item() == pytest.approx(expected.item(), abs=1e-5)
    shift = torch.zeros(1, 2, 6, 7)
    shift[:, 0] = 1.0                                          # one pixel right
    assert torch.allclose(warp(f2, shift)[..., :-1], f2[..., 1:], atol=1e-5)


def test_variational_refinement_runs_after_raft_when_the_settings_ask():
    from companion.flow.raft.variational import variational_refine

    img1, img2 = textured_pair(96, 128, (1.5, 0.5))
    plain = make_flow_backend("raft", random_init_seed=0, iters=2)
    refined = make_flow_backend("raft", random_init_seed=0, iters=2, variational_levels=2, variational_iters=5)
    raw = plain.estimate(img1, img2)
    np.testing.assert_allclose(refined.estimate(img1, img2), variational_refine(img1, img2, raw, 2, 5), atol=1e-5)
    assert "variational refinement on 2 scales" in refined.describe()
    name, options = parse_backend("raft:vr=2,vr_iters=5")
    assert options == {"variational_levels": 2, "variational_iters": 5}


def test_patch_refinement_runs_after_raft_and_before_the_variational_step():
    from companion.flow.raft.variational import patch_refine, variational_refine

    img1, img2 = textured_pair(96, 128, (1.5, 0.5))
    plain = make_flow_backend("raft", random_init_seed=0, iters=2)
    both = make_flow_backend("raft", random_init_seed=0, iters=2, patch_levels=3, variational_levels=1,
                             variational_iters=5)
    expected = variational_refine(img1, img2, patch_refine(img1, img2, plain.estimate(img1, img2), 3), 1, 5)
    np.testing.assert_allclose(both.estimate(img1, img2), expected, atol=1e-5)
    assert "DIS patch refinement on 3 scales, variational refinement on 1 scale" in both.describe()
    assert parse_backend("raft:patch=3,vr=0")[1] == {"patch_levels": 3, "variational_levels": 0}


def test_patch_refinement_pulls_a_coarse_flow_onto_the_true_motion_and_needs_it_to_start_from():
    from companion.flow.raft.variational import patch_refine

    img1, img2 = textured_pair(120, 160, (18.0, -9.0))
    inner = (slice(30, -30), slice(30, -30))
    truth = np.array([18.0, -9.0], np.float32)
    coarse = np.broadcast_to(truth + np.float32([0.8, -0.6]), img1.shape[:2] + (2,)).copy()  # 1 px off
    refined = patch_refine(img1, img2, coarse, levels=2)
    assert not np.shares_memory(refined, coarse)
    error = np.linalg.norm(refined[inner] - truth, axis=-1)
    assert np.median(error) < 0.1, np.median(error)       # from 1 px off to within a tenth of a pixel
    # on the full frame alone a patch search steps a few pixels: started from zero it stays short of 20 px
    from_zero = patch_refine(img1, img2, np.zeros_like(coarse), levels=1)
    assert np.median(np.linalg.norm(from_zero[inner] - truth, axis=-1)) > 1.0
    np.testing.assert_array_equal(patch_refine(img1, img2, coarse, levels=0), coarse)
    with pytest.raises(ValueError, match="levels"):
        patch_refine(img1, img2, coarse, levels=-1)


@pytest.mark.parametrize("options, needle", [({"variational_levels": 5}, "variational_levels"),
                                             ({"variational_iters": 0}, "variational_iters"),
                                             ({"patch_levels": 5}, "patch_levels")])
def test_bad_variational_settings_are_refused(options, needle):
    with pytest.raises(ValueError, match=needle):
        make_flow_backend("raft", random_init_seed=0, **options)


@pytest.mark.parametrize("variant", ["small-convex", "small-refined"])
def test_a_sequence_reuses_the_shared_frames_features_and_flows_as_if_it_did_not(variant):
    a, b = textured_pair(96, 128, (1.5, 0.5))
    c = np.roll(b, (1, 2), axis=(0, 1))
    seq = make_flow_backend("raft", random_init_seed=0, iters=3, refine_scale=0, variant=variant)
    fresh = make_flow_backend("raft", random_init_seed=0, iters=3, refine_scale=0, variant=variant)
    if variant == "small-refined":       # its correction starts at zero: give it one that reads the features
        for backend in (seq, fresh):
            weight = backend.model.refiner.flow.weight
            with torch.no_grad():
                weight.copy_(0.01 * torch.randn(weight.shape, generator=torch.Generator().manual_seed(3)))
    assert seq.reuses_features
    calls = []
    original = seq.model.fnet.forward
    seq.model.fnet.forward = lambda x, *args, **kw: calls.append(x.shape[0]) or original(x, *args, **kw)
    seq.estimate(a, b)
    second = seq.estimate(b, c)                       # b's features come from the first pair
    assert calls == [2, 1]                            # one frame encoded for the second pair, not two
    np.testing.assert_allclose(second, fresh.estimate(b, c), atol=1e-3)
    seq.estimate(a, c)                                # a new first frame: both encoded again
    assert calls == [2, 1, 2]
    assert not make_flow_backend("raft", random_init_seed=0, refine_scale=2.0).reuses_features

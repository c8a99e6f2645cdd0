import numpy as np
import pytest

from companion.flow import FlowBackend, available_backends, make_flow_backend
from tests.companion.synthetic import textured_pair

SHIFT = (2.5, -1.5)


@pytest.mark.parametrize("name, options, bound", [
    ("dis", {"preset": "ultrafast"}, 0.4),
    ("dis", {"preset": "fast"}, 0.4),
    ("dis", {"preset": "medium"}, 0.1),
    ("dis", {"preset": "fine"}, 0.1),
    ("farneback", {}, 0.1),
])
def test_known_shift_epe(name, options, bound):
    img1, img2 = textured_pair(120, 160, SHIFT)
    backend = make_flow_backend(name, **options)
    assert isinstance(backend, FlowBackend) and backend.name == name and backend.device == "cpu"
    flow = backend.estimate(img1, img2)
    assert flow.shape == (120, 160, 2) and flow.dtype == np.float32
    epe = np.hypot(flow[..., 0] - SHIFT[0], flow[..., 1] - SHIFT[1])[8:-8, 8:-8]
    assert epe.mean() < bound, f"{name} {options}: mean EPE {epe.mean():.3f} px"


def test_dis_warm_start_uses_previous_flow():
    """A 23 px shift is beyond DIS ultrafast's reach from zero; started from the previous call's flow (here one
    refined from the exact shift) it is found.  Without warm start each call starts from zero again, even after
    a call given an initial flow (OpenCV's DIS would otherwise keep using it)."""
    shift = (20.0, -12.0)
    img1, img2 = textured_pair(120, 160, shift)
    exact = np.broadcast_to(np.float32(shift), (120, 160, 2)).copy()

    def epe(flow):
        return float(np.hypot(flow[..., 0] - shift[0], flow[..., 1] - shift[1])[30:-30, 30:-30].mean())

    for warm, bound_ok in ((True, lambda e: e < 0.5), (False, lambda e: e > 5.0)):
        backend = make_flow_backend("dis", preset="ultrafast", warm_start=warm)
        assert epe(backend.estimate(img1, img2, flow_init=exact)) < 0.5
        assert bound_ok(epe(backend.estimate(img1, img2))), f"warm_start={warm}"
    backend.reset()
    assert epe(make_flow_backend("dis", preset="ultrafast").estimate(img1, img2)) > 5.0   # cold: lost


def test_registry_rejects_unknown_and_bad_inputs():
    assert {"dis", "farneback", "raft"} <= set(available_backends())
    with pytest.raises(KeyError, match="unknown flow backend"):
        make_flow_backend("nope")
    with pytest.raises(ValueError, match="preset"):
        make_flow_backend("dis", preset="slow")
    img = np.zeros((10, 10, 3), np.uint8)
    with pytest.raises(ValueError, match="uint8"):
        make_flow_backend("dis").estimate(img.astype(np.float32), img)
    with pytest.raises(ValueError, match="shape"):
        make_flow_backend("dis").estimate(img, np.zeros((10, 12, 3), np.uint8))


@pytest.mark.parametrize("spec, expected", [
    ("dis", ("dis", {})),
    ("dis:fine", ("dis", {"preset": "fine"})),
    ("raft", ("raft", {})),
    ("raft:large", ("raft", {"variant": "large"})),
    ("raft:scale=1.5", ("raft", {"input_scale": 1.5})),
    ("raft:small,iters=20,scale=2", ("raft", {"variant": "small", "iters": 20, "input_scale": 2.0})),
    ("raft:mirror=1", ("raft", {"mirror_average": True})),
    ("raft:scale=1.5,mirror=0", ("raft", {"input_scale": 1.5, "mirror_average": False})),
    ("raft:refine=0", ("raft", {"refine_scale": 0.0})),
    ("raft:refine=1.5,refine_iters=6", ("raft", {"refine_scale": 1.5, "refine_iters": 6})),
    ("raft:refine_min=1.5,refine_flow=0", ("raft", {"refine_min_scale": 1.5, "refine_max_flow": 0.0})),
    ("raft:small-convex,precision=fp32", ("raft", {"variant": "small-convex", "precision": "fp32"})),
])
def test_backend_specs_parse_to_options(spec, expected):
    from companion.flow.registry import parse_backend

    assert parse_backend(spec) == expected


@pytest.mark.parametrize("spec, needle", [
    ("raft:zoom=2", "unknown RAFT option 'zoom'"),
    ("raft:scale=big", "scale must be a number"),
    ("raft:precision=fp16", "precision must be auto, bf16 or fp32"),
    ("raft:mirror=yes", "mirror must be 0 or 1"),
    ("raft:refine=x", "refine must be a number"),
    ("raft:refine_iters=1.5", "refine_iters must be a number"),
    ("raft:refine_flow=far", "refine_flow must be a number of pixels"),
    ("farneback:x", "only dis:<preset>"),
])
def test_bad_backend_specs_are_one_line_errors(spec, needle):
    from companion.flow.registry import parse_backend

    with pytest.raises(ValueError, match=needle) as info:
        parse_backend(spec)
    assert "\n" not in str(info.value)

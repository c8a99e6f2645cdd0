"""Flow backends by name: ``make_flow_backend("dis", preset="fast")``.

Backends are imported lazily so that choosing DIS never imports torch.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

from companion.flow.base import FlowBackend

# name -> "module:factory"; a factory takes keyword options and returns a FlowBackend.
_BACKENDS: dict[str, str] = {
    "dis": "companion.flow.opencv_flow:DisBackend",
    "farneback": "companion.flow.opencv_flow:FarnebackBackend",
    "raft": "companion.flow.raft.backend:RaftBackend",
    "groundtruth": "companion.flow.groundtruth:GroundTruthBackend",
}
_FACTORIES: dict[str, Callable[..., FlowBackend]] = {}

# What the companion flies unless told otherwise: the shipped RAFT-small-refined at its default inference
# settings (2 iterations, DIS patch refinement; docs/perception.md), better than DIS fine on the suite, random
# scenes and held-out pairs at about 3x its cost (bench/results.json).
DEFAULT_FLOW = "raft"


def register_flow_backend(name: str, factory: Callable[..., FlowBackend] | str) -> None:
    """Register a backend factory (a callable, or a lazy ``"module:attr"`` string) under ``name``."""
    if isinstance(factory, str):
        _BACKENDS[name] = factory
        _FACTORIES.pop(name, None)
    else:
        _FACTORIES[name] = factory


def available_backends() -> list[str]:
    """Names that ``make_flow_backend`` accepts."""
    return sorted(set(_BACKENDS) | set(_FACTORIES))


def _factory(name: str) -> Callable[..., FlowBackend]:
    if name in _FACTORIES:
        return _FACTORIES[name]
    if name not in _BACKENDS:
        raise KeyError(f"unknown flow backend {name!r}; choose from {available_backends()}")
    module_name, attr = _BACKENDS[name].split(":")
    factory = getattr(importlib.import_module(module_name), attr)
    _FACTORIES[name] = factory
    return factory


def make_flow_backend(name: str, **options) -> FlowBackend:
    """Build the backend registered as ``name`` with its keyword ``options``."""
    return _factory(name)(**options)


def parse_backend(spec: str) -> tuple[str, dict]:
    """A backend spec -> (name, options).

    'dis:fast' -> ('dis', {'preset': 'fast'}); 'raft' -> ('raft', {}); 'raft:large' -> a variant;
    'raft:scale=1.5', 'raft:small,iters=20,mirror=1', 'raft:refine=0' -> RAFT options (``scale`` is the
    backend's ``input_scale``, ``mirror`` its ``mirror_average``, 0 or 1, ``refine`` its ``refine_scale``,
    0 for one pass, ``refine_iters`` its ``refine_iters``, ``refine_min`` its ``refine_min_scale``,
    ``refine_flow`` its ``refine_max_flow``, 0 for a fixed refinement scale, ``patch`` its ``patch_levels``, 0
    for none, ``vr`` its ``variational_levels``,
    0 for none, ``vr_iters`` its ``variational_iters``, ``quarter`` its ``quarter_refine``, 0 or 1, ``precision``
    auto, bf16 or fp32).
    Options not given are the weights file's own.
    """
    name, _, arg = spec.partition(":")
    if not arg:
        return name, {}
    if name == "dis":
        return name, {"preset": arg}
    if name == "raft":
        return name, _raft_options(spec, arg)
    raise ValueError(f"backend {spec!r}: only dis:<preset> and raft:<variant>,{_RAFT_USAGE} take an argument")


def _zero_or_one(text: str) -> bool:
    if text not in ("0", "1"):
        raise ValueError(text)
    return text == "1"


def _precision(text: str) -> str:
    if text not in ("auto", "bf16", "fp32"):
        raise ValueError(text)
    return text


# spec key -> (backend option, parser, what the value must be)
_RAFT_KEYS = {"scale": ("input_scale", float, "a number"), "iters": ("iters", int, "a number"),
              "mirror": ("mirror_average", _zero_or_one, "0 or 1"),
              "refine": ("refine_scale", float, "a number (0: one pass)"),
              "refine_iters": ("refine_iters", int, "a number"),
              "refine_min": ("refine_min_scale", float, "a number"),
              "refine_flow": ("refine_max_flow", float, "a number of pixels (0: a fixed refinement scale)"),
              "patch": ("patch_levels", int, "a number of scales (0: no DIS patch refinement)"),
              "vr": ("variational_levels", int, "a number of scales (0: no variational refinement)"),
              "vr_iters": ("variational_iters", int, "a number"),
              "quarter": ("quarter_refine", _zero_or_one, "0 or 1"),
              "precision": ("precision", _precision, "auto, bf16 or fp32")}
_RAFT_USAGE = ("scale=<s>,iters=<n>,mirror=<0|1>,refine=<s|0>,refine_iters=<n>,refine_min=<s>,refine_flow=<px|0>,"
               "patch=<levels|0>,vr=<levels|0>,vr_iters=<n>,quarter=<0|1>,precision=<auto|bf16|fp32>")


def _raft_options(spec: str, arg: str) -> dict:
    options: dict = {}
    for item in arg.split(","):
        key, eq, value = item.partition("=")
        if not eq:
            options["variant"] = key
            continue
        if key not in _RAFT_KEYS:
            raise ValueError(f"backend {spec!r}: unknown RAFT option {key!r} (use {_RAFT_USAGE})")
        option, kind, what = _RAFT_KEYS[key]
        try:
            options[option] = kind(value)
        except ValueError:
            raise ValueError(f"backend {spec!r}: {key} must be {what} (got {value!r})") from None
    return options

"""Dense optical flow behind one interface: ``make_flow_backend(name, **options).estimate(img1, img2)``.

Backends: ``dis`` and ``farneback`` (OpenCV), ``raft`` (our PyTorch RAFT / RAFT-small), ``groundtruth``
(the renderer's exact flow; evaluation only).  See :mod:`companion.flow.base` for the contract.
"""

from companion.flow.base import FlowBackend, FlowError, FlowWeightsError
from companion.flow.colour import flow_to_colour
from companion.flow.registry import available_backends, make_flow_backend, register_flow_backend

__all__ = ["FlowBackend", "FlowError", "FlowWeightsError", "available_backends", "flow_to_colour",
           "make_flow_backend", "register_flow_backend"]

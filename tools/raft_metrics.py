"""RAFT training's loss, and the validation EPE that judges weights.

:func:`sequence_loss` is RAFT's sequence loss (L1 on valid pixels of every iteration's upsampled flow, weighted
``gamma**(iters-1-k)``), optionally counting the pixels near a motion boundary (:func:`motion_boundaries`) more;
:func:`evaluate` runs a model as the ``raft`` backend's settings say on the fixed validation pairs, with DIS on the
same pairs beside it. Apart from the training run (``tools.raft_training``) because they are what a run is
measured by, and are called on their own.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from companion.flow.raft.backend import InferenceSettings, estimate_flow, resolve_precision
from tools.raft_data import RenderedFlowDataset


def motion_boundaries(flow_gt: torch.Tensor, radius: int = 3, jump_px: float = 0.5) -> torch.Tensor:
    """(B, 1, H, W) float mask of the pixels within ``radius`` of a ground-truth motion boundary: where the flow
    jumps by more than ``jump_px`` (L1) between neighbours, as it does along the opening's outline, whose far
    surface moves less than the wall around it."""
    jump_x = (flow_gt[:, :, :, 1:] - flow_gt[:, :, :, :-1]).abs().sum(1) > jump_px
    jump_y = (flow_gt[:, :, 1:, :] - flow_gt[:, :, :-1, :]).abs().sum(1) > jump_px
    edge = torch.zeros_like(flow_gt[:, 0], dtype=torch.bool)
    edge[:, :, 1:] |= jump_x
    edge[:, :, :-1] |= jump_x
    edge[:, 1:, :] |= jump_y
    edge[:, :-1, :] |= jump_y
    return F.max_pool2d(edge.unsqueeze(1).to(flow_gt.dtype), 2 * radius + 1, stride=1, padding=radius)


def sequence_loss(predictions: list[torch.Tensor], flow_gt: torch.Tensor, valid: torch.Tensor,
                  gamma: float = 0.8, max_flow: float = 400.0,
                  boundary_weight: float = 0.0) -> tuple[torch.Tensor, float]:
    """(loss, EPE of the last prediction) over valid pixels; prediction k of n weighted gamma**(n-1-k).

    ``boundary_weight`` > 0 counts the pixels near a motion boundary (``motion_boundaries``) 1 + that many times:
    the opening's outline is a thin band of the frame that the mask's IoU depends on, and the plain mean over
    pixels hardly sees it.  The loss stays a weighted mean (it is divided by the weights' sum)."""
    mag = torch.linalg.vector_norm(flow_gt, dim=1)
    mask = (valid > 0.5) & (mag < max_flow)
    maskf = mask.unsqueeze(1).to(flow_gt.dtype)
    if boundary_weight > 0:
        maskf = maskf * (1.0 + boundary_weight * motion_boundaries(flow_gt))
    denom = maskf.sum().clamp_min(1.0) * flow_gt.shape[1]
    n = len(predictions)
    loss = flow_gt.new_zeros(())
    for k, pred in enumerate(predictions):
        loss = loss + gamma ** (n - 1 - k) * ((pred - flow_gt).abs() * maskf).sum() / denom
    with torch.no_grad():
        epe = torch.linalg.vector_norm(predictions[-1] - flow_gt, dim=1)[mask]
        epe_value = float(epe.mean()) if epe.numel() else float("nan")
    return loss, epe_value


def _epe_sum(flow: np.ndarray, gt: np.ndarray, valid: np.ndarray) -> tuple[float, int]:
    err = np.linalg.norm(flow.astype(np.float64) - gt, axis=-1)[valid]
    return float(err.sum()), int(err.size)


@torch.no_grad()
def evaluate(model: torch.nn.Module, dataset: RenderedFlowDataset, settings: InferenceSettings,
             device: torch.device, with_dis: bool = False) -> dict:
    """Validation EPE (mean over all valid pixels of all pairs) of ``model`` run as ``settings`` say (the
    ``raft`` backend's :class:`InferenceSettings`), optionally of DIS medium and DIS fine on the same pairs."""
    was_training = model.training
    model.eval()
    precision = resolve_precision(settings.precision, torch.device(device))
    raft_sum = 0.0
    count = 0
    dis = {}
    if with_dis:
        from companion.flow.registry import make_flow_backend

        dis = {preset: [make_flow_backend("dis", preset=preset), 0.0] for preset in ("medium", "fine")}
    for i in range(len(dataset)):
        img1, img2, gt, valid = dataset.pair(i)
        flow, _ = estimate_flow(model, img1, img2, settings, device=device, precision=precision)
        s, c = _epe_sum(flow, gt, valid)
        raft_sum += s
        count += c
        for entry in dis.values():
            dflow = entry[0].estimate(np.rint(img1).astype(np.uint8), np.rint(img2).astype(np.uint8))
            entry[1] += _epe_sum(dflow, gt, valid)[0]
    model.train(was_training)
    two_pass = bool(settings.refine_scale)
    result = {"pairs": len(dataset), "valid_pixels": count, "width": dataset.width, "height": dataset.height,
              "iters": settings.iters, "input_scale": settings.input_scale,
              "mirror_average": settings.mirror_average, "refine_scale": settings.refine_scale,
              "refine_iters": settings.refine_iters if two_pass else 0,
              "refine_min_scale": settings.refine_min_scale if two_pass else 0.0,
              "refine_max_flow": settings.refine_max_flow if two_pass else 0.0,
              "patch_levels": settings.patch_levels,
              "variational_levels": settings.variational_levels,
              "variational_iters": settings.variational_iters if settings.variational_levels else 0,
              "quarter_refine": settings.quarter_refine,
              "precision": precision,
              "epe": raft_sum / count if count else float("nan")}
    for preset, (_, total) in dis.items():
        result[f"dis_{preset}_epe"] = total / count if count else float("nan")
    return result

"""Train (or evaluate) our RAFT on rendered flow pairs: ``flowgap-train-raft``.

Training: RAFT's sequence loss (L1 on valid pixels of every iteration's upsampled flow, weighted
``gamma**(iters-1-k)``), AdamW + OneCycleLR (linear anneal, as the RAFT authors), gradient-norm clipping.
Batch ``t`` (0-based) is always items ``t*batch .. t*batch+batch-1`` of the seeded
:class:`tools.raft_data.RenderedFlowDataset`, so a run is a function of its settings and ``--resume``
continues exactly where a checkpoint left off.

Files under ``--out``:

``checkpoint-NNNNNN.pth``
    Resumable state every ``--save-every`` steps and at the end (the newest ``--keep`` are kept).  It is a
    flowgap-raft weights file (``{"format": "flowgap-raft", "version", "variant", "state_dict"}``, as
    written by :func:`companion.flow.raft.weights.save_flowgap_weights`) with one extra ``"train"`` entry
    (optimizer, scheduler, step, RNG state, settings), so ``make_flow_backend("raft", weights=...)``,
    ``--init`` and ``--eval-only`` accept it as it is.
``raft-<variant>-flowgap.pth``
    The final weights, written by ``save_flowgap_weights``.
``log.jsonl``
    One line per step (loss, training EPE, learning rate) and per validation.
``eval.json``
    Validation EPE of the final weights (and of DIS medium on the same pairs).

``--eval-only WEIGHTS`` prints the validation EPE of any official / torchvision / flowgap RAFT weights on
the fixed validation set, with DIS medium's EPE on the same pairs, and writes ``<out>/eval.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from companion.flow.raft.backend import (
    INPUT_SCALE_RANGE,
    PRECISIONS,
    RAFT_DEFAULTS,
    InferenceSettings,
    describe_settings,
    estimate_flow,
    resolve_precision,
)
from companion.flow.raft.model import VARIANTS
from tools.raft_data import (
    DEFAULT_CROP,
    DEFAULT_HEIGHT,
    DEFAULT_VALIDATION_SIZE,
    DEFAULT_WIDTH,
    VALIDATION_SEED,
    RenderedFlowDataset,
    collate,
    validation_set,
)

PROG = "flowgap-train-raft"
TRAIN_KEYS = ("variant", "steps", "batch", "lr", "wdecay", "clip", "gamma", "iters", "width", "height", "crop",
              "crop_focus", "zoom", "seed", "jitter", "pairs_per_scene", "max_flow", "val_size", "val_iters",
              "upsample", "distance", "precision", "head_lr_mult", "boundary_weight")
UPSAMPLE_MODES = {"centres": False, "corners": True}   # --upsample -> RaftConfig.upsample_align_corners


class CliError(Exception):
    """A bad input: reported as one line, exit status 2."""


# ---------------------------------------------------------------------------------------------------------
# Loss and metrics
# ---------------------------------------------------------------------------------------------------------

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


def inference_overrides(args: argparse.Namespace) -> dict:
    """The inference settings the command line sets (None: not set), as :meth:`InferenceSettings.replace`
    takes them."""
    return {"iters": args.val_iters, "input_scale": args.input_scale, "mirror_average": args.mirror_average,
            "refine_scale": args.refine_scale, "refine_iters": args.refine_iters,
            "refine_min_scale": args.refine_min_scale, "refine_max_flow": args.refine_max_flow,
            "patch_levels": args.patch_levels, "variational_levels": args.variational_levels,
            "variational_iters": args.variational_iters, "quarter_refine": args.quarter_refine,
            "precision": args.eval_precision}


# ---------------------------------------------------------------------------------------------------------
# Model, weights, checkpoints
# ---------------------------------------------------------------------------------------------------------

def build_model(variant: str, upsample: str = "centres"):
    from companion.flow.raft.model import RAFT, RaftConfig

    return RAFT(RaftConfig.for_variant(variant, upsample_align_corners=UPSAMPLE_MODES[upsample]))


# variant being trained -> variants whose weights it can start from, missing only its own new head
GROWS_FROM = {"small-convex": ("small",), "small-refined": ("small-convex", "small")}
NEW_HEAD_PREFIXES = ("update_block.mask.", "refiner.")


def load_weights_into(model: torch.nn.Module, path: str | Path, variant: str) -> str:
    """Load official / torchvision / flowgap weights from ``path`` with the project's loader; layout name.

    RAFT-small weights also start a RAFT-small-convex: everything but its mask head, which keeps its
    bilinear initialisation (see :class:`~companion.flow.raft.model.RAFT`)."""
    from companion.flow.base import FlowWeightsError
    from companion.flow.raft.weights import load_raft_state_dict

    try:
        loaded = load_raft_state_dict(path)
    except FlowWeightsError as exc:
        raise CliError(str(exc)) from None
    grows = loaded.variant in GROWS_FROM.get(variant, ())
    if loaded.variant != variant and not grows:
        raise CliError(f"{path} holds RAFT-{loaded.variant} weights, RAFT-{variant} was requested "
                       f"(use --variant {loaded.variant})")
    try:
        result = model.load_state_dict(loaded.state_dict, strict=not grows)
    except RuntimeError as exc:
        raise CliError(f"{path} does not fit RAFT-{variant}: {str(exc).splitlines()[0][:200]}") from None
    if grows:
        unexpected = list(result.unexpected_keys)
        foreign = [k for k in result.missing_keys if not k.startswith(NEW_HEAD_PREFIXES)]
        if unexpected or foreign:
            raise CliError(f"{path} does not fit RAFT-{variant}: {(unexpected + foreign)[0]}")
        print(f"{PROG}: note: RAFT-{variant} starts from {path}'s RAFT-{loaded.variant} weights; its new heads "
              f"({', '.join(sorted({k.split('.')[0] + '.' + k.split('.')[1] for k in result.missing_keys}))}) "
              f"start as bilinear upsampling and no correction", file=sys.stderr)
    return loaded.layout


def read_weights(path: str | Path):
    """:class:`RaftWeights` of ``path``; a bad file is a one-line :class:`CliError`."""
    from companion.flow.base import FlowWeightsError
    from companion.flow.raft.weights import load_raft_state_dict

    try:
        return load_raft_state_dict(path)
    except FlowWeightsError as exc:
        raise CliError(str(exc)) from None


def upsample_mode(align_corners: bool) -> str:
    """The ``--upsample`` name of an ``upsample_align_corners`` setting."""
    return next(k for k, v in UPSAMPLE_MODES.items() if v == align_corners)


def _rng_state() -> dict:
    state = {"torch": torch.get_rng_state()}
    if torch.cuda.is_available() and torch.cuda.is_initialized():
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def _set_rng_state(state: dict) -> None:
    torch.set_rng_state(state["torch"])
    if "cuda" in state and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])


def save_checkpoint(path: Path, model, optimizer, scheduler, step: int, config: dict,
                    inference: InferenceSettings | None = None) -> Path:
    """A flowgap-raft weights file (with the ``inference`` settings it is validated with) and the training
    state under ``"train"`` (see the module docstring)."""
    from companion.flow.raft.weights import flowgap_weights_record

    path.parent.mkdir(parents=True, exist_ok=True)
    obj = flowgap_weights_record(model, config["variant"], inference)
    obj["train"] = {"optimizer": optimizer.state_dict(), "scheduler": scheduler.state_dict(), "step": step,
                    "rng": _rng_state(), "config": dict(config)}
    tmp = path.with_suffix(path.suffix + ".tmp")
    torch.save(obj, tmp)
    tmp.replace(path)
    return path


def read_checkpoint(path: str | Path) -> dict:
    path = Path(path).expanduser()
    if not path.is_file():
        raise CliError(f"checkpoint not found: {path}")
    try:
        obj = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - any unreadable file gets the same one-line error
        raise CliError(f"checkpoint unreadable: {path} ({type(exc).__name__})") from None
    if not isinstance(obj, dict) or not isinstance(obj.get("train"), dict) or "state_dict" not in obj:
        raise CliError(f"{path} is not a {PROG} checkpoint (no training state; use --init to start from weights)")
    return obj


# ---------------------------------------------------------------------------------------------------------
# Training
# ---------------------------------------------------------------------------------------------------------

def parse_crop(text: str) -> tuple[int, int] | None:
    """'160x120' -> (160, 120); 'none' -> None (train on whole frames)."""
    if str(text).lower() == "none":
        return None
    try:
        w, h = (int(v) for v in str(text).lower().split("x"))
    except ValueError:
        raise CliError(f"--crop must be WIDTHxHEIGHT (e.g. 160x120) or none (got {text!r})") from None
    return w, h


def _device(name: str) -> torch.device:
    try:
        dev = torch.device(name)
    except RuntimeError:
        raise CliError(f"unknown device {name!r} (use cpu or cuda)") from None
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise CliError("--device cuda requested but CUDA is not available")
    return dev


def _log(path: Path, record: dict) -> None:
    with path.open("a") as f:
        f.write(json.dumps(record) + "\n")


def _prune(out: Path, keep: int) -> None:
    ckpts = sorted(out.glob("checkpoint-*.pth"))
    for old in ckpts[:-keep] if keep > 0 else []:
        old.unlink(missing_ok=True)


def train(args: argparse.Namespace) -> dict:
    device = _device(args.device)
    config = {k: getattr(args, k) for k in TRAIN_KEYS}
    resume = read_checkpoint(args.resume) if args.resume else None
    if resume is not None:
        stored = resume["train"]["config"]
        changed = [k for k in TRAIN_KEYS if k in stored and stored[k] != config[k]
                   and getattr(args, "_explicit", {}).get(k)]
        if changed:
            print(f"{PROG}: note: resuming with the checkpoint's settings; ignoring {', '.join(changed)}",
                  file=sys.stderr)
        config.update({k: stored[k] for k in TRAIN_KEYS if k in stored})
        if "crop" not in stored:
            config["crop"] = "none"        # checkpoints from before --crop existed trained on whole frames
        if "zoom" not in stored:
            config["zoom"] = None          # nor did they zoom
        if "crop_focus" not in stored:
            config["crop_focus"] = 0.0     # nor move crops onto the opening
        if "upsample" not in stored:
            config["upsample"] = "corners"  # nor upsample from block centres
        if "distance" not in stored:
            config["distance"] = None      # nor stand further than 2.6 m from the wall
        if "precision" not in stored:
            config["precision"] = "fp32"   # nor train under bf16 autocast
        if "boundary_weight" not in stored:
            config["boundary_weight"] = 0.0  # nor weight the motion boundaries
        if "head_lr_mult" not in stored:
            config["head_lr_mult"] = 1.0   # nor give new heads a larger learning rate

    out = Path(args.out)
    if args.init and not resume:
        read_weights(args.init)  # fail early with a one-line error
    dataset = RenderedFlowDataset(seed=config["seed"], length=max(1, config["steps"] * config["batch"]),
                                  width=config["width"], height=config["height"],
                                  pairs_per_scene=config["pairs_per_scene"], exposure_jitter=config["jitter"],
                                  crop=parse_crop(config.get("crop", "none")), crop_focus=config["crop_focus"],
                                  zoom=tuple(config["zoom"]) if config.get("zoom") else None,
                                  distance=tuple(config["distance"]) if config.get("distance") else None)
    val = validation_set(config["val_size"], config["width"], config["height"]) if config["val_size"] else None
    # Validation runs the weights as they will be run: bf16-trained weights in bf16 where the CPU has it.
    trained_precision = "auto" if config["precision"] == "bf16" else "fp32"
    val_settings = RAFT_DEFAULTS.replace(precision=trained_precision).replace(
        **{**inference_overrides(args), "iters": config["val_iters"]})

    torch.manual_seed(config["seed"])
    model = build_model(config["variant"], config["upsample"]).to(device)
    if resume is not None:
        model.load_state_dict(resume["state_dict"], strict=True)
    elif args.init:
        load_weights_into(model, args.init, config["variant"])
    model.train()
    # The heads a variant adds (convex upsampling, quarter refinement) may learn faster than the weights they
    # grow from: Adam moves every parameter by about the learning rate per step, and RAFT's mask logits are
    # scaled by 0.25.
    heads = [p for name, p in model.named_parameters() if name.startswith(NEW_HEAD_PREFIXES)]
    rest = [p for name, p in model.named_parameters() if not name.startswith(NEW_HEAD_PREFIXES)]
    if not heads or (resume is not None and len(resume["train"]["optimizer"]["param_groups"]) == 1):
        rest, heads = rest + heads, []       # (checkpoints from before the head group have one group)
    groups = [{"params": rest, "lr": config["lr"]}]
    if heads:
        groups.append({"params": heads, "lr": config["lr"] * config["head_lr_mult"]})
    lrs = [g["lr"] for g in groups]
    optimizer = torch.optim.AdamW(groups, weight_decay=config["wdecay"], eps=1e-8)
    scheduler = torch.optim.lr_scheduler.OneCycleLR(optimizer, max_lr=lrs, total_steps=config["steps"] + 100,
                                                    pct_start=0.05, cycle_momentum=False, anneal_strategy="linear")
    step = 0
    if resume is not None:
        optimizer.load_state_dict(resume["train"]["optimizer"])
        scheduler.load_state_dict(resume["train"]["scheduler"])
        step = int(resume["train"]["step"])
        _set_rng_state(resume["train"]["rng"])
    out.mkdir(parents=True, exist_ok=True)
    log_path = out / "log.jsonl"

    from torch.utils.data import DataLoader

    stop = min(config["steps"], args.stop_at or config["steps"])
    if stop <= step:
        raise CliError(f"--stop-at {stop} is not after the checkpoint's step {step}")
    indices = list(range(step * config["batch"], stop * config["batch"]))
    loader = DataLoader(dataset, batch_size=config["batch"], sampler=indices, num_workers=args.workers,
                        collate_fn=collate, drop_last=False, persistent_workers=False,
                        multiprocessing_context="spawn" if args.workers else None)
    from tqdm import tqdm

    bar = tqdm(total=config["steps"], initial=step, desc="train", unit="step", disable=args.quiet,
               dynamic_ncols=True)
    last_val = float("nan")
    t0 = time.perf_counter()
    steps_run = 0
    for batch in loader:
        img1, img2 = batch["image1"].to(device), batch["image2"].to(device)
        flow, valid = batch["flow"].to(device), batch["valid"].to(device)
        optimizer.zero_grad(set_to_none=True)
        with torch.autocast(device.type, torch.bfloat16, enabled=config["precision"] == "bf16"):
            output = model(img1, img2, iters=config["iters"], all_predictions=True)
        loss, epe = sequence_loss(output.predictions, flow, valid, config["gamma"], config["max_flow"],
                                  config.get("boundary_weight", 0.0))
        loss_value = float(loss.detach())
        if not math.isfinite(loss_value):
            bar.close()
            raise CliError(f"loss became {loss_value} at step {step + 1}; lower --lr")
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), config["clip"])
        optimizer.step()
        scheduler.step()
        step += 1
        steps_run += 1
        record = {"step": step, "loss": loss_value, "epe": epe, "lr": scheduler.get_last_lr()[0]}
        _log(log_path, record)
        if val is not None and args.val_every and step % args.val_every == 0 and step < stop:
            last_val = evaluate(model, val, val_settings, device)["epe"]
            _log(log_path, {"step": step, "val_epe": last_val})
        if args.save_every and step % args.save_every == 0 and step < stop:
            save_checkpoint(out / f"checkpoint-{step:06d}.pth", model, optimizer, scheduler, step, config,
                            val_settings)
            _prune(out, args.keep)
        bar.set_postfix(loss=f"{loss_value:.3f}", epe=f"{epe:.2f}", val_epe=f"{last_val:.2f}")
        bar.update(1)
    bar.close()
    elapsed = time.perf_counter() - t0

    from companion.flow.raft.weights import save_flowgap_weights

    save_checkpoint(out / f"checkpoint-{step:06d}.pth", model, optimizer, scheduler, step, config, val_settings)
    _prune(out, args.keep)
    final = save_flowgap_weights(model, out / f"raft-{config['variant']}-flowgap.pth", config["variant"],
                                 inference=val_settings)
    summary = {"weights": str(final), "step": step, "steps_run": steps_run,
               "seconds_per_step": elapsed / steps_run if steps_run else None}
    if val is not None:
        result = evaluate(model, val, val_settings, device, with_dis=True)
        _log(log_path, {"step": step, "val_epe": result["epe"], "dis_medium_epe": result["dis_medium_epe"],
                        "dis_fine_epe": result["dis_fine_epe"]})
        summary["validation"] = result
        (out / "eval.json").write_text(json.dumps({"weights": str(final), **result}, indent=2) + "\n")
    print(f"{PROG}: step {step}/{config['steps']}, "
          + (f"{summary['seconds_per_step']:.3f} s/step, " if steps_run else "")
          + (f"validation EPE {summary['validation']['epe']:.3f} px "
             f"(DIS medium {summary['validation']['dis_medium_epe']:.3f} px, fine "
             f"{summary['validation']['dis_fine_epe']:.3f} px), " if val is not None else "")
          + f"weights {final}")
    return summary


def _weights_as_run(path: str | Path, args: argparse.Namespace):
    """(weights, model holding them, their layout, inference settings) for ``path``: the model built as the weights
    were trained, whatever --upsample says, and the weights' own settings (their model card's) with what the
    command line changes."""
    loaded = read_weights(path)
    model = build_model(loaded.variant, upsample_mode(loaded.upsample_align_corners))
    layout = load_weights_into(model, path, loaded.variant)
    try:
        settings = (loaded.inference or RAFT_DEFAULTS).replace(**inference_overrides(args))
    except ValueError as exc:
        raise CliError(str(exc)) from None
    return loaded, model, layout, settings


def eval_only(args: argparse.Namespace) -> dict:
    device = _device(args.device)
    loaded, model, layout, settings = _weights_as_run(args.eval_only, args)
    variant, upsample = loaded.variant, upsample_mode(loaded.upsample_align_corners)
    model.to(device).eval()
    size = args.val_size or DEFAULT_VALIDATION_SIZE
    distance = tuple(args.distance) if args.distance else None
    pairs = validation_set(size, args.width, args.height, seed=args.val_seed, distance=distance)
    result = evaluate(model, pairs, settings, device, with_dis=True)
    result = {"weights": str(args.eval_only), "layout": layout, "variant": variant, "upsample": upsample,
              "seed": args.val_seed, **({"distance": list(distance)} if distance else {}), **result}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "eval.json").write_text(json.dumps(result, indent=2) + "\n")
    which = "validation" if args.val_seed == VALIDATION_SEED and not distance else f"seed-{args.val_seed}"
    if distance:
        which += f" {distance[0]:g}-{distance[1]:g} m"
    print(f"EPE raft-{variant} {result['epe']:.3f} px, dis:medium {result['dis_medium_epe']:.3f} px, dis:fine "
          f"{result['dis_fine_epe']:.3f} px ({result['pairs']} {which} pairs, {args.width}x{args.height}, "
          f"{describe_settings(settings)}, {result['precision']}) -> {out / 'eval.json'}")
    return result


def export(args: argparse.Namespace) -> Path:
    """Write weights (a run's final file or a checkpoint's, official or torchvision ones) as a flowgap weights
    file in <out>, carrying the inference settings the companion is to run them with: the weights' own, with
    what the command line changes (--val-iters, --refine-scale, --variational-levels, ...)."""
    from companion.flow.raft.weights import save_flowgap_weights

    loaded, model, _, settings = _weights_as_run(args.export, args)
    variant = loaded.variant
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    written = save_flowgap_weights(model, out / f"raft-{variant}-flowgap.pth", variant, inference=settings)
    print(f"{PROG}: wrote {written} (raft-{variant}, {describe_settings(settings)})")
    return Path(written)


# ---------------------------------------------------------------------------------------------------------
# Command line
# ---------------------------------------------------------------------------------------------------------

class _Formatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    pass


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG, formatter_class=_Formatter,
        description="Train our RAFT / RAFT-small on rendered flowgap scenes with exact ground-truth flow,\n"
                    "or evaluate weights on the fixed validation set (--eval-only).",
        epilog="examples:\n"
               f"  {PROG} --steps 2000 --batch 4 --threads 2 --out runs/raft-train\n"
               f"  {PROG} --resume runs/raft-train/checkpoint-001000.pth --out runs/raft-train\n"
               f"  {PROG} --init raft-small.pth --device cuda --batch 16 --steps 20000\n"
               f"  {PROG} --eval-only companion/flow/weights/raft-small-refined-flowgap.pth\n"
               "The final weights (<out>/raft-<variant>-flowgap.pth) load with "
               "make_flow_backend('raft', weights=PATH).")
    m = p.add_argument_group("mode")
    m.add_argument("--eval-only", metavar="WEIGHTS",
                   help="only print (and write <out>/eval.json) the validation EPE of these RAFT weights "
                        "(official, torchvision or flowgap), with DIS medium's EPE on the same pairs")
    m.add_argument("--export", metavar="WEIGHTS",
                   help="only write these weights (a run's weights or checkpoint) to <out>/raft-VARIANT-flowgap.pth "
                        "with the inference settings given here (--val-iters N for the iterations, "
                        "--variational-levels, ...; the rest the weights' own), as the companion will run them")
    m.add_argument("--resume", metavar="CHECKPOINT",
                   help="continue a run from one of its checkpoint-NNNNNN.pth files (its settings win)")
    m.add_argument("--init", metavar="WEIGHTS",
                   help="start from official / torchvision / flowgap RAFT weights instead of random ones")
    t = p.add_argument_group("training")
    t.add_argument("--variant", choices=VARIANTS, default="small",
                   help="RAFT variant (small-convex: RAFT-small with a learned convex upsampling head; "
                        "--init accepts RAFT-small weights for it)")
    t.add_argument("--steps", type=int, default=2000, help="total optimiser steps")
    t.add_argument("--batch", type=int, default=4, help="pairs per step")
    t.add_argument("--lr", type=float, default=4e-4, help="OneCycle peak learning rate (AdamW)")
    t.add_argument("--wdecay", type=float, default=1e-4, help="AdamW weight decay")
    t.add_argument("--clip", type=float, default=1.0, help="gradient-norm clipping")
    t.add_argument("--gamma", type=float, default=0.8, help="sequence-loss decay over iterations")
    t.add_argument("--iters", type=int, default=8, help="RAFT refinement iterations while training")
    t.add_argument("--upsample", choices=tuple(UPSAMPLE_MODES), default="centres",
                   help="RAFT-small's bilinear x8 upsampling: each 1/8-resolution value at its 8x8 block's "
                        "centre, or stretched to the frame's corners as the RAFT authors (and flowgap's "
                        "stage 1-3 weights); the run's choice wins over --init weights'")
    t.add_argument("--head-lr-mult", dest="head_lr_mult", type=float, default=1.0, metavar="M",
                   help="learning rate of the heads a variant adds to the weights it grows from (convex "
                        "upsampling, quarter refinement), as a multiple of --lr")
    t.add_argument("--precision", choices=("fp32", "bf16"), default="fp32",
                   help="bf16: the forward pass under bf16 autocast (weights, optimiser, correlation, upsampling "
                        "and loss stay float32); about 1.6x faster on CPUs with AVX512-BF16 or AMX")
    t.add_argument("--boundary-weight", dest="boundary_weight", type=float, default=0.0, metavar="W",
                   help="count pixels within 3 px of a ground-truth motion boundary (the opening's outline) "
                        "1+W times in the loss (0: every pixel alike)")
    t.add_argument("--max-flow", dest="max_flow", type=float, default=400.0,
                   help="ignore ground-truth flow longer than this (px)")
    d = p.add_argument_group("data")
    d.add_argument("--width", type=int, default=DEFAULT_WIDTH,
                   help="rendered image width (multiple of 8), also the validation frames'")
    d.add_argument("--height", type=int, default=DEFAULT_HEIGHT,
                   help="rendered image height (multiple of 8), also the validation frames'")
    d.add_argument("--crop", default="x".join(map(str, DEFAULT_CROP)),
                   help="train on a random WIDTHxHEIGHT window of each rendered pair (none: whole frames)")
    d.add_argument("--crop-focus", dest="crop_focus", type=float, default=0.0, metavar="P",
                   help="probability that a crop is placed to contain the opening (the background seen through "
                        "it) rather than anywhere (about a third of random crops of zoomed frames show only wall)")
    d.add_argument("--zoom", type=float, nargs=2, metavar=("LOW", "HIGH"), default=None,
                   help="enlarge each rendered pair by a random factor in [LOW, HIGH] before cropping, so the "
                        "weights also fit the raft backend's input_scale (none: no zoom)")
    d.add_argument("--distance", type=float, nargs=2, metavar=("NEAR", "FAR"), default=None,
                   help="range (m) of the first camera's distance before the wall in training pairs (none: "
                        "0.6 2.6; flights start 3 m away, up to 4 m in random scenes); validation while "
                        "training keeps its fixed pairs, --eval-only draws its held-out pairs from this range")
    d.add_argument("--seed", type=int, default=0, help="training data and initialisation seed")
    d.add_argument("--jitter", type=float, default=0.1, help="exposure jitter (max relative gain change)")
    d.add_argument("--pairs-per-scene", dest="pairs_per_scene", type=int, default=8,
                   help="consecutive pairs rendered from one random scene")
    d.add_argument("--workers", type=int, default=0, help="DataLoader worker processes")
    v = p.add_argument_group("validation")
    v.add_argument("--val-size", dest="val_size", type=int, default=DEFAULT_VALIDATION_SIZE,
                   help="validation pairs (fixed seed; 0 disables validation while training)")
    v.add_argument("--val-iters", dest="val_iters", type=int, default=None,
                   help="RAFT iterations for validation (default: the weights' own with --eval-only, RAFT's 12 "
                        "while training)")
    v.add_argument("--val-seed", dest="val_seed", type=int, default=VALIDATION_SEED,
                   help="with --eval-only: the held-out pairs' seed (another seed gives other held-out pairs, "
                        "for tuning inference settings without touching the validation set)")
    v.add_argument("--input-scale", dest="input_scale", type=float, default=None,
                   help="enlarge validation frames by this factor before RAFT, as the raft backend's "
                        "input_scale does (default for this and the options below: the weights file's own "
                        "inference settings with --eval-only, RAFT's one pass on the frames as they are while "
                        "training)")
    v.add_argument("--mirror-average", dest="mirror_average", action=argparse.BooleanOptionalAction,
                   default=None,
                   help="also run each validation pair mirrored left-right and average the flows, as the raft "
                        "backend's mirror_average does")
    v.add_argument("--refine-scale", dest="refine_scale", type=float, default=None, metavar="S",
                   help="after the pass at --input-scale, refine on frames enlarged by S, started from that "
                        "pass's flow, as the raft backend's refine_scale does (0: one pass)")
    v.add_argument("--refine-min-scale", dest="refine_min_scale", type=float, default=None,
                   metavar="S", help="lower the refinement scale no further than this (raft refine_min_scale)")
    v.add_argument("--refine-max-flow", dest="refine_max_flow", type=float, default=None,
                   metavar="PX", help="lower the refinement scale so that the first pass's 99th-percentile "
                                      "flow, enlarged, stays within PX pixels (raft refine_max_flow; 0: always "
                                      "--refine-scale)")
    v.add_argument("--refine-iters", dest="refine_iters", type=int, default=None, metavar="N",
                   help="RAFT iterations of the refinement pass")
    v.add_argument("--patch-levels", dest="patch_levels", type=int, default=None, metavar="N",
                   help="then refine the flow by DIS's patch search on N scales, the coarsest at 1/2**(N-1) of "
                        "the frame (raft patch_levels; 0: none)")
    v.add_argument("--variational-levels", dest="variational_levels", type=int, default=None, metavar="N",
                   help="then refine the flow variationally on N scales, coarse to fine (raft "
                        "variational_levels; 0: RAFT's flow as it is)")
    v.add_argument("--variational-iters", dest="variational_iters", type=int, default=None, metavar="N",
                   help="fixed-point iterations of the variational refinement on each scale (raft "
                        "variational_iters)")
    v.add_argument("--quarter-refine", dest="quarter_refine", action=argparse.BooleanOptionalAction, default=None,
                   help="run RAFT-small-refined's quarter-resolution refinement head (raft quarter_refine; "
                        "--no-quarter-refine skips it, as when --patch-levels refines the flow anyway)")
    v.add_argument("--eval-precision", dest="eval_precision", choices=PRECISIONS, default=None,
                   help="the network's precision when validating, as the raft backend's precision (auto: bf16 "
                        "on a CPU with AVX512-BF16 or AMX, else fp32; default: the weights' own with "
                        "--eval-only, while training bf16-trained weights run auto, others fp32)")
    v.add_argument("--val-every", dest="val_every", type=int, default=200,
                   help="validate every N steps (0: only at the end)")
    o = p.add_argument_group("output and runtime")
    o.add_argument("-o", "--out", default="runs/raft-train", help="output directory")
    o.add_argument("--save-every", dest="save_every", type=int, default=200,
                   help="checkpoint every N steps (0: only at the end)")
    o.add_argument("--stop-at", dest="stop_at", type=int, default=None, metavar="STEP",
                   help="end this run after STEP (checkpoint and weights written; the learning-rate schedule "
                        "still spans --steps, so --resume continues the same run)")
    o.add_argument("--keep", type=int, default=3, help="newest checkpoints to keep")
    o.add_argument("--device", default="cpu", help="cpu or cuda")
    o.add_argument("--threads", type=int, default=None, help="torch CPU threads (torch.set_num_threads)")
    o.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def _check(args: argparse.Namespace) -> None:
    positive = {"steps": args.steps, "batch": args.batch, "iters": args.iters, "val-iters": args.val_iters or 1,
                "width": args.width, "height": args.height, "pairs-per-scene": args.pairs_per_scene,
                "keep": args.keep}
    for name, value in positive.items():
        if value <= 0:
            raise CliError(f"--{name} must be positive (got {value})")
    if not (math.isfinite(args.boundary_weight) and args.boundary_weight >= 0):
        raise CliError(f"--boundary-weight must be 0 or positive (got {args.boundary_weight})")
    for name, value in {"val-size": args.val_size, "val-every": args.val_every, "save-every": args.save_every,
                        "workers": args.workers}.items():
        if value < 0:
            raise CliError(f"--{name} must be >= 0 (got {value})")
    if args.width % 8 or args.height % 8:
        raise CliError(f"--width and --height must be multiples of 8 (got {args.width}x{args.height})")
    if min(args.width, args.height) < 64:
        raise CliError(f"--width and --height must be at least 64 (RAFT's 4-level correlation pyramid needs "
                       f"1/8-resolution features of at least 8 cells; got {args.width}x{args.height})")
    crop = parse_crop(args.crop)
    if crop is not None and not args.eval_only:
        cw, ch = crop
        if cw % 8 or ch % 8 or min(cw, ch) < 64:
            raise CliError(f"--crop must be multiples of 8, at least 64x64 (got {args.crop})")
        if cw > args.width or ch > args.height:
            raise CliError(f"--crop {args.crop} is larger than the {args.width}x{args.height} frames "
                           f"(use a smaller --crop or --crop none)")
    lo, hi = INPUT_SCALE_RANGE
    if args.input_scale is not None and not (math.isfinite(args.input_scale) and lo <= args.input_scale <= hi):
        raise CliError(f"--input-scale must be within {lo:g}..{hi:g} (got {args.input_scale})")
    if args.refine_scale not in (None, 0) and not (math.isfinite(args.refine_scale) and lo <= args.refine_scale <= hi):
        raise CliError(f"--refine-scale must be 0 (one pass) or within {lo:g}..{hi:g} (got {args.refine_scale})")
    if args.refine_min_scale is not None and not (math.isfinite(args.refine_min_scale)
                                                  and lo <= args.refine_min_scale <= hi):
        raise CliError(f"--refine-min-scale must be within {lo:g}..{hi:g} (got {args.refine_min_scale})")
    if args.refine_max_flow is not None and not (math.isfinite(args.refine_max_flow) and args.refine_max_flow >= 0):
        raise CliError(f"--refine-max-flow must be 0 (a fixed --refine-scale) or positive pixels "
                       f"(got {args.refine_max_flow})")
    if args.refine_iters is not None and args.refine_iters < 1:
        raise CliError(f"--refine-iters must be at least 1 (got {args.refine_iters}); use --refine-scale 0 "
                       "for one pass")
    if args.patch_levels is not None and not 0 <= args.patch_levels <= 4:
        raise CliError(f"--patch-levels must be 0 (off) to 4 (got {args.patch_levels})")
    if args.variational_levels is not None and not 0 <= args.variational_levels <= 4:
        raise CliError(f"--variational-levels must be 0 (off) to 4 (got {args.variational_levels})")
    if args.variational_iters is not None and args.variational_iters < 1:
        raise CliError(f"--variational-iters must be at least 1 (got {args.variational_iters})")
    if not 0.0 <= args.crop_focus <= 1.0:
        raise CliError(f"--crop-focus must be a probability in [0, 1] (got {args.crop_focus})")
    if args.crop_focus > 0 and crop is None and not args.eval_only:
        raise CliError("--crop-focus needs a --crop (it chooses where the crop goes)")
    if args.zoom is not None:
        lo, hi = args.zoom
        if not (1.0 <= lo <= hi and math.isfinite(hi)):
            raise CliError(f"--zoom must be 1 <= LOW <= HIGH (got {lo} {hi})")
        if crop is None and not args.eval_only:
            raise CliError("--zoom needs a --crop (zoomed frames are larger than the camera's)")
    if args.distance is not None:
        near, far = args.distance
        if not (0.0 < near <= far and math.isfinite(far)):
            raise CliError(f"--distance must be 0 < NEAR <= FAR metres (got {near} {far})")
    if not 0.0 <= args.jitter < 1.0:
        raise CliError(f"--jitter must be in [0, 1) (got {args.jitter})")
    if not (args.lr > 0 and math.isfinite(args.lr)):
        raise CliError(f"--lr must be positive (got {args.lr})")
    if not (args.head_lr_mult > 0 and math.isfinite(args.head_lr_mult)):
        raise CliError(f"--head-lr-mult must be positive (got {args.head_lr_mult})")
    if not 0.0 < args.gamma <= 1.0:
        raise CliError(f"--gamma must be in (0, 1] (got {args.gamma})")
    if args.clip <= 0:
        raise CliError(f"--clip must be positive (got {args.clip})")
    if args.stop_at is not None and args.stop_at <= 0:
        raise CliError(f"--stop-at must be positive (got {args.stop_at})")
    if args.threads is not None and args.threads <= 0:
        raise CliError(f"--threads must be positive (got {args.threads})")
    if args.eval_only and (args.resume or args.init):
        raise CliError("--eval-only cannot be combined with --resume or --init")
    if args.resume and args.init:
        raise CliError("--resume and --init are exclusive (a resumed run already has its weights)")
    for flag, path in (("--eval-only", args.eval_only), ("--init", args.init), ("--resume", args.resume)):
        if path and not Path(path).expanduser().is_file():
            raise CliError(f"{flag}: file not found: {path}")


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(argv)
    defaults = parser.parse_args([])
    args._explicit = {k: getattr(args, k) != getattr(defaults, k) for k in TRAIN_KEYS}
    try:
        _check(args)
        if args.threads is not None:
            torch.set_num_threads(args.threads)
        if args.eval_only:
            eval_only(args)
        elif args.export:
            export(args)
        else:
            train(args)
    except CliError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted (resume from the newest checkpoint in {args.out})", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())

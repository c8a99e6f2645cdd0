"""A ``flowgap-train-raft`` run: the model and checkpoint I/O, the training loop, --eval-only and --export.

Training: AdamW + OneCycleLR (linear anneal, as the RAFT authors) and gradient-norm clipping on RAFT's sequence
loss (``tools.raft_metrics``). Batch ``t`` (0-based) is always items ``t*batch .. t*batch+batch-1`` of the seeded
:class:`tools.raft_data.RenderedFlowDataset`, so a run is a function of its settings and ``--resume`` continues
exactly where a checkpoint left off; the files a run writes are described in ``tools.train_raft``. Apart from the
command line (``tools.train_raft``), which parses and checks the options: everything here takes them parsed.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import torch

from companion.flow.raft.backend import RAFT_DEFAULTS, InferenceSettings, describe_settings
from tools.raft_data import (
    DEFAULT_VALIDATION_SIZE,
    VALIDATION_SEED,
    RenderedFlowDataset,
    collate,
    validation_set,
)
from tools.raft_metrics import evaluate, sequence_loss

PROG = "flowgap-train-raft"
TRAIN_KEYS = ("variant", "steps", "batch", "lr", "wdecay", "clip", "gamma", "iters", "width", "height", "crop",
              "crop_focus", "zoom", "seed", "jitter", "pairs_per_scene", "max_flow", "val_size", "val_iters",
              "upsample", "distance", "precision", "head_lr_mult", "boundary_weight")
UPSAMPLE_MODES = {"centres": False, "corners": True}   # --upsample -> RaftConfig.upsample_align_corners


class CliError(Exception):
    """A bad input: reported as one line, exit status 2."""


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
    state under ``"train"`` (see ``tools.train_raft``'s module docstring)."""
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

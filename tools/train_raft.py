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

The command line is this module; the run, with its model and checkpoint I/O (``tools.raft_training``), and its
loss and validation EPE (``tools.raft_metrics``) have modules of their own, whose names are importable from here
too.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import torch

from companion.flow.raft.backend import INPUT_SCALE_RANGE, PRECISIONS
from companion.flow.raft.model import VARIANTS
from tools.raft_data import (
    DEFAULT_CROP,
    DEFAULT_HEIGHT,
    DEFAULT_VALIDATION_SIZE,
    DEFAULT_WIDTH,
    VALIDATION_SEED,
)
from tools.raft_metrics import evaluate, motion_boundaries, sequence_loss
from tools.raft_training import (
    GROWS_FROM,
    NEW_HEAD_PREFIXES,
    PROG,
    TRAIN_KEYS,
    UPSAMPLE_MODES,
    CliError,
    build_model,
    eval_only,
    export,
    inference_overrides,
    load_weights_into,
    parse_crop,
    read_checkpoint,
    read_weights,
    save_checkpoint,
    train,
    upsample_mode,
)

__all__ = [
    "GROWS_FROM", "NEW_HEAD_PREFIXES", "PROG", "TRAIN_KEYS", "UPSAMPLE_MODES", "CliError", "build_model",
    "build_parser", "eval_only", "evaluate", "export", "inference_overrides", "load_weights_into", "main",
    "motion_boundaries", "parse_crop", "read_checkpoint", "read_weights", "save_checkpoint", "sequence_loss", "train",
    "upsample_mode",
]


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

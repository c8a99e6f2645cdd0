"""Convert RAFT weights to the flowgap layout: ``python -m companion.flow.raft.convert SRC DST``.

SRC may be an official RAFT checkpoint (``raft-things.pth``, ``raft-small.pth``, ...), a torchvision
``raft_large`` / ``raft_small`` state dict, or a flowgap-raft file.  The weights are checked by loading them
into our model (strict) before DST is written.  Prints the detected layout and variant.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from companion.flow.base import FlowWeightsError
from companion.flow.raft.model import RAFT
from companion.flow.raft.weights import load_raft_state_dict, save_flowgap_weights


def convert(src: Path, dst: Path) -> tuple[str, str]:
    """Write ``src``'s weights to ``dst`` in the flowgap layout; returns (source layout, variant)."""
    loaded = load_raft_state_dict(src)
    layout, variant = loaded.layout, loaded.variant
    model = RAFT(loaded.config())
    try:
        model.load_state_dict(loaded.state_dict, strict=True)
    except RuntimeError as exc:
        detail = " ".join(str(exc).split())[:200]
        raise FlowWeightsError(f"RAFT weights mismatch: {src} does not fit RAFT-{variant} ({detail})") from None
    save_flowgap_weights(model, dst, variant)
    return layout, variant


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m companion.flow.raft.convert",
                                     description="Convert official / torchvision RAFT weights to the flowgap layout.")
    parser.add_argument("src", type=Path, help="official, torchvision or flowgap RAFT weights (.pth)")
    parser.add_argument("dst", type=Path, help="output .pth (flowgap-raft layout)")
    args = parser.parse_args(argv)
    try:
        layout, variant = convert(args.src, args.dst)
    except FlowWeightsError as exc:
        print(f"convert: {exc}", file=sys.stderr)
        return 1
    print(f"{args.src}: {layout} layout, RAFT-{variant} -> {args.dst} (flowgap-raft)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""``spacepose recover-checkpoint GRAPH --out CKPT``: a fine-tunable checkpoint from a shipped ONNX graph."""

from __future__ import annotations

import argparse
from pathlib import Path

HELP = "rebuild a training checkpoint (for --init) from an exported stereo, pose or flip graph"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("graph", type=Path, help="stereo.onnx, pose.onnx or flip.onnx exported by this project")
    parser.add_argument("--out", type=Path, required=True, help="checkpoint file to write (.pt)")
    parser.add_argument("--force", action="store_true", help="overwrite an existing --out")


def run(args: argparse.Namespace) -> int:
    from spacepose._optional import import_optional

    import_optional("torch")
    import_optional("onnx")
    from spacepose.export.onnx_common import check_overwrite
    from spacepose.export.recover import checkpoint_from_graph
    from spacepose.tools.training_common import atomic_save

    if not args.graph.is_file():
        raise SystemExit(f"no such graph: {args.graph}")
    out = check_overwrite(args.out, args.force)
    ckpt = checkpoint_from_graph(args.graph)
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_save(ckpt, out)
    print(f"wrote {out}: {ckpt['kind']} model from {args.graph} (trained {ckpt['step']} steps; "
          f"{len(ckpt['folded_bn'])} folded BatchNorms, fine-tune them frozen; parity {ckpt['parity']:.2g})")
    return 0

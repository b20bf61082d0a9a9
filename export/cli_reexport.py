"""``spacepose reexport GRAPH --out NEW``: a shipped graph exported again by the current exporter."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

HELP = "export a shipped stereo or pose graph again with the current exporter (same weights and metadata)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("graph", type=Path, help="stereo.onnx or pose.onnx exported by this project")
    parser.add_argument("--out", type=Path, required=True, help="the new graph (never the old one)")
    parser.add_argument("--force", action="store_true", help="overwrite an existing --out")


def run(args: argparse.Namespace) -> int:
    from spacepose.export.cli_common import require_export_extras

    require_export_extras()
    from spacepose.export.reexport import reexport_graph

    result = reexport_graph(args.graph, args.out, force=args.force)
    print(f"wrote {result['path']} ({result['kind']}, export {json.dumps(result['export'], sort_keys=True)}); "
          f"max |diff|: recovered model vs old graph {result['recovery_parity']:.2g}, "
          f"vs new graph {result['torch_parity']:.2g}, old vs new graph {result['graph_parity']:.2g}")
    return 0

"""The ``spacepose`` command line: one entry point, one module per subcommand.

Each subcommand module defines ``HELP: str``, ``add_arguments(parser)`` and ``run(args) -> int``
and imports nothing heavy at module level (training-side modules import torch/trimesh inside
``run``), so ``spacepose --help`` stays fast and works without the ``[train]`` extra.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from typing import Sequence

from .errors import MissingExtraError, SpaceposeError

log = logging.getLogger(__name__)

#: subcommand name -> module implementing it (flight side first, then training side)
COMMANDS: dict[str, str] = {
    "estimate": "spacepose.cli_estimate",
    "disparity": "spacepose.cli_disparity",
    "profile": "spacepose.cli_profile",
    "demo": "spacepose.cli_demo",
    "calibrate": "spacepose.calibration.cli_calibrate",
    "render": "spacepose.tools.cli_render",
    "dataset-card": "spacepose.tools.cli_dataset_card",
    "keypoints": "spacepose.tools.cli_keypoints",
    "train-stereo": "spacepose.tools.cli_train_stereo",
    "eval-stereo": "spacepose.tools.cli_eval_stereo",
    "export-stereo": "spacepose.export.cli_export_stereo",
    "train-pose": "spacepose.tools.cli_train_pose",
    "eval-pose": "spacepose.tools.cli_eval_pose",
    "export-pose": "spacepose.export.cli_export_pose",
    "train-flip": "spacepose.tools.train_flip",
    "export-flip": "spacepose.export.onnx_flip",
    "train-outline": "spacepose.tools.train_outline",
    "export-outline": "spacepose.export.onnx_outline",
    "quantize": "spacepose.export.cli_quantize",
    "recover-checkpoint": "spacepose.export.cli_recover",
    "reexport": "spacepose.export.cli_reexport",
    "export-surface": "spacepose.export.cli_surface",
}


def _load(module_name: str):
    try:
        return importlib.import_module(module_name)
    except ModuleNotFoundError as err:
        if err.name == module_name:  # the subcommand is not part of this build
            return None
        raise


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="spacepose", description="spacepose: stereo 6-DoF pose of a non-cooperative spacecraft")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more logging (-vv for debug)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, module_name in COMMANDS.items():
        module = _load(module_name)
        if module is None:
            continue
        cmd = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(cmd)
        cmd.set_defaults(_run=module.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    level = logging.WARNING - 10 * min(args.verbose, 2)
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    if not getattr(args, "command", None):
        parser.print_help()
        return 2
    try:
        return int(args._run(args) or 0)
    except MissingExtraError as err:
        print(f"spacepose {args.command}: {err}", file=sys.stderr)
        return 3
    except SpaceposeError as err:
        print(f"spacepose {args.command}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

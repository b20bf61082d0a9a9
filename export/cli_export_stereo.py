"""``spacepose export-stereo CKPT --out runtime/bundles/default/stereo.onnx --iters 4 --size 256x256``."""

from __future__ import annotations

import argparse
from pathlib import Path

from spacepose.cli_args import parse_size
from spacepose.export.cli_common import (add_checkpoint_arguments, add_metrics_arguments, load_metrics,
                                         require_export_extras)

HELP = "export a TSCA-Stereo checkpoint to one ONNX file (fixed size and iterations) with a parity check"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_checkpoint_arguments(parser, "stereo")
    parser.add_argument("--iters", type=int, default=4, help="iterations frozen into the graph")
    parser.add_argument("--size", type=parse_size, default=(256, 256), help="graph input WxH (multiples of 32)")
    add_metrics_arguments(parser, "stereo")
    parser.add_argument("--rig", type=Path, default=None,
                        help="rig the graph was trained on (default: rig.yaml of the checkpoint's dataset); "
                             "with it the stereo and rig sections of bundle.json beside --out are written")
    parser.add_argument("--no-manifest", action="store_true", help="do not touch bundle.json beside --out")
    parser.add_argument("--force", action="store_true", help="overwrite an existing file")


def run(args: argparse.Namespace) -> int:
    require_export_extras()
    from spacepose.export.onnx_stereo import export_checkpoint

    metrics = load_metrics(args.metrics)
    result = export_checkpoint(args.checkpoint, args.out, iters=args.iters, size=tuple(args.size), force=args.force,
                               metrics=metrics, parity=not args.no_parity)
    print(f"wrote {result['path']} ({args.size[0]}x{args.size[1]}, {args.iters} iters)")
    if not args.no_manifest:
        from spacepose.export.onnx_stereo import write_stereo_manifest

        meta = result["metadata"]
        dataset = dict(meta.get("dataset") or {})
        rig = args.rig or (Path(dataset["path"]) / "rig.yaml" if dataset.get("path") else None)
        if rig is None or not Path(rig).is_file():
            print("bundle.json not updated: pass --rig (the training rig file)")
        else:
            manifest = write_stereo_manifest(args.out.parent, input_size=tuple(args.size), iters=args.iters,
                                             max_disp=float(meta["max_disp"]), rig_path=rig,
                                             stereo_file=args.out.name, metrics=metrics)
            print(f"updated {manifest}")
    if result["parity_max_abs_px"] is not None:
        print(f"parity torch vs onnxruntime: max |diff| = {result['parity_max_abs_px']:.2e} px (limit 1e-3)")
    return 0

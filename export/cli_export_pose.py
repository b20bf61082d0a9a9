"""``spacepose export-pose CKPT --out runtime/bundles/default/pose.onnx [--force]``."""

from __future__ import annotations

import argparse

from spacepose.export.cli_common import (add_checkpoint_arguments, add_metrics_arguments, load_metrics,
                                         require_export_extras)

HELP = "export a pose-net checkpoint to one ONNX file with its metadata contract and a parity check"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_checkpoint_arguments(parser, "pose")
    add_metrics_arguments(parser, "pose")
    parser.add_argument("--no-manifest", action="store_true", help="do not write the pose side of OUT_DIR/bundle.json")
    parser.add_argument("--force", action="store_true", help="overwrite an existing file")


def run(args: argparse.Namespace) -> int:
    require_export_extras()
    from spacepose.export.onnx_pose import export_checkpoint

    metrics = load_metrics(args.metrics)
    result = export_checkpoint(args.checkpoint, args.out, force=args.force, parity=not args.no_parity, metrics=metrics,
                               update_manifest=not args.no_manifest)
    meta = result["metadata"]
    print(f"wrote {result['path']} ({meta['n_points']} points, crop {meta['crop_size'][0]}x{meta['crop_size'][1]}, "
          f"{meta['n_keypoints']} keypoints, target {meta['target']})")
    if result["parity"] is not None:
        p = result["parity"]
        print("parity torch vs onnxruntime: max |diff| = {:.2e} (seg {:.1e}, kp {:.1e}, ctr {:.1e}; limit 1e-4)".format(
            p["max"], p["seg_logits"], p["kp_offsets"], p["ctr_offsets"]))
    if result["manifest"]:
        print(f"updated the pose side of {result['manifest']}")
    return 0

"""``spacepose export-pose CKPT --out runtime/bundles/default/pose.onnx [--force]``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

HELP = "export a pose-net checkpoint to one ONNX file with its metadata contract and a parity check"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("checkpoint", type=Path, help="training checkpoint (runs/pose/last.pt)")
    parser.add_argument("--out", type=Path, default=Path("runtime/bundles/default/pose.onnx"))
    parser.add_argument("--metrics", type=Path, default=None, help="JSON of test metrics to embed (eval-pose output)")
    parser.add_argument("--no-parity", action="store_true", help="skip the torch vs onnxruntime check")
    parser.add_argument("--no-manifest", action="store_true", help="do not write the pose side of OUT_DIR/bundle.json")
    parser.add_argument("--force", action="store_true", help="overwrite an existing file")


def run(args: argparse.Namespace) -> int:
    from spacepose._optional import import_optional

    import_optional("torch")
    import_optional("onnx")
    from spacepose.export.onnx_pose import export_checkpoint

    metrics = None
    if args.metrics is not None:
        doc = json.loads(args.metrics.read_text())
        metrics = doc.get("ours", {}).get("overall", doc) if isinstance(doc, dict) else None
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

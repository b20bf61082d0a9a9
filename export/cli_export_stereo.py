"""``spacepose export-stereo CKPT --out runtime/bundles/default/stereo.onnx --iters 4 --size 256x256``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

HELP = "export a TSCA-Stereo checkpoint to one ONNX file (fixed size and iterations) with a parity check"


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"size must be WxH, got {text!r}") from err
    return w, h


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("checkpoint", type=Path, help="training checkpoint (runs/stereo/last.pt)")
    parser.add_argument("--out", type=Path, default=Path("runtime/bundles/default/stereo.onnx"))
    parser.add_argument("--iters", type=int, default=4, help="iterations frozen into the graph")
    parser.add_argument("--size", type=_size, default=(256, 256), help="graph input WxH (multiples of 32)")
    parser.add_argument("--metrics", type=Path, default=None, help="JSON of test metrics to embed (eval-stereo output)")
    parser.add_argument("--no-parity", action="store_true", help="skip the torch vs onnxruntime check")
    parser.add_argument("--rig", type=Path, default=None,
                        help="rig the graph was trained on (default: rig.yaml of the checkpoint's dataset); "
                             "with it the stereo and rig sections of bundle.json beside --out are written")
    parser.add_argument("--no-manifest", action="store_true", help="do not touch bundle.json beside --out")
    parser.add_argument("--force", action="store_true", help="overwrite an existing file")


def run(args: argparse.Namespace) -> int:
    from spacepose._optional import import_optional

    import_optional("torch")
    import_optional("onnx")
    from spacepose.export.onnx_stereo import export_checkpoint

    metrics = None
    if args.metrics is not None:
        doc = json.loads(args.metrics.read_text())
        metrics = doc.get("ours", {}).get("overall", doc) if isinstance(doc, dict) else None
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

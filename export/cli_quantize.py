"""``spacepose quantize BUNDLE --out DIR --precision int8 --calib-data DATASET``: a reduced-precision bundle copy."""

from __future__ import annotations

import argparse
from pathlib import Path


HELP = "write an int8 (calibrated) or fp16 copy of a model bundle; the source is never modified"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bundle", nargs="?", default=None, help="source bundle folder (default: the shipped one)")
    parser.add_argument("--out", type=Path, required=True, help="new bundle folder")
    parser.add_argument("--precision", choices=("int8", "fp16"), required=True)
    parser.add_argument("--calib-data", default=None, help="dataset whose train frames calibrate int8 activations")
    parser.add_argument("--calib-frames", type=int, default=32, help="frames to calibrate on (int8)")
    parser.add_argument("--force", action="store_true", help="write into a non-empty --out")


def run(args: argparse.Namespace) -> int:
    from spacepose._optional import import_optional

    import_optional("onnx")  # onnx + onnxruntime only: no torch needed
    from spacepose.export.quantize import quantize_bundle

    if args.calib_frames < 1:
        raise SystemExit("--calib-frames must be >= 1")
    out = quantize_bundle(args.bundle, args.out, args.precision, dataset=args.calib_data,
                          calib_frames=args.calib_frames, force=args.force)
    sizes = ", ".join(f"{p.name} {p.stat().st_size / 2**20:.1f} MiB" for p in sorted(out.glob("*.onnx")))
    print(f"wrote {args.precision} bundle {out} ({sizes})")
    return 0

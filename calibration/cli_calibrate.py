"""``spacepose calibrate FOLDER``: calibrate a stereo rig from chessboard pairs in left/ and right/."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

HELP = "calibrate a stereo rig from chessboard image pairs (FOLDER/left, FOLDER/right) and write a rig file"


def _board(text: str) -> tuple[int, int]:
    try:
        cols, rows = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"board must be COLSxROWS inner corners, e.g. 9x6; got {text!r}") from None
    if cols < 3 or rows < 3:
        raise argparse.ArgumentTypeError(f"board needs at least 3x3 inner corners, got {text!r}")
    return cols, rows


def _square(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"square must be a length in metres, got {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"square must be a positive length in metres, got {text!r}")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("folder", type=Path, help="folder with left/ and right/ chessboard images (same file names)")
    parser.add_argument("--board", type=_board, default=(9, 6), help="inner corners COLSxROWS (default 9x6)")
    parser.add_argument("--square", type=_square, required=True, help="side of one board square in metres, e.g. 0.025")
    parser.add_argument("--out", type=Path, required=True, help="rig file to write (.yaml, .yml, .xml or .json)")
    parser.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    parser.add_argument("--free-k3", action="store_true", help="also estimate the k3 distortion coefficient")


def run(args: argparse.Namespace) -> int:
    from .chessboard import calibrate_stereo
    from .rig import RIG_EXTENSIONS, save_rig

    out: Path = args.out
    if out.suffix.lower() not in RIG_EXTENSIONS:
        print(f"spacepose calibrate: error: --out must end in one of {', '.join(RIG_EXTENSIONS)}", file=sys.stderr)
        return 2
    if out.exists() and not args.force:
        print(f"spacepose calibrate: error: {out} exists; pass --force to overwrite it", file=sys.stderr)
        return 2
    result = calibrate_stereo(args.folder, board=args.board, square_m=args.square, fix_k3=not args.free_k3)
    try:
        save_rig(result.rig, out, overwrite=args.force)
    except FileExistsError as err:
        print(f"spacepose calibrate: error: {err}", file=sys.stderr)
        return 2
    rig = result.rig
    print(f"pairs used:        {result.n_pairs_used} (skipped {len(result.pairs_skipped)})")
    print(f"RMS reprojection:  {result.rms:.4f} px")
    print(f"image size:        {rig.width}x{rig.height}")
    print(f"fx, fy left:       {rig.M1[0, 0]:.3f}, {rig.M1[1, 1]:.3f} px")
    print(f"fx, fy right:      {rig.M2[0, 0]:.3f}, {rig.M2[1, 1]:.3f} px")
    print(f"baseline:          {rig.baseline_m:.6f} m")
    print(f"wrote {out}")
    return 0

"""``spacepose eval-pose DATASET --bundle DIR --out DIR [--limit N] [--baseline classical]``."""

from __future__ import annotations

import argparse
from pathlib import Path

HELP = "run the full flight pipeline on a dataset's test split: e_t, e_R, ADD, SPEED score, flips, plots"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dataset", type=Path, help="dataset folder (CONVENTIONS layout)")
    parser.add_argument("--bundle", type=Path, default=None, help="model bundle folder (default: the shipped one)")
    parser.add_argument("--out", type=Path, default=Path("runs/eval_pose"), help="report folder")
    parser.add_argument("--limit", type=int, default=None, help="only the first N test frames")
    parser.add_argument("--skip", type=int, default=0, help="leave out the first N frames of the split (before --limit)")
    parser.add_argument("--split", default="test")
    parser.add_argument("--baseline", choices=("classical",), default=None, help="add a classical baseline column")
    parser.add_argument("--overlays", type=int, default=6, help="frames with a projected-box overlay image")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--refine", action="store_true", help="the estimator's ICP refinement after the checks")


def run(args: argparse.Namespace) -> int:
    from spacepose.tools.eval_pose import evaluate_pose, format_tables, write_report

    report = evaluate_pose(args.dataset, args.bundle, limit=args.limit, skip=args.skip, baseline=args.baseline, threads=args.threads,
                           split=args.split, overlays=args.overlays, out_dir=args.out, refine=args.refine,
                           progress=lambda i, n: print(f"\r{i}/{n}", end="", flush=True))
    print()
    path = write_report(report, args.out)
    print(format_tables(report))
    print(f"report: {path}")
    return 0

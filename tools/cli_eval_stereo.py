"""``spacepose eval-stereo DATASET --bundle DIR [--limit N] --out DIR``: ours vs StereoSGBM on the test split."""

from __future__ import annotations

import argparse
from pathlib import Path

HELP = "stereo metrics (EPE, RMSE, bad-1/3, D1) on the test split: ours vs OpenCV StereoSGBM, + figure"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dataset", type=Path, help="dataset folder (CONVENTIONS layout, with a test split)")
    parser.add_argument("--bundle", type=Path, default=None, help="bundle folder holding stereo.onnx (default: shipped)")
    parser.add_argument("--out", type=Path, required=True, help="folder for stereo_eval.json/.md and the figure")
    parser.add_argument("--limit", type=int, default=None, help="first N test frames only")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--tune-sgbm", type=int, default=0, metavar="N",
                        help="grid-search SGBM block size/uniqueness on N training frames first (0: documented defaults)")


def run(args: argparse.Namespace) -> int:
    from spacepose.calibration.rectify import rectify
    from spacepose.calibration.rig import load_rig
    from spacepose.cli_disparity import default_stereo_graph
    from spacepose.tools.eval_stereo import evaluate_stereo, format_table, sgbm_for_rig, tune_sgbm, write_report

    graph = (args.bundle / "stereo.onnx") if args.bundle is not None else default_stereo_graph()
    params = None
    if args.tune_sgbm > 0:
        rect = rectify(load_rig(args.dataset / "rig.yaml"))
        params, trials = tune_sgbm(args.dataset, sgbm_for_rig(rect.focal_px, rect.baseline_m), args.tune_sgbm)
        print(f"SGBM tuned on {args.tune_sgbm} training frames: block {params.block_size}, uniqueness {params.uniqueness_ratio}")
    report = evaluate_stereo(args.dataset, graph, limit=args.limit, threads=args.threads, sgbm=params,
                             figure=args.out / "stereo_fig13.png")
    path = write_report(report, args.out)
    print(format_table(report))
    print(f"SGBM: {report['sgbm_params']}")
    print(f"median latency ms: {report['latency_ms_median']}")
    print(f"wrote {path}")
    return 0

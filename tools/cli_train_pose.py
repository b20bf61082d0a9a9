"""``spacepose train-pose DATASET --out runs/pose --steps N --batch 8 --depth-source stereo|gt_noisy``.

Adam with the paper's cyclic learning rate (1e-5 -> 1e-3 -> 1e-5, three cycles over the run).
``--depth-source stereo`` (paper §4) needs ``DATASET/pred_disparity/*.pfm``; ``--stereo-graph
BUNDLE_or_stereo.onnx`` predicts the missing ones first. CPU by default, the GPU when torch sees
one; under ``torchrun`` (``WORLD_SIZE`` set) DDP, no flag needed.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from spacepose.tools.cli_training_args import add_loop_arguments, add_run_arguments

HELP = "train the pose network (RGB + points + ECFT, FFB6D heads) on a rendered dataset; resumable"


def _override(text: str) -> tuple[str, object]:
    key, sep, value = text.partition("=")
    if not sep:
        raise argparse.ArgumentTypeError(f"--net takes KEY=VALUE (JSON value), got {text!r}")
    try:
        return key, json.loads(value)
    except json.JSONDecodeError:
        return key, value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_run_arguments(parser, out="runs/pose", batch=8)
    parser.add_argument("--depth-source", choices=("stereo", "gt_noisy"), default="stereo",
                        help="stereo: cached predicted disparity (paper §4); gt_noisy: GT + stereo-like noise (bootstrap)")
    parser.add_argument("--stereo-graph", type=Path, default=None,
                        help="bundle folder or stereo.onnx: predict missing pred_disparity/*.pfm before training")
    parser.add_argument("--fusion", choices=("both", "rgb2pt", "pt2rgb", "none"), default="both")
    parser.add_argument("--attention", choices=("ecaa", "vanilla"), default="ecaa")
    parser.add_argument("--preset", choices=("cpu", "paper"), default="cpu", help="network size")
    parser.add_argument("--net", type=_override, action="append", default=[], metavar="KEY=VALUE",
                        help="PoseNetConfig override, e.g. --net n_points=512 --net 'crop_size=[96,96]'")
    parser.add_argument("--lr-min", type=float, default=1e-5)
    parser.add_argument("--lr-max", type=float, default=1e-3)
    parser.add_argument("--cycles", type=int, default=3)
    parser.add_argument("--no-augment", action="store_true", help="no photometric augmentation")
    parser.add_argument("--symmetric-flip", choices=("x", "y", "z"), default=None,
                        help="score keypoints against the nearer of the true pose and the pose flipped 180° about "
                             "this body axis (not the paper's loss; for a near-symmetric target)")
    parser.add_argument("--init", type=Path, default=None,
                        help="fine-tune: start from this checkpoint's weights (e.g. one from spacepose "
                             "recover-checkpoint) with a fresh optimiser and schedule")
    add_loop_arguments(parser, workers=1)


def run(args: argparse.Namespace) -> int:
    from spacepose._optional import import_optional

    import_optional("torch")
    from spacepose.tools.train_pose import TrainPoseConfig, train_pose

    if args.stereo_graph is not None:
        from spacepose.tools.predict_disparity import predict_disparity

        result = predict_disparity(args.dataset, args.stereo_graph, threads=max(args.threads, 1) if args.threads else 2)
        print(f"predicted disparity: {result['written']} written, {result['skipped']} cached -> {result['dir']}")
    cfg = TrainPoseConfig(dataset=str(args.dataset), out=str(args.out), steps=args.steps, batch=args.batch,
                          depth_source=args.depth_source, fusion=args.fusion, attention=args.attention,
                          preset=args.preset, net=dict(args.net), lr_min=args.lr_min, lr_max=args.lr_max,
                          cycles=args.cycles, augment=not args.no_augment, ckpt_every=args.ckpt_every,
                          val_every=args.val_every, val_samples=args.val_samples, log_every=args.log_every,
                          workers=args.workers, threads=args.threads, seed=args.seed, limit=args.limit,
                          init=str(args.init) if args.init else None, time_limit_s=args.time_limit_s, pace_lr=args.pace_lr,
                          symmetric_flip=args.symmetric_flip)
    if args.pace_lr and not args.time_limit_s:
        raise SystemExit("--pace-lr needs --time-limit-s")
    if args.init and args.resume:
        raise SystemExit("--init starts a new run; --resume continues one: give one of them")
    summary = train_pose(cfg, resume=args.resume)
    print(json.dumps(summary, indent=2))
    return 0

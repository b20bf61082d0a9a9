"""``spacepose train-stereo DATASET --out runs/stereo --steps N ...``: train TSCA-Stereo.

CPU by default, the GPU when torch sees one; under ``torchrun`` (``WORLD_SIZE`` set) every rank
trains on its own shard with DDP, no flag needed.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from spacepose.cli_args import parse_size
from spacepose.tools.cli_training_args import add_loop_arguments, add_run_arguments

HELP = "train TSCA-Stereo (IGEV loss and schedule) on a rendered dataset; resumable"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_run_arguments(parser, out="runs/stereo", batch=4)
    parser.add_argument("--variant", choices=("igev", "ta", "seca", "full"), default="full")
    parser.add_argument("--preset", choices=("cpu", "paper"), default="cpu", help="model widths")
    parser.add_argument("--iters", type=int, default=4, help="update iterations in training")
    parser.add_argument("--lr", type=float, default=4e-4)
    parser.add_argument("--size", type=parse_size, default=(256, 256), help="sample size WxH (the graph input)")
    parser.add_argument("--train-crop", type=parse_size, default=None,
                        help="random sub-crop WxH of each sample (cheaper steps; default: whole sample)")
    parser.add_argument("--oversample", type=parse_oversample, nargs="+", default=[], metavar="REGIME=K",
                        help="list every training frame of REGIME K times per epoch (e.g. mixed=3 penumbra=2)")
    parser.add_argument("--init", type=Path, default=None,
                        help="fine-tune: start from this checkpoint's weights with a fresh optimiser and schedule")
    parser.add_argument("--target-weight", type=float, default=1.0,
                        help="loss weight of target pixels relative to the background's (default 1: plain mean)")
    parser.add_argument("--edge-weight", type=float, default=1.0,
                        help="extra loss factor of target pixels near the silhouette (default 1: none)")
    parser.add_argument("--edge-radius", type=int, default=3,
                        help="silhouette band of --edge-weight, in pixels (default 3)")
    parser.add_argument("--photometric", choices=("mild", "wide"), default="mild",
                        help="photometric augmentation: mild per-view jitter (default), or wide: also one look per "
                             "sample shared by both views (tone curve, tint, clipping exposure, blur)")
    add_loop_arguments(parser, workers=0)


def parse_oversample(text: str) -> tuple[str, int]:
    """``"mixed=3"`` -> ``("mixed", 3)``."""
    regime, sep, k = text.partition("=")
    try:
        factor = int(k)
    except ValueError:
        factor = 0
    if not sep or not regime or factor < 1:
        raise argparse.ArgumentTypeError(f"expected REGIME=K with K >= 1, got {text!r}")
    return regime, factor


def run(args: argparse.Namespace) -> int:
    from spacepose._optional import import_optional

    import_optional("torch")
    from spacepose.tools.train_stereo import TrainConfig, train_stereo

    cfg = TrainConfig(dataset=str(args.dataset), out=str(args.out), steps=args.steps, batch=args.batch,
                      variant=args.variant, preset=args.preset, iters=args.iters, lr=args.lr, size=tuple(args.size),
                      train_crop=tuple(args.train_crop) if args.train_crop else None,
                      ckpt_every=args.ckpt_every, val_every=args.val_every, val_samples=args.val_samples,
                      log_every=args.log_every, workers=args.workers, threads=args.threads, seed=args.seed,
                      limit=args.limit, oversample=dict(args.oversample),
                      init=str(args.init) if args.init else None, time_limit_s=args.time_limit_s,
                      pace_lr=args.pace_lr, target_weight=args.target_weight,
                      edge_weight=args.edge_weight, edge_radius=args.edge_radius,
                      photometric=args.photometric)
    if not args.target_weight > 0:
        raise SystemExit("--target-weight must be > 0")
    if not args.edge_weight > 0 or args.edge_radius < 1:
        raise SystemExit("--edge-weight must be > 0 and --edge-radius >= 1")
    if args.pace_lr and not args.time_limit_s:
        raise SystemExit("--pace-lr needs --time-limit-s")
    if args.init and args.resume:
        raise SystemExit("--init starts a new run; --resume continues one: give one of them")
    summary = train_stereo(cfg, resume=args.resume)
    print(json.dumps(summary, indent=2))
    return 0

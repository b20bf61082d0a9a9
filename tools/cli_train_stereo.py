"""``spacepose train-stereo DATASET --out runs/stereo --steps N ...``: train TSCA-Stereo.

CPU by default, the GPU when torch sees one; under ``torchrun`` (``WORLD_SIZE`` set) every rank
trains on its own shard with DDP, no flag needed.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

HELP = "train TSCA-Stereo (IGEV loss and schedule) on a rendered dataset; resumable"


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"size must be WxH, got {text!r}") from err
    return w, h


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dataset", type=Path, help="dataset folder (CONVENTIONS layout)")
    parser.add_argument("--out", type=Path, default=Path("runs/stereo"), help="run folder (checkpoint, log, config)")
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--batch", type=int, default=4, help="batch per process")
    parser.add_argument("--variant", choices=("igev", "ta", "seca", "full"), default="full")
    parser.add_argument("--preset", choices=("cpu", "paper"), default="cpu", help="model widths")
    parser.add_argument("--iters", type=int, default=4, help="update iterations in training")
    parser.add_argument("--lr", type=float, default=4e-4)
    parser.add_argument("--size", type=_size, default=(256, 256), help="sample size WxH (the graph input)")
    parser.add_argument("--train-crop", type=_size, default=None,
                        help="random sub-crop WxH of each sample (cheaper steps; default: whole sample)")
    parser.add_argument("--ckpt-every", type=int, default=200)
    parser.add_argument("--val-every", type=int, default=200)
    parser.add_argument("--val-samples", type=int, default=8)
    parser.add_argument("--log-every", type=int, default=10)
    parser.add_argument("--workers", type=int, default=0, help="DataLoader workers")
    parser.add_argument("--threads", type=int, default=0, help="torch.set_num_threads (0: torch default)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--limit", type=int, default=None, help="use only the first N training frames")
    parser.add_argument("--resume", action="store_true", help="continue OUT/last.pt")


def run(args: argparse.Namespace) -> int:
    from spacepose._optional import import_optional

    import_optional("torch")
    from spacepose.tools.train_stereo import TrainConfig, train_stereo

    cfg = TrainConfig(dataset=str(args.dataset), out=str(args.out), steps=args.steps, batch=args.batch,
                      variant=args.variant, preset=args.preset, iters=args.iters, lr=args.lr, size=tuple(args.size),
                      train_crop=tuple(args.train_crop) if args.train_crop else None,
                      ckpt_every=args.ckpt_every, val_every=args.val_every, val_samples=args.val_samples,
                      log_every=args.log_every, workers=args.workers, threads=args.threads, seed=args.seed,
                      limit=args.limit)
    summary = train_stereo(cfg, resume=args.resume)
    print(json.dumps(summary, indent=2))
    return 0

"""Arguments shared by ``spacepose train-stereo`` and ``spacepose train-pose`` (stdlib only)."""

from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["add_run_arguments", "add_loop_arguments"]


def add_run_arguments(parser: argparse.ArgumentParser, *, out: str, batch: int) -> None:
    """DATASET, --out (default ``out``), --steps, --batch (default ``batch``)."""
    parser.add_argument("dataset", type=Path, help="dataset folder (CONVENTIONS layout)")
    parser.add_argument("--out", type=Path, default=Path(out), help="run folder (checkpoint, log, config)")
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--batch", type=int, default=batch, help="batch per process")


def add_loop_arguments(parser: argparse.ArgumentParser, *, workers: int) -> None:
    """Checkpoint / validation / log cadence, DataLoader workers (default ``workers``), threads, seed,
    --limit and --resume."""
    parser.add_argument("--ckpt-every", type=int, default=200)
    parser.add_argument("--val-every", type=int, default=200)
    parser.add_argument("--val-samples", type=int, default=8)
    parser.add_argument("--log-every", type=int, default=10)
    parser.add_argument("--workers", type=int, default=workers, help="DataLoader workers")
    parser.add_argument("--threads", type=int, default=0, help="torch.set_num_threads (0: torch default)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--limit", type=int, default=None, help="use only the first N training frames")
    parser.add_argument("--resume", action="store_true", help="continue OUT/last.pt")
    parser.add_argument("--time-limit-s", type=float, default=None,
                        help="also stop (checkpoint saved, resumable) after this many seconds of training")
    parser.add_argument("--pace-lr", action="store_true",
                        help="with --time-limit-s: run the learning-rate schedule to its end by the time limit, "
                             "jumping ahead of the step count when the steps are slower than steps/time")

"""``spacepose render``: render a synthetic stereo dataset (sharded, resumable)."""

from __future__ import annotations

import argparse
import sys
import time

from spacepose.cli_args import parse_size

HELP = "render a synthetic binocular dataset of a target spacecraft (sharded, resumable)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dataset", help="output folder (created; an existing one is resumed if it is the same dataset)")
    parser.add_argument("--target", default="tdrs", help="tdrs, mro or a mesh file path (default tdrs)")
    parser.add_argument("--count", type=int, default=2000, help="frames in total, train+test 9:1 (default 2000; the paper: 39600)")
    parser.add_argument("--size", type=parse_size, default=(640, 480), help="WIDTHxHEIGHT (default 640x480; the paper: 1280x960)")
    parser.add_argument("--seed", type=int, default=0, help="dataset seed (default 0)")
    parser.add_argument("--shard", default="1/1", help="render only shard k of K (1 <= k <= K), e.g. 3/8 (default 1/1)")
    parser.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    parser.add_argument("--depth", type=float, nargs=2, default=(10.0, 50.0), metavar=("MIN", "MAX"), help="target z range in metres (default 10 50)")
    parser.add_argument("--rig", default=None, help="ideal parallel rig file to render with (default: the paper rig scaled to --size)")
    parser.add_argument("--no-depth", action="store_true",
                        help="do not write depth/<name>.pfm (halves the maps' disk use; evaluation needs no depth)")
    parser.add_argument("--paper", action="store_true", help="the paper's dataset: --count 39600 --size 1280x960")


def run(args: argparse.Namespace) -> int:
    from spacepose.calibration.rig import load_rig

    from .dataset import RenderConfig, parse_shard, render_dataset

    count, size = args.count, args.size
    if args.paper:
        count, size = 39600, (1280, 960)
    shard = parse_shard(args.shard)
    config = RenderConfig(target=args.target, count=count, size=size, seed=args.seed, depth_range=tuple(args.depth),
                          depth_maps=not args.no_depth)
    rig = load_rig(args.rig) if args.rig else None
    start = time.perf_counter()
    interactive = sys.stderr.isatty()

    def progress(done: int, todo: int) -> None:
        if interactive or done == todo or done % 100 == 0:
            rate = done / max(time.perf_counter() - start, 1e-9)
            end = "\n" if done == todo or not interactive else "\r"
            print(f"  {done}/{todo} frames ({rate:.2f}/s)", end=end, file=sys.stderr, flush=True)

    summary = render_dataset(args.dataset, config, shard=shard, workers=max(1, args.workers), rig=rig, progress=progress)
    elapsed = time.perf_counter() - start
    print(
        f"{args.dataset}: shard {summary['shard']}: rendered {summary['rendered']}, skipped {summary['skipped']} complete, "
        f"labels.jsonl {summary['labels']} frames, {elapsed:.1f} s"
    )
    return 0

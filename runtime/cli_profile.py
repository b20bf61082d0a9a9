"""``spacepose profile FOLDER --calib RIG [--budget FILE] [--json OUT]``: latency and memory vs budget.

Runs the estimator on every frame of a sequence (after ``--warmup`` untimed frames), prints the
p50 / p95 / max of every stage and the peak RSS, writes them as JSON, and exits with 1 when the
run is over budget (p95 frame time above ``1000 / rate_hz`` ms, or peak RSS above the limit).
"""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path

HELP = "profile the flight runtime on an image folder against a latency/memory budget"

logger = logging.getLogger(__name__)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("folder", type=Path, help="sequence folder with left/ and right/ subfolders")
    parser.add_argument("--calib", type=Path, required=True, help="stereo calibration file")
    parser.add_argument("--budget", type=Path, default=None, help="budget file (JSON or YAML: rate_hz, peak_rss_mb, cores)")
    parser.add_argument("--json", type=Path, default=None, help="write the profile as JSON here")
    parser.add_argument("--bundle", type=Path, default=None, help="model bundle folder (default: the shipped one)")
    parser.add_argument("--threads", type=int, default=None, help="onnxruntime threads (default: the budget's cores)")
    parser.add_argument("--limit", type=int, default=None, help="profile at most this many frames")
    parser.add_argument("--warmup", type=int, default=1, help="untimed frames run first (default 1)")
    parser.add_argument("--force", action="store_true", help="overwrite an existing --json file")


def format_table(summary: dict[str, dict[str, float]]) -> str:
    lines = [f"{'stage':<14}{'p50 ms':>10}{'p95 ms':>10}{'max ms':>10}{'n':>6}"]
    for name, row in summary.items():
        lines.append(f"{name:<14}{row['p50']:>10.1f}{row['p95']:>10.1f}{row['max']:>10.1f}{row['n']:>6d}")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from .cli_estimate import Progress, check_outputs, list_frames, read_pair
    from .errors import DatasetError, ImageReadError
    from .estimator import PoseEstimator
    from .profiler import (budget_to_dict, check_budget, load_budget, network_split, peak_rss_bytes,
                           summarize_timings)

    try:
        budget = load_budget(args.budget)
    except (OSError, ValueError) as err:
        raise DatasetError(f"cannot read budget {args.budget}: {err}") from err
    names = list_frames(args.folder)
    if args.limit is not None:
        names = names[: max(args.limit, 0)]
    if not names:
        raise DatasetError(f"{args.folder} holds no frames to profile")
    check_outputs([args.json], None, args.force)
    threads = args.threads or budget.cores
    rss_before = peak_rss_bytes()
    estimator = PoseEstimator(args.calib, bundle=args.bundle, threads=threads)
    samples, statuses, network = [], {}, []
    progress = Progress(len(names))
    try:
        for i, name in enumerate(names):
            try:
                left, right = read_pair(args.folder, name)
            except ImageReadError as err:
                logger.warning("frame %s skipped: %s", name, err)
                continue
            if i < args.warmup:
                estimator.estimate(left, right)
                estimator.reset()
                continue
            result = estimator.estimate(left, right)
            samples.append(result.timings_ms)
            network.append(result.network_ms)
            statuses[result.status] = statuses.get(result.status, 0) + 1
            progress.update(i + 1, result.status)
    finally:
        progress.close()
    if not samples:
        raise DatasetError(f"no frame of {args.folder} could be profiled (all unreadable or warm-up)")
    summary = summarize_timings(samples)
    peak = peak_rss_bytes()
    problems = check_budget(summary, peak, budget)
    print(format_table(summary))
    print(f"peak RSS {peak / 2**20:.0f} MiB (before loading: {rss_before / 2**20:.0f} MiB); "
          f"budget: {budget.frame_ms:.0f} ms/frame, {budget.peak_rss_mb:.0f} MiB, {budget.cores} cores")
    split = network_split([sum(t.values()) for t in samples], network)
    print(f"inside the graphs: {split['network_ms_sum'] / len(samples):.0f} ms/frame; outside them (the pipeline's own "
          f"work): {100 * split['non_network_share']:.1f} % of the time")
    print("statuses: " + ", ".join(f"{k}={v}" for k, v in sorted(statuses.items())))
    for problem in problems:
        print(f"OVER BUDGET: {problem}")
    if args.json is not None:
        report = {"frames": len(samples), "threads": threads, "stages_ms": summary, "network_split": split,
                  "peak_rss_mb": peak / 2**20, "budget": budget_to_dict(budget), "over_budget": problems,
                  "statuses": statuses, "bundle": str(estimator.bundle.path)}
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    return 1 if problems else 0

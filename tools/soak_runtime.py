"""Soak test of the flight runtime: many frames through one PoseEstimator, RSS sampled as it goes.

    python tools/soak_runtime.py FOLDER --calib RIG.yaml [--bundle DIR] [--frames 2000]
        [--every 100] [--threads 2] --out soak.json

The frames of FOLDER (left/, right/) are read once and cycled. Every ``--every`` frames the current
and peak resident set size, the frame rate and the statuses so far are recorded; the JSON report
ends with the RSS growth between the first sample and the last (a leak shows as steady growth).
Not run by the test suite (it takes ~2,000 estimator calls).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path)
    parser.add_argument("--calib", type=Path, required=True)
    parser.add_argument("--bundle", type=Path, default=None)
    parser.add_argument("--frames", type=int, default=2000)
    parser.add_argument("--every", type=int, default=100)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--max-pairs", type=int, default=20, help="distinct frames kept in memory")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)

    from spacepose.cli_estimate import list_frames, read_pair
    from spacepose.estimator import PoseEstimator
    from spacepose.profiler import current_rss_bytes, peak_rss_bytes

    names = list_frames(args.folder)[: args.max_pairs]
    pairs = [read_pair(args.folder, name) for name in names]
    if not pairs:
        print(f"no frames in {args.folder}", file=sys.stderr)
        return 2
    estimator = PoseEstimator(args.calib, bundle=args.bundle, threads=args.threads)
    samples, statuses = [], {}
    start = last = time.perf_counter()
    for i in range(args.frames):
        result = estimator.estimate(*pairs[i % len(pairs)])
        statuses[result.status] = statuses.get(result.status, 0) + 1
        if (i + 1) % args.every == 0 or i + 1 == args.frames:
            now = time.perf_counter()
            samples.append({"frame": i + 1, "rss_mb": current_rss_bytes() / 2**20,
                            "peak_rss_mb": peak_rss_bytes() / 2**20,
                            "fps": args.every / max(now - last, 1e-9)})
            last = now
            print(f"{i + 1:>6} frames  RSS {samples[-1]['rss_mb']:.0f} MiB  peak {samples[-1]['peak_rss_mb']:.0f} MiB  "
                  f"{samples[-1]['fps']:.2f} fps", file=sys.stderr)
    report = {
        "frames": args.frames, "distinct_pairs": len(pairs), "threads": args.threads,
        "seconds": time.perf_counter() - start, "statuses": statuses, "samples": samples,
        "rss_growth_mb": samples[-1]["rss_mb"] - samples[0]["rss_mb"],
        "peak_rss_mb": peak_rss_bytes() / 2**20,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    print(f"RSS growth {report['rss_growth_mb']:+.1f} MiB over {args.frames} frames -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

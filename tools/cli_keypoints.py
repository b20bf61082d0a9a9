"""``spacepose keypoints --target tdrs``: SIFT-FPS keypoints stored next to the target mesh."""

from __future__ import annotations

import argparse
from pathlib import Path

HELP = "select SIFT-FPS keypoints (+ centre) for a target and store them with it"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--target", default="tdrs", help="tdrs, mro or a mesh path")
    parser.add_argument("--count", type=int, default=8, help="number of keypoints (centre not counted)")
    parser.add_argument("--views", type=int, default=32)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=None,
                        help="output JSON (default: keypoints.json beside a shipped target's mesh)")
    parser.add_argument("--force", action="store_true", help="overwrite an existing file")


def run(args: argparse.Namespace) -> int:
    from spacepose.tools import keypoints as kp
    from spacepose.tools.targets import load_target

    target = load_target(args.target)
    out = args.out or target.path.parent / "keypoints.json"
    kps = kp.select_keypoints(target, kp.KeypointConfig(n_keypoints=args.count, n_views=args.views, seed=args.seed))
    kp.save_keypoints(kps, out, overwrite=args.force)
    print(f"{target.name}: {len(kps.keypoints)} keypoints from {kps.n_candidates} SIFT candidates -> {out}")
    for i, p in enumerate(kps.keypoints):
        print(f"  kp{i}: {p[0]:+.3f} {p[1]:+.3f} {p[2]:+.3f}")
    print(f"  centre: {kps.centre[0]:+.3f} {kps.centre[1]:+.3f} {kps.centre[2]:+.3f}")
    return 0

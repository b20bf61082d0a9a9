"""The test split and the unseen set with the bundle shipped in session 34, next to session 31's (the bundle before).

    python reports/floor_s34/shipped_summary.py

Reads the committed reports: ``reports/pose_test640_s34/pose_eval.json.gz`` (``spacepose eval-pose data/tdrs640
--limit 150`` and ``--skip 150``, ``--threads 1 --overlays 0``, the frames of both halves) and
``reports/pose_unseen1280_s34/pose_eval.json.gz`` (``spacepose eval-pose data/tdrs1280_eval --split train
--threads 1 --overlays 0``), and session 31's ``reports/pose_test640_s31`` / ``reports/pose_unseen1280_s31``.
Wrong: a valid pose off by more than 20 deg or 0.5 m; within the bar: e_t <= 0.10 m and e_R <= 2 deg.
"""
from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np

REPORTS = Path(__file__).resolve().parent.parent
SETS = (("test split, 300 frames", "pose_test640"), ("unseen 1280x960, 90 frames", "pose_unseen1280"))


def summary(frames: list[dict]) -> str:
    v = [r for r in frames if r["valid"]]
    e_t, e_R = np.array([r["e_t"] for r in v]), np.array([r["e_R"] for r in v])
    wrong = int(np.sum((e_t > 0.5) | (e_R > 20.0)))
    within = int(np.sum((e_t <= 0.10) & (e_R <= 2.0)))
    return (f"{len(v):>4} valid ({100 * len(v) / len(frames):.1f} %)  mean {e_t.mean():.3f} m / {e_R.mean():.2f} deg  "
            f"median {np.median(e_t):.3f} m / {np.median(e_R):.2f} deg  > 90 deg {int(np.sum(e_R > 90.0))}  "
            f"wrong {wrong}  within {within}  positions {sum(bool(r['position_valid']) for r in frames)}")


def main() -> int:
    for what, stem in SETS:
        print(what)
        for session in ("s31", "s34"):
            with gzip.open(REPORTS / f"{stem}_{session}" / "pose_eval.json.gz", "rt") as fh:
                print(f"  {session}: {summary(json.load(fh)['frames'])}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

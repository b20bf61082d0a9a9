"""Session 38: the default bundle before (session 35's gates) and after (the image route's margin 0 and score 0.05)
on the test split, the unseen 1,280x960 set and the restyled test split (measured, not judged: rule2.txt).

    python reports/tone_s38/shipped_summary.py

Rows: before, ``reports/pose_test640_s35``, ``reports/pose_unseen1280_s35`` and ``reports/restyle_s36/
pose_restyle_shipped.json.gz`` (the same bundle; session 36's run); after, ``reports/pose_{test640,unseen1280,
restyle640}_s38/pose_eval.json.gz`` (``python -m spacepose.tools.shard_eval data/tdrs640 --split test --workers 2
--out …``; ``data/tdrs1280_eval --split train``; ``data/tdrs640_restyle --split test``).
"""
from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np

REPORTS = Path(__file__).resolve().parent.parent
SETS = {"test split": ("pose_test640_s35/pose_eval.json.gz", "pose_test640_s38/pose_eval.json.gz"),
        "unseen 1280x960": ("pose_unseen1280_s35/pose_eval.json.gz", "pose_unseen1280_s38/pose_eval.json.gz"),
        "restyled test split": ("restyle_s36/pose_restyle_shipped.json.gz", "pose_restyle640_s38/pose_eval.json.gz")}


def summary(path: Path) -> dict:
    rows = json.loads(gzip.decompress(path.read_bytes()))["frames"]
    valid = [r for r in rows if r["valid"]]
    e_t, e_R = np.array([r["e_t"] for r in valid]), np.array([r["e_R"] for r in valid])
    return {"frames": len(rows), "valid": len(valid), "e_t_mean": e_t.mean(), "e_R_mean": e_R.mean(),
            "e_t_median": np.median(e_t), "e_R_median": np.median(e_R),
            "within": int(((e_t <= 0.10) & (e_R <= 2.0)).sum()), "wrong": int(((e_t > 0.5) | (e_R > 20.0)).sum()),
            "far": int((e_R > 90.0).sum()), "positions": sum(bool(r.get("position_valid")) for r in rows),
            "frames_valid": {r["frame"] for r in valid}}


def print_table(sets: dict[str, tuple[str, ...]], labels: tuple[str, ...], before: int, after: int) -> None:
    """A table row per set (its row files, relative to ``reports/``) and label, then, where every file exists, how
    many valid frames labels ``before`` and ``after`` (indices) share."""
    print("| set | bundle | valid | mean e_t / e_R | median e_t / e_R | within 0.10 m / 2° | wrong | > 90° | positions |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, files in sets.items():
        got = {}
        for label, rel in zip(labels, files):
            path = REPORTS / rel
            if not path.is_file():
                print(f"| {name} | {label} | (no {rel}) |")
                continue
            s = got[label] = summary(path)
            print(f"| {name} | {label} | {s['valid']} of {s['frames']} ({100 * s['valid'] / s['frames']:.1f} %) | "
                  f"{s['e_t_mean']:.3f} m / {s['e_R_mean']:.2f}° | {s['e_t_median']:.3f} m / {s['e_R_median']:.2f}° | "
                  f"{s['within']} | {s['wrong']} | {s['far']} | {s['positions']} |")
        if len(got) == len(labels):
            a, b = got[labels[before]]["frames_valid"], got[labels[after]]["frames_valid"]
            print(f"|  | valid in both {len(a & b)}, only before {len(a - b)}, only after {len(b - a)} | | | | | | | |")


def main() -> int:
    print_table(SETS, ("session 35", "session 38"), 0, 1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

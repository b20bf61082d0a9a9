"""Session 39: the default bundle before (session 38's) and after flip_classifier.decide_tone_gamma 2.0 on the test
split, the unseen 1,280x960 set and the restyled test split (measured, not judged: reports/tone_s39/rule.txt).

Session 38's rows came from another machine; on this session's machine session 38's bundle (and session 38's code)
gives slightly different poses on most frames (a few mm and tenths of a degree; the frames re-rendered here are
identical to those rendered without ``--no-depth``), so before and after are compared on this machine: session 38's
bundle (``--bundle`` of a checkout of commit 11c3a97) in ``pose_eval_before.json.gz`` beside the after rows.

    python reports/tone_s39/shipped_summary.py

Rows: session 38's, ``reports/pose_{test640,unseen1280,restyle640}_s38/pose_eval.json.gz``; before and after,
``reports/pose_{test640,unseen1280,restyle640}_s39/pose_eval.json.gz`` (``python -m spacepose.tools.shard_eval data/tdrs640
--split test --workers 2 --out …``; ``data/tdrs1280_eval --split train``; ``data/tdrs640_restyle --split test``), the
rows cut to their columns by :func:`spacepose.tools.shard_eval.write_rows`.
"""
from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np

REPORTS = Path(__file__).resolve().parent.parent
SETS = {name: (f"pose_{stem}_s38/pose_eval.json.gz", f"pose_{stem}_s39/pose_eval_before.json.gz",
                f"pose_{stem}_s39/pose_eval.json.gz")
        for name, stem in (("test split", "test640"), ("unseen 1280x960", "unseen1280"),
                           ("restyled test split", "restyle640"))}


def summary(path: Path) -> dict:
    rows = json.loads(gzip.decompress(path.read_bytes()))["frames"]
    valid = [r for r in rows if r["valid"]]
    e_t, e_R = np.array([r["e_t"] for r in valid]), np.array([r["e_R"] for r in valid])
    return {"frames": len(rows), "valid": len(valid), "e_t_mean": e_t.mean(), "e_R_mean": e_R.mean(),
            "e_t_median": np.median(e_t), "e_R_median": np.median(e_R),
            "within": int(((e_t <= 0.10) & (e_R <= 2.0)).sum()), "wrong": int(((e_t > 0.5) | (e_R > 20.0)).sum()),
            "far": int((e_R > 90.0).sum()), "positions": sum(bool(r.get("position_valid")) for r in rows),
            "frames_valid": {r["frame"] for r in valid}}


def main() -> int:
    print("| set | bundle | valid | mean e_t / e_R | median e_t / e_R | within 0.10 m / 2° | wrong | > 90° | positions |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, (s38, before, after) in SETS.items():
        got = {}
        for label, rel in (("session 38 (its machine)", s38), ("session 38's bundle, here", before),
                           ("session 39", after)):
            path = REPORTS / rel
            if not path.is_file():
                print(f"| {name} | {label} | (no {rel}) |")
                continue
            s = got[label] = summary(path)
            print(f"| {name} | {label} | {s['valid']} of {s['frames']} ({100 * s['valid'] / s['frames']:.1f} %) | "
                  f"{s['e_t_mean']:.3f} m / {s['e_R_mean']:.2f}° | {s['e_t_median']:.3f} m / {s['e_R_median']:.2f}° | "
                  f"{s['within']} | {s['wrong']} | {s['far']} | {s['positions']} |")
        if len(got) == 3:
            a, b = got["session 38's bundle, here"]["frames_valid"], got["session 39"]["frames_valid"]
            print(f"|  | valid in both {len(a & b)}, only before {len(a - b)}, only after {len(b - a)} | | | | | | | |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

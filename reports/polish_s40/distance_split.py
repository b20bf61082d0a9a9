"""Session 40: the valid poses' errors per 10 m distance bin, from committed rows (session 39's, the shipped bundle).

    python reports/polish_s40/distance_split.py [ROWS.json.gz ...]

Default rows: reports/pose_test640_s39/pose_eval.json.gz and reports/pose_unseen1280_s39/pose_eval.json.gz.
|los|: the position error along the line of sight (``e_pos_los``), most of e_t.
"""
from __future__ import annotations

import gzip
import json
import sys
from pathlib import Path

import numpy as np

REPORTS = Path(__file__).resolve().parent.parent
DEFAULT = [REPORTS / "pose_test640_s39" / "pose_eval.json.gz", REPORTS / "pose_unseen1280_s39" / "pose_eval.json.gz"]


def main(paths: list[str]) -> int:
    for path in paths or DEFAULT:
        rows = [r for r in json.load(gzip.open(path, "rt"))["frames"] if r["valid"]]
        print(f"{path}: {len(rows)} valid poses")
        print("| distance | poses | mean e_t (m) | mean \\|los\\| (m) | mean e_R (deg) | median e_R | within |")
        print("|---|---|---|---|---|---|---|")
        for lo in range(10, 60, 10):
            s = [r for r in rows if lo <= r["distance"] < lo + 10]
            if not s:
                continue
            et = np.array([r["e_t"] for r in s])
            er = np.array([r["e_R"] for r in s])
            los = np.array([abs(r["e_pos_los"]) for r in s])
            print(f"| {lo}-{lo + 10} m | {len(s)} | {et.mean():.3f} | {los.mean():.3f} | {er.mean():.2f} | "
                  f"{np.median(er):.2f} | {int(np.sum((et <= 0.10) & (er <= 2.0)))} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))

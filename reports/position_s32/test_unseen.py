"""The test split and the unseen 1280x960 set with session 32's bundle: positions before and after the range bias.

    python reports/position_s32/test_unseen.py [RUNS]

``RUNS`` (default ``runs/final``) holds this bundle's ``eval-pose`` reports, run from commit 593ef15:
``test_a`` / ``test_b`` (``spacepose eval-pose data/tdrs640 --limit 150 | --skip 150 --threads 1 --overlays 0 --out
…``) and ``unseen_a`` / ``unseen_b`` (``spacepose eval-pose data/tdrs1280_eval --split train --limit 45 | --skip 45
--threads 1 --overlays 0 --out …``). "Before" is session 31's committed rows (``reports/pose_test640_s31``,
``reports/pose_unseen1280_s31``). When the runs are there their frames are cut to the columns used here and
written to ``rows_test_unseen.json.gz`` beside this script; otherwise that committed file is read.
"""
from __future__ import annotations

import gzip
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "position_s25"))
sys.path.insert(0, str(HERE))
from _rows import compact_rows  # noqa: E402
from judge import KEYS, _same, position_table, print_table  # noqa: E402  (reports/position_s32/judge.py)

SETS = {"test": ("pose_test640_s31", ("test_a", "test_b")), "unseen": ("pose_unseen1280_s31", ("unseen_a", "unseen_b"))}


def all_positions(rows: list[dict]) -> str:
    p = [r for r in rows if r["position_valid"]]
    e = np.array([r["e_pos"] for r in p])
    tau = np.array([r["depth_tolerance_m"] for r in p])
    v = [r for r in rows if r["valid"]]
    return (f"valid {len(v)}, positions {len(p)}: mean e_pos {e.mean():.3f} m, median {np.median(e):.3f} m, max "
            f"{e.max():.2f} m, within tau {100 * np.mean(e <= tau):.1f} %")


def main(argv: list[str]) -> int:
    runs = Path(argv[0]) if argv else Path("runs/final")
    files = {name: [runs / part / "pose_eval.json" for part in parts] for name, (_, parts) in SETS.items()}
    new = compact_rows(files, HERE / "rows_test_unseen.json.gz", KEYS)
    for name, (before, _) in SETS.items():
        with gzip.open(HERE.parent / before / "pose_eval.json.gz", "rt") as fh:
            old = [{k: r.get(k) for k in KEYS} for r in json.load(fh)["frames"]]
        same = len(old) == len(new[name]) and all(
            all(_same(a[k], b[k]) for k in ("frame", "valid", "status", "e_t", "e_R", "position_valid"))
            for a, b in zip(old, new[name]))
        print(f"{name}: {len(old)} frames; decisions the same as session 31's: {same}")
        print(f"  session 31 (before): {all_positions(old)}")
        print(f"  session 32 (after):  {all_positions(new[name])}")
        print("  position-only frames:")
        print_table("before", position_table(old))
        print_table("after", position_table(new[name]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))

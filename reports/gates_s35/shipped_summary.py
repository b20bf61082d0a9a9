"""The test split and the unseen set with the bundle shipped in session 35, next to sessions 31 and 34's.

    python reports/gates_s35/shipped_summary.py

Reads the committed reports ``reports/pose_test640_s35/pose_eval.json.gz`` (``spacepose eval-pose data/tdrs640
--limit 150`` and ``--skip 150``, ``--threads 1 --overlays 0``, the frames of both halves) and
``reports/pose_unseen1280_s35/pose_eval.json.gz`` (``spacepose eval-pose data/tdrs1280_eval --split train --threads 1
--overlays 0``), and sessions 31 and 34's (reports/floor_s34/shipped_summary.py, whose ``summary`` this uses).
"""
from __future__ import annotations

import gzip
import importlib.util
import json
from pathlib import Path

REPORTS = Path(__file__).resolve().parent.parent
_SPEC = importlib.util.spec_from_file_location("shipped_summary_s34", REPORTS / "floor_s34" / "shipped_summary.py")
s34 = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(s34)


def main() -> int:
    for what, stem in s34.SETS:
        print(what)
        for session in ("s31", "s34", "s35"):
            with gzip.open(REPORTS / f"{stem}_{session}" / "pose_eval.json.gz", "rt") as fh:
                print(f"  {session}: {s34.summary(json.load(fh)['frames'])}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

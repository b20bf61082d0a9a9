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

import importlib.util
from pathlib import Path

REPORTS = Path(__file__).resolve().parent.parent
SETS = {name: (f"pose_{stem}_s38/pose_eval.json.gz", f"pose_{stem}_s39/pose_eval_before.json.gz",
                f"pose_{stem}_s39/pose_eval.json.gz")
        for name, stem in (("test split", "test640"), ("unseen 1280x960", "unseen1280"),
                           ("restyled test split", "restyle640"))}


def main() -> int:
    spec = importlib.util.spec_from_file_location("tone_s38_shipped_summary",
                                                  REPORTS / "tone_s38" / "shipped_summary.py")
    s38 = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(s38)                 # session 38's table, on this session's rows
    s38.print_table(SETS, ("session 38 (its machine)", "session 38's bundle, here", "session 39"), 1, 2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Session 42: the default bundle before (session 41's) and with the range fit on the test split, the unseen 1,280x960
set and the restyled test split (measured, not judged: reports/range_s42/plan.txt).

    python reports/range_s42/shipped_summary.py

Rows: before, session 41's ``reports/pose_{test640,unseen1280,restyle640}_s41/pose_eval.json.gz``; after,
``reports/pose_{test640,unseen1280,restyle640}_s42/pose_eval.json.gz`` (``python -m spacepose.tools.shard_eval
data/tdrs640 --split test --workers 2 --out …``; ``data/tdrs1280_eval --split train``; ``data/tdrs640_restyle --split
test``, the restyled copy of the test split: ``python -m spacepose.tools.restyle data/tdrs640 data/tdrs640_restyle
--seed 1616 --split test``).
"""
from __future__ import annotations

import importlib.util
from pathlib import Path

REPORTS = Path(__file__).resolve().parent.parent
SETS = {name: (f"pose_{stem}_s41/pose_eval.json.gz", f"pose_{stem}_s42/pose_eval.json.gz")
        for name, stem in (("test split", "test640"), ("unseen 1280x960", "unseen1280"),
                           ("restyled test split", "restyle640"))}


def main() -> int:
    spec = importlib.util.spec_from_file_location("tone_s38_shipped_summary",
                                                  REPORTS / "tone_s38" / "shipped_summary.py")
    s38 = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(s38)                 # session 38's table, on these rows
    s38.print_table(SETS, ("session 41", "session 42 (the range fit)"), 0, 1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

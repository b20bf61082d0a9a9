"""The exploration behind reports/floor_s34/rule.txt: a floor on the reported confidence, simulated on session 33's
rows (spent sets), for the shipped bundle and for session 19's stereo graph in it.

    python reports/floor_s34/explore.py

Reads ``reports/stereo_s33/rows_explore.json.gz`` (test split, unseen, val3, val4 and 12 of session 30's fit
sequences) and ``reports/stereo_s33/rows.json.gz`` (session 33's check sets, spent by that check): 2,804 frames per
bundle. A floor turns a valid pose whose ``confidence`` is under it into an invalid one. On independent frames that
is exact (``eval-pose`` runs without a prior); in sequences a refused pose no longer serves as the next frame's prior,
which these rows cannot show, so the sequences' part is an estimate.
"""
from __future__ import annotations

import importlib.util
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROWS = [HERE.parent / "stereo_s33" / "rows_explore.json.gz", HERE.parent / "stereo_s33" / "rows.json.gz"]
FLOORS = (0.0, 0.02, 0.03, 0.04, 0.05, 0.06, 0.07, 0.08, 0.09, 0.10, 0.12, 0.15)

_spec = importlib.util.spec_from_file_location("judge_s34", HERE / "judge.py")
judge = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(judge)   # floored; its _load and s33 (session 33's judge: counts)
floor_s33 = judge._load("confidence_floor_s33", HERE.parent / "stereo_s33" / "confidence_floor.py")   # valid_rows


def load(mode: str) -> list[dict]:
    """The valid rows of ``mode`` (``base`` or ``gpu19``) in both files."""
    return [r for path in ROWS for r in floor_s33.valid_rows(path, mode)]


def counts(rows: list[dict], floor: float) -> dict[str, int]:
    """Session 33's counts of ``rows`` with the poses under ``floor`` turned invalid."""
    return judge.s33.counts(judge.floored(rows, floor))


def main() -> int:
    print("floor on confidence, simulated on 2,804 spent frames per bundle (valid / wrong / > 20 deg / > 90 deg / "
          "within 0.10 m and 2 deg):")
    print(f"{'floor':>6}  {'shipped':<28}{'session 19 stereo':<28}")
    for floor in FLOORS:
        cells = []
        for mode in ("base", "gpu19"):
            c = counts(load(mode), floor)
            cells.append(f"{c['valid']:>5} / {c['wrong']:>2} / {c['rotated']} / {c['flips']} / {c['within']:>3}      ")
        print(f"{floor:>6.2f}  " + "".join(cells))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

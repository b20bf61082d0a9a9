"""The shipped bundle's confidence against the share of its valid poses within the bar, by distance (session 35).

    python reports/gates_s35/confidence_by_distance.py

Reads committed rows only: the shipped bundle's independent 640x480 frames of session 34's two check rounds
(reports/floor_s34/rows.json.gz ``a_cand``, rows2.json.gz ``a2_cand``: this bundle, then the candidate) and of
session 35's check (reports/gates_s35/rows.json.gz ``a_base``). Within: e_t <= 0.10 m and e_R <= 2 deg.
"""
from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np

REPORTS = Path(__file__).resolve().parent.parent
SOURCES = ((REPORTS / "floor_s34" / "rows.json.gz", "a_cand"), (REPORTS / "floor_s34" / "rows2.json.gz", "a2_cand"),
           (REPORTS / "gates_s35" / "rows.json.gz", "a_base"))
BINS = ((10, 15), (15, 20), (20, 25), (25, 30), (30, 40), (40, 50))


def valid_rows() -> list[dict]:
    rows = []
    for path, group in SOURCES:
        with gzip.open(path, "rt") as fh:
            rows += [r for r in json.load(fh)[group] if r["valid"]]
    return rows


def main() -> int:
    rows = valid_rows()
    d = np.array([r["distance"] for r in rows])
    conf = np.array([r["confidence"] for r in rows])
    e_t, e_r = np.array([r["e_t"] for r in rows]), np.array([r["e_R"] for r in rows])
    print(f"{len(rows)} valid poses of the shipped bundle")
    print("distance   poses  confidence  within  e_t<=0.10  e_R<=2")
    for lo, hi in BINS:
        s = (d >= lo) & (d < hi)
        print(f"{lo:>2}-{hi:<2} m  {int(s.sum()):>6}  {conf[s].mean():>10.3f}  {((e_t <= 0.10) & (e_r <= 2.0))[s].mean():>6.3f}"
              f"  {(e_t <= 0.10)[s].mean():>9.3f}  {(e_r <= 2.0)[s].mean():>6.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Session 25: where the shipped position's error comes from, on round 2's fresh sets (seeds 2503, 2504).

    python reports/position_s25/error_split.py [RUNS]

reads ``RUNS/{q640_a_los,q640_b_los,q1280_los}/pose_eval.json`` (default ``runs/s25``: the shipped bundle,
``spacepose eval-pose data/tdrs640_s25q --split train [--limit 450 | --skip 450] --threads 1 --overlays 0`` and
``data/tdrs1280_s25q``) when they exist and writes the compact rows beside this file (``error_rows.json.gz``); else
reads those committed rows. Splits the position-valid frames by what gave the position: a valid pose, the outline's
best fit (a ``weak_votes`` frame whose outline chamfer is within 1.5 px) or the registered pose. For each: the
range part of the error along the line of sight (mean: the bias; mean absolute) and the lateral part.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from _rows import compact_rows

HERE = Path(__file__).resolve().parent
PARTS = {"640x480 (seed 2503)": ["q640_a_los", "q640_b_los"], "1280x960 (seed 2504)": ["q1280_los"]}
KEYS = ("frame", "valid", "status", "position_valid", "e_pos", "e_pos_los", "outline_chamfer_px", "depth_tolerance_m",
        "distance", "regime")
MAX_CHAMFER_PX = 1.5   # the shipped silhouette.max_chamfer_px


def load(runs: Path) -> dict[str, list[dict]]:
    files = {name: [runs / p / "pose_eval.json" for p in parts] for name, parts in PARTS.items()}
    return compact_rows(files, HERE / "error_rows.json.gz", KEYS, keep=lambda r: r["position_valid"])


def source(r: dict) -> str:
    if r["valid"]:
        return "valid pose"
    return "outline's best fit" if r["outline_chamfer_px"] <= MAX_CHAMFER_PX else "registered pose"


def main() -> int:
    data = load(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("runs/s25"))
    print(f"{'set':<22}{'source':<20}{'frames':>7}{'bias m':>8}{'|range| m':>10}{'lateral m':>10}{'e_pos m':>9}")
    for name, rows in data.items():
        for src in ("valid pose", "outline's best fit", "registered pose"):
            sel = [r for r in rows if source(r) == src]
            if not sel:
                continue
            los = np.array([r["e_pos_los"] for r in sel])
            e = np.array([r["e_pos"] for r in sel])
            lat = np.sqrt(np.maximum(e ** 2 - los ** 2, 0.0))
            print(f"{name:<22}{src:<20}{len(sel):>7}{los.mean():>8.3f}{np.abs(los).mean():>10.3f}{lat.mean():>10.3f}"
                  f"{e.mean():>9.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Session 39: what limits the valid share, read from the open rows of sessions 35 and 37 (every gate open).

    python reports/tone_s39/open_rows.py        # output: open_rows_output.txt

The gate choice on the same rows, every gate free to move (the card's "Gates re-chosen on all open rows"):

    python -m spacepose.tools.choose_gates reports/gates_s35/open_rows.json.gz reports/wide_s37/open_shipped_plain.json.gz
        reports/wide_s37/open_shipped_rest.json.gz --bundle runtime/bundles/default --margin-rows 0
        --classifier-rows 0 --out CHOICE.json
"""
from __future__ import annotations

import gzip
import json
import math
from pathlib import Path

import numpy as np

REPORTS = Path(__file__).resolve().parent.parent
ROWS = ("gates_s35/open_rows.json.gz", "wide_s37/open_shipped_plain.json.gz", "wide_s37/open_shipped_rest.json.gz")
KEYS = ("e_R", "e_t", "e_R_sym", "flip_prob", "outline_chamfer_px", "depth_tolerance_m")


def _value(row: dict, key: str) -> float:
    v = row.get(key)
    return float(v) if isinstance(v, (int, float)) and v is not None and math.isfinite(v) else float("nan")


def main() -> int:
    rows = []
    for rel in ROWS:
        doc = json.loads(gzip.decompress((REPORTS / rel).read_bytes()))
        rows += doc["frames"] if isinstance(doc, dict) else doc
    a = {k: np.array([_value(r, k) for r in rows]) for k in KEYS}
    posed = ~np.isnan(a["e_R"])
    sure = posed & ((a["flip_prob"] >= 0.995) | (a["flip_prob"] <= 0.005))
    right = (a["flip_prob"] > 0.5) == (a["e_R"] < 90.0)
    fits = sure & (a["outline_chamfer_px"] <= 1.5)
    print(f"{len(rows)} open rows; a pose on {posed.sum()}")
    print(f"the classifier sure (p >= 0.995 either way) on {sure.sum()}, right on {right[sure].sum()} "
          f"({100 * right[sure].mean():.1f} %)")
    print(f"  of them the outline within 1.5 px: {fits.sum()}; and the depth tolerance within 1.0 m: "
          f"{(fits & (a['depth_tolerance_m'] <= 1.0)).sum()}")
    either = (a["e_R_sym"] <= 2.0) & (a["e_t"] <= 0.10)
    print(f"within 0.10 m / 2 deg whichever way the flip is decided (e_R_sym): {either.sum()} "
          f"({100 * either.sum() / len(rows):.0f} % of the rows)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

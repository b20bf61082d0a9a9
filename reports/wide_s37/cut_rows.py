"""Cut the session-37 row files beside this file to the columns choose_gates and judge.py read (in place), so that
they fit the tracked tree (tests/runtime/test_package.py). Run once after the Makefile of rule.txt's commands:

    python reports/wide_s37/cut_rows.py
"""
from __future__ import annotations

import gzip
import json
from pathlib import Path

from spacepose.tools.shard_eval import write_rows

HERE = Path(__file__).resolve().parent
KEYS = ("frame", "regime", "distance", "valid", "status", "confidence", "e_t", "e_R", "e_R_sym", "flip_prob",
        "outline_chamfer_px", "outline_margin_px", "outline_image_score", "outline_image_background",
        "outline_image_pixels", "depth_tolerance_m", "polish_deg", "decided_by", "position_valid", "e_pos")


def main() -> int:
    for path in sorted(HERE.glob("*_*.json.gz")):
        doc = json.loads(gzip.decompress(path.read_bytes()))
        if "cut_to" in doc:
            continue
        doc["frames"] = [{k: r.get(k) for k in KEYS} for r in doc["frames"]]
        doc["cut_to"] = list(KEYS)
        write_rows(doc, path)
        print(f"{path.name}: {len(doc['frames'])} rows, {path.stat().st_size} bytes")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

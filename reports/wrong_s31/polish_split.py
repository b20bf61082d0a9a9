"""What tells the valid poses more than 10 degrees off from the others, by decision route (session 31, exploratory).

    python reports/wrong_s31/polish_split.py

Reads the committed rows of session 22's 2,700 fresh frames (``reports/flip_s22/big2700_shipped.json.gz``: the
bundle of session 22, whose outline and image routes are this bundle's) and prints, per route and factor, the median
and 90th percentile over the poses within 10 degrees and every value of the poses more than 10 degrees off, and
what a gate on the polish's turn (``polish_deg``) would keep. Nothing here was judged on fresh data.
"""
from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np

ROWS = Path(__file__).resolve().parent.parent / "flip_s22" / "big2700_shipped.json.gz"
FACTORS = ("polish_deg", "outline_chamfer_px", "outline_margin_px", "outline_image_score", "depth_tolerance_m",
           "distance")


def main() -> int:
    with gzip.open(ROWS, "rt") as fh:
        frames = [r for r in json.load(fh)["frames"] if r["valid"]]
    print(f"{len(frames)} valid poses, {sum(r['e_R'] > 10 for r in frames)} more than 10 deg off")
    for route in ("outline", "image", "classifier", "registration"):
        poses = [r for r in frames if r["decided_by"] == route]
        off = [r for r in poses if r["e_R"] > 10]
        print(f"\n{route}: {len(poses)} poses, {len(off)} more than 10 deg off")
        if not off:
            continue
        for key in FACTORS:
            right = np.array([r[key] for r in poses if r["e_R"] <= 10], dtype=float)
            values = sorted(round(float(r[key]), 2) for r in off)
            print(f"  {key:<20} within 10 deg: median {np.nanmedian(right):.2f}, p90 {np.nanpercentile(right, 90):.2f}"
                  f" | more than 10 deg off: {values}")
    print("\na gate on polish_deg (all routes): kept poses within 10 deg / kept poses more than 10 deg off")
    for cap in (2.0, 3.0, 4.0, 5.0):
        kept = [r for r in frames if not r["polish_deg"] > cap]
        print(f"  polish_deg <= {cap:.0f}: {sum(r['e_R'] <= 10 for r in kept)} / {sum(r['e_R'] > 10 for r in kept)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

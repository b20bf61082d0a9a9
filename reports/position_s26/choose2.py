"""Session 26, round 2: an outline gate for the position of a frame without a pose, chosen on spent rows.

    python reports/position_s26/choose2.py [RUNS]

Reads the candidate-C runs of round 1 (``RUNS/{f640a,f640b,f1280}_lat26``, seeds 2601/2602, now spent) and
``RUNS/dev640_lat26`` (450 frames of seed 2501, spent in session 25) when they exist, writing their compact rows
beside this file (``choose2_rows.json.gz``), else reads those committed rows; prints, for a position-only frame kept when
its outline's best chamfer is at most X px (valid poses always keep theirs): the share of frames with a position,
e_pos mean / p95 / max, the share within ``depth_tolerance_m``, and the count over 1 m and over 2 m.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "position_s25"))
from _rows import compact_rows  # noqa: E402

runs = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("runs/s26")
files = {"spent": [runs / f"{part}_lat26" / "pose_eval.json" for part in ("f640a", "f640b", "f1280", "dev640")]}
rows = compact_rows(files, HERE / "choose2_rows.json.gz",
                    ("frame", "valid", "position_valid", "e_pos", "depth_tolerance_m", "outline_chamfer_px"))["spent"]
print(f"{len(rows)} spent frames; a position-only frame kept when its outline chamfer <= X px")
print(f"{'X px':>6}{'share':>8}{'mean':>7}{'p95':>7}{'max':>7}{'<=tau':>8}{'>1 m':>6}{'>2 m':>6}")
for x in (1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 5.0, float("inf")):
    pos = [r for r in rows if r["position_valid"] and (r["valid"] or r["outline_chamfer_px"] <= x)]
    e = np.array([r["e_pos"] for r in pos])
    within = np.mean([r["e_pos"] <= r["depth_tolerance_m"] for r in pos])
    print(f"{x:>6}{100 * len(pos) / len(rows):>7.1f}%{e.mean():>7.3f}{np.percentile(e, 95):>7.3f}{e.max():>7.2f}"
          f"{100 * within:>7.1f}%{int((e > 1).sum()):>6}{int((e > 2).sum()):>6}")

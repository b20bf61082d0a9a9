"""Session 35: the silhouette, image-route and flip-classifier gates re-derived for the shipped stereo graph.

    python reports/gates_s35/explore.py [RUNS]

RUNS (default ``runs/s35``) holds ``open_{a,c}{0..5}/pose_eval.json``: ``spacepose eval-pose`` of the spent sets
``data/tdrs640_s34a`` (seed 3401) and ``data/tdrs640_s34c`` (seed 3441), train frames 0-900 of each in chunks of
150, with the open bundle of ``open_bundle.py`` (the shipped bundle with the outline, image and classifier gates
open, the registration's margin closed and no confidence floor). When every run is there, the rows are cut to the
columns used here and written beside this script (``open_rows.json.gz``); otherwise that file is read, so the
tables reproduce from the repository alone.

The shipped confidence floor (0.08) acts after every gate, so a pose under it is refused whatever the gates say:
the rows' poses under it are turned invalid before any table (for the classifier's choice of the outline winner's
flip, the winner's confidence stands in for the flip's). Then :func:`spacepose.tools.calibrate_gates.flip_gate_table`
replays the outline, image and classifier gates jointly over a grid (every outline x image setting, the
classifier's grid inside), and this prints the shipped gates' cell, the cells that keep no flip and no more wrong
poses than the shipped gates, ranked by poses within the bar, and the neighbourhood of the chosen cell.
"""
from __future__ import annotations

import gzip
import itertools
import json
import sys
from pathlib import Path

from spacepose.tools.calibrate_gates import flip_gate_table
from spacepose.tools.shard_eval import compact

HERE = Path(__file__).resolve().parent
FLOOR = 0.08
KEYS = ("frame", "valid", "status", "e_t", "e_R", "e_R_sym", "confidence", "outline_chamfer_px", "outline_margin_px",
        "outline_image_score", "outline_image_background", "outline_image_pixels", "flip_prob", "depth_tolerance_m",
        "polish_deg", "distance", "regime", "decided_by")
STEMS = [f"open_{s}{k}" for s in "ac" for k in range(6)]
#: the gates shipped before session 35 (bundle.json, sessions 18-23; rule2.txt changed four of them)
SHIPPED = {"max_chamfer_px": 1.5, "min_margin_px": 0.5, "image_margin": 0.2, "image_score": 0.1, "image_pixels": 16,
           "image_veto": 0.0, "image_chamfer": 2.0, "flip_pixels": 16, "max_background": 0.02,
           "decide_prob": 0.995, "veto_prob": 0.05, "flip_chamfer": 1.5}
#: the cell chosen for reports/gates_s35/rule.txt
CANDIDATE = {"max_chamfer_px": 1.5, "min_margin_px": 1.0, "image_margin": 0.1, "image_score": 0.1, "image_veto": -0.5,
             "image_chamfer": 2.0, "decide_prob": 0.97, "veto_prob": 0.05, "flip_chamfer": 2.0}
NEIGHBOURS = {"max_chamfer_px": (1.25, 1.75), "min_margin_px": (0.7, 1.5), "image_margin": (0.0, 0.2),
              "image_score": (0.0, 0.05, 0.2), "image_veto": (-1.0, 0.0), "image_chamfer": (0.0, 2.5),
              "decide_prob": (0.95, 0.99, 0.995), "veto_prob": (-1.0, 0.1), "flip_chamfer": (1.5, 2.5)}
GRID = {"max_chamfer_px": (1.0, 1.25, 1.5, 1.75, 2.0, 2.5, 3.0), "min_margin_px": (0.2, 0.3, 0.4, 0.5, 0.7, 1.0),
        "image_margin": (0.1, 0.2, 0.3), "image_score": (0.05, 0.1, 0.2), "image_veto": (-1.0, 0.0),
        "image_chamfer": (0.0, 2.0, 2.5, 3.0)}
#: the classifier's own limits, shipped and kept (it decides no frame over them)
CLASSIFIER_MAX_TAU_M = 0.7
CLASSIFIER_MAX_POLISH_DEG = 2.0
DECIDES = (0.97, 0.99, 0.995, 0.999, 2.0)
VETOES = (-1.0, 0.05, 0.1, 0.2)
FLIP_CHAMFERS = (1.0, 1.5, 2.0, 2.5)


def open_rows(runs: Path) -> list[dict]:
    """The open evaluation's rows (cut and written when the runs are there, else read)."""
    path = HERE / "open_rows.json.gz"
    files = [runs / s / "pose_eval.json" for s in STEMS]
    if all(f.is_file() for f in files):
        write_compact(path, [{k: r.get(k) for k in KEYS} for f in files for r in json.loads(f.read_text())["frames"]])
    with gzip.open(path, "rt") as fh:
        return json.load(fh)


def write_compact(path: Path, rows) -> None:
    """Write ``rows`` as gzipped JSON (no timestamp), floats to 6 significant digits: the committed row files stay
    small (the tracked tree must fit the device transfer, tests/runtime/test_package.py)."""
    with open(path, "wb") as raw, gzip.GzipFile(fileobj=raw, mode="wb", mtime=0) as fh:
        fh.write(json.dumps(compact(rows)).encode())


def floored(rows: list[dict]) -> list[dict]:
    """``rows`` with every valid pose under the floor turned invalid."""
    return [dict(r, valid=False) if r["valid"] and r["confidence"] < FLOOR else r for r in rows]


def table(rows: list[dict], grid: dict[str, tuple], decides=DECIDES, vetoes=VETOES, chamfers=FLIP_CHAMFERS
          ) -> list[dict]:
    """Every cell of ``grid`` (the outline and image gates; image_pixels, flip_pixels and the background fixed at the
    shipped values) x the classifier's ``decides`` x ``vetoes`` x ``chamfers``."""
    out = []
    names = list(grid)
    for values in itertools.product(*(grid[n] for n in names)):
        cell = dict(zip(names, values))
        if cell["image_veto"] >= cell["image_score"]:
            continue
        fixed = {k: SHIPPED[k] for k in ("image_pixels", "flip_pixels", "max_background")}
        for r in flip_gate_table(rows, decides, vetoes, chamfers, max_e_t=0.5, max_e_r=20.0, **fixed, **cell,
                                 max_depth_tolerance_m=CLASSIFIER_MAX_TAU_M, max_polish_deg=CLASSIFIER_MAX_POLISH_DEG):
            out.append({**cell, "decide_prob": r["decide_prob"], "veto_prob": r["veto_prob"],
                        "flip_chamfer": r["max_chamfer_px"],
                        **{k: r[k] for k in ("kept", "decided", "vetoed", "flips", "wrong", "within", "e_t_mean",
                                             "e_R_mean")}})
    return out


COLS = ("max_chamfer_px", "min_margin_px", "image_margin", "image_score", "image_veto", "image_chamfer",
        "decide_prob", "veto_prob", "flip_chamfer")


def show(r: dict) -> str:
    return ("  ".join(f"{r[c]:g}" for c in COLS) + f"  | kept {r['kept']:>4} within {r['within']:>4} wrong "
            f"{r['wrong']:>3} flips {r['flips']:>2}  e_t {r['e_t_mean']:.3f} e_R {r['e_R_mean']:.2f}")


def main(argv: list[str]) -> int:
    rows = open_rows(Path(argv[0]) if argv else Path("runs/s35"))
    print(f"{len(rows)} frames; {sum(bool(r['valid']) for r in rows)} with a pose with the gates open")
    rows = floored(rows)
    print(f"{sum(bool(r['valid']) for r in rows)} of them at confidence >= {FLOOR}")
    shipped = table(rows, {k: (SHIPPED[k],) for k in GRID}, (SHIPPED["decide_prob"],), (SHIPPED["veto_prob"],),
                    (SHIPPED["flip_chamfer"],))[0]
    print("columns: " + "  ".join(COLS))
    print("shipped gates:\n" + show(shipped))
    full = table(rows, GRID)
    safe = [r for r in full if r["flips"] == 0 and r["wrong"] <= shipped["wrong"]]
    safe.sort(key=lambda r: (-r["within"], -r["kept"], r["wrong"]))
    print(f"{len(full)} cells; {len(safe)} with no flip and at most {shipped['wrong']} wrong; the top 25 by within:")
    for r in safe[:25]:
        print(show(r))
    print("the candidate (rule.txt) and its neighbours, one setting moved at a time:")
    print(show(table(rows, {k: (CANDIDATE[k],) for k in GRID}, (CANDIDATE["decide_prob"],),
                     (CANDIDATE["veto_prob"],), (CANDIDATE["flip_chamfer"],))[0]))
    for key, values in NEIGHBOURS.items():
        for value in values:
            cell = {**CANDIDATE, key: value}
            if cell["image_veto"] >= cell["image_score"]:
                continue
            print(f"  {key} {value:g}: " + show(table(rows, {k: (cell[k],) for k in GRID}, (cell["decide_prob"],),
                                                   (cell["veto_prob"],), (cell["flip_chamfer"],))[0]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))

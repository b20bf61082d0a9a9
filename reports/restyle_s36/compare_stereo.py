"""Session 36: EPE and D1 of three stereo graphs on the same test frames, plain and restyled.

    python reports/restyle_s36/compare_stereo.py RUNS_DIR [--out FILE]

RUNS_DIR holds ``st36_{shipped,mild,wide}_{plain,rest}/stereo_eval.json`` of ``spacepose eval-stereo
data/tdrs640[_restyle] --limit 150 --threads 1 [--bundle B] --out RUNS_DIR/st36_G_S``. Prints a markdown table per
group (overall, regimes, distance bins, interior / silhouette), with StereoSGBM on the same frames, and writes
the numbers as JSON (default ``reports/restyle_s36/compare_stereo.json``).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

GRAPHS = ("shipped", "mild", "wide")
SETS = ("plain", "rest")


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", type=Path)
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "compare_stereo.json")
    args = ap.parse_args(argv)
    docs = {(g, s): json.loads((args.runs / f"st36_{g}_{s}" / "stereo_eval.json").read_text())
            for g in GRAPHS for s in SETS if (args.runs / f"st36_{g}_{s}" / "stereo_eval.json").is_file()}
    groups = list(next(iter(docs.values()))["ours"])
    cols = [(g, s) for g in GRAPHS for s in SETS if (g, s) in docs]
    print("EPE px / D1 % (plain -> restyled); sgbm from the shipped graph's runs\n")
    print("| group | " + " | ".join(f"{g} {s}" for g, s in cols) + " | sgbm plain | sgbm rest |")
    print("|---|" + "---|" * (len(cols) + 2))
    table = {}
    for grp in groups:
        cells = []
        for g, s in cols:
            m = docs[(g, s)]["ours"][grp]
            cells.append(f"{m['epe']:.3f} / {m['d1']:.2f}")
            table.setdefault(grp, {})[f"{g}_{s}"] = {"epe": m["epe"], "d1": m["d1"]}
        for s in SETS:
            m = docs.get(("shipped", s), {}).get("sgbm", {}).get(grp)
            cells.append(f"{m['epe']:.3f} / {m['d1']:.2f}" if m else "-")
            if m:
                table[grp][f"sgbm_{s}"] = {"epe": m["epe"], "d1": m["d1"]}
        print(f"| {grp} | " + " | ".join(cells) + " |")
    args.out.write_text(json.dumps({"frames": next(iter(docs.values()))["frames"], "table": table}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))

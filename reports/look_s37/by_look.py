"""Session 37: the shipped bundle on the test split as rendered, restyled (session 36) and in grey — valid, within,
wrong, positions, and whether the confidence stays calibrated under another look.

    python reports/look_s37/by_look.py

Reads committed rows: ``reports/pose_test640_s35/pose_eval.json.gz`` (as rendered),
``reports/restyle_s36/pose_restyle_shipped.json.gz`` (restyled) and ``pose_grey_shipped.json.gz`` beside this file
(grey: ``python reports/look_s37/normalise.py copy data/tdrs640 /tmp/s37/d_plain_grey300 grey 300``, then
``spacepose eval-pose /tmp/s37/d_plain_grey300 --skip {0,150} --limit 150 --threads 1 --overlays 0``; the rows cut
to the columns used here). Within: e_t <= 0.10 m and e_R <= 2 deg; wrong: > 0.5 m or > 20 deg.
"""
from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SETS = {"as rendered": HERE.parent / "pose_test640_s35" / "pose_eval.json.gz",
        "restyled": HERE.parent / "restyle_s36" / "pose_restyle_shipped.json.gz",
        "grey": HERE / "pose_grey_shipped.json.gz"}
BINS = ((0.0, 0.15), (0.15, 0.3), (0.3, 0.5), (0.5, 1.01))


def rows(path: Path) -> list[dict]:
    doc = json.loads(gzip.decompress(path.read_bytes()))
    return doc["frames"] if isinstance(doc, dict) else doc


def main() -> int:
    print("| set | frames | valid | within | wrong | positions | e_t mean | e_R mean | confidence mean | within share |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    tables = {}
    for name, path in SETS.items():
        r = rows(path)
        v = [x for x in r if x["valid"]]
        conf = np.array([x["confidence"] for x in v])
        within = np.array([x["e_t"] <= 0.10 and x["e_R"] <= 2.0 for x in v])
        wrong = sum(x["e_t"] > 0.5 or x["e_R"] > 20.0 for x in v)
        print(f"| {name} | {len(r)} | {len(v)} | {int(within.sum())} | {wrong} | {sum(bool(x['position_valid']) for x in r)}"
              f" | {np.mean([x['e_t'] for x in v]):.3f} m | {np.mean([x['e_R'] for x in v]):.2f} | {conf.mean():.3f}"
              f" | {within.mean():.3f} |")
        tables[name] = [(lo, hi, int(((conf >= lo) & (conf < hi)).sum()), conf[(conf >= lo) & (conf < hi)],
                         within[(conf >= lo) & (conf < hi)]) for lo, hi in BINS]
    print("\nconfidence bins: poses, mean confidence / share within")
    for name, bins in tables.items():
        print(f"{name}: " + "; ".join(f"[{lo:g}, {min(hi, 1):g}) {n}: {c.mean():.2f} / {w.mean():.2f}" if n else
                                      f"[{lo:g}, {min(hi, 1):g}) 0" for lo, hi, n, c, w in bins))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

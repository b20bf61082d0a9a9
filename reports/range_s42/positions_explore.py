"""Session 42, exploratory: the range fit on positions without a pose (``range_fit.positions`` 1), on spent rows.

    python reports/range_s42/positions_explore.py BEFORE.json.gz AFTER.json.gz [...]   # pairs of shard_eval rows

Per pair (the same frames; BEFORE without the positions switch, AFTER with it): the frames with a position but no
pose in each, their mean / median position error (``e_pos``), how many are within 0.10 m and how many miss by more
than 0.5 m, and the valid poses (which the switch must not change).
"""
from __future__ import annotations

import gzip
import json
import sys

import numpy as np


def _rows(path: str) -> dict[str, dict]:
    return {r["frame"]: r for r in json.loads(gzip.decompress(open(path, "rb").read()))["frames"]}


def main(paths: list[str]) -> None:
    print("| rows | frames with a position only | mean / median e_pos | within 0.10 m | > 0.5 m off | valid |")
    print("|---|---|---|---|---|---|")
    for before, after in zip(paths[::2], paths[1::2]):
        for path in (before, after):
            rows = _rows(path)
            only = [r for r in rows.values() if r["position_valid"] and not r["valid"]]
            e = np.array([r["e_pos"] for r in only])
            print(f"| {path} | {len(only)} | {e.mean():.3f} / {np.median(e):.3f} m | {int((e <= 0.1).sum())} | "
                  f"{int((e > 0.5).sum())} | {sum(bool(r['valid']) for r in rows.values())} |")


if __name__ == "__main__":
    main(sys.argv[1:])

"""Session 26 exploration: errors of the alternative centre estimates (rows of explore.py).

    python reports/position_s26/analyse.py ROWS.jsonl [...]
"""
from __future__ import annotations

import json
import sys

import numpy as np


def split(miss, truth):
    los = truth / np.linalg.norm(truth)
    r = float(miss @ los)
    lat = float(np.linalg.norm(miss - r * los))
    return r, lat


def main(paths):
    rows = [json.loads(l) for p in paths for l in open(p)]
    pos = [r for r in rows if r["position_valid"] and not r["valid"] and "reg" in r]
    print(f"{len(rows)} frames, {len(pos)} position-only frames with an outline")
    for sub, sel in (("all", lambda r: True), ("chamfer>1.5", lambda r: r["chamfer"] > 1.5),
                     ("chamfer<=1.5", lambda r: r["chamfer"] <= 1.5)):
        rs = [r for r in pos if sel(r)]
        print(f"\n{sub}: {len(rs)} frames")
        print(f"{'estimate':10s} {'mean e':>7s} {'median':>7s} {'p95':>6s} {'max':>6s} {'range bias':>10s} {'|range|':>8s} {'lateral':>8s} {'<=tau':>6s}")
        for key in ("position", "reg", "reg_lat", "best", "best_lat", "xyz_mean", "reg_area", "best_area",
                    "reg_pol", "best_pol"):
            es, rr, ll, within = [], [], [], []
            for r in rs:
                if key not in r:
                    continue
                truth = np.asarray(r["truth"])
                miss = np.asarray(r[key]) - truth
                e = float(np.linalg.norm(miss))
                a, b = split(miss, truth)
                es.append(e); rr.append(a); ll.append(b); within.append(e <= r["tau"])
            if not es:
                continue
            es = np.asarray(es)
            print(f"{key:10s} {es.mean():7.3f} {np.median(es):7.3f} {np.percentile(es, 95):6.2f} {es.max():6.2f} "
                  f"{np.mean(rr):+10.3f} {np.mean(np.abs(rr)):8.3f} {np.mean(ll):8.3f} {np.mean(within):6.1%}")


if __name__ == "__main__":
    main(sys.argv[1:])

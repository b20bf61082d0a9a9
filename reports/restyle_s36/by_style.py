"""Session 36: the restyled test split against the plain one, frame by frame, split by the style factors.

``python reports/restyle_s36/by_style.py PLAIN_REPORT RESTYLED_REPORT RESTYLED_DATASET``
(reports are ``pose_eval.json[.gz]`` of ``spacepose eval-pose``; the dataset's ``labels.jsonl`` holds the styles).
Prints, per factor tercile: frames, valid plain -> restyled, wrong (> 20 deg or > 0.5 m) plain -> restyled,
and the frames' decision routes and refusal statuses that changed; then the restyled report's wrong poses (range
error in range sigmas) and the outline chamfer of the poses the restyle lost.
"""
from __future__ import annotations

import collections
import gzip
import json
import math
import sys
from pathlib import Path

from spacepose.tools.calibrate_gates import WITHIN_R_DEG, WITHIN_T_M


def load(path: str) -> dict[str, dict]:
    p = Path(path)
    text = gzip.open(p, "rt").read() if p.suffix == ".gz" else p.read_text()
    return {r["frame"]: r for r in json.loads(text)["frames"]}


def wrong(r: dict) -> bool:
    return bool(r["valid"]) and (r["e_R"] > 20.0 or r["e_t"] > 0.5)


def within(r: dict) -> bool:
    return bool(r["valid"]) and r["e_R"] <= WITHIN_R_DEG and r["e_t"] <= WITHIN_T_M


def main(argv: list[str]) -> None:
    plain, rest = load(argv[0]), load(argv[1])
    styles = {}
    for line in Path(argv[2], "labels.jsonl").read_text().splitlines():
        d = json.loads(line)
        styles[d["frame"] if "frame" in d else d["name"]] = d["restyle"]
    frames = sorted(set(plain) & set(rest) & set(styles))
    print(f"{len(frames)} frames in both reports")
    tot = lambda rows, f: sum(f(r) for r in rows)
    P = [plain[f] for f in frames]; Q = [rest[f] for f in frames]
    print(f"overall: valid {tot(P, lambda r: r['valid'])} -> {tot(Q, lambda r: r['valid'])}, "
          f"within {tot(P, within)} -> {tot(Q, within)}, wrong {tot(P, wrong)} -> {tot(Q, wrong)}, "
          f"position {tot(P, lambda r: r['position_valid'])} -> {tot(Q, lambda r: r['position_valid'])}")
    factors = {"gamma": lambda s: s["gamma"], "gain": lambda s: s["gain"], "blur_px": lambda s: s["blur_px"],
               "noise": lambda s: s["noise"], "tint_spread": lambda s: max(s["tint"]) - min(s["tint"]),
               "brightness": lambda s: s["gain"] * 0.5 ** s["gamma"]}
    for name, fn in factors.items():
        vals = sorted(fn(styles[f]) for f in frames)
        cuts = [vals[len(vals) // 3], vals[2 * len(vals) // 3]]
        print(f"\n{name} (tercile cuts {cuts[0]:.3g}, {cuts[1]:.3g})")
        print("| tercile | frames | valid plain -> restyled | within | wrong |")
        print("|---|---|---|---|---|")
        for k, (lo, hi) in enumerate([(-math.inf, cuts[0]), (cuts[0], cuts[1]), (cuts[1], math.inf)]):
            sel = [f for f in frames if lo <= fn(styles[f]) < hi]
            p = [plain[f] for f in sel]; q = [rest[f] for f in sel]
            print(f"| {k + 1} | {len(sel)} | {tot(p, lambda r: r['valid'])} -> {tot(q, lambda r: r['valid'])} | "
                  f"{tot(p, within)} -> {tot(q, within)} | {tot(p, wrong)} -> {tot(q, wrong)} |")
    lost = collections.Counter((plain[f]["decided_by"] or "-", rest[f]["status"]) for f in frames
                               if plain[f]["valid"] and not rest[f]["valid"])
    won = collections.Counter((plain[f]["status"], rest[f]["decided_by"] or "-") for f in frames
                              if rest[f]["valid"] and not plain[f]["valid"])
    print("\nlost (plain route, restyled status):", dict(lost.most_common()))
    print("won (plain status, restyled route):", dict(won.most_common()))
    status_p = collections.Counter(r["status"] for r in P); status_q = collections.Counter(r["status"] for r in Q)
    print("\nstatus plain:", dict(status_p.most_common()))
    print("status restyled:", dict(status_q.most_common()))
    print("\nwrong in the restyled report: frame, distance m, e_t m, range error / sigma_range, e_R deg, confidence")
    for f in frames:
        r = rest[f]
        if wrong(r):
            print(f"  {f} {r['distance']:.1f} {r['e_t']:.2f} {r['e_pos_los'] / r['sigma_range_m']:+.1f} "
                  f"{r['e_R']:.1f} {r['confidence']:.2f}")
    lost_chamfer = sorted((plain[f]["outline_chamfer_px"], rest[f]["outline_chamfer_px"]) for f in frames
                          if plain[f]["valid"] and not rest[f]["valid"])
    fin = [(a, b) for a, b in lost_chamfer if math.isfinite(b)]
    print(f"\nlost poses' outline chamfer px, plain -> restyled ({len(fin)} of {len(lost_chamfer)} with one): median "
          f"{sorted(a for a, _ in fin)[len(fin) // 2]:.2f} -> {sorted(b for _, b in fin)[len(fin) // 2]:.2f}, "
          f"restyled over 2.5 px: {sum(b > 2.5 for _, b in fin)}")


if __name__ == "__main__":
    main(sys.argv[1:])

"""Session 26: the verdicts of ``plan.txt`` (round 1, the registered position moved onto the observed outline)
and ``plan2.txt`` (round 2, that plus an outline gate for positions without a pose).

    python reports/position_s26/judge.py [--round 2] [RUNS]

Round 1 reads ``RUNS/{f640a,f640b,f1280}_{default,lat26}/pose_eval.json`` (default ``runs/s26``) when they exist
and writes their compact rows beside this file (``rows.json.gz``); else reads those committed rows. Round 2:
``RUNS/{g640a,g640b,g1280}_{default,d26}``, ``rows2.json.gz``. Prints, per fresh set and bundle, the row of
``_rows.position_stats`` (frames, valid poses, position-valid frames and their share, e_pos mean / median / p95 /
max, the share within the frame's ``depth_tolerance_m``); the same for the frames whose position the candidate
moves, and per regime; then the rule's clauses.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "position_s25"))
from _rows import STATS_HEAD, compact_rows, position_stats  # noqa: E402

ROUNDS = {1: ({"fresh s26 (900, 640x480, seed 2601)": ["f640a", "f640b"],
               "fresh s26 (270, 1280x960, seed 2602)": ["f1280"]}, ("default", "lat26"), "rows.json.gz"),
          2: ({"fresh s26b (900, 640x480, seed 2603)": ["g640a", "g640b"],
               "fresh s26b (270, 1280x960, seed 2604)": ["g1280"]}, ("default", "d26"), "rows2.json.gz")}
KEYS = ("frame", "regime", "distance", "valid", "status", "position_valid", "e_pos", "e_pos_los",
        "depth_tolerance_m", "e_t", "e_R", "position")


def load(runs: Path, rnd: int) -> dict[str, list[dict]]:
    sets, bundles, rows_file = ROUNDS[rnd]
    files = {f"{name}|{b}": [runs / f"{part}_{b}" / "pose_eval.json" for part in parts]
             for name, parts in sets.items() for b in bundles}
    return compact_rows(files, HERE / rows_file, KEYS)


def same(a: float, b: float) -> bool:
    return (np.isnan(a) and np.isnan(b)) or a == b


def safe(pos: list[dict]) -> bool:
    """The rules' safety clause: e_pos within the tolerance on at least 95 % of ``pos``, and none over 2.0 m."""
    return (np.mean([r["e_pos"] <= r["depth_tolerance_m"] for r in pos]) >= 0.95
            and max(r["e_pos"] for r in pos) <= 2.0)


def main(runs: Path, rnd: int = 1) -> int:
    sets, bundles, _ = ROUNDS[rnd]
    label = "candidate C" if rnd == 1 else "candidate D"
    rows = load(runs, rnd)
    verdicts = []
    for name in sets:
        base, cand = rows[f"{name}|default"], rows[f"{name}|{bundles[1]}"]
        assert [r["frame"] for r in base] == [r["frame"] for r in cand], "the two runs differ in frames"
        keys = ("valid", "status", "position_valid") if rnd == 1 else ("valid", "status")
        identical = all(a[k] == b[k] for a, b in zip(base, cand) for k in keys)
        if rnd == 2:   # D's positions are a subset of the shipped bundle's
            identical &= all(a["position_valid"] or not b["position_valid"] for a, b in zip(base, cand))
        identical &= all(same(a[k], b[k]) for a, b in zip(base, cand) for k in ("e_t", "e_R"))
        moved = [i for i, (a, b) in enumerate(zip(base, cand)) if a["position_valid"] and b["position_valid"]
                 and not np.allclose(a["position"], b["position"], rtol=0, atol=1e-9)]
        print(f"\n{name}\n{'':34s}{STATS_HEAD}")
        for b, rs in (("shipped", base), (label, cand)):
            print(f"{b:34s}{position_stats(rs)}")
        for b, rs in (("shipped, moved frames", base), (label + ", moved frames", cand)):
            print(f"{b:34s}{position_stats([rs[i] for i in moved])}")
        for regime in sorted({r["regime"] for r in base}):
            for b, rs in (("shipped", base), (label[-1], cand)):
                print(f"{'  ' + regime + ', ' + b:34s}{position_stats([r for r in rs if r['regime'] == regime])}")
        e_moved = {b: [rs[i]["e_pos"] for i in moved] for b, rs in (("s", base), ("c", cand))}
        los = {b: [abs(rs[i]["e_pos_los"]) for i in moved] for b, rs in (("s", base), ("c", cand))}
        if moved:
            better = sum(c < s for s, c in zip(e_moved["s"], e_moved["c"]))
            print(f"moved frames: {len(moved)}; better with {label[-1]} on {better}; "
                  f"mean |range error| {np.mean(los['s']):.3f} -> {np.mean(los['c']):.3f} m")
        pos_b = [r for r in base if r["position_valid"]]
        pos_c = [r for r in cand if r["position_valid"]]
        lower = float(np.mean([r["e_pos"] for r in pos_c])) < float(np.mean([r["e_pos"] for r in pos_b]))
        if rnd == 1:
            clauses = {
                "1 same poses, validity, position_valid": identical,
                "2 moved frames: mean e_pos lower with C": (
                    bool(moved) and np.mean(e_moved["c"]) < np.mean(e_moved["s"])),
                "3 all position-valid frames: mean e_pos lower with C": lower,
                "4 with C >= 95 % within tolerance, none > 2.0 m": safe(pos_c),
            }
        else:
            dropped = sum(a["position_valid"] and not b["position_valid"] for a, b in zip(base, cand))
            print(f"positions dropped by the outline gate: {dropped}; {label} gives a position on "
                  f"{100 * len(pos_c) / len(cand):.1f} % of frames (shipped {100 * len(pos_b) / len(base):.1f} %)")
            print(f"  the shipped bundle: >= 95 % within tolerance and none > 2.0 m: {'yes' if safe(pos_b) else 'NO'}")
            clauses = {
                "1 same poses and validity, D's positions a subset": identical,
                "2 with D >= 95 % within tolerance, none > 2.0 m": safe(pos_c),
                "3 mean e_pos lower with D": lower,
                "4 D gives a position on >= 55 % of frames": len(pos_c) >= 0.55 * len(cand),
            }
        for clause, ok in clauses.items():
            print(f"  {clause}: {'met' if ok else 'NOT met'}")
        verdicts.append(all(clauses.values()))
    print(f"\nrule: {'MET — ' + label[-1] + ' ships' if all(verdicts) else 'NOT met — nothing ships'}")
    return 0


if __name__ == "__main__":
    args = sys.argv[1:]
    rnd = 1
    if args[:1] == ["--round"]:
        rnd, args = int(args[1]), args[2:]
    sys.exit(main(Path(args[0]) if args else Path("runs/s26"), rnd))

"""Session 25: the target position without attitude, measured by the commands of ``plan.txt``.

    python reports/position_s25/summarize.py [--round 2] [RUNS]
    python reports/position_s25/summarize.py --choose [RUNS]

``--choose``: how round 2's tolerance gate was chosen, on round 1's rows (every position-only frame kept when its
``depth_tolerance_m`` is at most X; valid poses always): share with a position, e_pos mean / median / p95 / max and
the share within the tolerance, per X.

Round 1 (``plan.txt``) reads ``RUNS/{test_final,unseen_final,fresh640_a,fresh640_b,fresh1280}/pose_eval.json``
(default ``runs/s25``) when they exist and writes the compact rows beside this file (``rows.json.gz``); else it
reads those committed rows. Round 2 (``plan2.txt``): ``RUNS/{q640_a,q640_b,q1280}``, ``rows2.json.gz``.
Prints, per set: frames, valid poses, position-valid frames, e_pos mean / median / p95 / max, the share within
the frame's ``depth_tolerance_m``, per regime and per 10 m distance bin; then the verdict of the plan's rule on
the two fresh sets.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from _rows import STATS_HEAD, compact_rows
from _rows import position_stats as stats

HERE = Path(__file__).resolve().parent
SETS = {"test split (300, 640x480)": ["test_final"], "unseen (90, 1280x960)": ["unseen_final"],
        "fresh s25p (900, 640x480, seed 2501)": ["fresh640_a", "fresh640_b"],
        "fresh s25p (135, 1280x960, seed 2502)": ["fresh1280"]}
FRESH = ("fresh s25p (900, 640x480, seed 2501)", "fresh s25p (135, 1280x960, seed 2502)")
SETS2 = {"fresh s25q (900, 640x480, seed 2503)": ["q640_a", "q640_b"],
         "fresh s25q (135, 1280x960, seed 2504)": ["q1280"]}
ROUNDS = {1: (SETS, FRESH, "rows.json.gz", 5.0), 2: (SETS2, tuple(SETS2), "rows2.json.gz", 2.0)}
KEYS = ("frame", "regime", "distance", "valid", "status", "position_valid", "e_pos", "depth_tolerance_m", "e_t")


def load(runs: Path, sets: dict[str, list[str]], rows_file: str) -> dict[str, list[dict]]:
    files = {name: [runs / part / "pose_eval.json" for part in parts] for name, parts in sets.items()}
    return compact_rows(files, HERE / rows_file, KEYS)


def choose(runs: Path) -> int:
    rows = [r for part in load(runs, SETS, "rows.json.gz").values() for r in part]
    print(f"round 1's {len(rows)} frames; a position-only frame kept when its tolerance <= X")
    print(f"{'X m':>6}{'share':>8}{'mean':>7}{'median':>7}{'p95':>7}{'max':>7}{'<=tau':>8}")
    for x in (0.5, 0.7, 1.0, 1.2, 1.5, 2.0, float("inf")):
        pos = [r for r in rows if r["position_valid"] and (r["valid"] or r["depth_tolerance_m"] <= x)]
        e = np.array([r["e_pos"] for r in pos])
        within = np.mean([r["e_pos"] <= r["depth_tolerance_m"] for r in pos])
        print(f"{x:>6.1f}{100 * len(pos) / len(rows):>7.1f}%{e.mean():>7.3f}{np.median(e):>7.3f}"
              f"{np.percentile(e, 95):>7.3f}{e.max():>7.2f}{100 * within:>7.1f}%")
    return 0


def main() -> int:
    args = sys.argv[1:]
    if args[:1] == ["--choose"]:
        return choose(Path(args[1]) if len(args) > 1 else Path("runs/s25"))
    round_ = 1
    if args[:1] == ["--round"]:
        round_, args = int(args[1]), args[2:]
    sets, fresh, rows_file, max_m = ROUNDS[round_]
    runs = Path(args[0]) if args else Path("runs/s25")
    data = load(runs, sets, rows_file)
    head = f"{'group':<34}{STATS_HEAD}"
    for name, rows in data.items():
        print(f"\n{name}  (e_pos in m over position-valid frames)\n{head}")
        print(f"{'all':<34}" + stats(rows))
        print(f"{'  only weak_votes (no attitude)':<34}" + stats([r for r in rows if r["status"] == "weak_votes"]))
        for regime in ("sun", "albedo", "penumbra", "mixed"):
            print(f"{'  regime ' + regime:<34}" + stats([r for r in rows if r["regime"] == regime]))
        for lo in (10, 20, 30, 40):
            print(f"{f'  distance {lo}-{lo + 10} m':<34}" + stats([r for r in rows if lo <= r["distance"] < lo + 10]))
    plan = "plan.txt" if round_ == 1 else f"plan{round_}.txt"
    print(f"\nrule ({plan}) on the fresh sets: e_pos <= depth_tolerance_m on >= 95 % of position-valid frames, "
          f"none > {max_m:g} m")
    ok = True
    for name in fresh:
        pos = [r for r in data[name] if r["position_valid"]]
        within = float(np.mean([r["e_pos"] <= r["depth_tolerance_m"] for r in pos]))
        worst = max(r["e_pos"] for r in pos)
        met = within >= 0.95 and worst <= max_m
        ok &= met
        print(f"  {name}: within {100 * within:.1f} %, max {worst:.2f} m -> {'met' if met else 'NOT met'}")
    print("verdict:", ("met, the feature stays" if round_ == 1 else "met, ship position_max_tau_m") if ok else
          ("NOT met, withdraw the feature" if round_ == 1 else "NOT met, the feature stays off"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Fit and verdict of reports/uncertainty_s29/rule.txt (the covariance of a position without a pose, session 29).

    python reports/uncertainty_s29/judge.py [RUNS]

RUNS (default ``runs``) holds the ``eval-pose`` reports of the shipped bundle's decisions: to fit on,
``s28/full_s27f``, ``s28/full_s27g_a`` + ``s28/full_s27g_b`` (seed 2704 in two halves) and ``s27/extra640_S``
(seed 2703); the check sets ``s29/p640_a`` + ``s29/p640_b`` (A, seed 2901) and ``s29/p1280`` (B, seed 2902); and,
reported only, session 28's check sets (``s28/fresh640d_*``, ``fresh1280d``, ``fresh640``, ``fresh1280``), the
test split (``s28/test640``), the unseen set (``s28/unseen1280``) and the five sequences ``s28/seq_w*.json``
(commands in reports/uncertainty_s28/judge.py). When all are there, their frames with a position and no pose are
cut to the columns used here and written to ``rows.json.gz`` beside this script; otherwise that committed file is
read, so the verdict reproduces from the repository alone.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "position_s25"))
from _rows import compact_rows  # noqa: E402

from spacepose.tools.calibrate_uncertainty import (NOMINAL, fit_position_uncertainty, position_coverage,
                                                   position_errors)

KEYS = ("frame", "distance", "valid", "position_valid", "tracked", "depth_tolerance_m", "position", "e_pos",
        "e_pos_los", "e_R", "outline_chamfer_px")
FIT_SETS = ("fit_s27f", "fit_s27g", "fit_s27x")
FOCAL_1280 = ("check_1280", "s28_fresh1280d", "s28_fresh1280", "unseen1280")   # f 1600 px; every other set f 800 px
RULE_A_SHARES, RULE_A_NEES = (("range_2", 0.88), ("lateral_2", 0.80)), (0.6, 1.6)
RULE_B_SHARES, RULE_B_NEES = (("range_2", 0.70), ("lateral_2", 0.70)), (0.4, 2.5)
NEES = ("nees_range", "nees_lateral")
MISSING = {**{k: None for k in KEYS}, "tracked": False}   # a key a run's rows lack: as in session 28's judge


def _files(runs: Path) -> dict[str, list[Path]]:
    s28, s29 = runs / "s28", runs / "s29"
    files = {"fit_s27f": [s28 / "full_s27f"], "fit_s27g": [s28 / "full_s27g_a", s28 / "full_s27g_b"],
             "fit_s27x": [runs / "s27" / "extra640_S"],
             "check_640": [s29 / "p640_a", s29 / "p640_b"], "check_1280": [s29 / "p1280"],
             "s28_fresh640d": [s28 / "fresh640d_a", s28 / "fresh640d_b"], "s28_fresh1280d": [s28 / "fresh1280d"],
             "s28_fresh640": [s28 / "fresh640"], "s28_fresh1280": [s28 / "fresh1280"],
             "test640": [s28 / "test640"], "unseen1280": [s28 / "unseen1280"]}
    out = {name: [p / "pose_eval.json" for p in paths] for name, paths in files.items()}
    for i in range(1, 6):
        out[f"seq_w{i}"] = [s28 / f"seq_w{i}.json"]
    return out


def _rows(files: dict[str, list[Path]]) -> dict[str, list[dict]]:
    return compact_rows(files, HERE / "rows.json.gz", KEYS, keep=lambda r: r.get("position_valid") and not r["valid"],
                        defaults=MISSING)


def main(argv: list[str]) -> int:
    runs = Path(argv[0]) if argv else Path("runs")
    rows = _rows(_files(runs))
    focal = {name: 1600.0 if name in FOCAL_1280 else 800.0 for name in rows}
    err = {name: position_errors(v, focal[name]) for name, v in rows.items()}
    pooled = {k: np.concatenate([err[n][k] for n in FIT_SETS]) for k in err[FIT_SETS[0]]}
    config = fit_position_uncertainty(pooled)
    print(f"fit on {len(pooled['range'])} positions without a pose of {', '.join(FIT_SETS)}:")
    print(json.dumps({"position_uncertainty": {k: round(v, 4) for k, v in vars(config).items()}}))
    print()
    shares = ("range_1", "range_2", "lateral_1", "lateral_2")
    print(f"{'set':<15}{'pos.':>5}{'>0.5m':>6} " + " ".join(f"{k:>10}" for k in shares)
          + f" {'nees r':>7} {'nees l':>7} {'gate in/out':>11} {'rho e_pos':>9} {'med s_r':>8} {'med s_l':>8}")
    print(f"{'(normal)':<26} " + " ".join(f"{100 * NOMINAL[k]:>9.1f}%" for k in shares) + f" {1:>7.2f} {1:>7.2f}")
    results = {}
    for name in rows:
        cov = position_coverage(err[name], config, focal[name])
        results[name] = cov
        if not cov.get("positions"):
            print(f"{name:<15}{0:>5}")
            continue
        gate = f"{100 * cov['right_flagged']:.1f}/" + ("-" if not cov["wrong"] else f"{100 * cov['wrong_flagged']:.0f}")
        print(f"{name:<15}{cov['positions']:>5}{cov['wrong']:>6} " + " ".join(f"{100 * cov[k]:>9.1f}%" for k in shares)
              + "".join(f" {cov[k]:>7.2f}" for k in NEES) + f" {gate:>11} {cov['spearman_position']:>9.2f}"
              + f" {cov['sigma_range_median_m']:>8.3f} {cov['sigma_lateral_median_m']:>8.3f}")
    print("(>0.5m: positions missing by more than 0.5 m, left out of the nees; gate in/out: % of those within 0.5 m /"
          " of the others beyond a 3-sigma chi-square gate; rho: rank correlation of e_pos with sqrt(trace cov); med:"
          " median sigmas, m)")
    a, b = results["check_640"], results["check_1280"]
    fails = [f"A {k} {100 * a[k]:.1f}% < {100 * lo:.0f}%" for k, lo in RULE_A_SHARES if a[k] < lo]
    fails += [f"A {k} {a[k]:.2f} outside {RULE_A_NEES}" for k in NEES if not RULE_A_NEES[0] <= a[k] <= RULE_A_NEES[1]]
    fails += [f"A spearman {a['spearman_position']:.2f} < 0.25"] if a["spearman_position"] < 0.25 else []
    fails += [f"B {k} {100 * b[k]:.1f}% < {100 * lo:.0f}%" for k, lo in RULE_B_SHARES if b[k] < lo]
    fails += [f"B {k} {b[k]:.2f} outside {RULE_B_NEES}" for k in NEES if not RULE_B_NEES[0] <= b[k] <= RULE_B_NEES[1]]
    print()
    print("verdict (rule.txt, A = tdrs640_s29p, B = tdrs1280_s29p): " + ("MET" if not fails else "NOT MET: " + "; ".join(fails)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))

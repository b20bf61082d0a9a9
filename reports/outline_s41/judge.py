"""Session 41: the clauses of reports/outline_s41/plan.txt (cand: the shipped bundle with the outline refiner;
base: the shipped bundle).

    python reports/outline_s41/judge.py collect [RUNS]   # once: rows of RUNS (runs/s41) -> compact files here
    python reports/outline_s41/judge.py                  # the clauses and the verdict, from the files beside this file
"""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RUNS = HERE.parent.parent / "runs" / "s41"

_spec = importlib.util.spec_from_file_location("tone_s38_judge", HERE.parent / "tone_s38" / "judge.py")
_s38 = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_s38)          # session 38's row helpers and definitions
BUNDLES, _within = _s38.BUNDLES, _s38._within


def _valid(r: dict) -> bool:
    return bool(r["valid"])


def judge() -> int:
    data = _s38.sets("cand", HERE, "seq_mr")
    _s38.table(data, "base: the shipped bundle; cand: the same with the outline refiner (session 41)")
    clauses: dict[str, bool] = {}
    _s38.clause_no_new_far(data, clauses, "C1")
    _s38.clause_no_more_wrong(data, clauses, "C2")
    frames, seqs = ("F", "R"), ("S", "SR")
    v = {b: _s38.pooled(data, frames, b, _valid) for b in BUNDLES}
    w = {b: _s38.pooled(data, frames, b, _within) for b in BUNDLES}
    print(f"C3 F+R: within cand {w['cand']} vs base {w['base']} (x{w['cand'] / max(w['base'], 1):.3f}, bar 1.05); "
          f"valid cand {v['cand']} vs base {v['base']} (x{v['cand'] / max(v['base'], 1):.3f}, bar 0.98)")
    clauses["C3 the gain"] = w["cand"] >= 1.05 * w["base"] and v["cand"] >= 0.98 * v["base"]
    e_r = {b: [r["e_R"] for n in frames for r in data[n][b].values() if r["valid"]] for b in BUNDLES}
    mean = {b: float(np.mean(e_r[b])) if e_r[b] else float("nan") for b in BUNDLES}
    median = {b: float(np.median(e_r[b])) if e_r[b] else float("nan") for b in BUNDLES}
    e_t = {b: float(np.mean([r["e_t"] for n in frames for r in data[n][b].values() if r["valid"]])) for b in BUNDLES}
    print(f"C4 F+R: mean e_R of valid poses cand {mean['cand']:.2f} vs base {mean['base']:.2f} deg "
          f"(x{mean['cand'] / mean['base']:.3f}, bar 0.9); medians {median['cand']:.2f} vs {median['base']:.2f} deg; "
          f"mean e_t {e_t['cand']:.3f} vs {e_t['base']:.3f} m")
    clauses["C4 the rotation"] = mean["cand"] <= 0.9 * mean["base"]
    v = {b: _s38.pooled(data, seqs, b, _valid) for b in BUNDLES}
    w = {b: _s38.pooled(data, seqs, b, _within) for b in BUNDLES}
    print(f"C5 S+SR: within cand {w['cand']} vs base {w['base']} (bar 1.0); valid cand {v['cand']} vs base "
          f"{v['base']} (x{v['cand'] / max(v['base'], 1):.3f}, bar 0.98)")
    clauses["C5 no loss in sequences"] = w["cand"] >= w["base"] and v["cand"] >= 0.98 * v["base"]
    _s38.print_verdict(clauses, "MET: the outline refiner ships")
    return 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["collect"]:
        _s38.collect(list(BUNDLES), Path(sys.argv[2]) if len(sys.argv) > 2 else RUNS, HERE, "seq_m*")
    else:
        raise SystemExit(judge())

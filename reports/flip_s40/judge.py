"""Session 40: the clauses of reports/flip_s40/rule.txt (cand: the shipped bundle with session 40's flip classifier;
base: the shipped bundle).

    python reports/flip_s40/judge.py collect [RUNS]   # once: rows of RUNS (runs/s40) -> compact files beside this file
    python reports/flip_s40/judge.py                  # the clauses and the verdict, from the files beside this file

``collect`` cuts ``RUNS/check_{base,cand}_{plain,rest}.json.gz`` (``spacepose.tools.shard_eval`` rows) to the columns
read here and merges the ``sequence eval`` reports ``RUNS/{base,cand}_seq_u*.json`` into ``seq_{base,cand}.json.gz``.
"""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
RUNS = HERE.parent.parent / "runs" / "s40"

_spec = importlib.util.spec_from_file_location("tone_s38_judge", HERE.parent / "tone_s38" / "judge.py")
_s38 = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_s38)          # session 38's row helpers and definitions
BUNDLES, _wrong, _within, table = _s38.BUNDLES, _s38._wrong, _s38._within, _s38.table


def judge() -> int:
    data = _s38.sets("cand", HERE, "seq_ur")
    table(data, "base: the shipped bundle; cand: the same with session 40's flip classifier")

    def valid(r: dict) -> bool:
        return bool(r["valid"])

    clauses = {}
    _s38.clause_no_new_far(data, clauses, "C1")
    _s38.clause_no_more_wrong(data, clauses, "C2")
    for clause, names, (bar_v, bar_w) in (("C3 the gain", ("F", "R"), (1.03, 1.02)),
                                          ("C4 no loss in sequences", ("S", "SR"), (0.98, 0.98))):
        v = {b: _s38.pooled(data, names, b, valid) for b in BUNDLES}
        w = {b: _s38.pooled(data, names, b, _within) for b in BUNDLES}
        print(f"{clause.split()[0]} {'+'.join(names)}: valid cand {v['cand']} vs base {v['base']} "
              f"(x{v['cand'] / max(v['base'], 1):.3f}, bar {bar_v}); within cand {w['cand']} vs base {w['base']} "
              f"(x{w['cand'] / max(w['base'], 1):.3f}, bar {bar_w})")
        clauses[clause] = v["cand"] >= bar_v * v["base"] and w["cand"] >= bar_w * w["base"]
    added = [(n, k, r) for n, by in data.items() for k, r in by["cand"].items() if r["valid"] and not by["base"][k]["valid"]]
    lost = [(n, k, r) for n, by in data.items() for k, r in by["base"].items() if r["valid"] and not by["cand"][k]["valid"]]
    print(f"poses cand adds: {len(added)} ({sum(_within(r) for *_, r in added)} within, "
          f"{sum(_wrong(r) for *_, r in added)} wrong); poses cand drops: {len(lost)} "
          f"({sum(_within(r) for *_, r in lost)} within, {sum(_wrong(r) for *_, r in lost)} wrong)")
    _s38.print_verdict(clauses, "MET: session 40's flip classifier ships")
    return 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["collect"]:
        _s38.collect(list(BUNDLES), Path(sys.argv[2]) if len(sys.argv) > 2 else RUNS, HERE, "seq_u*")
    else:
        raise SystemExit(judge())

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
BUNDLES, _wrong, _within, _far, table = _s38.BUNDLES, _s38._wrong, _s38._within, _s38._far, _s38.table


def judge() -> int:
    data = _s38.sets("cand", HERE, "seq_ur")
    table(data, "base: the shipped bundle; cand: the same with session 40's flip classifier")

    def pooled(names: tuple[str, ...], b: str, test) -> int:
        return sum(test(r) for n in names for r in data[n][b].values())

    def valid(r: dict) -> bool:
        return bool(r["valid"])

    clauses = {}
    new_far = [(n, k) for n, by in data.items() for k, r in by["cand"].items() if _far(r) and not _far(by["base"][k])]
    print("C1: cand's far poses that base does not report:", new_far)
    clauses["C1 no new far pose"] = not new_far
    c2 = []
    for names in (("F", "R"), ("S", "SR")):
        w = {b: pooled(names, b, _wrong) for b in BUNDLES}
        print(f"C2 {'+'.join(names)}: wrong cand {w['cand']} vs base {w['base']}")
        c2.append(w["cand"] <= w["base"])
    clauses["C2 no more wrong"] = all(c2)
    for clause, names, (bar_v, bar_w) in (("C3 the gain", ("F", "R"), (1.03, 1.02)),
                                          ("C4 no loss in sequences", ("S", "SR"), (0.98, 0.98))):
        v = {b: pooled(names, b, valid) for b in BUNDLES}
        w = {b: pooled(names, b, _within) for b in BUNDLES}
        print(f"{clause.split()[0]} {'+'.join(names)}: valid cand {v['cand']} vs base {v['base']} "
              f"(x{v['cand'] / max(v['base'], 1):.3f}, bar {bar_v}); within cand {w['cand']} vs base {w['base']} "
              f"(x{w['cand'] / max(w['base'], 1):.3f}, bar {bar_w})")
        clauses[clause] = v["cand"] >= bar_v * v["base"] and w["cand"] >= bar_w * w["base"]
    added = [(n, k, r) for n, by in data.items() for k, r in by["cand"].items() if r["valid"] and not by["base"][k]["valid"]]
    lost = [(n, k, r) for n, by in data.items() for k, r in by["base"].items() if r["valid"] and not by["cand"][k]["valid"]]
    print(f"poses cand adds: {len(added)} ({sum(_within(r) for *_, r in added)} within, "
          f"{sum(_wrong(r) for *_, r in added)} wrong); poses cand drops: {len(lost)} "
          f"({sum(_within(r) for *_, r in lost)} within, {sum(_wrong(r) for *_, r in lost)} wrong)")
    for name, ok in clauses.items():
        print(f"{name}: {'holds' if ok else 'FAILS'}")
    met = all(clauses.values())
    print("verdict:", "MET: session 40's flip classifier ships" if met else "NOT MET: nothing of it ships")
    return 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["collect"]:
        _s38.collect(list(BUNDLES), Path(sys.argv[2]) if len(sys.argv) > 2 else RUNS, HERE, "seq_u*")
    else:
        raise SystemExit(judge())

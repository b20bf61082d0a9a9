"""Session 39: the clauses of reports/tone_s39/rule.txt (cand: the shipped bundle with flip_classifier.decide_tone_gamma
2.0; base: the shipped bundle), round 2 of session 38's rule 1.

    python reports/tone_s39/judge.py collect   # once: rows of RUNS -> compact files beside this file
    python reports/tone_s39/judge.py           # the clauses and the verdict, from the files beside this file and
                                               # round 1's (reports/tone_s38)

``collect`` cuts ``RUNS/check_{base,cand}_{plain,rest}.json.gz`` (``spacepose.tools.shard_eval`` rows) to the columns
read here and merges the ``sequence eval`` reports ``RUNS/{base,cand}_seq_y*.json`` into ``seq_{base,cand}.json.gz``
(a row per frame, with its sequence's name). RUNS: ``/tmp/s39/w/runs/s39`` (the checkout the check ran from) or the
first argument after ``collect``.
"""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROUND1 = HERE.parent / "tone_s38"
RUNS = Path("/tmp/s39/w/runs/s39")


def _round1_judge():
    """Session 38's judge (its row helpers and definitions serve both rounds)."""
    spec = importlib.util.spec_from_file_location("tone_s38_judge", ROUND1 / "judge.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


_s38 = _round1_judge()
BUNDLES, _wrong, _within, table = _s38.BUNDLES, _s38._wrong, _s38._within, _s38.table


def collect(runs: Path) -> None:
    _s38.collect(list(BUNDLES), runs, HERE, "seq_y*")


def _valid(r: dict) -> bool:
    return bool(r["valid"])


def sets(folder: Path, restyled_prefix: str) -> dict[str, dict[str, dict[tuple, dict]]]:
    """{set: {"base" | "cand": {(sequence, frame): row}}} for F, R, S and SR of one round."""
    return _s38.sets("cand", folder, restyled_prefix)


def judge() -> int:
    data = sets(HERE, "seq_yr")
    round1 = sets(ROUND1, "seq_zr")
    table(data, "round 2 (this session's fresh sets); base: the shipped bundle; cand: decide_tone_gamma 2.0")
    table(round1, "round 1 (session 38's sets; its base had the image gates of before rule 2)")

    pooled = _s38.pooled
    clauses = {}
    _s38.clause_no_new_far(data, clauses)
    _s38.clause_no_more_wrong(data, clauses)
    refused = [(rnd, n, k, by["base"][k]) for rnd, d in (("round 2", data), ("round 1", round1)) for n, by in d.items()
               for k, r in by["cand"].items() if by["base"][k]["valid"] and not r["valid"]]
    d_wrong = sum(_wrong(r) for *_, r in refused)
    names = tuple(data)
    base_valid = pooled(data, names, "base", _valid) + pooled(round1, names, "base", _valid)
    base_wrong = pooled(data, names, "base", _wrong) + pooled(round1, names, "base", _wrong)
    share_d, share_b = d_wrong / max(len(refused), 1), base_wrong / max(base_valid, 1)
    print(f"V3 (both rounds): D = {len(refused)} poses base reports and cand refuses, {d_wrong} of them wrong "
          f"({100 * share_d:.1f} %); base: {base_wrong} wrong of {base_valid} valid ({100 * share_b:.2f} %)")
    for rnd, n, k, r in refused:
        if rnd == "round 2":
            print(f"    {n} {k[0]} {k[1]}: e_t {r['e_t']:.2f} m, e_R {r['e_R']:.1f} deg, {r['decided_by']}, "
                  f"confidence {r['confidence']:.2f}" + (" WRONG" if _wrong(r) else ""))
    clauses["V3 the refused are the wrong"] = d_wrong >= 2 and share_d >= 2.0 * share_b
    v4 = []
    for names_, (bar_v, bar_w) in ((("F", "R"), (0.90, 0.93)), (("S", "SR"), (0.95, 0.95))):
        v = {b: pooled(data, names_, b, _valid) for b in BUNDLES}
        w = {b: pooled(data, names_, b, _within) for b in BUNDLES}
        print(f"V4 {'+'.join(names_)}: valid cand {v['cand']} vs base {v['base']} ({v['cand'] / max(v['base'], 1):.3f}, "
              f"bar {bar_v}); within cand {w['cand']} vs base {w['base']} ({w['cand'] / max(w['base'], 1):.3f}, bar {bar_w})")
        v4.append(v["cand"] >= bar_v * v["base"] and w["cand"] >= bar_w * w["base"])
    clauses["V4 the cost"] = all(v4)
    _s38.print_verdict(clauses, "MET: decide_tone_gamma 2.0 ships")
    return 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["collect"]:
        collect(Path(sys.argv[2]) if len(sys.argv) > 2 else RUNS)
    else:
        raise SystemExit(judge())

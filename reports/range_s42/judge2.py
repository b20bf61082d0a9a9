"""Session 42, round 2: the clauses of reports/range_s42/plan2.txt on the frame sets F2 and R2 (cand: the shipped
bundle with its uncertainty, tails and confidence constants fitted again; base: the shipped bundle, with the range
fit).

    python reports/range_s42/judge2.py collect [RUNS]   # once: rows of RUNS (runs/s42) -> files beside this one
    python reports/range_s42/judge2.py                  # the clauses and the verdict
"""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RUNS = HERE.parent.parent / "runs" / "s42"
KEYS_EXTRA = ("range_fit_m", "t")

_spec = importlib.util.spec_from_file_location("range_s42_judge", HERE / "judge.py")
_r1 = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_r1)           # round 1's judge: the row helpers of every round, session 38's definitions
_s38 = _r1._s38
BUNDLES, _within, _wrong, _far = _s38.BUNDLES, _s38._within, _s38._wrong, _s38._far
SETS = (("F2", "plain"), ("R2", "rest"))
PATTERN = "check2_{arm}_{set}.json.gz"
_valid = _r1.valid_rows


def collect(runs: Path) -> None:
    _r1.collect_rows(runs, PATTERN, BUNDLES, (*_s38.KEYS, *KEYS_EXTRA))


def frame_sets() -> dict[str, dict[str, dict[str, dict]]]:
    return _r1.load_sets(PATTERN, BUNDLES, SETS)


def judge() -> int:
    data = frame_sets()
    _s38.table(data, "base: the shipped bundle (range fit); cand: its uncertainty and confidence fitted again "
                     "(plan2.txt)")
    clauses: dict[str, bool] = {}
    far = [(n, k) for n, by in data.items() for k, r in by["cand"].items() if _far(r) and not _far(by["base"][k])]
    print(f"D1 F2, R2: cand poses > 90 deg off where base's is not: {len(far)} {far}")
    clauses["D1 no new far pose"] = not far
    wrong = {b: sum(map(_wrong, _valid(data, b))) for b in BUNDLES}
    print(f"D2 F2+R2: wrong cand {wrong['cand']} vs base {wrong['base']}")
    clauses["D2 no more wrong"] = wrong["cand"] <= wrong["base"]
    v = {b: len(_valid(data, b)) for b in BUNDLES}
    w = {b: sum(map(_within, _valid(data, b))) for b in BUNDLES}
    print(f"D3 F2+R2: valid cand {v['cand']} vs base {v['base']}; within cand {w['cand']} vs base {w['base']}")
    clauses["D3 no loss"] = v["cand"] >= v["base"] and w["cand"] >= w["base"]
    gap, brier = {}, {}
    for b in BUNDLES:
        rows = _valid(data, b)
        conf = np.array([r["confidence"] for r in rows])
        hit = np.array([_within(r) for r in rows], dtype=float)
        gap[b] = abs(conf.mean() - hit.mean())
        brier[b] = float(np.mean((conf - hit) ** 2))
        const = float(np.mean((hit.mean() - hit) ** 2))
        print(f"    {b}: {len(rows)} valid, mean confidence {conf.mean():.3f}, share within {hit.mean():.3f} "
              f"(gap {gap[b]:.3f}); Brier {brier[b]:.3f} (constant {const:.3f})")
        if b == "cand":
            brier_const = const
    print(f"D4 F2+R2: calibration gap cand {gap['cand']:.3f} (bar 0.05 and base's {gap['base']:.3f})")
    clauses["D4 calibration"] = gap["cand"] <= 0.05 and gap["cand"] <= gap["base"]
    print(f"D5 F2+R2: Brier cand {brier['cand']:.3f} vs base {brier['base']:.3f} and constant {brier_const:.3f}")
    clauses["D5 Brier"] = brier["cand"] < brier["base"] and brier["cand"] < brier_const
    only = [(n, k) for n, by in data.items() for k, r in by["cand"].items() if r["valid"] and not by["base"][k]["valid"]]
    for n, k in only:
        r = data[n]["cand"][k]
        print(f"    valid only with cand: {n} {k}: e_t {r['e_t']:.3f} m, e_R {r['e_R']:.2f} deg, confidence "
              f"{r['confidence']:.3f}" + (" WRONG" if _wrong(r) else ""))
    _s38.print_verdict(clauses, "MET: the constants ship")
    return 0


if __name__ == "__main__":
    raise SystemExit(_r1.main(sys.argv[1:], collect, judge))

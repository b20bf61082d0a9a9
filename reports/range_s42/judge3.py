"""Session 42, round 3: the clauses of reports/range_s42/plan3.txt on the frame sets F3 and R3 (base: the shipped
bundle; conf: the refitted constants with the floor 0.22; pos: the range fit for positions too; both: the two).

    python reports/range_s42/judge3.py collect [RUNS]   # once: rows of RUNS (runs/s42) -> files beside this one
    python reports/range_s42/judge3.py                  # the clauses and the verdict
"""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RUNS = HERE.parent.parent / "runs" / "s42"
ARMS = ("base", "conf", "pos", "both")
SETS = (("F3", "plain"), ("R3", "rest"))
KEYS_EXTRA = ("range_fit_m", "t", "e_pos_los", "position")

_spec = importlib.util.spec_from_file_location("range_s42_judge", HERE / "judge.py")
_r1 = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_r1)           # round 1's judge: the row helpers of every round, session 38's definitions
_s38 = _r1._s38
_within, _wrong, _far = _s38._within, _s38._wrong, _s38._far
PATTERN = "check3_{arm}_{set}.json.gz"
_valid = _r1.valid_rows


def collect(runs: Path) -> None:
    _r1.collect_rows(runs, PATTERN, ARMS, (*_s38.KEYS, *KEYS_EXTRA))


def frame_sets() -> dict[str, dict[str, dict[str, dict]]]:
    return _r1.load_sets(PATTERN, ARMS, SETS)


def _pair(data: dict, base: str, cand: str) -> dict:
    return {n: {"base": by[base], "cand": by[cand]} for n, by in data.items()}


def part_a(data: dict) -> dict[str, bool]:
    """plan2.txt's D1-D5, conf against base."""
    d = _pair(data, "base", "conf")
    clauses: dict[str, bool] = {}
    far = [(n, k) for n, by in d.items() for k, r in by["cand"].items() if _far(r) and not _far(by["base"][k])]
    print(f"A/D1: conf poses > 90 deg off where base's is not: {len(far)} {far}")
    clauses["A/D1 no new far pose"] = not far
    wrong = {b: sum(map(_wrong, _valid(d, b))) for b in ("base", "cand")}
    print(f"A/D2: wrong conf {wrong['cand']} vs base {wrong['base']}")
    clauses["A/D2 no more wrong"] = wrong["cand"] <= wrong["base"]
    v = {b: len(_valid(d, b)) for b in ("base", "cand")}
    w = {b: sum(map(_within, _valid(d, b))) for b in ("base", "cand")}
    print(f"A/D3: valid conf {v['cand']} vs base {v['base']}; within conf {w['cand']} vs base {w['base']}")
    clauses["A/D3 no loss"] = v["cand"] >= v["base"] and w["cand"] >= w["base"]
    gap, brier, const = {}, {}, {}
    for b in ("base", "cand"):
        rows = _valid(d, b)
        conf = np.array([r["confidence"] for r in rows])
        hit = np.array([_within(r) for r in rows], dtype=float)
        gap[b], brier[b] = abs(conf.mean() - hit.mean()), float(np.mean((conf - hit) ** 2))
        const[b] = float(np.mean((hit.mean() - hit) ** 2))
        print(f"    {b}: {len(rows)} valid, mean confidence {conf.mean():.3f}, share within {hit.mean():.3f} "
              f"(gap {gap[b]:.3f}); Brier {brier[b]:.3f} (constant {const[b]:.3f})")
    print(f"A/D4: calibration gap conf {gap['cand']:.3f} (bar 0.05 and base's {gap['base']:.3f})")
    clauses["A/D4 calibration"] = gap["cand"] <= 0.05 and gap["cand"] <= gap["base"]
    print(f"A/D5: Brier conf {brier['cand']:.3f} vs base {brier['base']:.3f} and constant {const['cand']:.3f}")
    clauses["A/D5 Brier"] = brier["cand"] < brier["base"] and brier["cand"] < const["cand"]
    return clauses


def part_positions(data: dict, base: str, cand: str, tag: str) -> dict[str, bool]:
    """P1-P5, cand against base."""
    clauses: dict[str, bool] = {}
    moved, same = 0, True
    for by in data.values():
        for k, rb in by[base].items():
            rc = by[cand][k]
            if bool(rb["valid"]) != bool(rc["valid"]):
                same = False
            elif rb["valid"] and np.max(np.abs(np.subtract(rb["t"], rc["t"]))) > 1e-9:
                moved += 1
    print(f"{tag}/P1: the same frames valid: {same}; valid poses moved: {moved}")
    clauses[f"{tag}/P1 the same poses"] = same and moved == 0
    only = {b: {(n, k) for n, by in data.items() for k, r in by[b].items() if r["position_valid"] and not r["valid"]}
            for b in (base, cand)}
    print(f"{tag}/P2: frames with a position only: {cand} {len(only[cand])} vs {base} {len(only[base])}, the same "
          f"frames: {only[cand] == only[base]}")
    clauses[f"{tag}/P2 the same positions"] = only[cand] == only[base]
    e = {b: np.array([data[n][b][k]["e_pos"] for n, k in sorted(only[b])]) for b in (base, cand)}
    w = {b: int((e[b] <= 0.10).sum()) for b in (base, cand)}
    print(f"{tag}/P3: positions within 0.10 m {cand} {w[cand]} vs {base} {w[base]} (x{w[cand] / max(w[base], 1):.3f}, "
          "bar 1.15)")
    clauses[f"{tag}/P3 more within"] = w[cand] >= 1.15 * w[base]
    m = {b: float(e[b].mean()) for b in (base, cand)}
    print(f"{tag}/P4: mean e_pos {cand} {m[cand]:.3f} vs {base} {m[base]:.3f} m (x{m[cand] / m[base]:.3f}, bar 0.9); "
          f"medians {np.median(e[cand]):.3f} vs {np.median(e[base]):.3f} m")
    clauses[f"{tag}/P4 nearer"] = m[cand] <= 0.9 * m[base]
    far = {b: int((e[b] > 0.5).sum()) for b in (base, cand)}
    print(f"{tag}/P5: positions > 0.5 m off {cand} {far[cand]} vs {base} {far[base]}")
    clauses[f"{tag}/P5 no more far off"] = far[cand] <= far[base]
    return clauses


def judge() -> int:
    data = frame_sets()
    print("| set | arm | frames | valid | within | wrong | far | positions only | their mean e_pos | within 0.10 m |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for n, by in data.items():
        for arm, rows in by.items():
            v = list(rows.values())
            po = [r["e_pos"] for r in v if r["position_valid"] and not r["valid"]]
            print(f"| {n} | {arm} | {len(v)} | {sum(bool(r['valid']) for r in v)} | {sum(map(_within, v))} | "
                  f"{sum(map(_wrong, v))} | {sum(map(_far, v))} | {len(po)} | {np.mean(po):.3f} m | "
                  f"{sum(e <= 0.1 for e in po)} |")
    a = part_a(data)
    b = part_positions(data, "base", "pos", "B")
    c = part_positions(data, "conf", "both", "C")
    met_a = _s38.print_verdict(a, "part A met")
    met_b = _s38.print_verdict(b, "part B met")
    met_c = _s38.print_verdict(c, "part C met")
    ships = ("A and B" if met_a and met_b and met_c else "A" if met_a else "B" if met_b else "nothing")
    print(f"decision (plan3.txt): {ships} ships")
    return 0


if __name__ == "__main__":
    raise SystemExit(_r1.main(sys.argv[1:], collect, judge))

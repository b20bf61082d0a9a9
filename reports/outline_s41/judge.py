"""Session 41: the clauses of reports/outline_s41/plan.txt (round 1) and plan2.txt (round 2) on the frame sets F and
R (cand: the shipped bundle with the outline refiner; base: the shipped bundle).

    python reports/outline_s41/judge.py collect [--round 2] [RUNS]   # once: rows of RUNS (runs/s41) -> files here
    python reports/outline_s41/judge.py [--round 2]                  # the clauses and the verdict

Round 1's sequences (C5) were not run: C3 had already failed on F and R (plan.txt, "Outcome"). Round 2 has no
sequence clause (plan2.txt says why).
"""
from __future__ import annotations

import gzip
import importlib.util
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RUNS = HERE.parent.parent / "runs" / "s41"

_spec = importlib.util.spec_from_file_location("tone_s38_judge", HERE.parent / "tone_s38" / "judge.py")
_s38 = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_s38)          # session 38's row helpers and definitions
BUNDLES, _within, _wrong, _far = _s38.BUNDLES, _s38._within, _s38._wrong, _s38._far


def _suffix(round_: int) -> str:
    return "" if round_ == 1 else f"_r{round_}"


def collect(runs: Path, round_: int) -> None:
    from spacepose.tools.shard_eval import write_rows

    for b in BUNDLES:
        for s in ("plain", "rest"):
            name = f"check_{b}_{s}{_suffix(round_)}.json.gz"
            doc = json.loads(gzip.decompress((runs / name).read_bytes()))
            doc["frames"] = [{k: r.get(k) for k in _s38.KEYS if k in r} for r in doc["frames"]]
            doc["cut_to"] = list(_s38.KEYS)
            write_rows(doc, HERE / name)


def frame_sets(round_: int) -> dict[str, dict[str, dict[str, dict]]]:
    """{"F" | "R": {"base" | "cand": {frame: row}}} of the collected rows of ``round_``."""
    out: dict = {}
    for name, s in (("F", "plain"), ("R", "rest")):
        for b in BUNDLES:
            rows = json.loads(gzip.decompress((HERE / f"check_{b}_{s}{_suffix(round_)}.json.gz").read_bytes()))
            out.setdefault(name, {})[b] = {r["frame"]: r for r in rows["frames"]}
        if out[name]["base"].keys() != out[name]["cand"].keys():
            raise SystemExit(f"{name}: base and cand rows are not of the same frames")
    return out


def judge(round_: int) -> int:
    data = frame_sets(round_)
    _s38.table(data, f"round {round_}: base the shipped bundle; cand the same with the outline refiner")
    clauses: dict[str, bool] = {}
    far = [(n, k) for n, by in data.items() for k, r in by["cand"].items()
           if _far(r) and not _far(by["base"][k])]
    print(f"C1 F, R: cand poses > 90 deg off where base's is not: {len(far)} {far}")
    clauses["C1 no new far pose"] = not far
    pooled = {b: {t.__name__: sum(t(r) for n in data for r in data[n][b].values()) for t in (_wrong, _within)}
              for b in BUNDLES}
    valid = {b: sum(bool(r["valid"]) for n in data for r in data[n][b].values()) for b in BUNDLES}
    print(f"C2 F+R: wrong cand {pooled['cand']['_wrong']} vs base {pooled['base']['_wrong']}")
    clauses["C2 no more wrong"] = pooled["cand"]["_wrong"] <= pooled["base"]["_wrong"]
    w = {b: pooled[b]["_within"] for b in BUNDLES}
    print(f"C3 F+R: within cand {w['cand']} vs base {w['base']} (x{w['cand'] / max(w['base'], 1):.3f}, bar 1.05); "
          f"valid cand {valid['cand']} vs base {valid['base']} (x{valid['cand'] / max(valid['base'], 1):.3f}, "
          "bar 0.98)")
    clauses["C3 the gain"] = w["cand"] >= 1.05 * w["base"] and valid["cand"] >= 0.98 * valid["base"]
    e_r = {b: [r["e_R"] for n in data for r in data[n][b].values() if r["valid"]] for b in BUNDLES}
    e_t = {b: [r["e_t"] for n in data for r in data[n][b].values() if r["valid"]] for b in BUNDLES}
    print(f"C4 F+R: mean e_R of valid poses cand {np.mean(e_r['cand']):.2f} vs base {np.mean(e_r['base']):.2f} deg "
          f"(x{np.mean(e_r['cand']) / np.mean(e_r['base']):.3f}, bar 0.9); medians {np.median(e_r['cand']):.2f} vs "
          f"{np.median(e_r['base']):.2f} deg; mean e_t {np.mean(e_t['cand']):.3f} vs {np.mean(e_t['base']):.3f} m")
    clauses["C4 the rotation"] = np.mean(e_r["cand"]) <= 0.9 * np.mean(e_r["base"])
    both = [(n, k) for n, by in data.items() for k in by["cand"] if by["cand"][k]["valid"] and by["base"][k]["valid"]]
    print(f"valid in both: {len(both)}; only base: {valid['base'] - len(both)}; only cand: {valid['cand'] - len(both)}")
    if round_ == 1:
        print("C5 (sequences): not run; C3 had already failed")
        clauses["C5 no loss in sequences"] = False
    _s38.print_verdict(clauses, "MET: the outline refiner ships")
    return 0


if __name__ == "__main__":
    argv = sys.argv[1:]
    cmd = argv.pop(0) if argv[:1] == ["collect"] else "judge"
    rnd = int(argv[1]) if argv[:1] == ["--round"] else 1
    argv = argv[2:] if argv[:1] == ["--round"] else argv
    if cmd == "collect":
        collect(Path(argv[0]) if argv else RUNS, rnd)
    else:
        raise SystemExit(judge(rnd))

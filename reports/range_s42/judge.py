"""Session 42: the clauses of reports/range_s42/plan.txt on the frame sets F and R (cand: the shipped bundle with
the range fit; base: the shipped bundle).

    python reports/range_s42/judge.py collect [RUNS]   # once: rows of RUNS (runs/s42) -> files beside this one
    python reports/range_s42/judge.py                  # the clauses and the verdict
"""
from __future__ import annotations

import gzip
import importlib.util
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
RUNS = HERE.parent.parent / "runs" / "s42"
#: the columns kept: session 38's, and how far the fit moved the pose
KEYS_EXTRA = ("range_fit_m", "t")

_spec = importlib.util.spec_from_file_location("tone_s38_judge", HERE.parent / "tone_s38" / "judge.py")
_s38 = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_s38)          # session 38's row helpers and definitions
BUNDLES, _within, _wrong, _far = _s38.BUNDLES, _s38._within, _s38._wrong, _s38._far


def collect(runs: Path) -> None:
    from spacepose.tools.shard_eval import write_rows

    keys = (*_s38.KEYS, *KEYS_EXTRA)
    for b in BUNDLES:
        for s in ("plain", "rest"):
            name = f"check_{b}_{s}.json.gz"
            doc = json.loads(gzip.decompress((runs / name).read_bytes()))
            doc["frames"] = [{k: r.get(k) for k in keys if k in r} for r in doc["frames"]]
            doc["cut_to"] = list(keys)
            write_rows(doc, HERE / name)


def frame_sets() -> dict[str, dict[str, dict[str, dict]]]:
    """{"F" | "R": {"base" | "cand": {frame: row}}} of the collected rows."""
    out: dict = {}
    for name, s in (("F", "plain"), ("R", "rest")):
        for b in BUNDLES:
            rows = json.loads(gzip.decompress((HERE / f"check_{b}_{s}.json.gz").read_bytes()))
            out.setdefault(name, {})[b] = {r["frame"]: r for r in rows["frames"]}
        if out[name]["base"].keys() != out[name]["cand"].keys():
            raise SystemExit(f"{name}: base and cand rows are not of the same frames")
    return out


def _mean_e_t(data: dict, names: tuple[str, ...], b: str) -> float:
    return float(np.mean([r["e_t"] for n in names for r in data[n][b].values() if r["valid"]]))


def _count(data: dict, names: tuple[str, ...], b: str, test) -> int:
    return sum(bool(test(r)) for n in names for r in data[n][b].values())


def judge() -> int:
    data = frame_sets()
    _s38.table(data, "base: the shipped bundle; cand: the same with the range fit (plan.txt)")
    clauses: dict[str, bool] = {}
    far = [(n, k) for n, by in data.items() for k, r in by["cand"].items() if _far(r) and not _far(by["base"][k])]
    print(f"C1 F, R: cand poses > 90 deg off where base's is not: {len(far)} {far}")
    clauses["C1 no new far pose"] = not far
    both = ("F", "R")
    wrong = {b: _count(data, both, b, _wrong) for b in BUNDLES}
    print(f"C2 F+R: wrong cand {wrong['cand']} vs base {wrong['base']}")
    clauses["C2 no more wrong"] = wrong["cand"] <= wrong["base"]
    w = {b: _count(data, both, b, _within) for b in BUNDLES}
    v = {b: _count(data, both, b, lambda r: r["valid"]) for b in BUNDLES}
    print(f"C3 F+R: within cand {w['cand']} vs base {w['base']} (x{w['cand'] / max(w['base'], 1):.3f}, bar 1.15); "
          f"valid cand {v['cand']} vs base {v['base']} (x{v['cand'] / max(v['base'], 1):.3f}, bar 0.99)")
    clauses["C3 the gain"] = w["cand"] >= 1.15 * w["base"] and v["cand"] >= 0.99 * v["base"]
    e = {b: _mean_e_t(data, both, b) for b in BUNDLES}
    med = {b: float(np.median([r["e_t"] for n in both for r in data[n][b].values() if r["valid"]])) for b in BUNDLES}
    print(f"C4 F+R: mean e_t of valid poses cand {e['cand']:.3f} vs base {e['base']:.3f} m "
          f"(x{e['cand'] / e['base']:.3f}, bar 0.8); medians {med['cand']:.3f} vs {med['base']:.3f} m")
    clauses["C4 the range"] = e["cand"] <= 0.8 * e["base"]
    er = {b: _mean_e_t(data, ("R",), b) for b in BUNDLES}
    wr = {b: _count(data, ("R",), b, _within) for b in BUNDLES}
    print(f"C5 R: mean e_t cand {er['cand']:.3f} vs base {er['base']:.3f} m; within cand {wr['cand']} vs base "
          f"{wr['base']}")
    clauses["C5 the other look"] = er["cand"] <= er["base"] and wr["cand"] >= wr["base"]
    moves = [r["range_fit_m"] for n in both for r in data[n]["cand"].values()
             if r["valid"] and r.get("range_fit_m") is not None and np.isfinite(r["range_fit_m"])]
    n_valid = v["cand"]
    print(f"the fit applied on {len(moves)} of {n_valid} valid cand poses; |move| median {np.median(np.abs(moves)):.3f} "
          f"m, 95th percentile {np.percentile(np.abs(moves), 95):.3f} m, largest {np.max(np.abs(moves)):.3f} m")
    _s38.print_verdict(clauses, "MET: the range fit ships")
    return 0


if __name__ == "__main__":
    argv = sys.argv[1:]
    if argv[:1] == ["collect"]:
        collect(Path(argv[1]) if len(argv) > 1 else RUNS)
    else:
        raise SystemExit(judge())

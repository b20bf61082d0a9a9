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


def collect_rows(runs: Path, pattern: str, arms: tuple[str, ...], keys: tuple[str, ...],
                 suffixes: tuple[str, ...] = ("plain", "rest")) -> None:
    """Each ``pattern.format(arm=..., set=...)`` file of ``runs`` (``shard_eval`` rows), cut to ``keys``, into the
    same name beside this file. Every round's ``collect`` of this session."""
    from spacepose.tools.shard_eval import write_rows

    for arm in arms:
        for s in suffixes:
            name = pattern.format(arm=arm, set=s)
            doc = json.loads(gzip.decompress((runs / name).read_bytes()))
            doc["frames"] = [{k: r.get(k) for k in keys if k in r} for r in doc["frames"]]
            doc["cut_to"] = list(keys)
            write_rows(doc, HERE / name)


def load_sets(pattern: str, arms: tuple[str, ...], sets: tuple[tuple[str, str], ...]) -> dict[str, dict[str, dict]]:
    """{set name: {arm: {frame: row}}} of the collected files ``pattern.format(arm=..., set=suffix)`` for ``sets``
    = ((name, suffix), ...); exits when the arms' rows of a set are not of the same frames."""
    out: dict = {}
    for name, s in sets:
        for arm in arms:
            rows = json.loads(gzip.decompress((HERE / pattern.format(arm=arm, set=s)).read_bytes()))
            out.setdefault(name, {})[arm] = {r["frame"]: r for r in rows["frames"]}
        if len({tuple(sorted(out[name][a])) for a in arms}) != 1:
            raise SystemExit(f"{name}: the arms' rows are not of the same frames")
    return out


def valid_rows(data: dict, arm: str) -> list[dict]:
    """The valid rows of ``arm`` over every set of ``data`` (:func:`load_sets`)."""
    return [r for n in data for r in data[n][arm].values() if r["valid"]]


def main(argv: list[str], collect, judge) -> int:
    """``collect [RUNS]`` (``collect(RUNS)``, default runs/s42) or the judge."""
    if argv[:1] == ["collect"]:
        collect(Path(argv[1]) if len(argv) > 1 else RUNS)
        return 0
    return judge()


def collect(runs: Path) -> None:
    collect_rows(runs, "check_{arm}_{set}.json.gz", BUNDLES, (*_s38.KEYS, *KEYS_EXTRA))


def frame_sets() -> dict[str, dict[str, dict[str, dict]]]:
    """{"F" | "R": {"base" | "cand": {frame: row}}} of the collected rows."""
    return load_sets("check_{arm}_{set}.json.gz", BUNDLES, (("F", "plain"), ("R", "rest")))


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
    for n, by in data.items():     # the wrong poses of either bundle, frame by frame
        for k in sorted(by["base"]):
            rb, rc = by["base"][k], by["cand"][k]
            if _wrong(rb) or _wrong(rc):
                print(f"    wrong in {'both' if _wrong(rb) and _wrong(rc) else 'base' if _wrong(rb) else 'cand'}: "
                      f"{n} {k} at {rb['distance']:.1f} m: base e_t {rb['e_t']:.3f} m / e_R {rb['e_R']:.2f} deg, "
                      f"cand e_t {rc['e_t']:.3f} m (moved {rc['range_fit_m']:+.3f} m)")
    _s38.print_verdict(clauses, "MET: the range fit ships")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:], collect, judge))

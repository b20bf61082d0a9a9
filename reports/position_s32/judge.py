"""Tables and verdict of reports/position_s32/rule.txt (the range bias of positions without a pose, session 32).

    python reports/position_s32/judge.py --fit      # the fit on spent rows that the rule's background quotes
    python reports/position_s32/judge.py [RUNS]     # the check (and the reported 1280x960 set, when it ran)

``--fit`` reads session 29's committed rows (reports/uncertainty_s29/rows.json.gz: the shipped bundle's positions
on six spent sets at 640x480) and fits, for each source of a position-only frame, the share k of the depth
tolerance tau that the range reads too far, under three models (k * tau, a constant, k * distance), by least
absolute error on a grid; then it simulates the candidate (0.07 / 0.24) on those rows.

The check reads ``RUNS`` (default ``runs/s32``): ``b_shipped_{a,b}`` and ``b_cand_{a,b}`` (the ``eval-pose``
commands in rule.txt, run from a checkout of commit abb44ef; the candidate bundle is the default one with
``registration.position_range_bias_outline`` 0.07 and ``position_range_bias_registered`` 0.24), and the reported
``q_shipped`` / ``q_cand`` at 1280x960 when present. When a set's runs are all there its frames are cut to the
columns used here and written to ``rows.json.gz`` / ``rows1280.json.gz`` beside this script; otherwise those
committed files are read, so the verdict reproduces from the repository alone.
"""
from __future__ import annotations

import gzip
import json
import math
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "position_s25"))
from _rows import compact_rows  # noqa: E402

MAX_CHAMFER_PX = 1.5                      # the shipped silhouette.max_chamfer_px: which source a position came from
CANDIDATE = {"outline": 0.07, "registered": 0.24}
FIT_SETS = ("fit_s27f", "fit_s27g", "fit_s27x", "check_640", "s28_fresh640", "s28_fresh640d")
KEYS = ("frame", "valid", "status", "e_t", "e_R", "position_valid", "e_pos", "e_pos_los", "depth_tolerance_m",
        "outline_chamfer_px", "distance", "regime", "sigma_range_m", "sigma_lateral_m")


def source(row: dict) -> str | None:
    """Where a position-only frame's position came from (``None`` for a valid pose or no position)."""
    if row["valid"] or not row["position_valid"]:
        return None
    return "outline" if row["outline_chamfer_px"] <= MAX_CHAMFER_PX else "registered"


def _same(a, b) -> bool:
    """Equal, NaN equal to NaN (an invalid frame's e_t and e_R)."""
    return a == b or (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b))


def position_table(rows: list[dict], shift: dict[str, float] | None = None) -> dict[str, dict[str, float]]:
    """Per source and over all position-only frames: count, range bias, mean |range error|, mean e_pos, share
    within tau, max e_pos, and with sigmas: the range NSE and the share within 2 sigma_range. ``shift``: simulate
    moving each position nearer by ``shift[source] * tau`` (the lateral part unchanged)."""
    out = {}
    for name in ("outline", "registered", "all"):
        sel = [r for r in rows if source(r) and (name == "all" or source(r) == name)]
        if not sel:
            continue
        los = np.array([r["e_pos_los"] for r in sel])
        e = np.array([r["e_pos"] for r in sel])
        tau = np.array([r["depth_tolerance_m"] for r in sel])
        if shift:
            lat = np.sqrt(np.maximum(e ** 2 - los ** 2, 0.0))
            los = los - np.array([shift[source(r)] for r in sel]) * tau
            e = np.hypot(lat, los)
        row = {"n": len(sel), "bias": float(los.mean()), "abs_los": float(np.abs(los).mean()), "e_pos": float(e.mean()),
               "within_tau": float(np.mean(e <= tau)), "max": float(e.max())}
        if all(r.get("sigma_range_m") for r in sel):
            s = np.array([r["sigma_range_m"] for r in sel])
            row.update(nse_range=float(np.mean((los / s) ** 2)), within_2s=float(np.mean(np.abs(los) <= 2.0 * s)))
        out[name] = row
    return out


def print_table(label: str, table: dict[str, dict[str, float]]) -> None:
    for name, r in table.items():
        extra = (f"  NSE range {r['nse_range']:.2f}  |e_los|<=2sigma {r['within_2s']:.3f}" if "nse_range" in r else "")
        print(f"  {label:<22}{name:<11}{r['n']:>5}  bias {r['bias']:+.3f} m  |range err| {r['abs_los']:.3f} m  "
              f"e_pos {r['e_pos']:.3f} m  within tau {r['within_tau']:.3f}  max {r['max']:.2f} m{extra}")


def fit() -> int:
    from spacepose.bundle import load_bundle
    from spacepose.uncertainty import position_uncertainty

    with gzip.open(HERE.parent / "uncertainty_s29" / "rows.json.gz", "rt") as fh:
        spent = json.load(fh)
    rows = [r for name in FIT_SETS for r in spent[name]]
    config = load_bundle(None, verify_graphs=False).position_uncertainty
    for r in rows:   # the shipped sigma_range, which these rows lack, from the bundle's model (focal 800 px at 640x480)
        if source(r):
            u = position_uncertainty(np.array(r["position"]), r["depth_tolerance_m"], 800.0, config,
                                     r["outline_chamfer_px"])
            r["sigma_range_m"] = u.sigma_range_m
    print(f"spent rows ({', '.join(FIT_SETS)}), position-only frames; least absolute range error on a grid:")
    for name in ("outline", "registered"):
        sel = [r for r in rows if source(r) == name]
        los = np.array([r["e_pos_los"] for r in sel])
        for model, basis in (("k * tau", np.array([r["depth_tolerance_m"] for r in sel])),
                             ("constant", np.ones(len(sel))), ("k * distance", np.array([r["distance"] for r in sel]))):
            ks = np.linspace(0.0, 2.0 * np.median(los / basis), 201)
            cost = [np.abs(los - k * basis).mean() for k in ks]
            i = int(np.argmin(cost))
            print(f"  {name:<11}{model:<14}k = {ks[i]:.4f}: mean |range error| {cost[0]:.4f} -> {cost[i]:.4f} m")
    print("the candidate (outline 0.07, registered 0.24) simulated on the same rows:")
    print_table("shipped", position_table(rows))
    print_table("candidate (simulated)", position_table(rows, CANDIDATE))
    return 0


def check(runs: Path) -> int:
    files = {mode: [runs / f"b_{mode}_{half}" / "pose_eval.json" for half in "ab"] for mode in ("shipped", "cand")}
    rows = compact_rows(files, HERE / "rows.json.gz", KEYS)
    old, new = rows["shipped"], rows["cand"]
    t_old, t_new = position_table(old), position_table(new)
    print(f"fresh tdrs640_s32b (seed 3221, {len(old)} frames), position-only frames:")
    print_table("shipped", t_old)
    print_table("candidate", t_new)
    print_table("shipped, simulated", position_table(old, CANDIDATE))
    same = len(old) == len(new) and all(
        a["frame"] == b["frame"] and all(_same(a[k], b[k]) for k in ("valid", "status", "e_t", "e_R", "position_valid"))
        for a, b in zip(old, new))
    fails = [] if same else ["1. the runs differ in a frame's valid, status, e_t, e_R or position_valid"]
    o, n = t_old["registered"], t_new["registered"]
    fails += ([f"2. registered |range error| {n['abs_los']:.4f} > 0.92 x {o['abs_los']:.4f}"]
              if n["abs_los"] > 0.92 * o["abs_los"] else [])
    fails += [f"2. registered |bias| {abs(n['bias']):.3f} > 0.06"] if abs(n["bias"]) > 0.06 else []
    o, n = t_old["outline"], t_new["outline"]
    fails += ([f"3. outline |range error| {n['abs_los']:.4f} > {o['abs_los']:.4f} + 0.002"]
              if n["abs_los"] > o["abs_los"] + 0.002 else [])
    o, n = t_old["all"], t_new["all"]
    fails += [f"4. e_pos {n['e_pos']:.4f} >= {o['e_pos']:.4f}"] if not n["e_pos"] < o["e_pos"] else []
    fails += ([f"4. within tau {n['within_tau']:.3f} < {o['within_tau']:.3f} - 0.01"]
              if n["within_tau"] < o["within_tau"] - 0.01 else [])
    fails += [f"4. max e_pos {n['max']:.3f} > {o['max']:.3f} + 0.10"] if n["max"] > o["max"] + 0.10 else []
    fails += ([f"5. range NSE {n['nse_range']:.2f} outside [0.6, 1.6]"]
              if not 0.6 <= n["nse_range"] <= 1.6 else [])
    fails += ([f"5. within 2 sigma_range {n['within_2s']:.3f} < {o['within_2s']:.3f} - 0.01"]
              if n["within_2s"] < o["within_2s"] - 0.01 else [])
    q_files = {mode: [runs / f"q_{mode}" / "pose_eval.json"] for mode in ("shipped", "cand")}
    if all(f.is_file() for fs in q_files.values() for f in fs) or (HERE / "rows1280.json.gz").is_file():
        q = compact_rows(q_files, HERE / "rows1280.json.gz", KEYS)
        print(f"reported, not judged: fresh tdrs1280_s32b (seed 3222, {len(q['shipped'])} frames at 1280x960):")
        print_table("shipped", position_table(q["shipped"]))
        print_table("candidate", position_table(q["cand"]))
    print()
    print("verdict (rule.txt, candidate = position_range_bias_outline 0.07, position_range_bias_registered 0.24): "
          + ("MET" if not fails else "NOT MET: " + "; ".join(fails)))
    return 0


def main(argv: list[str]) -> int:
    if argv[:1] == ["--fit"]:
        return fit()
    return check(Path(argv[0]) if argv else Path("runs/s32"))


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))

"""Session 34's bundle's confidence (its uncertainty and confidence constants are older than its stereo graph, and
still shipped) against the share of its valid poses within the bar, by distance (session 35).

    python reports/gates_s35/confidence_by_distance.py

Reads committed rows only: session 34's bundle's independent 640x480 frames of session 34's two check rounds
(reports/floor_s34/rows.json.gz ``a_cand``, rows2.json.gz ``a2_cand``: this bundle, then the candidate) and of
session 35's round 1 (reports/gates_s35/rows.json.gz ``a_base``). Within: e_t <= 0.10 m and e_R <= 2 deg.

Then the constants refitted on session 34's check runs (``REFIT``; reports/gates_s35/uncertainty_refit.txt), against
the shipped ones: the confidence they give round 1's valid poses (not in the fit), by distance, and what the
floor (0.08) on each does to session 34's gates' replay on the open rows (explore.py). Both recompute the confidence
from the rows' distance (for the range to the target's centre), depth tolerance and outline chamfer; on the open rows
that differs from the reported confidence by 0.0005 at the median.
"""
from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np

from spacepose.bundle import DEFAULT_BUNDLE_DIR
from spacepose.confidence import ConfidenceConfig, calibrated_confidence, within_probability
from spacepose.uncertainty import UncertaintyConfig, pose_uncertainty

REPORTS = Path(__file__).resolve().parent.parent
SOURCES = ((REPORTS / "floor_s34" / "rows.json.gz", "a_cand"), (REPORTS / "floor_s34" / "rows2.json.gz", "a2_cand"),
           (REPORTS / "gates_s35" / "rows.json.gz", "a_base"))
#: session 35's refit (reports/gates_s35/uncertainty_refit.txt), rounded to 4 digits
REFIT = {"uncertainty": {"range_k": 0.2678, "lateral_px": 0.0, "lateral_floor_m": 0.0259, "rotation_k_deg": 12.2968,
                         "rotation_floor_deg": 0.4322, "rotation_chamfer_deg": 1.5016},
         "confidence": {"bias": 1.0858, "slope": 1.1232}}
FOCAL_PX = 800.0
BINS = ((10, 15), (15, 20), (20, 25), (25, 30), (30, 40), (40, 50))


def valid_rows() -> list[dict]:
    rows = []
    for path, group in SOURCES:
        with gzip.open(path, "rt") as fh:
            rows += [r for r in json.load(fh)[group] if r["valid"]]
    return rows


def main() -> int:
    rows = valid_rows()
    d = np.array([r["distance"] for r in rows])
    conf = np.array([r["confidence"] for r in rows])
    e_t, e_r = np.array([r["e_t"] for r in rows]), np.array([r["e_R"] for r in rows])
    print(f"{len(rows)} valid poses of session 34's bundle")
    print("distance   poses  confidence  within  e_t<=0.10  e_R<=2")
    for lo, hi in BINS:
        s = (d >= lo) & (d < hi)
        print(f"{lo:>2}-{hi:<2} m  {int(s.sum()):>6}  {conf[s].mean():>10.3f}  {((e_t <= 0.10) & (e_r <= 2.0))[s].mean():>6.3f}"
              f"  {(e_t <= 0.10)[s].mean():>9.3f}  {(e_r <= 2.0)[s].mean():>6.3f}")
    shipped = json.loads((DEFAULT_BUNDLE_DIR / "bundle.json").read_text())
    models = {"shipped": (UncertaintyConfig(**shipped["uncertainty"]), ConfidenceConfig(**shipped["confidence"]))}
    models["refit"] = (UncertaintyConfig(**{**shipped["uncertainty"], **REFIT["uncertainty"]}),
                       ConfidenceConfig(**{**shipped["confidence"], **REFIT["confidence"]}))
    with gzip.open(REPORTS / "gates_s35" / "rows.json.gz", "rt") as fh:
        held = [r for r in json.load(fh)["a_base"] if r["valid"]]
    d = np.array([r["distance"] for r in held])
    w = np.array([r["e_t"] <= 0.10 and r["e_R"] <= 2.0 for r in held])
    conf = {name: np.array([confidence(r, *m) for r in held]) for name, m in models.items()}
    print()
    print(f"round 1's {len(held)} valid poses of session 34's bundle (not in the refit): Brier score "
          + ", ".join(f"{name} {np.mean((c - w) ** 2):.4f}" for name, c in conf.items()))
    print("distance   poses  within  shipped  refit")
    for lo, hi in BINS:
        s = (d >= lo) & (d < hi)
        print(f"{lo:>2}-{hi:<2} m  {int(s.sum()):>6}  {w[s].mean():>6.3f}  {conf['shipped'][s].mean():>7.3f}  "
              f"{conf['refit'][s].mean():>5.3f}")
    explore = _explore()
    raw = explore.open_rows(REPORTS / "gates_s35" / "no_runs")
    print()
    print("session 34's gates replayed on the open rows (explore.py), the floor on each confidence:")
    for name, m in models.items():
        rows = [dict(r, confidence=confidence(r, *m)) if r["valid"] else r for r in raw]
        cell = explore.table(explore.floored(rows), {k: (explore.SHIPPED[k],) for k in explore.GRID},
                             (explore.SHIPPED["decide_prob"],), (explore.SHIPPED["veto_prob"],),
                             (explore.SHIPPED["flip_chamfer"],))[0]
        print(f"  {name:<8} kept {cell['kept']}, wrong {cell['wrong']}, flips {cell['flips']}, within {cell['within']}")
    return 0


def confidence(row: dict, uncertainty: UncertaintyConfig, config: ConfidenceConfig) -> float:
    """The calibrated confidence of a row's pose under ``uncertainty`` and ``config`` (the row's distance as the
    range to the target's centre)."""
    u = pose_uncertainty(np.array([0.0, 0.0, row["distance"]]), row["depth_tolerance_m"], FOCAL_PX, uncertainty,
                         row["outline_chamfer_px"])
    if u is None:
        return float("nan")
    return calibrated_confidence(within_probability(u.sigma_range_m, u.sigma_lateral_m, u.sigma_rotation_deg, config),
                                 config)


def _explore():
    import importlib.util
    spec = importlib.util.spec_from_file_location("explore_s35", Path(__file__).resolve().parent / "explore.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


if __name__ == "__main__":
    raise SystemExit(main())

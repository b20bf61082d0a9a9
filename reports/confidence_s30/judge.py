"""Fit and verdict of reports/confidence_s30/rule.txt (a confidence that follows the error, session 30).

    python reports/confidence_s30/judge.py [RUNS]

The fit: ``bias`` and ``slope`` of the ``confidence`` section by
:func:`spacepose.tools.calibrate_uncertainty.fit_confidence`, over the valid poses of the three spent fit sets
of the uncertainty rule (``fit_s27f``, ``fit_s27g``, ``fit_s27x`` in ``reports/uncertainty_s28/rows.json.gz``),
with the sigmas of the default bundle's ``uncertainty`` section and the tolerance 0.10 m / 2 degrees.

The check sets, evaluated with the shipped bundle of commit 7b7b4b5 (RUNS, default ``runs/s30``):
``spacepose render data/tdrs640_s30c --target tdrs --count 1000 --size 640x480 --seed 3001 --workers 2 --no-depth``,
then ``spacepose eval-pose data/tdrs640_s30c --split train --limit 450 --threads 1 --overlays 0 --out
runs/s30/s30c_a`` and the same with ``--skip 450 --out runs/s30/s30c_b``; ``spacepose render data/tdrs1280_s30c
--target tdrs --count 100 --size 1280x960 --seed 3002 --workers 2 --no-depth``, then ``spacepose eval-pose
data/tdrs1280_s30c --split train --threads 1 --overlays 0 --out runs/s30/s30c1280``. When those runs are there,
their valid poses are cut to the columns used here and written to ``rows.json.gz`` beside this script; otherwise
that committed file is read, so the verdict reproduces from the repository alone.

The confidence is recomputed from each pose's depth tolerance, range and chamfer (as the estimator computes it
from the covariance it reports). Reported only: the old (decision) confidence's rank correlations on the check
sets, and the uncertainty rule's sets (spent for this rule: looked at before it was written).
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

from spacepose.bundle import load_bundle  # noqa: E402
from spacepose.confidence import ConfidenceConfig, calibrated_confidence  # noqa: E402
from spacepose.tools.calibrate_uncertainty import (_spearman, confidence_check, fit_confidence,  # noqa: E402
                                                   format_confidence_check, normal_within, pose_errors,
                                                   within_tolerance)

KEYS = ("frame", "distance", "valid", "depth_tolerance_m", "position", "e_pos", "e_pos_los", "e_R", "e_t",
        "outline_chamfer_px", "confidence")
FIT_SETS = ("fit_s27f", "fit_s27g", "fit_s27x")
SPENT = ("fresh640", "fresh640d", "fresh1280", "fresh1280d", "test640", "unseen1280", "seq_w1", "seq_w2", "seq_w3",
         "seq_w4", "seq_w5")
FOCAL = {"fresh1280": 1600.0, "fresh1280d": 1600.0, "unseen1280": 1600.0, "check1280": 1600.0}  # others: 800 px
TOLERANCE = ConfidenceConfig(position_m=0.10, rotation_deg=2.0, bias=0.0, slope=1.0)
# rule.txt, A (check640) and B (check1280)
A_SPEARMAN, A_CALIBRATION, A_BIN, A_RISE = -0.25, 0.06, 0.15, 0.25
B_CALIBRATION = 0.15


def _check_rows(runs: Path) -> dict[str, list[dict]]:
    files = {"check640": [runs / "s30c_a" / "pose_eval.json", runs / "s30c_b" / "pose_eval.json"],
             "check1280": [runs / "s30c1280" / "pose_eval.json"]}
    return compact_rows(files, HERE / "rows.json.gz", KEYS, keep=lambda r: r["valid"])


def main(argv: list[str]) -> int:
    runs = Path(argv[0]) if argv else Path("runs/s30")
    with gzip.open(HERE.parent / "uncertainty_s28" / "rows.json.gz", "rt") as fh:
        spent = json.load(fh)
    rows = {**{k: spent[k] for k in FIT_SETS + SPENT}, **_check_rows(runs)}
    uncertainty = load_bundle(None, verify_graphs=False).uncertainty
    err = {name: pose_errors(v, FOCAL.get(name, 800.0)) for name, v in rows.items()}
    p = {name: normal_within(e, uncertainty, FOCAL.get(name, 800.0), TOLERANCE) for name, e in err.items()}
    within = {name: within_tolerance(e, TOLERANCE) for name, e in err.items()}
    config = fit_confidence(np.concatenate([p[n] for n in FIT_SETS]), np.concatenate([within[n] for n in FIT_SETS]),
                            TOLERANCE.position_m, TOLERANCE.rotation_deg)
    print(f"fit on {sum(len(p[n]) for n in FIT_SETS)} valid poses of {', '.join(FIT_SETS)}:")
    print(json.dumps({"confidence": {k: round(v, 4) for k, v in vars(config).items()}}))
    print()
    checks = {}
    for name in rows:
        conf = np.array([calibrated_confidence(v, config) if math.isfinite(v) else np.nan for v in p[name]])
        checks[name] = confidence_check(conf, within[name], err[name]["e_t"], err[name]["e_R"])
        tag = "fit" if name in FIT_SETS else ("spent" if name in SPENT else "CHECK")
        print(f"[{tag}] " + format_confidence_check(name, checks[name]))
    print()
    for name in ("check640", "check1280"):
        old = np.array([r["confidence"] for r in rows[name]])
        print(f"{name}: the old (decision) confidence: spearman e_t {_spearman(err[name]['e_t'], old):+.2f}, "
              f"e_R {_spearman(err[name]['e_R'], old):+.2f}")
    a, b = checks["check640"], checks["check1280"]
    fails = [f"A spearman {k} {a[k]:+.2f} > {A_SPEARMAN}" for k in ("spearman_t", "spearman_R") if a[k] > A_SPEARMAN]
    gap = abs(a["mean_confidence"] - a["share_within"])
    fails += [f"A |mean confidence - share within| {gap:.3f} > {A_CALIBRATION}"] if gap > A_CALIBRATION else []
    fails += [f"A bin {i} |{x['share_within']:.2f} - {x['mean_confidence']:.2f}| > {A_BIN}"
              for i, x in enumerate(a["bins"]) if abs(x["share_within"] - x["mean_confidence"]) > A_BIN]
    rise = a["bins"][-1]["share_within"] - a["bins"][0]["share_within"]
    fails += [f"A top bin - bottom bin {rise:.2f} < {A_RISE}"] if rise < A_RISE else []
    fails += [f"A brier {a['brier']:.3f} >= constant {a['brier_base']:.3f}"] if a["brier"] >= a["brier_base"] else []
    gap_b = abs(b["mean_confidence"] - b["share_within"])
    fails += [f"B |mean confidence - share within| {gap_b:.3f} > {B_CALIBRATION}"] if gap_b > B_CALIBRATION else []
    fails += [f"B spearman e_t {b['spearman_t']:+.2f} >= 0"] if not b["spearman_t"] < 0 else []
    print()
    print("verdict (rule.txt, A = check640 seed 3001, B = check1280 seed 3002): "
          + ("MET" if not fails else "NOT MET: " + "; ".join(fails)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))

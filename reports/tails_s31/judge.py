"""Fit, table and verdict of reports/tails_s31/rule.txt (the errors' Student-t tails, session 31).

    python reports/tails_s31/judge.py [RUNS]

The fit: ``tail_dof`` by :func:`spacepose.tools.calibrate_uncertainty.fit_tail_dof` over the right poses' position
and rotation NEES (against the default bundle's ``uncertainty`` sigmas) of the three fit sets of the uncertainty
rule (``fit_s27f``, ``fit_s27g``, ``fit_s27x`` in ``reports/uncertainty_s28/rows.json.gz``, 640x480, focal 800 px).

The check set, evaluated from a checkout of commit c410a53 (the bundle as shipped since session 30; RUNS, default
``runs/s31``):
``spacepose render data/tdrs640_s31t --target tdrs --count 1000 --size 640x480 --seed 3131 --workers 2 --no-depth``,
then ``spacepose eval-pose data/tdrs640_s31t --split train --limit 225 --threads 1 --overlays 0 --out runs/s31/t_a``
and ``... --skip 225 --limit 225 --out runs/s31/t_b``. Reported only: ``tdrs1280_s31c`` (``spacepose render
data/tdrs1280_s31c --target tdrs --count 300 --size 1280x960 --seed 3121 --workers 2 --no-depth``, then ``eval-pose
... --split train --limit 135 --out runs/s31/c1280_a`` and ``--skip 135 --out runs/s31/c1280_b``), and the spent sets
of ``reports/uncertainty_s28/rows.json.gz``. When the runs are there, their valid poses are cut to the columns used
here and written to ``rows.json.gz`` beside this script; otherwise that committed file is read, so the verdict
reproduces from the repository alone. The tails need no graph: only each pose's errors, depth tolerance, range and
chamfer, from which the sigmas are recomputed.
"""
from __future__ import annotations

import gzip
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "position_s25"))
from _rows import compact_rows  # noqa: E402

from spacepose.bundle import load_bundle  # noqa: E402
from spacepose.confidence import calibrated_confidence  # noqa: E402
from spacepose.tails import nees_gate  # noqa: E402
from spacepose.tools.calibrate_uncertainty import (confidence_check, coverage, fit_tail_dof,  # noqa: E402
                                                   format_tail_check, normal_within, pose_errors, right_nees,
                                                   tail_check, within_tolerance)

FIT_SETS = ("fit_s27f", "fit_s27g", "fit_s27x")
SPENT_FOCAL = {"fresh1280": 1600.0, "fresh1280d": 1600.0, "unseen1280": 1600.0}
KEYS = ("frame", "valid", "depth_tolerance_m", "position", "e_pos", "e_pos_los", "e_R", "e_t", "outline_chamfer_px")
CHECK = {"check640": (("t_a", "t_b"), 800.0), "check1280 (reported)": (("c1280_a", "c1280_b"), 1600.0)}


def _check_rows(runs: Path) -> dict[str, list[dict]]:
    files = {name: [runs / part / "pose_eval.json" for part in parts] for name, (parts, _) in CHECK.items()}
    return compact_rows(files, HERE / "rows.json.gz", KEYS, keep=lambda r: bool(r["valid"]))


def main(argv: list[str]) -> int:
    runs = Path(argv[0]) if argv else Path("runs/s31")
    bundle = load_bundle(None, verify_graphs=False)
    config = bundle.uncertainty
    with gzip.open(HERE.parent / "uncertainty_s28" / "rows.json.gz", "rt") as fh:
        spent = json.load(fh)
    fit_err = [(pose_errors(spent[name], 800.0), 800.0) for name in FIT_SETS]
    nu = round(fit_tail_dof(right_nees(fit_err, config)), 4)
    print(f"fit on the right poses of {', '.join(FIT_SETS)}: " + json.dumps({"uncertainty": {"tail_dof": nu}}))
    probabilities = (0.90, 0.95, 0.99, 0.997, 0.999)
    for label, dof in ((f"t, {nu} dof", nu), ("chi-square", 0.0)):
        print(f"  gates ({label}): " + ", ".join(f"{100 * p:g}% {nees_gate(p, 3, dof):.2f}" for p in probabilities))
    print()
    for name, rows in spent.items():
        focal = SPENT_FOCAL.get(name, 800.0)
        err = pose_errors(rows, focal)
        if len(err["range"]) == 0:
            continue
        tag = "fit" if name in FIT_SETS else "spent"
        print(format_tail_check(f"[{tag}] {name}", tail_check(err, config, focal, nu)))
    checks = {}
    for name, rows in _check_rows(runs).items():
        focal = CHECK[name][1]
        checks[name] = tail_check(pose_errors(rows, focal), config, focal, nu)
        print(format_tail_check(f"[CHECK] {name}" if "reported" not in name else f"[reported] {name}", checks[name]))
    print("(right: not off by > 20 deg or > 0.5 m; the NEES of position and rotation each have 3 axes)")
    # reported only: how the sigmas and the confidence fare at 1,280x960 (the model card's "The errors' tails")
    focal = CHECK["check1280 (reported)"][1]
    err = pose_errors(_check_rows(runs)["check1280 (reported)"], focal)
    cov = coverage(err, config, focal)
    conf = np.array([calibrated_confidence(p, bundle.confidence) for p in
                     normal_within(err, config, focal, bundle.confidence)])
    check = confidence_check(conf, within_tolerance(err, bundle.confidence), err["e_t"], err["e_R"])
    print(f"[reported] check1280: per-axis NEES of the right poses: range {cov['nees_range']:.2f}, lateral "
          f"{cov['nees_lateral']:.2f}, rotation {cov['nees_rotation']:.2f}; confidence {check['mean_confidence']:.3f} "
          f"against {check['share_within']:.3f} within the bar ({check['poses']} poses)")
    g = checks["check640"]["gates"]
    fails = []
    for p, limit in ((0.99, 0.025), (0.997, 0.010), (0.95, 0.09)):
        for axis in ("position", "rotation"):
            share = g[f"t_{p}"][f"right_{axis}"]
            if not share <= limit:
                fails.append(f"{p:g} gate: right {axis} {100 * share:.1f}% > {100 * limit:.1f}%")
    for axis in ("position", "rotation"):
        if not g["chi2_0.99"][f"right_{axis}"] > g["t_0.99"][f"right_{axis}"]:
            fails.append(f"4. chi-square's 99% gate rejects no more right {axis} poses than the t gate")
    print()
    print(f"verdict (rule.txt, check640 = tdrs640_s31t seed 3131, tail_dof {nu}): "
          + ("MET" if not fails else "NOT MET: " + "; ".join(fails)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))

"""Validity thresholds of the pose stage from train-split frames: ``min_confidence``, ``min_flip_margin``
(and, for a registration bundle, ``max_tau_m`` with ``--taus``).

    spacepose eval-pose data/tdrs640 --split train --limit 400 --bundle B --out runs/gates_train
    python -m spacepose.tools.calibrate_gates runs/gates_train/pose_eval.json --out reports/gates_train.json

The evaluation must run with both gates open (``voting.min_confidence`` 0 and ``voting.min_flip_margin``
0 in bundle B), so that every pose the other checks pass is in the report with its confidence and flip
margin. For each pair of thresholds on a grid, this counts the poses that would stay valid, the
180° flips among them (e_R > 90°) and the wrong poses (e_t or e_R over ``--max-e-t`` / ``--max-e-r``).
It proposes the pair that keeps the most poses with no flip and no wrong pose. Ties go to the stricter
pair. The thresholds come from train frames only; the test split measures them. Numbers only.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np

from spacepose.tools.eval_pose import FLIP_DEG

__all__ = ["gate_table", "propose", "main"]


def _finite(value: Any) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        return float("nan")
    return v if math.isfinite(v) else float("nan")


def gate_table(rows: Iterable[dict[str, Any]], confidences: Sequence[float], margins: Sequence[float],
               max_e_t: float, max_e_r: float, taus: Sequence[float] = (math.inf,)) -> list[dict[str, float]]:
    """One row per (min_confidence, min_flip_margin, max_tau_m): kept poses, flips, wrong poses among them.

    ``max_tau_m`` gates on the rows' ``depth_tolerance_m`` (the registration's; a row without one
    passes every value)."""
    ok = [r for r in rows if r.get("valid")]
    tau = np.nan_to_num(np.array([_finite(r.get("depth_tolerance_m")) for r in ok]), nan=0.0)
    conf = np.array([_finite(r.get("confidence")) for r in ok])
    margin = np.nan_to_num(np.array([_finite(r.get("flip_margin")) for r in ok]), nan=np.inf)  # no flip stage
    e_t = np.array([_finite(r.get("e_t")) for r in ok])
    e_r = np.array([_finite(r.get("e_R")) for r in ok])
    flip = e_r > FLIP_DEG
    wrong = (e_t > max_e_t) | (e_r > max_e_r)
    table = []
    for c, m, tmax in itertools.product(confidences, margins, taus):
        keep = (conf >= c) & (margin >= m) & (tau <= tmax)
        table.append({"min_confidence": float(c), "min_flip_margin": float(m), "max_tau_m": float(tmax),
                      "kept": int(keep.sum()), "flips": int((keep & flip).sum()), "wrong": int((keep & wrong).sum()),
                      "e_t_median": float(np.median(e_t[keep])) if keep.any() else float("nan"),
                      "e_R_median": float(np.median(e_r[keep])) if keep.any() else float("nan")})
    return table


def propose(table: list[dict[str, float]]) -> dict[str, float] | None:
    """The row keeping the most poses with no flip and no wrong pose (stricter on ties); None if none keeps any."""
    safe = [r for r in table if r["flips"] == 0 and r["wrong"] == 0 and r["kept"] > 0]
    if not safe:
        return None
    return max(safe, key=lambda r: (r["kept"], r["min_confidence"], r["min_flip_margin"], -r.get("max_tau_m", math.inf)))


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m spacepose.tools.calibrate_gates", description=__doc__.split("\n")[0])
    p.add_argument("report", type=Path, help="pose_eval.json of eval-pose on train frames with both gates open")
    p.add_argument("--max-e-t", type=float, default=0.5, help="a pose farther off than this (m) is wrong")
    p.add_argument("--max-e-r", type=float, default=20.0, help="a pose turned more than this (deg) is wrong")
    p.add_argument("--out", type=Path, default=None, help="also write the table and proposal as JSON")
    p.add_argument("--taus", type=float, nargs="*", default=None,
                   help="also try these max depth tolerances (m; registration bundles: max_tau_m)")
    p.add_argument("--margins", type=float, nargs="*", default=None, help="min_flip_margin grid")
    args = p.parse_args(argv)
    report = json.loads(args.report.read_text())
    if report.get("split") == "test":
        raise SystemExit("calibrate on train frames, not the test split")
    rows = report["frames"]
    confidences = [0.0, 0.3, 0.5, 0.6, 0.7, 0.8, 0.9]
    margins = args.margins or [0.0, 0.005, 0.01, 0.02, 0.03, 0.05, 0.08]
    taus = args.taus or [math.inf]
    table = gate_table(rows, confidences, margins, args.max_e_t, args.max_e_r, taus)
    best = propose(table)
    print(f"{sum(1 for r in rows if r.get('valid'))} of {len(rows)} {report.get('split')} frames valid with the gates open")
    print("| min_confidence | min_flip_margin | max_tau_m | kept | flips | wrong | e_t median m | e_R median ° |\n"
          "|---|---|---|---|---|---|---|---|")
    for r in table:
        print(f"| {r['min_confidence']:.2f} | {r['min_flip_margin']:.3f} | {r['max_tau_m']:g} | {r['kept']} | {r['flips']} "
              f"| {r['wrong']} | {r['e_t_median']:.3f} | {r['e_R_median']:.2f} |")
    print("proposed:", "none (no set keeps a pose without a flip or a wrong pose)" if best is None else
          f"min_confidence {best['min_confidence']}, min_flip_margin {best['min_flip_margin']}, "
          f"max_tau_m {best['max_tau_m']:g} ({best['kept']} poses kept)")
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps({"report": str(args.report), "max_e_t": args.max_e_t, "max_e_r": args.max_e_r,
                                        "table": table, "proposed": best}, indent=2))
    return 0


if __name__ == "__main__":  # pragma: no cover
    import sys

    sys.exit(main())

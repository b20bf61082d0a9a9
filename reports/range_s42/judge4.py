"""Session 42, round 4: the clauses of reports/range_s42/plan4.txt (the position covariance fitted again) on F4 and R4.

    python reports/range_s42/judge4.py collect [RUNS]   # once: rows of RUNS (runs/s42) -> files beside this one
    python reports/range_s42/judge4.py                  # the clauses and the verdict

One evaluation per set with the shipped bundle; the covariance of each frame with a position but no pose is
recomputed from its position, depth tolerance and chamfer for the constants shipped before round 4 (base,
:data:`BASE_CONSTANTS`) and the candidate's (``fit4_positions.json``, rounded to 4 decimals), by
``spacepose.tools.calibrate_uncertainty.position_coverage``.
"""
from __future__ import annotations

import gzip
import importlib.util
import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
RUNS = HERE.parent.parent / "runs" / "s42"
KEYS = ("frame", "valid", "position_valid", "position", "depth_tolerance_m", "e_pos", "e_pos_los",
        "outline_chamfer_px", "e_R", "e_t", "confidence")

_spec = importlib.util.spec_from_file_location("range_s42_judge", HERE / "judge.py")
_r1 = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_r1)           # round 1's judge: the row helpers of every round, session 38's definitions
_s38 = _r1._s38

#: the default bundle's position_uncertainty when plan4.txt was written (its "shipped" constants)
BASE_CONSTANTS = {"range_k": 0.2487, "range_chamfer_k": 0.1189, "lateral_px": 0.0, "lateral_floor_m": 0.0,
                  "lateral_chamfer_m": 0.0337}


def collect(runs: Path) -> None:
    _r1.collect_rows(runs, "check4_{set}.json.gz", ("",), KEYS)


def judge() -> int:
    """plan4.txt's clauses; ``base`` is the section as shipped when plan4.txt was written (:data:`BASE_CONSTANTS`),
    not the default bundle's, which holds the candidate since round 4 was met."""
    from spacepose.tools.calibrate_uncertainty import format_position_coverage, position_coverage, position_errors
    from spacepose.uncertainty import PositionUncertaintyConfig

    docs = [json.loads(gzip.decompress((HERE / f"check4_{s}.json.gz").read_bytes())) for s in ("plain", "rest")]
    rows = [r for d in docs for r in d["frames"]]
    focal = float(docs[0]["focal_px"])
    err = position_errors(rows, focal)
    fit = json.loads((HERE / "fit4_positions.json").read_text())["fit"]
    configs = {"base": PositionUncertaintyConfig(**BASE_CONSTANTS),
               "cand": PositionUncertaintyConfig(**{k: round(float(v), 4) for k, v in fit.items()})}
    cov = {}
    for name, config in configs.items():
        cov[name] = position_coverage(err, config, focal)
        print(format_position_coverage(f"F4+R4 {name} {config}", cov[name]))
    b, c = cov["base"], cov["cand"]
    clauses = {}
    for axis, key in (("Q1 range", "nees_range"), ("Q2 lateral", "nees_lateral")):
        print(f"{axis}: NSE cand {c[key]:.3f} vs base {b[key]:.3f}")
        clauses[axis] = abs(c[key] - 1.0) <= abs(b[key] - 1.0) and 0.6 <= c[key] <= 1.6
    print(f"Q3: beyond the 3-sigma gate, positions > 0.5 m off: cand {c['wrong_flagged']:.3f} vs base "
          f"{b['wrong_flagged']:.3f} ({c['wrong']} of them); the others: cand {c['right_flagged']:.3f} (bar 0.06)")
    clauses["Q3 the gate"] = c["wrong_flagged"] >= b["wrong_flagged"] - 0.05 and c["right_flagged"] <= 0.06
    print(f"Q4: Spearman cand {c['spearman_position']:.3f} vs base {b['spearman_position']:.3f}")
    clauses["Q4 ranking"] = c["spearman_position"] >= b["spearman_position"] - 0.05
    _s38.print_verdict(clauses, "MET: the constants ship")
    return 0


if __name__ == "__main__":
    raise SystemExit(_r1.main(sys.argv[1:], collect, judge))

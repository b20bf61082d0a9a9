"""Table and verdict of reports/wrong_s31/rule.txt (a polish cap on decided poses, session 31).

    python reports/wrong_s31/judge.py [RUNS]

RUNS (default ``runs/s31``) holds the ``eval-pose`` reports of the rule, made from a checkout of commit c410a53 (the
bundle as shipped): ``w_a`` and ``w_b`` (the commands in rule.txt), and ``w_cand100``, the candidate bundle (the
default bundle with ``silhouette.max_decided_polish_deg`` 3.0, run from a checkout of commit 257cfd4, the first with
that key) on the first 100 of those frames: ``spacepose eval-pose data/tdrs640_s31w --split train --limit 100
--threads 1 --overlays 0 --bundle B --out runs/s31/w_cand100``. When the runs are there, their frames are cut to the
columns used here and written to ``rows.json.gz`` beside this script; otherwise that committed file is read, so the
verdict reproduces from the repository alone.

The candidate's rows are the shipped rows with the valid poses of the outline, image and registration routes whose
``polish_deg`` is over the cap made invalid (without a prior nothing else changes); ``w_cand100`` checks that the
bundle does exactly that on 100 frames.
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

from spacepose.tools.eval_pose import BAR_R_DEG, BAR_T_M  # noqa: E402

CAP_DEG = 3.0
ROUTES = ("outline", "image", "registration")
KEYS = ("frame", "regime", "distance", "valid", "status", "e_t", "e_R", "decided_by", "polish_deg")
OFF_DEG = 10.0


def refused(row: dict, cap: float = CAP_DEG) -> bool:
    """Whether the cap refuses this (shipped) row's pose."""
    return bool(row["valid"]) and row["decided_by"] in ROUTES and row["polish_deg"] is not None and \
        float(row["polish_deg"]) > cap


def candidate(rows: list[dict], cap: float = CAP_DEG) -> list[dict]:
    return [{**r, "valid": False} if refused(r, cap) else r for r in rows]


def stats(rows: list[dict]) -> dict[str, float]:
    v = [r for r in rows if r["valid"]]
    e_t, e_R = np.array([r["e_t"] for r in v]), np.array([r["e_R"] for r in v])
    return {"frames": len(rows), "valid": len(v), "near": int(np.sum(e_R <= OFF_DEG)), "off": int(np.sum(e_R > OFF_DEG)),
            "wrong": int(np.sum((e_R > 20.0) | (e_t > 0.5))), "flips": int(np.sum(e_R > 90.0)),
            "within": int(np.sum((e_t <= BAR_T_M) & (e_R <= BAR_R_DEG))),
            "e_t_mean": float(e_t.mean()) if len(v) else float("nan"),
            "e_t_median": float(np.median(e_t)) if len(v) else float("nan"),
            "e_R_mean": float(e_R.mean()) if len(v) else float("nan"),
            "e_R_median": float(np.median(e_R)) if len(v) else float("nan")}


def _line(name: str, s: dict[str, float]) -> str:
    return (f"{name:<26}{s['frames']:>6}{s['valid']:>6}{s['near']:>7}{s['off']:>6}{s['wrong']:>6}{s['flips']:>5}"
            f"{s['within']:>7}{s['e_t_mean']:>9.3f}{s['e_R_mean']:>8.2f}{s['e_R_median']:>8.2f}")


def main(argv: list[str]) -> int:
    runs = Path(argv[0]) if argv else Path("runs/s31")
    files = {"shipped": [runs / "w_a" / "pose_eval.json", runs / "w_b" / "pose_eval.json"],
             "candidate_first100": [runs / "w_cand100" / "pose_eval.json"]}
    rows = compact_rows(files, HERE / "rows.json.gz", KEYS)
    shipped = rows["shipped"]
    cand = candidate(shipped)
    print(f"{'set':<26}{'frames':>6}{'valid':>6}{'<=10deg':>7}{'>10':>6}{'wrong':>6}{'>90':>5}{'within':>7}"
          f"{'e_t mean':>9}{'e_R mean':>8}{'median':>8}")
    old, new = stats(shipped), stats(cand)
    print(_line("shipped", old))
    print(_line(f"candidate (cap {CAP_DEG:g} deg)", new))
    for cap in (2.0, 4.0, 5.0):
        print(_line(f"  reported: cap {cap:g} deg", stats(candidate(shipped, cap))))
    print(f"(<=10deg / >10: valid poses within / more than {OFF_DEG:g} deg off; wrong: e_R > 20 deg or e_t > 0.5 m; "
          f"within: e_t <= {BAR_T_M} m and e_R <= {BAR_R_DEG} deg)")
    print()
    print("refused by the cap, by route (e_R of each, deg):")
    for route in ROUTES:
        gone = sorted(round(float(r["e_R"]), 1) for r in shipped if refused(r) and r["decided_by"] == route)
        kept = sum(1 for r in shipped if r["valid"] and r["decided_by"] == route)
        print(f"  {route:<13} {len(gone)} of {kept}: {gone}")
    first = {r["frame"]: r for r in cand[:100]}
    ran = {r["frame"]: r for r in rows["candidate_first100"]}
    differ = [f for f in ran if f not in first or bool(ran[f]["valid"]) != bool(first[f]["valid"])
              or (ran[f]["valid"] and abs(float(ran[f]["e_R"]) - float(first[f]["e_R"])) > 1e-6)]
    print()
    print(f"the candidate bundle on the first {len(ran)} frames against the simulation: {len(differ)} frames differ"
          + (f" ({', '.join(differ[:10])})" if differ else ""))
    fails = []
    fails += [f"1. >10 deg {new['off']} > 0.7 x {old['off']}"] if new["off"] > 0.7 * old["off"] else []
    fails += [f"2. within 10 deg {new['near']} < 0.90 x {old['near']}"] if new["near"] < 0.90 * old["near"] else []
    fails += [f"3. within the bar {new['within']} < 0.95 x {old['within']}"] if new["within"] < 0.95 * old["within"] else []
    fails += ([f"4. mean e_R {new['e_R_mean']:.3f} >= {old['e_R_mean']:.3f}"]
              if not new["e_R_mean"] < old["e_R_mean"] else [])
    fails += [f"the candidate bundle differs from the simulation on {len(differ)} frames"] if differ or not ran else []
    print()
    print("reported, this bundle (with the cap) on the test split and the unseen set (committed eval-pose rows):")
    for name in ("pose_test640_s31", "pose_unseen1280_s31"):
        with gzip.open(HERE.parent / name / "pose_eval.json.gz", "rt") as fh:
            s = stats(json.load(fh)["frames"])
        print(f"  {name}: {s['valid']} of {s['frames']} valid, mean {s['e_t_mean']:.3f} m / {s['e_R_mean']:.2f} deg, "
              f"median {s['e_t_median']:.3f} m / {s['e_R_median']:.2f} deg, wrong {s['wrong']}, > 90 deg {s['flips']}, "
              f"within the bar {s['within']}")
    print()
    print("verdict (rule.txt, tdrs640_s31w seed 3141, 1,800 frames, cap 3 deg): "
          + ("MET" if not fails else "NOT MET: " + "; ".join(fails)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))

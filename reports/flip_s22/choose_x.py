"""X of reports/flip_s22/ship_rule.txt: the depth-tolerance cap for classifier-decided poses.

Usage: python reports/flip_s22/choose_x.py VAL2_EVAL.json [...]   (the candidate's eval-pose reports on val2)
"""
import gzip
import json
import math
import sys


def frames(path):
    opener = gzip.open if path.endswith(".gz") else open
    with opener(path, "rt") as fh:
        return json.load(fh)["frames"]


def wrong(f):
    return f["e_R"] > 20.0 or f["e_t"] > 0.5


spent = [f"reports/flip_s21/{s}_cand.json.gz" for s in ("val6", "v1280", "test", "unseen", "restyle", "val3_400",
                                                         "val4_400")]
pool = []
for path in sys.argv[1:] + spent:
    rows = [f for f in frames(path) if f["valid"] and f["decided_by"] == "classifier"]
    bad = [f for f in rows if wrong(f)]
    print(f"{path}: {len(rows)} classifier-decided, {len(bad)} wrong: "
          + ", ".join(f"{f['frame']} tau {f['depth_tolerance_m']:.3f} m, {f['e_R']:.1f} deg / {f['e_t']:.2f} m"
                      for f in bad))
    pool += rows
w = min(f["depth_tolerance_m"] for f in pool if wrong(f))
x = min(1.0, math.floor(0.9 * w / 0.05 + 1e-9) * 0.05)
kept = [f for f in pool if f["depth_tolerance_m"] <= x]
print(f"pooled {len(pool)} classifier-decided poses, {sum(map(wrong, pool))} wrong; w = {w:.4f} m; X = {x:.2f} m")
print(f"with X: {len(kept)} kept, {sum(map(wrong, kept))} wrong")

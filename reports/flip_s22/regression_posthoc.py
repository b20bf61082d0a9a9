"""The rule's regression check on session 21's single-frame sets: the candidate with the depth gate X is session
21's candidate with the classifier-decided poses whose depth tolerance exceeds X made invalid.

Usage: python reports/flip_s22/regression_posthoc.py [X]
"""
import gzip
import json
import sys

X = float(sys.argv[1]) if len(sys.argv) > 1 else 0.70


def frames(path):
    with gzip.open(path, "rt") as fh:
        return json.load(fh)["frames"]


def count(rows):
    valid = [f for f in rows if f["valid"]]
    return (len(valid), sum(f["e_R"] > 20.0 or f["e_t"] > 0.5 for f in valid), sum(f["e_R"] > 90.0 for f in valid))


print(f"X = {X:.2f} m; valid / wrong (> 20 deg or > 0.5 m) / flips")
print(f"{'set':10s} {'shipped':>14s} {'cand (s21)':>14s} {'cand + gate':>14s}  rule")
ok_all = True
for name in ("val6", "v1280", "test", "unseen", "restyle", "val3_400", "val4_400"):
    shipped = frames(f"reports/flip_s21/{name}_default.json.gz")
    cand = frames(f"reports/flip_s21/{name}_cand.json.gz")
    gated = [dict(f, valid=False) if f["valid"] and f["decided_by"] == "classifier"
             and not f["depth_tolerance_m"] <= X else f for f in cand]
    a, b, c = count(shipped), count(cand), count(gated)
    ok = c[1] <= a[1] and c[2] == 0
    ok_all &= ok
    print(f"{name:10s} {'%d/%d/%d' % a:>14s} {'%d/%d/%d' % b:>14s} {'%d/%d/%d' % c:>14s}  {'met' if ok else 'NOT met'}")
print("regression on single-frame sets:", "met" if ok_all else "NOT met")

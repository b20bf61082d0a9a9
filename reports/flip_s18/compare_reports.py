"""compare two eval-pose reports (pose_eval.json) frame by frame: valid, wrong (> 20 deg or > 0.5 m), flips (e_R > 90 deg).

    python reports/flip_s18/compare_reports.py A/pose_eval.json B/pose_eval.json
"""
import json, math, sys
import gzip

def load(p):
    return {r["frame"]: r for r in json.load((gzip.open if p.endswith(".gz") else open)(p, "rt"))["frames"]}
def stats(rows):
    v = [r for r in rows if r["valid"]]
    flips = sum(1 for r in v if r["e_R"] > 90)
    wrong = sum(1 for r in v if r["e_R"] > 20 or r["e_t"] > 0.5)
    good = [r for r in v if r["e_R"] <= 90]
    et = sum(r["e_t"] for r in good) / max(len(good), 1); er = sum(r["e_R"] for r in good) / max(len(good), 1)
    return dict(n=len(rows), valid=len(v), flips=flips, wrong=wrong, e_t=round(et, 4), e_R=round(er, 3))
a, b = load(sys.argv[1]), load(sys.argv[2])
common = sorted(set(a) & set(b))
print("A", stats([a[f] for f in common])); print("B", stats([b[f] for f in common]))
gained = [f for f in common if b[f]["valid"] and not a[f]["valid"]]
lost = [f for f in common if a[f]["valid"] and not b[f]["valid"]]
changed = [f for f in common if a[f]["valid"] and b[f]["valid"] and abs(a[f]["e_R"] - b[f]["e_R"]) > 1e-3]
print("gained", len(gained), "lost", len(lost), "changed", len(changed))
for f in gained: print("  +", f, b[f]["regime"], round(b[f]["e_t"], 3), round(b[f]["e_R"], 2), round(b[f].get("flip_prob", float("nan")), 3))
for f in lost: print("  -", f, a[f]["regime"], b[f]["status"], round(a[f]["e_R"], 2), round(b[f].get("flip_prob", float("nan")), 3))
